"""Build a natural scene in Blender and save it: nine rocks and two trees on a grassy mound,
lit by a sun and a sky. The scene whose objects volgen's samples must keep apart (docs/training.md,
"Objects"): rocks of varied size and shape stand a rock's width or less apart, so a generator
that blurs them runs them together; the trees (a brown trunk under a green crown) stand out of a
ground of another green.

    python tools/blender/make_rocks_scene.py OUT.blend [--seed S]

The scene lies inside volgen's cube [-1, 1]^3 (the ground's skirt reaches the cube's sides, its
rocks and trees within 0.75 of the z axis), so `volgen train` needs no --bounds; `--bounds auto`
works as well. Every rock is an icosphere pushed in and out by a seeded noise, scaled and turned,
sunk a little into the ground; every surface has a procedural texture (colour noise), which the
renders show as a real scene's grain. `export_dataset.py` renders it as a volgen dataset.
"""

import argparse
import math
import random
import sys

import bpy
from mathutils import Vector, noise

ROCKS = 9
TREES = 2
GRASS = (0.24, 0.42, 0.12)
ROCK = (0.42, 0.41, 0.39)
BARK = (0.28, 0.17, 0.09)
LEAVES = (0.08, 0.26, 0.07)


def material(name, rgb, grain=9.0):
    """Principled BSDF whose base colour varies by a noise texture between darker and lighter
    versions of `rgb`."""
    mat = bpy.data.materials.new(name)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.9
    tex = nodes.new("ShaderNodeTexNoise")
    tex.inputs["Scale"].default_value = grain
    tex.inputs["Detail"].default_value = 4.0
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (*(0.7 * c for c in rgb), 1.0)
    ramp.color_ramp.elements[1].color = (*(min(1.0, 1.25 * c) for c in rgb), 1.0)
    links.new(tex.outputs["Fac"], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def ground_height(x, y):
    """A low mound with gentle ripples (world units)."""
    return -0.6 + 0.14 * math.exp(-1.4 * (x * x + y * y)) + 0.015 * math.sin(6 * x) * math.cos(5 * y)


def add_ground():
    """A grid mesh following `ground_height`, 2 units wide, with a skirt down to z = -1."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=64, y_subdivisions=64, size=1.98)
    ground = bpy.context.active_object
    for v in ground.data.vertices:
        v.co.z = ground_height(v.co.x, v.co.y)
    ground.data.materials.append(material("grass", GRASS, grain=30.0))
    # Solidify downwards so the ground is a closed slab rather than a sheet.
    mod = ground.modifiers.new("slab", "SOLIDIFY")
    mod.thickness = 0.35
    mod.offset = -1.0
    return ground


def add_rock(rng, centre, size):
    """An icosphere displaced by noise, scaled to `size` (half extents) and turned."""
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=4, radius=1.0)
    rock = bpy.context.active_object
    offset = Vector((rng.uniform(0, 100), rng.uniform(0, 100), rng.uniform(0, 100)))
    for v in rock.data.vertices:
        n = noise.noise(v.co * 1.6 + offset)
        v.co *= 1.0 + 0.28 * n
    rock.scale = size
    rock.rotation_euler = (rng.uniform(-0.25, 0.25), rng.uniform(-0.25, 0.25), rng.uniform(0, math.tau))
    # Sunk by a fifth of its height into the ground under its centre.
    rock.location = (centre[0], centre[1], ground_height(*centre) + 0.8 * size[2])
    rock.data.materials.append(material(f"rock{len(bpy.data.materials)}", ROCK, grain=14.0))
    bpy.ops.object.shade_smooth()
    return rock


def add_tree(rng, centre):
    """A tapered trunk under a lumpy crown."""
    z0 = ground_height(*centre)
    height = rng.uniform(0.32, 0.4)
    bpy.ops.mesh.primitive_cone_add(vertices=16, radius1=0.05, radius2=0.03, depth=height)
    trunk = bpy.context.active_object
    trunk.location = (centre[0], centre[1], z0 + height / 2 - 0.02)
    trunk.data.materials.append(material("bark", BARK, grain=20.0))
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=1.0)
    crown = bpy.context.active_object
    offset = Vector((rng.uniform(0, 100), rng.uniform(0, 100), 0))
    for v in crown.data.vertices:
        v.co *= 1.0 + 0.22 * noise.noise(v.co * 2.2 + offset)
    radius = rng.uniform(0.17, 0.2)
    crown.scale = (radius, radius, 1.25 * radius)
    crown.location = (centre[0], centre[1], z0 + height + 0.9 * radius)
    crown.data.materials.append(material("leaves", LEAVES, grain=25.0))
    bpy.ops.object.shade_smooth()


def layout(rng):
    """Rock and tree positions: trees on opposite sides, rocks in two loose groups and
    alone between them, each a rock's width or less from a neighbour."""
    trees = [(-0.45, 0.35), (0.5, -0.3)]
    rocks = []
    while len(rocks) < ROCKS:
        angle = rng.uniform(0, math.tau)
        radius = rng.uniform(0.05, 0.7)
        p = (radius * math.cos(angle), radius * math.sin(angle))
        near_tree = any(math.dist(p, t) < 0.3 for t in trees)
        clear = all(math.dist(p, q) > 0.24 for q in rocks)
        if clear and not near_tree:
            rocks.append(p)
    return rocks, trees


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", help="the .blend file to write")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(sys.argv[1:])
    rng = random.Random(args.seed)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    add_ground()
    rocks, trees = layout(rng)
    for centre in rocks:
        size = (rng.uniform(0.07, 0.11), rng.uniform(0.06, 0.09), rng.uniform(0.06, 0.12))
        add_rock(rng, centre, size)
    for centre in trees:
        add_tree(rng, centre)
    bpy.ops.object.light_add(type="SUN", location=(0, 0, 3), rotation=(0.5, 0.15, 0.9))
    bpy.context.active_object.data.energy = 3.5
    world = bpy.data.worlds.new("sky")
    world.color = (0.35, 0.38, 0.42)
    bpy.context.scene.world = world
    bpy.ops.wm.save_as_mainfile(filepath=args.out)
    print(f"saved {args.out}: {len(rocks)} rocks, {len(trees)} trees")


if __name__ == "__main__":
    main()
