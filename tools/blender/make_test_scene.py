"""Build the round trip's small scene and save it: a few coloured primitives on a ground plane,
lit by a sun, away from the origin (centred at OFFSET) so that the round trip needs and tests
`volgen train --bounds`. With --textured every surface's colour varies by a procedural noise
(darker and lighter than its colour), which structure from motion needs to find features
(tools/colmap/sfm_check.sh).

    python tools/blender/make_test_scene.py OUT.blend [--textured]
"""

import sys

import bpy
from mathutils import Vector

OFFSET = Vector((2.0, -1.0, 0.5))


TEXTURED = "--textured" in sys.argv


def material(name, rgb):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.8
    if TEXTURED:
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        noise = nodes.new("ShaderNodeTexNoise")
        noise.inputs["Scale"].default_value = 9.0
        noise.inputs["Detail"].default_value = 6.0
        ramp = nodes.new("ShaderNodeValToRGB")
        ramp.color_ramp.elements[0].color = (*(0.25 * c for c in rgb), 1.0)
        ramp.color_ramp.elements[1].color = (*(min(1.0, 0.3 + c) for c in rgb), 1.0)
        links.new(noise.outputs["Fac"], ramp.inputs["Fac"])
        links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def add(op, rgb, location, **kwargs):
    op(location=OFFSET + Vector(location), **kwargs)
    obj = bpy.context.active_object
    obj.data.materials.append(material(obj.name, rgb))
    return obj


def main():
    args = [a for a in sys.argv[1:] if a != "--textured"]
    if len(args) != 1:
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
    bpy.ops.wm.save_as_mainfile(filepath=args[0])


if __name__ == "__main__":
    main()
