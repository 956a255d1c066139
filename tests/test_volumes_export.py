"""Export of volume shaders (Principled Volume, Volume Absorption/Scatter, Add/Mix, the world's
Volume output) to the core's homogeneous media, in Cycles 5.0's coefficients. Skipped without bpy."""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(REPO, "blend_scenes")
for p in (REPO, SCENES):
    if p not in sys.path:
        sys.path.insert(0, p)

import _common as C  # noqa: E402
from addon.export.blend import export_current  # noqa: E402
from test_addon import ensure_registered  # noqa: E402

pytestmark = pytest.mark.blender


@pytest.fixture
def fresh():
    ensure_registered()
    scene = C.reset()
    C.camera((0, -5, 1), (0, 0, 0))
    return scene


def _material(res, name):
    return next(m for m in res.header["materials"] if m["name"] == name)


def test_principled_volume_only(fresh):
    mat, nodes, out = C._new_material("Fog")
    v = nodes.new("ShaderNodeVolumePrincipled")
    v.inputs["Color"].default_value = (0.8, 0.5, 0.2, 1)
    v.inputs["Density"].default_value = 2.0
    v.inputs["Anisotropy"].default_value = 0.4
    v.inputs["Absorption Color"].default_value = (0.25, 0.0, 1.0, 1)
    v.inputs["Emission Strength"].default_value = 3.0
    v.inputs["Emission Color"].default_value = (1.0, 0.5, 0.0, 1)
    mat.node_tree.links.new(v.outputs[0], out.inputs["Volume"])
    C.box("B", (1.0, 1.0, 1.0), (0, 0, 0), mat)
    res = export_current()
    m = _material(res, "Fog")
    assert m["surface"] is False and m["lobes"] == []
    c = np.array([0.8, 0.5, 0.2])
    np.testing.assert_allclose(m["volume"]["scatter"], 2.0 * c, rtol=1e-6)
    ac = np.sqrt([0.25, 0.0, 1.0])
    np.testing.assert_allclose(m["volume"]["absorption"], 2.0 * (1 - c) * (1 - ac), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(m["volume"]["emission"], [3.0, 1.5, 0.0], rtol=1e-6)
    assert m["volume"]["anisotropy"] == pytest.approx(0.4)


def test_glass_with_absorption_mix_and_world_volume(fresh):
    mat, nodes, out = C._new_material("Liquid")
    g = nodes.new("ShaderNodeBsdfGlass")
    mat.node_tree.links.new(g.outputs[0], out.inputs["Surface"])
    a = nodes.new("ShaderNodeVolumeAbsorption")
    a.inputs["Color"].default_value = (0.9, 0.3, 0.1, 1)
    a.inputs["Density"].default_value = 4.0
    s = nodes.new("ShaderNodeVolumeScatter")
    s.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1)
    s.inputs["Density"].default_value = 1.0
    mix = nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.25
    mat.node_tree.links.new(a.outputs[0], mix.inputs[1])
    mat.node_tree.links.new(s.outputs[0], mix.inputs[2])
    mat.node_tree.links.new(mix.outputs[0], out.inputs["Volume"])
    C.box("B", (1.0, 1.0, 1.0), (0, 0, 0), mat)
    world = bpy.context.scene.world or bpy.data.worlds.new("W")
    bpy.context.scene.world = world
    C.set_world(world, (0.1, 0.1, 0.1), 1.0)
    wo = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeOutputWorld")
    ws = world.node_tree.nodes.new("ShaderNodeVolumeScatter")
    ws.inputs["Density"].default_value = 0.05
    ws.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1)
    world.node_tree.links.new(ws.outputs[0], wo.inputs["Volume"])
    bpy.context.scene.drt.volume_bounces = 3
    res = export_current()
    m = _material(res, "Liquid")
    assert "surface" not in m and m["lobes"][0]["type"] == "GLASS"
    np.testing.assert_allclose(m["volume"]["absorption"], 0.75 * 4.0 * (1 - np.array([0.9, 0.3, 0.1])), rtol=1e-6)
    np.testing.assert_allclose(m["volume"]["scatter"], [0.25] * 3, rtol=1e-6)
    np.testing.assert_allclose(res.header["world"]["volume"]["scatter"], [0.025] * 3, rtol=1e-6)
    assert res.header["render"]["volume_bounces"] == 3
    from drt.scene import scene_from_dict
    sc = scene_from_dict(res.header, res.arrays)
    assert sc.world_volume["scatter"] == pytest.approx([0.025] * 3)
    assert sc.render.volume_bounces == 3


def test_volume_emission_and_blackbody_match_cycles(fresh, tmp_path):
    """A non-extinguishing Principled Volume with emission and blackbody (1500 K) seen through 1 m:
    radiance = emission per metre × 1 m, against Cycles's render of the same file (exact paths)."""
    sys.path.insert(0, os.path.join(REPO, "scripts"))
    import compare_cycles as cc

    scene = bpy.context.scene
    C.set_world(scene.world or bpy.data.worlds.new("W"), (0, 0, 0), 0.0)
    m = C.volume_material("Flame", Density=0.0, Emission_Strength=0.5, Emission_Color=(1.0, 0.5, 0.25),
                          Blackbody_Intensity=0.7, Temperature=1500.0)
    C.box("B", (1, 1, 1), (0, 0, 0), m)
    C.camera((0, -5, 0), (0, 0, 0), lens=200.0)
    scene.render.resolution_x = scene.render.resolution_y = 8
    C.reference_settings(scene, 4)
    cyc = cc.render(scene, "CYCLES", 4, str(tmp_path / "c.exr"))
    drt = cc.render(scene, "DRT", 4, str(tmp_path / "d.exr"))
    np.testing.assert_allclose(drt[4, 4], cyc[4, 4], rtol=1e-3)
    assert cyc[4, 4, 0] > 0.5 and cyc[4, 4, 0] > 2 * cyc[4, 4, 1]  # the blackbody term is really there


def test_world_volume_ends_at_infinity_not_clip_end_as_cycles(fresh, tmp_path):
    """An absorbing world medium swallows the world for camera rays that miss, also with a short
    clip_end (Cycles renders black; a medium cut at clip_end would give e^(−σ·9.9) = 0.37)."""
    sys.path.insert(0, os.path.join(REPO, "scripts"))
    import compare_cycles as cc

    scene = bpy.context.scene
    world = scene.world or bpy.data.worlds.new("W")
    scene.world = world
    C.set_world(world, (1, 1, 1), 1.0)
    out = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeOutputWorld")
    a = world.node_tree.nodes.new("ShaderNodeVolumeAbsorption")
    a.inputs["Color"].default_value = (0.9, 0.9, 0.9, 1)
    world.node_tree.links.new(a.outputs[0], out.inputs["Volume"])
    cam = C.camera((0, 0, 0), (0, 1, 0), lens=200.0)
    cam.data.clip_start, cam.data.clip_end = 0.1, 10.0
    scene.render.resolution_x = scene.render.resolution_y = 4
    C.reference_settings(scene, 4)
    cyc = cc.render(scene, "CYCLES", 4, str(tmp_path / "c.exr"))
    drt = cc.render(scene, "DRT", 4, str(tmp_path / "d.exr"))
    assert np.all(cyc == 0.0) and np.all(drt == 0.0)
