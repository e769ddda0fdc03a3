"""Render a volgen dataset (transforms.json, RGBA PNGs, Z-pass EXRs) from a .blend.

With the `bpy` package from PyPI (bpy 5.0.x needs CPython 3.11):

    python tools/blender/export_dataset.py scene.blend --out DIR --views 100 --size 128

Inside Blender:

    blender -b scene.blend --python tools/blender/export_dataset.py -- --out DIR --views 100

Cameras are either the paper's hemisphere (default: `--views` cameras placed uniformly by area
on the upper half of a sphere around the scene, at least 0.05 of the radius above the
centre so that no camera sits on the horizon, field of view 33.4 degrees, radius 3.5 times
the half side of the scene's bounding cube, looking at its centre with +Z up) or the scene's
own camera objects (`--cameras scene`). Each view is rendered with Cycles on a transparent
film: `images/r_000.png` holds straight-alpha RGBA (view transform Standard, so colours are the
scene's linear colours encoded as sRGB) and `depth/r_000.exr` Blender's Depth pass (channel
`ViewLayer.Depth.Z`, planar depth, 1e10 where nothing is hit), so transforms.json says
`"depth_kind": "z"` and volgen converts it to expected depth on loading.

The script prints the scene's bounds (the bounding box of its visible meshes) as the
`--bounds` flag of `volgen train`: a scene outside volgen's cube [-1, 1]^3 needs it (or
`--bounds auto`, the box of the depth maps' points).
"""

import argparse
import json
import math
import os
import random
import sys

import bpy
from mathutils import Matrix, Vector

PAPER_FOV_DEG = 33.4
PAPER_RADIUS = 3.5


def parse_args(argv):
    inside_blender = "--" in argv
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    if not inside_blender:
        parser.add_argument("blend", help="the .blend file to render")
    parser.add_argument("--out", required=True, help="the dataset directory to write")
    parser.add_argument("--views", type=int, default=100, help="hemisphere cameras (default 100)")
    parser.add_argument("--size", type=int, default=128, help="image width and height (default 128)")
    parser.add_argument(
        "--cameras",
        choices=["hemisphere", "scene"],
        default="hemisphere",
        help="the paper's hemisphere around the scene (default) or the scene's camera objects",
    )
    parser.add_argument("--samples", type=int, default=32, help="Cycles samples per pixel (default 32)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the hemisphere placement")
    args = parser.parse_args(argv[argv.index("--") + 1 :] if inside_blender else argv[1:])
    if args.views < 1 or args.size < 1 or args.samples < 1:
        parser.error("--views, --size and --samples must be at least 1")
    return args


def scene_bounds(scene):
    """The world-space bounding box of the visible meshes."""
    lo = Vector((math.inf,) * 3)
    hi = Vector((-math.inf,) * 3)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for obj in scene.objects:
        if obj.type != "MESH" or obj.hide_render:
            continue
        evaluated = obj.evaluated_get(depsgraph)
        for corner in evaluated.bound_box:
            p = evaluated.matrix_world @ Vector(corner)
            lo = Vector(map(min, lo, p))
            hi = Vector(map(max, hi, p))
    if lo.x == math.inf:
        sys.exit("error: the scene has no visible mesh to render")
    return lo, hi


def report_bounds(lo, hi):
    flag = ",".join(f"{v:.4g}" for v in (*lo, *hi))
    inside = min(lo) >= -1.0 and max(hi) <= 1.0
    where = "inside [-1, 1]^3, no --bounds needed" if inside else "outside [-1, 1]^3"
    print(f"scene bounds: --bounds {flag} ({where})")


def look_at(eye, target):
    """Camera-to-world rotation looking from `eye` at `target` with +Z up (-Z forward, +Y up)."""
    forward = (target - eye).normalized()
    up = Vector((0.0, 0.0, 1.0))
    if abs(forward.dot(up)) > 0.999:
        up = Vector((0.0, 1.0, 0.0))
    right = forward.cross(up).normalized()
    true_up = right.cross(forward)
    return Matrix((right, true_up, -forward)).transposed()


def hemisphere_matrices(views, centre, radius, seed):
    """`views` camera-to-world matrices uniform by area on the upper hemisphere, above 0.05 of
    the radius."""
    rng = random.Random(seed)
    matrices = []
    for _ in range(views):
        z = rng.uniform(0.05, 1.0)  # uniform z is uniform area; keep off the horizon
        phi = rng.uniform(0.0, 2.0 * math.pi)
        r = math.sqrt(1.0 - z * z)
        eye = centre + radius * Vector((r * math.cos(phi), r * math.sin(phi), z))
        m = look_at(eye, centre).to_4x4()
        m.translation = eye
        matrices.append(m)
    return matrices


def rigid(matrix):
    """The rotation and translation of a camera's world matrix, without scale."""
    loc, rot, _ = matrix.decompose()
    m = rot.to_matrix().to_4x4()
    m.translation = loc
    return m


