"""Build the round trip's small scene and save it: a few coloured primitives on a ground plane,
lit by a sun, away from the origin (centred at OFFSET) so that the round trip needs and tests
`volgen train --bounds`.

    python tools/blender/make_test_scene.py OUT.blend
"""

import sys

import bpy
from mathutils import Vector

OFFSET = Vector((2.0, -1.0, 0.5))


def material(name, rgb):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.8
    return mat


def add(op, rgb, location, **kwargs):
    op(location=OFFSET + Vector(location), **kwargs)
    obj = bpy.context.active_object
    obj.data.materials.append(material(obj.name, rgb))
    return obj


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    add(bpy.ops.mesh.primitive_plane_add, (0.35, 0.55, 0.25), size=1.8, location=(0, 0, -0.4))
    add(bpy.ops.mesh.primitive_cube_add, (0.8, 0.25, 0.15), size=0.5, location=(-0.4, -0.3, -0.15))
    add(bpy.ops.mesh.primitive_uv_sphere_add, (0.2, 0.35, 0.85), radius=0.3, location=(0.35, 0.2, -0.1))
    add(
        bpy.ops.mesh.primitive_cylinder_add,
        (0.9, 0.8, 0.3),
        radius=0.15,
        depth=0.7,
        location=(-0.2, 0.45, -0.05),
    )
    bpy.ops.object.light_add(type="SUN", location=OFFSET + Vector((0, 0, 3)), rotation=(0.6, 0.2, 0.8))
    bpy.context.active_object.data.energy = 3.0
    world = bpy.data.worlds.new("world")
    world.color = (0.3, 0.3, 0.3)
    bpy.context.scene.world = world
    bpy.ops.wm.save_as_mainfile(filepath=sys.argv[1])


if __name__ == "__main__":
    main()
