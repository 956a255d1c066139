"""An HDRI-lit scene (issue 11, World): a sunny sky the script generates — a 512 × 256
equirectangular float image (half-float EXR, packed into the .blend): a blue gradient sky, a
dim brown ground and a very bright sun disk (1° radius, radiance 15 000, about 80 % of the
irradiance on an upward surface) — seen through a Mapping node that turns it 40° about Z, lighting
a diffuse floor, a diffuse sphere, two glossy spheres (roughness 0.3 and 0.45: sharper ones make diffuse → glossy → sun caustics whose fireflies dominate both renderers' error) and a matte cube.
Nothing else lights the scene: the sun's shadows and highlights come from importance sampling
the world's map (docs/materials.md, World)."""

import math
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

import bpy  # noqa: E402

FINISH = dict(resolution=(160, 96), samples=64)
SKY_W, SKY_H = 512, 256
SUN_ELEVATION, SUN_AZIMUTH, SUN_RADIUS, SUN_RADIANCE = 35.0, 120.0, 1.0, 15000.0


def sky_pixels(w=SKY_W, h=SKY_H):
    """(h, w, 4) float32 linear RGBA, bottom row first (Blender's order), of the sunny sky in
    Cycles's equirectangular layout (u = ½ − φ/2π, v = 1 − θ/π)."""
    sub = 4  # supersampling per pixel side: the sun disk is anti-aliased
    u = (np.arange(w * sub) + 0.5) / (w * sub)
    v = (np.arange(h * sub) + 0.5) / (h * sub)
    uu, vv = np.meshgrid(u, v)
    phi = np.pi - 2 * np.pi * uu
    theta = np.pi - np.pi * vv
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    z = d[..., 2]
    up = np.clip(z, 0, 1)[..., None]
    horizon = np.array([0.95, 0.97, 1.0])
    zenith = np.array([0.18, 0.35, 0.85])
    sky = horizon + (zenith - horizon) * up ** 0.6
    ground = np.array([0.22, 0.17, 0.12]) * (0.6 + 0.4 * np.clip(-z, 0, 1))[..., None]
    rgb = np.where(z[..., None] >= 0, sky, ground)
    el, az = math.radians(SUN_ELEVATION), math.radians(SUN_AZIMUTH)
    sun = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    in_sun = d @ sun > math.cos(math.radians(SUN_RADIUS))
    rgb = np.where(in_sun[..., None], SUN_RADIANCE * np.array([1.0, 0.95, 0.85]), rgb)
    rgb = rgb.reshape(h, sub, w, sub, 3).mean(axis=(1, 3))
    px = np.ones((h, w, 4), np.float32)
    px[..., :3] = rgb
    return px


def sky_image():
    """The sky as a half-float EXR (written to a temporary file, loaded and packed)."""
    import OpenEXR

    px = sky_pixels()
    path = os.path.join(tempfile.mkdtemp(), "sunny_sky.exr")
    top_first = np.ascontiguousarray(px[::-1, :, :3].astype(np.float16))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": top_first}) as f:
        f.write(path)
    img = bpy.data.images.load(path)
    img.colorspace_settings.name = "Linear Rec.709"
    img.pack()
    return img


def set_hdri_world(world):
    nt = world.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputWorld")
    tc = nt.nodes.new("ShaderNodeTexCoord")
    mp = nt.nodes.new("ShaderNodeMapping")
    mp.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(40.0))
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = sky_image()
    env.interpolation = "Linear"
    bg = nt.nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = 1.0
    nt.links.new(tc.outputs["Generated"], mp.inputs["Vector"])
    nt.links.new(mp.outputs[0], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    nt.links.new(bg.outputs[0], out.inputs["Surface"])
    world.color = (0.5, 0.6, 0.8)


def build():
    scene = C.reset()
    set_hdri_world(scene.world)
    C.quad("Floor", (0, 0, 0), (16.0, 16.0), C.diffuse("Floor", (0.45, 0.45, 0.42)))
    C.uv_sphere("Diffuse", 0.6, (-1.3, 0.4, 0.6), C.diffuse("Orange", (0.8, 0.35, 0.1)), segments=48, rings=24)
    C.uv_sphere("Chrome", 0.6, (0.1, 0.9, 0.6), C.glossy("Chrome", (0.9, 0.9, 0.9), 0.3), segments=48, rings=24)
    C.uv_sphere("Gold", 0.45, (1.3, 0.0, 0.45), C.glossy("Gold", (0.9, 0.6, 0.25), 0.45), segments=48, rings=24)
    C.box("Cube", (0.7, 0.7, 0.7), (-0.2, -0.8, 0.35), C.diffuse("Teal", (0.15, 0.55, 0.5)), rotation_z=0.4)
    C.camera((0.3, -6.0, 2.2), (0.0, 0.3, 0.6), lens=35.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "hdri", **FINISH)