def setup_render(scene, size, samples):
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.render.resolution_x = size
    scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    for layer in scene.view_layers:
        layer.use_pass_z = True


def save(scene, path, media_type, file_format, **settings):
    """Saves the last render; `media_type` is Blender 5's split of single- and multilayer."""
    image_settings = scene.render.image_settings
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = media_type
    image_settings.file_format = file_format
    for key, value in settings.items():
        setattr(image_settings, key, value)
    # Through a temporary name (same extension, which Blender's writers go by): a file under
    # its final name is complete.
    root, extension = os.path.splitext(path)
    partial = f"{root}.partial{extension}"
    bpy.data.images["Render Result"].save_render(filepath=partial, scene=scene)
    os.replace(partial, path)


def claim_output(out, args):
    """Record the settings that decide the views in OUT/export_settings.json, or check them
    against an earlier, killed export's: resuming with other settings would mix two datasets."""
    settings = {
        "blend": os.path.abspath(args.blend) if getattr(args, "blend", None) else None,
        "size": args.size,
        "samples": args.samples,
        "views": args.views,
        "seed": args.seed,
        "cameras": args.cameras,
    }
    path = os.path.join(out, "export_settings.json")
    if os.path.exists(path):
        with open(path) as f:
            earlier = json.load(f)
        if earlier != settings:
            sys.exit(
                f"error: {out} holds an export made with other settings ({path}: {earlier}, "
                f"this export: {settings}); give another --out or delete it"
            )
        return
    with open(path + ".tmp", "w") as f:
        json.dump(settings, f, indent=2)
    os.replace(path + ".tmp", path)


def main():
    args = parse_args(sys.argv)
    if "--" not in sys.argv:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
    scene = bpy.context.scene
    lo, hi = scene_bounds(scene)
    report_bounds(lo, hi)
    setup_render(scene, args.size, args.samples)

    if args.cameras == "scene":
        cameras = [o for o in scene.objects if o.type == "CAMERA"]
        if not cameras:
            sys.exit("error: --cameras scene, but the scene has no camera object")
        angles = {round(c.data.angle_x, 6) for c in cameras}
        if len(angles) != 1:
            sys.exit(f"error: the scene's cameras have different fields of view {sorted(angles)}")
        fov_x = cameras[0].data.angle_x
        matrices = [rigid(c.matrix_world) for c in cameras]
    else:
        fov_x = math.radians(PAPER_FOV_DEG)
        half_side = max(max(hi - lo) / 2.0, 1e-3)
        centre = (lo + hi) / 2.0
        matrices = hemisphere_matrices(args.views, centre, PAPER_RADIUS * half_side, args.seed)

    camera_data = bpy.data.cameras.new("volgen_export")
    camera_data.sensor_fit = "HORIZONTAL"
    camera_data.angle_x = fov_x
    camera_data.clip_start = 0.01
    camera_data.clip_end = 1000.0
    camera = bpy.data.objects.new("volgen_export", camera_data)
    scene.collection.objects.link(camera)
    scene.camera = camera

    out = os.path.abspath(args.out)
    os.makedirs(os.path.join(out, "images"), exist_ok=True)
    os.makedirs(os.path.join(out, "depth"), exist_ok=True)
    claim_output(out, args)
    frames = []
    for i, matrix in enumerate(matrices):
        colour, depth = f"images/r_{i:03d}.png", f"depth/r_{i:03d}.exr"
        frame = {
            "file_path": colour,
            "depth_file_path": depth,
            "transform_matrix": [list(row) for row in matrix],
        }
        frames.append(frame)
        # Both files are written atomically, the colour last: its presence means the view is
        # complete, so a killed export resumes where it stopped.
        if os.path.exists(os.path.join(out, colour)):
            print(f"view {i + 1}/{len(matrices)} kept from an earlier run", flush=True)
            continue
        camera.matrix_world = matrix
        bpy.ops.render.render(write_still=False)
        # The multilayer EXR holds every pass; volgen reads the channel ending in `.Z`.
        save(scene, os.path.join(out, depth), "MULTI_LAYER_IMAGE", "OPEN_EXR_MULTILAYER",
             color_depth="32", exr_codec="ZIP")
        save(scene, os.path.join(out, colour), "IMAGE", "PNG", color_mode="RGBA", color_depth="8")
        print(f"view {i + 1}/{len(matrices)} rendered", flush=True)
    transforms = {
        "camera_angle_x": fov_x,
        "w": args.size,
        "h": args.size,
        "depth_kind": "z",
        "frames": frames,
    }
    # transforms.json last, through a temporary name: a directory holding it is complete.
    path = os.path.join(out, "transforms.json")
    with open(path + ".tmp", "w") as f:
        json.dump(transforms, f, indent=2)
    os.replace(path + ".tmp", path)
    print(f"wrote {len(frames)} views to {path}")


if __name__ == "__main__":
    main()
