"""Lamps and the scenes the per-pixel light tests share (add-on and Cycles): a black world,
sun, point, spot and area lamps, a plate over a ground, and a white Lambert plane seen from
above for the SG lamps."""

from __future__ import annotations

import bpy
import numpy as np

from prt_relight.bench import scenes


def black_world():
    scenes.add_world(image=scenes.float_image("black", np.zeros((8, 16, 3), np.float32)))


def sun_lamp(strength, angle, tilt=0.0):
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = strength, angle
    lamp = bpy.data.objects.new("Sun", sun)
    bpy.context.scene.collection.objects.link(lamp)
    lamp.rotation_euler = (tilt, 0.0, 0.0)
    return lamp


def local_lamp(kind, power, location, radius=0.1, rotation=(0.0, 0.0, 0.0), size=0.8,
                blend=0.2):
    light = bpy.data.lights.new(kind.title(), kind)
    light.energy, light.shadow_soft_size = power, radius
    if kind == "SPOT":
        light.spot_size, light.spot_blend = size, blend
    lamp = bpy.data.objects.new(kind.title(), light)
    bpy.context.scene.collection.objects.link(lamp)
    lamp.location, lamp.rotation_euler = location, rotation
    return lamp


def area_lamp(power, location, size, size_y=None, shape="SQUARE", rotation=(0.0, 0.0, 0.0)):
    light = bpy.data.lights.new("Area", "AREA")
    light.energy, light.shape, light.size = power, shape, size
    if size_y is not None:
        light.size_y = size_y
    lamp = bpy.data.objects.new("Area", light)
    bpy.context.scene.collection.objects.link(lamp)
    lamp.location, lamp.rotation_euler = location, rotation
    return lamp


def plate_over_ground(height=1.0):
    ground = scenes.add_ground(size=4.0, cuts=8)
    ground.data.materials.append(scenes.bsdf_material("Lambert", "ShaderNodeBsdfDiffuse",
                                                  Color=(0.8, 0.8, 0.8, 1.0)))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(-0.5, 0.0, height))
    return ground


def lamp_scene():


    scene = scenes.reset()
    world = bpy.data.worlds.new("Black")
    world.color = (0.0, 0.0, 0.0)
    for node in world.node_tree.nodes if world.node_tree else ():
        if node.type == "BACKGROUND":          # a new world has nodes in Blender 5
            node.inputs["Strength"].default_value = 0.0
    scene.world = world
    bpy.ops.mesh.primitive_plane_add(size=3.0)      # larger than the view: no partial edge pixels
    plane = bpy.context.object
    plane.data.materials.append(scenes.bsdf_material("White", "ShaderNodeBsdfDiffuse",
                                                 Color=(0.8, 0.8, 0.8, 1.0)))
    cam = scenes.add_camera(location=(0.0, 0.0, 5.0), rotation=(0.0, 0.0, 0.0), resolution=None)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 2.0
    scenes.set_resolution(16, 16)
    return scene


def add_light(kind, location=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), **props):

    data = bpy.data.lights.new(kind, kind)
    for k, v in props.items():
        setattr(data, k, v)
    ob = bpy.data.objects.new(kind, data)
    ob.location = location
    ob.rotation_euler = rotation
    bpy.context.scene.collection.objects.link(ob)
    return ob
