"""Shared pieces of the picture scripts (`demo.py`, `gallery.py`): materials, lights,
render settings, a soft spill group, and Madder's own settings for a spill. Import only
after `bpy` may be imported (BLENDER_USER_RESOURCES set)."""

import math

import bpy
import numpy as np
from mathutils import Vector


def material(name, colour, roughness=0.8):
    """A Principled BSDF material (node trees exist by default in 5.0, not before)."""
    mat = bpy.data.materials.new(name)
    mat.diffuse_color = (*colour[:3], 1.0)
    if mat.node_tree is None:  # made on request (use_nodes) before 5.0
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour[:3], 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    return mat


def fabric_material(name, colour, weave, thread_count, roughness=0.9):
    """A material with a Madder fabric: `weave` (one of fabrics.WEAVES) at `thread_count`
    threads per centimetre, weft along the UV u axis."""
    mat = material(name, colour, roughness)
    fab = mat.madder_fabric
    fab.enabled = True
    fab.weave = weave
    fab.thread_count = thread_count
    return mat


def camera(scene, location, target, lens=50.0, name="Camera"):
    cam = bpy.data.objects.new(name, bpy.data.cameras.new(name))
    scene.collection.objects.link(cam)
    cam.data.lens = lens
    aim(cam, location, target)
    scene.camera = cam
    return cam


def aim(cam, location, target):
    cam.location = location
    cam.rotation_euler = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()


def sun(scene, rotation_deg, energy, angle_deg=3.0, name="Sun"):
    light = bpy.data.lights.new(name, type="SUN")
    light.energy = energy
    light.angle = math.radians(angle_deg)
    obj = bpy.data.objects.new(name, light)
    scene.collection.objects.link(obj)
    obj.rotation_euler = [math.radians(a) for a in rotation_deg]
    return obj


def world(scene, colour, strength=1.0):
    w = bpy.data.worlds.new("World")
    if w.node_tree is None:  # made on request (use_nodes) before 5.0
        w.use_nodes = True
    bg = w.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*colour[:3], 1.0)
    bg.inputs["Strength"].default_value = strength
    scene.world = w


def cycles(scene, width, height, samples):
    """Cycles on the CPU, denoised (OpenImageDenoise ships with bpy on x86-64)."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = True
    scene.cycles.use_adaptive_sampling = True
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.look = "None"


def soft_group(obj, name, centre_world, radius):
    """Vertex group `name` on `obj`: weight 1 at `centre_world` falling as a cosine to 0
    at `radius` (3-D distance, metres); the number of member vertices."""
    n = len(obj.data.vertices)
    co = np.empty(n * 3)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(n, 3) @ np.array(obj.matrix_world.to_3x3()).T + np.array(obj.matrix_world.translation)
    dist = np.linalg.norm(co - np.asarray(centre_world), axis=1)
    inside = np.flatnonzero(dist < radius)
    group = obj.vertex_groups.new(name=name)
    for i, w in zip(inside.tolist(), (0.5 * (1.0 + np.cos(np.pi * dist[inside] / radius))).tolist(), strict=True):
        group.add([i], w, "REPLACE")
    return len(inside)
