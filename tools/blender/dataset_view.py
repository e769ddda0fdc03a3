"""Rendering a .blend's scene as a volgen dataset's camera sees it, for the checks that compare
Blender's renders with a dataset's images or volgen's renders (check_round_trip.py,
mesh_accuracy.py)."""

import os
import tempfile

import bpy
from mathutils import Matrix


def set_up_cycles(scene, transforms, samples):
    """Cycles on the CPU at the dataset's resolution, a transparent film and the Standard view
    transform (colours written as they are), RGBA PNG output."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.render.resolution_x = transforms["w"]
    scene.render.resolution_y = transforms["h"]
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    settings = scene.render.image_settings
    settings.media_type = "IMAGE"
    settings.file_format = "PNG"
    settings.color_mode = "RGBA"


def render_frame(scene, transforms, frame):
    """Renders `frame` (an entry of transforms.json's frames) with the scene's render settings
    and returns the path of the PNG written; the camera is removed again."""
    data = bpy.data.cameras.new("dataset_view")
    data.sensor_fit = "HORIZONTAL"
    data.angle_x = transforms["camera_angle_x"]
    camera = bpy.data.objects.new("dataset_view", data)
    scene.collection.objects.link(camera)
    camera.matrix_world = Matrix(frame["transform_matrix"])
    scene.camera = camera
    bpy.ops.render.render()
    path = os.path.join(tempfile.mkdtemp(), "render.png")
    bpy.data.images["Render Result"].save_render(filepath=path, scene=scene)
    bpy.data.objects.remove(camera)
    return path
