"""Render an imported volgen volume or mesh with Cycles from a dataset's camera and check that
it is non-empty where the scene was (the round trip's last step; see round_trip.sh).

    python tools/blender/check_round_trip.py with_volume.blend DATASET --view 0 --picture out.png

Only what volgen made is rendered: Volume objects (import_volume.py) and meshes import_mesh.py
marked `volgen_import`; the scene's own meshes are hidden. The check compares the render's
opacity with the dataset image's: the import must cover the scene's pixels (mean
opacity over pixels with dataset alpha > 0.5 at least --min-inside) and be clearly fainter
elsewhere (mean opacity over pixels with alpha < 0.05 below the inside mean by at least
--min-contrast). --picture writes the dataset view and the volume's render side by side on grey.
"""

import argparse
import json
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from dataset_view import render_frame, set_up_cycles  # noqa: E402


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("blend", help="the .blend holding the imported volume or mesh")
    parser.add_argument("dataset", help="the dataset directory the scene was exported to")
    parser.add_argument("--view", type=int, default=0, help="the dataset frame to render (default 0)")
    parser.add_argument("--samples", type=int, default=32, help="Cycles samples (default 32)")
    parser.add_argument("--picture", help="write dataset view | volume render here (PNG)")
    parser.add_argument("--min-inside", type=float, default=0.3)
    parser.add_argument("--min-contrast", type=float, default=0.15)
    return parser.parse_args(argv[1:])


def rgba(path):
    """An image file's pixels as rows of (r, g, b, a), bottom row first (Blender's order)."""
    image = bpy.data.images.load(os.path.abspath(path))
    w, h = image.size
    flat = list(image.pixels)
    return w, h, [tuple(flat[4 * i : 4 * i + 4]) for i in range(w * h)]


def main():
    args = parse_args(sys.argv)
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
    scene = bpy.context.scene
    imported = [o for o in scene.objects if o.type == "VOLUME" or o.get("volgen_import")]
    if not imported:
        sys.exit(f"error: {args.blend} has no Volume object and no mesh import_mesh.py imported")
    for obj in scene.objects:
        if obj.type == "MESH" and not obj.get("volgen_import"):
            obj.hide_render = True

    with open(os.path.join(args.dataset, "transforms.json")) as f:
        transforms = json.load(f)
    frame = transforms["frames"][args.view]
    set_up_cycles(scene, transforms, args.samples)
    rendered_path = render_frame(scene, transforms, frame)

    kind = "volume" if any(o.type == "VOLUME" for o in imported) else "mesh"
    w, h, truth = rgba(os.path.join(args.dataset, frame["file_path"]))
    _, _, render = rgba(rendered_path)
    inside = [r[3] for t, r in zip(truth, render) if t[3] > 0.5]
    outside = [r[3] for t, r in zip(truth, render) if t[3] < 0.05]
    mean = lambda xs: sum(xs) / max(len(xs), 1)
    inside_mean, outside_mean = mean(inside), mean(outside)
    print(
        f"{kind} opacity: {inside_mean:.3f} mean over the scene's {len(inside)} pixels, "
        f"{outside_mean:.3f} over the {len(outside)} empty ones"
    )

    if args.picture:
        picture = bpy.data.images.new("round_trip", 2 * w, h, alpha=False)
        pixels = [0.0] * (8 * w * h)
        for half, source in enumerate([truth, render]):
            for i, (r, g, b, a) in enumerate(source):
                y, x = divmod(i, w)
                j = 4 * (y * 2 * w + half * w + x)
                grey = 0.5 * (1.0 - a)
                pixels[j : j + 4] = [r * a + grey, g * a + grey, b * a + grey, 1.0]
        picture.pixels = pixels
        picture.filepath_raw = os.path.abspath(args.picture)
        picture.file_format = "PNG"
        picture.save()
        print(f"picture: {args.picture}")

    if inside_mean < args.min_inside or inside_mean - outside_mean < args.min_contrast:
        sys.exit(
            f"error: the imported {kind} is not where the scene was (need opacity >= "
            f"{args.min_inside} over the scene and {args.min_contrast} more than elsewhere)"
        )
    print(f"round trip ok: the {kind} is where the scene was")


if __name__ == "__main__":
    main()
