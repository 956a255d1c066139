"""Textured materials (issue 11, phase 1): an image-textured floor (Principled base colour from
a plank texture the script paints and packs into the .blend, repeated by a Mapping node), a
sphere coloured by a Color Ramp over a Gradient texture, and a cube whose Principled base
colour is a Checker on Generated coordinates mixed (Mix, MULTIPLY) with a tint, under a sun
and a dim world. docs/materials.md.

Every Principled BSDF has Specular IOR Level 0 (matte): this scene measures texturing; the
specular layer (Principled v2 layering) is compared on its own in
tests/test_principled_layering.py.
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

import bpy  # noqa: E402

FINISH = dict(resolution=(128, 96), samples=16)


def plank_pixels(w=128, h=128, seed=7):
    """RGBA floats in [0, 1] (sRGB-encoded bytes /255): 4 rows of planks with per-plank tone,
    a grain ripple and dark seams; deterministic."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    row = y // (h // 4)
    offset = (row * 37) % w
    plank = ((x + offset) // (w // 2)) + 2 * row
    tone = rng.uniform(0.75, 1.15, plank.max() + 1)[plank]
    grain = 0.08 * np.sin((x + offset) * 0.35 + row * 1.3) * np.sin(y * 0.9)
    base = np.array([0.55, 0.36, 0.2])
    rgb = np.clip(base[None, None, :] * (tone + grain)[..., None], 0, 1)
    seam = ((y % (h // 4)) < 2) | (((x + offset) % (w // 2)) < 2)
    rgb[seam] *= 0.35
    px = np.ones((h, w, 4))
    px[..., :3] = np.round(rgb * 255) / 255
    return px


def matte_principled(nodes):
    p = nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Specular IOR Level"].default_value = 0.0
    return p


def plank_image():
    img = bpy.data.images.new("planks", 128, 128, alpha=False, float_buffer=False)
    img.pixels.foreach_set(plank_pixels().reshape(-1).astype(np.float32))
    img.pack()
    return img


def floor_material():
    mat, nodes, out = C._new_material("Floor")
    nt = mat.node_tree
    tc = nodes.new("ShaderNodeTexCoord")
    mp = nodes.new("ShaderNodeMapping")
    mp.inputs["Scale"].default_value = (3.0, 3.0, 1.0)
    nt.links.new(tc.outputs["UV"], mp.inputs["Vector"])
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = plank_image()
    tex.interpolation = "Linear"
    nt.links.new(mp.outputs[0], tex.inputs["Vector"])
    p = matte_principled(nodes)
    p.inputs["Roughness"].default_value = 0.6
    nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    return mat


def ramp_material():
    mat, nodes, out = C._new_material("Ramp")
    nt = mat.node_tree
    tc = nodes.new("ShaderNodeTexCoord")
    grad = nodes.new("ShaderNodeTexGradient")
    grad.gradient_type = "LINEAR"
    mp = nodes.new("ShaderNodeMapping")
    mp.inputs["Rotation"].default_value = (0.0, C.deg(90), 0.0)  # x′ = z: gradient along Z
    nt.links.new(tc.outputs["Generated"], mp.inputs["Vector"])
    nt.links.new(mp.outputs[0], grad.inputs["Vector"])
    ramp = nodes.new("ShaderNodeValToRGB")
    els = ramp.color_ramp.elements
    els[0].position, els[0].color = 0.2, (0.8, 0.1, 0.05, 1.0)
    els[1].position, els[1].color = 0.85, (0.05, 0.25, 0.8, 1.0)
    mid = els.new(0.5)
    mid.color = (0.95, 0.8, 0.1, 1.0)
    nt.links.new(grad.outputs["Fac"], ramp.inputs["Fac"])
    p = matte_principled(nodes)
    p.inputs["Roughness"].default_value = 0.5
    nt.links.new(ramp.outputs["Color"], p.inputs["Base Color"])
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    return mat


def checker_material():
    mat, nodes, out = C._new_material("Checker")
    nt = mat.node_tree
    ck = nodes.new("ShaderNodeTexChecker")
    ck.inputs["Scale"].default_value = 4.0
    ck.inputs["Color1"].default_value = (0.9, 0.9, 0.85, 1.0)
    ck.inputs["Color2"].default_value = (0.1, 0.1, 0.12, 1.0)
    mix = nodes.new("ShaderNodeMix")
    mix.data_type, mix.blend_type = "RGBA", "MULTIPLY"
    socks = [s for s in mix.inputs if s.enabled]
    socks[0].default_value = 0.6
    nt.links.new(ck.outputs["Color"], socks[1])
    socks[2].default_value = (0.3, 0.9, 0.4, 1.0)
    p = matte_principled(nodes)
    p.inputs["Roughness"].default_value = 0.7
    nt.links.new([o for o in mix.outputs if o.enabled][0], p.inputs["Base Color"])
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    return mat


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.35, 0.4, 0.5), 0.4)
    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0, 0, 0))
    floor = bpy.context.object
    floor.name = "Floor"
    floor.data.materials.append(floor_material())
    C.uv_sphere("Ball", 0.7, (-0.9, 0.3, 0.7), ramp_material(), segments=48, rings=24)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(1.0, -0.2, 0.5), rotation=(0, 0, C.deg(25)))
    cube = bpy.context.object
    cube.name = "Cube"
    cube.data.materials.append(checker_material())
    C.light("Sun", "SUN", (0, 0, 5), rotation=(C.deg(40), C.deg(15), C.deg(30)), energy=3.0)
    C.camera((0.0, -5.0, 2.6), (0.0, 0.2, 0.4), lens=40.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "textured", **FINISH)
