"""Load a mesh written by volgen (`volgen mesh`, `volgen sample --mesh`) into a .blend, where
the volume was.

With the `bpy` package from PyPI (bpy 5.0.x needs CPython 3.11):

    python tools/blender/import_mesh.py scene.blend scene_0.glb --out with_mesh.blend

Blender's own importer for the file's format reads it (glTF for .glb/.gltf, PLY, OBJ), with
the object at the identity transform: volgen writes vertices in the scene's coordinates (glTF
and OBJ y up, which the importers turn back to z up), so the mesh sits where the volume's box
was, which is where the dataset's scene was. Its material shows the vertex colours unlit (an
Emission shader of strength 1 reading the colour attribute): a radiance volume's colour is
what a camera sees, lighting included, so lighting it again would darken it. The object gets
the custom property `volgen_import` so that check_round_trip.py can tell it from the scene's
own meshes.
"""

import argparse
import os
import sys

import bpy


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("blend", help="the .blend to load the mesh into")
    parser.add_argument("mesh", help="the .glb, .gltf, .ply or .obj file volgen wrote")
    parser.add_argument("--out", required=True, help="save the .blend with the mesh here")
    return parser.parse_args(argv[1:])


def unlit_vertex_colours(name, attribute):
    """An Emission material of strength 1 coloured by the vertex colour `attribute`."""
    mat = bpy.data.materials.new(name)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    output = nodes.new("ShaderNodeOutputMaterial")
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    colour = nodes.new("ShaderNodeVertexColor")
    colour.layer_name = attribute
    links.new(colour.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], output.inputs["Surface"])
    for i, node in enumerate([colour, emission, output]):
        node.location = (250 * i - 500, 0)
    return mat


def import_mesh(path):
    """Imports the mesh at `path` into the current scene; returns its mesh objects."""
    before = set(bpy.data.objects)
    lower = path.lower()
    if lower.endswith((".glb", ".gltf")):
        bpy.ops.import_scene.gltf(filepath=os.path.abspath(path))
    elif lower.endswith(".ply"):
        bpy.ops.wm.ply_import(filepath=os.path.abspath(path))
    elif lower.endswith(".obj"):
        bpy.ops.wm.obj_import(filepath=os.path.abspath(path))
    else:
        sys.exit(f"error: {path}: expected a .glb, .gltf, .ply or .obj file")
    meshes = [o for o in set(bpy.data.objects) - before if o.type == "MESH"]
    if not meshes:
        sys.exit(f"error: {path} imported no mesh")
    for obj in meshes:
        attributes = obj.data.color_attributes
        if not attributes:
            sys.exit(f"error: {path}: the mesh {obj.name!r} has no colour attribute")
        obj.data.materials.clear()
        obj.data.materials.append(unlit_vertex_colours(f"{obj.name}_volgen", attributes[0].name))
        obj["volgen_import"] = True
    return meshes


def main():
    args = parse_args(sys.argv)
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
    for obj in import_mesh(args.mesh):
        corners = [obj.matrix_world @ v.co for v in obj.data.vertices]
        low = [min(c[i] for c in corners) for i in range(3)]
        high = [max(c[i] for c in corners) for i in range(3)]
        print(
            f"imported {args.mesh} as mesh object {obj.name!r}: {len(obj.data.vertices)} vertices, "
            f"bounds {[round(x, 3) for x in low]} to {[round(x, 3) for x in high]}"
        )
    bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.out))
    print(f"saved {args.out}")


if __name__ == "__main__":
    main()
