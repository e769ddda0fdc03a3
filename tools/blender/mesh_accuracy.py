"""How closely Blender's rendering of a volgen mesh matches volgen's rendering of its volume.

    volgen render scene_0.safetensors --cameras DATASET/transforms.json --width W --height H \
        --samples 256 --out renders/
    python tools/blender/mesh_accuracy.py scene_0.glb DATASET renders/ [--views 8] [--samples 16]

The mesh is imported with Blender's own importer (import_mesh.py: unlit vertex colours, at the
identity transform) into an empty scene and rendered by Cycles from `--views` of the dataset's
frames spread over them, with a transparent film; each render is compared with volgen's EXR of
the same frame (`volgen render` writes premultiplied colour over black and the opacity as A):
the silhouette IoU (Blender's alpha >= 1/2 against volgen's opacity >= 1/2) and the colour
PSNR with both composited over white, over the whole images and over the pixels both cover.
Prints one line per view and the totals.
"""

import argparse
import json
import math
import os
import sys

import bpy
import numpy as np
import OpenEXR

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from dataset_view import render_frame, set_up_cycles  # noqa: E402
from import_mesh import import_mesh  # noqa: E402


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mesh", help="the .glb, .gltf, .ply or .obj file volgen wrote")
    parser.add_argument("dataset", help="the dataset whose transforms.json volgen rendered from")
    parser.add_argument("renders", help="the directory `volgen render` wrote its EXR files to")
    parser.add_argument("--views", type=int, default=8, help="frames compared (default 8)")
    parser.add_argument("--samples", type=int, default=16, help="Cycles samples (default 16)")
    return parser.parse_args(argv[1:])


def blender_rgba(path):
    """An image file as Blender loads it: (h, w, 4) floats, top row first."""
    image = bpy.data.images.load(os.path.abspath(path))
    w, h = image.size
    flat = np.empty(w * h * 4, dtype=np.float32)
    image.pixels.foreach_get(flat)
    bpy.data.images.remove(image)
    return flat.reshape(h, w, 4)[::-1]


def volgen_rgba(path):
    """`volgen render`'s EXR (colour premultiplied over black, A the opacity): (h, w, 4), top
    row first, read by OpenEXR's own bindings."""
    with OpenEXR.File(path, separate_channels=True) as exr:
        channels = exr.channels()
        missing = {"R", "G", "B", "A"} - set(channels)
        if missing:
            sys.exit(f"error: {path}: no channel {sorted(missing)}; is it `volgen render`'s?")
        return np.stack([channels[c].pixels.astype(np.float32) for c in "RGBA"], axis=-1)


def psnr(squared, count):
    return -10.0 * math.log10(max(squared / max(count, 1), 1e-12))


def main():
    args = parse_args(sys.argv)
    with open(os.path.join(args.dataset, "transforms.json")) as f:
        transforms = json.load(f)
    frames = transforms["frames"]
    if args.views < 1 or args.views > len(frames):
        sys.exit(f"error: --views: expected 1 to {len(frames)} (the dataset's frames), got {args.views}")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    import_mesh(args.mesh)
    scene = bpy.context.scene
    set_up_cycles(scene, transforms, args.samples)

    both = either = 0
    squared = squared_both = 0.0
    values = values_both = 0
    for view in range(args.views):
        frame = frames[view * len(frames) // args.views]
        stem = os.path.splitext(os.path.basename(frame["file_path"]))[0]
        exr = os.path.join(args.renders, f"{stem}.exr")
        if not os.path.isfile(exr):
            sys.exit(f"error: {exr}: no volgen rendering of frame {stem!r} (run `volgen render` first)")
        mesh = blender_rgba(render_frame(scene, transforms, frame))
        volume = volgen_rgba(exr)
        if mesh.shape != volume.shape:
            sys.exit(f"error: {exr}: {volume.shape[1]}x{volume.shape[0]} pixels, Blender rendered "
                     f"{mesh.shape[1]}x{mesh.shape[0]} (the dataset's w and h)")
        mesh_alpha, volume_alpha = mesh[..., 3:], volume[..., 3:]
        over_white_mesh = mesh[..., :3] * mesh_alpha + 1.0 - mesh_alpha
        over_white_volume = volume[..., :3] + 1.0 - volume_alpha
        error = ((over_white_mesh - over_white_volume) ** 2).sum(axis=-1)
        mesh_covers, volume_covers = mesh_alpha[..., 0] >= 0.5, volume_alpha[..., 0] >= 0.5
        view_both = int((mesh_covers & volume_covers).sum())
        view_either = int((mesh_covers | volume_covers).sum())
        both += view_both
        either += view_either
        squared += float(error.sum())
        values += 3 * error.size
        squared_both += float(error[mesh_covers & volume_covers].sum())
        values_both += 3 * view_both
        print(f"view {stem}: silhouette IoU {view_both / max(view_either, 1):.3f}, "
              f"colour PSNR {psnr(float(error.sum()), 3 * error.size):.2f} dB")
    print(
        f"{args.mesh}: {args.views} views, silhouette IoU {both / max(either, 1):.3f}, "
        f"colour PSNR {psnr(squared, values):.2f} dB, "
        f"where both cover {psnr(squared_both, values_both):.2f} dB"
    )


if __name__ == "__main__":
    main()
