"""Alpha cut-outs, normal maps and bump (issue 11): leaf cards whose Principled Alpha comes from
an image's alpha (they cast cut-out shadows: transparent shadows), a fence cut out by a Brick
texture, a sphere with a tangent-space normal map (an image the script paints: a grid of domes,
Non-Color), and a box bumped by a Voronoi height, under a sun and a dim world. docs/materials.md.

Principled BSDFs here have Specular IOR Level 0 (matte), as in `textured.py`, so that the scene
measures cut-outs and normals, not the specular layer (compared on its own in
tests/test_principled_layering.py).
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

import bpy  # noqa: E402

FINISH = dict(resolution=(128, 96), samples=16)


def leaf_pixels(w=96, h=96):
    """RGBA in [0, 1]: a green leaf (an ellipse with a darker midrib and veins) on alpha 0."""
    y, x = (np.mgrid[0:h, 0:w] + 0.5) / np.array([h, w])[:, None, None]
    u, v = x - 0.5, y - 0.5
    inside = (u / 0.32) ** 2 + (v / 0.47) ** 2 < 1.0
    rib = np.abs(u) < 0.015
    veins = np.abs(np.sin((v - 1.3 * np.abs(u)) * 40.0)) < 0.15
    rgb = np.empty((h, w, 3))
    rgb[:] = (0.16, 0.45, 0.1)
    rgb[veins] = (0.22, 0.55, 0.14)
    rgb[rib] = (0.35, 0.5, 0.15)
    px = np.zeros((h, w, 4))
    px[..., :3] = np.round(rgb * 255) / 255
    px[..., 3] = inside
    return px


def dome_normals(w=128, h=128, cells=6):
    """A tangent-space normal map (RGB = 0.5 + 0.5·n) of a grid of smooth domes."""
    y, x = (np.mgrid[0:h, 0:w] + 0.5) / np.array([h, w])[:, None, None]
    fx, fy = (x * cells) % 1.0 - 0.5, (y * cells) % 1.0 - 0.5
    r2 = fx * fx + fy * fy
    k = np.where(r2 < 0.16, 1.0, 0.0) * 1.6  # dome slope inside a radius-0.4 disk
    n = np.stack([-k * fx, -k * fy, np.ones_like(fx)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    px = np.ones((h, w, 4))
    px[..., :3] = np.round((0.5 + 0.5 * n) * 255) / 255
    return px


def packed_image(name, pixels, non_color=False, alpha=False):
    h, w = pixels.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=alpha, float_buffer=False)
    img.pixels.foreach_set(pixels.reshape(-1).astype(np.float32))
    img.pack()
    if non_color:
        img.colorspace_settings.name = "Non-Color"
    return img


def matte(nodes):
    p = nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Specular IOR Level"].default_value = 0.0
    return p


def leaf_material():
    mat, nodes, out = C._new_material("Leaf")
    nt = mat.node_tree
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = packed_image("leaf", leaf_pixels(), alpha=True)
    p = matte(nodes)
    p.inputs["Roughness"].default_value = 0.6
    nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    nt.links.new(tex.outputs["Alpha"], p.inputs["Alpha"])
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    return mat


def fence_material():
    mat, nodes, out = C._new_material("Fence")
    nt = mat.node_tree
    tc = nodes.new("ShaderNodeTexCoord")
    brick = nodes.new("ShaderNodeTexBrick")
    brick.inputs["Scale"].default_value = 4.0
    brick.inputs["Mortar Size"].default_value = 0.05
    brick.inputs["Color1"].default_value = (0.0, 0.0, 0.0, 1.0)
    brick.inputs["Color2"].default_value = (0.0, 0.0, 0.0, 1.0)
    brick.inputs["Mortar"].default_value = (1.0, 1.0, 1.0, 1.0)
    nt.links.new(tc.outputs["UV"], brick.inputs["Vector"])
    dif = nodes.new("ShaderNodeBsdfDiffuse")
    dif.inputs["Color"].default_value = (0.55, 0.5, 0.45, 1.0)
    tr = nodes.new("ShaderNodeBsdfTransparent")
    mix = nodes.new("ShaderNodeMixShader")
    nt.links.new(brick.outputs["Fac"], mix.inputs[0])  # mortar (Fac 1) is the fence
    nt.links.new(tr.outputs[0], mix.inputs[1])
    nt.links.new(dif.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    return mat


def domes_material():
    mat, nodes, out = C._new_material("Domes")
    nt = mat.node_tree
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = packed_image("domes", dome_normals(), non_color=True)
    nm = nodes.new("ShaderNodeNormalMap")
    nt.links.new(tex.outputs["Color"], nm.inputs["Color"])
    p = matte(nodes)
    p.inputs["Base Color"].default_value = (0.75, 0.3, 0.2, 1.0)
    nt.links.new(nm.outputs["Normal"], p.inputs["Normal"])
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    return mat


def bumped_material():
    mat, nodes, out = C._new_material("Bumped")
    nt = mat.node_tree
    vor = nodes.new("ShaderNodeTexVoronoi")
    vor.inputs["Scale"].default_value = 5.0
    bump = nodes.new("ShaderNodeBump")
    bump.inputs["Distance"].default_value = 0.05
    nt.links.new(vor.outputs["Distance"], bump.inputs["Height"])
    dif = nodes.new("ShaderNodeBsdfDiffuse")
    dif.inputs["Color"].default_value = (0.3, 0.45, 0.75, 1.0)
    nt.links.new(bump.outputs["Normal"], dif.inputs["Normal"])
    nt.links.new(dif.outputs[0], out.inputs["Surface"])
    return mat


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.35, 0.4, 0.5), 0.4)
    floor = C.diffuse("Ground", (0.6, 0.58, 0.55))
    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0, 0, 0))
    bpy.context.object.data.materials.append(floor)
    leaf = leaf_material()
    for k, (loc, rot) in enumerate([((-1.3, 0.4, 1.2), (0.3, 0.2, 0.4)), ((-0.7, 0.9, 1.5), (-0.2, 0.4, 1.2)),
                                    ((-1.6, -0.3, 1.0), (0.5, -0.3, 2.0))]):
        bpy.ops.mesh.primitive_plane_add(size=0.9, location=loc, rotation=rot)
        bpy.context.object.name = f"Leaf{k}"
        bpy.context.object.data.materials.append(leaf)
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0.3, 1.6, 1.0), rotation=(C.deg(90), 0, 0))
    bpy.context.object.name = "Fence"
    bpy.context.object.data.materials.append(fence_material())
    C.uv_sphere("Domes", 0.6, (0.4, -0.2, 0.6), domes_material(), segments=48, rings=24)
    bpy.ops.mesh.primitive_cube_add(size=0.9, location=(1.7, 0.3, 0.45), rotation=(0, 0, C.deg(20)))
    bpy.context.object.name = "Bumped"
    bpy.context.object.data.materials.append(bumped_material())
    C.light("Sun", "SUN", (0, 0, 5), rotation=(C.deg(35), C.deg(10), C.deg(-30)), energy=3.0)
    C.camera((0.0, -5.2, 2.8), (0.0, 0.3, 0.7), lens=38.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "cutout", **FINISH)
