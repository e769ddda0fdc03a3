"""Open meshes written by `volgen mesh` in Blender (the bpy package) and check what arrived.

    python tools/blender/check_mesh.py mesh.glb mesh.ply mesh.obj [--expect-vertices N]
        [--picture out.png]

Each file is imported into an empty scene with Blender's own importer for its format (glTF,
PLY, OBJ); the script prints the object's vertex and face counts, its bounds and its colour
attribute, and exits non-zero when a file imports no mesh, no colour attribute, or (with
--expect-vertices) another vertex count than volgen reported, or when the files' bounds in
Blender disagree (glTF and OBJ are written y up and turned back to z up by the importers, PLY
stays z up: all must land where the volume's VDB does). glTF's importer merges nothing by
default, PLY's and OBJ's neither, so the counts compare exactly. With --picture, the last file
is rendered by Blender's Workbench engine with its vertex colours, from above and aside.
"""

import argparse
import math
import sys

import bpy
import mathutils


def import_file(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    lower = path.lower()
    if lower.endswith((".glb", ".gltf")):
        bpy.ops.import_scene.gltf(filepath=path)
    elif lower.endswith(".ply"):
        bpy.ops.wm.ply_import(filepath=path)
    elif lower.endswith(".obj"):
        bpy.ops.wm.obj_import(filepath=path)
    else:
        raise SystemExit(f"{path}: not a .glb, .gltf, .ply or .obj file")
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    if not meshes:
        raise SystemExit(f"{path}: Blender imported no mesh")
    return meshes[0]


def render_picture(obj, path, size=512):
    """Workbench, flat studio light, the colour attribute shown; camera on the box's diagonal."""
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "FLAT"
    scene.display.shading.color_type = "VERTEX"
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.film_transparent = False
    scene.world = bpy.data.worlds.new("white") if scene.world is None else scene.world
    scene.world.color = (1.0, 1.0, 1.0)
    corners = [obj.matrix_world @ mathutils.Vector(c) for c in obj.bound_box]
    centre = sum(corners, mathutils.Vector()) / 8
    radius = max((c - centre).length for c in corners)
    camera_data = bpy.data.cameras.new("camera")
    camera = bpy.data.objects.new("camera", camera_data)
    scene.collection.objects.link(camera)
    direction = mathutils.Vector((1.0, -1.2, 1.1)).normalized()
    camera.location = centre + direction * radius * 3.2
    camera.rotation_euler = (centre - camera.location).to_track_quat("-Z", "Y").to_euler()
    camera_data.lens_unit = "FOV"
    camera_data.angle = math.radians(40)
    scene.camera = camera
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    print(f"picture: {path}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="+")
    parser.add_argument("--expect-vertices", type=int, default=None)
    parser.add_argument("--picture", default=None, help="render the last file to this PNG")
    args = parser.parse_args()
    failed = False
    first_bounds = None
    for path in args.files:
        obj = import_file(path)
        mesh = obj.data
        colours = mesh.color_attributes
        corners = [obj.matrix_world @ v.co for v in mesh.vertices]
        low = [min(c[i] for c in corners) for i in range(3)]
        high = [max(c[i] for c in corners) for i in range(3)]
        colour = colours[0] if len(colours) else None
        print(
            f"{path}: {len(mesh.vertices)} vertices, {len(mesh.polygons)} faces, "
            f"bounds {[round(x, 3) for x in low]}..{[round(x, 3) for x in high]}, "
            f"colour attribute {colour.name + ' (' + colour.domain + ')' if colour else 'none'}"
        )
        if first_bounds is None:
            first_bounds = (low, high)
        elif max(abs(a - b) for a, b in zip(first_bounds[0] + first_bounds[1], low + high)) > 1e-3:
            print(f"{path}: bounds differ from {args.files[0]}'s", file=sys.stderr)
            failed = True
        if colour is None:
            print(f"{path}: no colour attribute", file=sys.stderr)
            failed = True
        if args.expect_vertices is not None and len(mesh.vertices) != args.expect_vertices:
            print(f"{path}: expected {args.expect_vertices} vertices", file=sys.stderr)
            failed = True
    if args.picture:
        render_picture(obj, args.picture)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
