"""Export of a textured volume Density (heterogeneous media, drt.volumes.hetero) and a noise
cloud against Cycles at equal samples. Skipped without bpy."""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(REPO, "blend_scenes")
for p in (REPO, SCENES, os.path.join(REPO, "scripts")):
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


def test_textured_density_exports_a_register_and_per_unit_coefficients(fresh):
    import volume_noise

    C.box("B", (2.0, 2.0, 2.0), (0, 0, 0), volume_noise.cloud_material("Cloud"))
    res = export_current()
    m = _material(res, "Cloud")
    v = m["volume"]
    assert isinstance(v["density_reg"], int) and 0 <= v["density_reg"] < m["program"]["registers"]
    c = np.array([0.9, 0.85, 0.8])
    np.testing.assert_allclose(v["scatter"], c, rtol=1e-6)  # per unit density
    np.testing.assert_allclose(v["absorption"], 1 - c, rtol=1e-5)
    assert "mesh0.generated" in res.arrays  # the noise reads Generated coordinates
    assert not any("Density" in w for w in res.warnings)


def test_textured_colour_exports_per_unit_colour_coefficients(fresh):
    """Principled Volume with a textured Color (density 2, absorption colour 0.25): S = σs at
    colour 1 = 2, A = σa at colour 0 = 2·(1 − √0.25) = 1, and ``color_reg``."""
    mat = C.volume_material("Tinted", Density=2.0, Absorption_Color=(0.25, 0.25, 0.25))
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    vol = next(n for n in nodes if n.bl_idname == "ShaderNodeVolumePrincipled")
    noise = nodes.new("ShaderNodeTexNoise")
    links.new(noise.outputs["Color"], vol.inputs["Color"])
    C.box("B", (2.0, 2.0, 2.0), (0, 0, 0), mat)
    res = export_current()
    m = _material(res, "Tinted")
    v = m["volume"]
    assert 0 <= v["color_reg"] < m["program"]["registers"] and "density_reg" not in v
    np.testing.assert_allclose(v["scatter"], [2.0] * 3, rtol=1e-6)
    np.testing.assert_allclose(v["absorption"], [1.0] * 3, rtol=1e-6)


def test_textured_density_in_a_mix_of_two_media_falls_back_with_a_warning(fresh):
    import volume_noise

    mat = volume_noise.cloud_material("Cloud")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    out = next(n for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    vol = next(n for n in nodes if n.bl_idname == "ShaderNodeVolumePrincipled")
    absorb = nodes.new("ShaderNodeVolumeAbsorption")
    add = nodes.new("ShaderNodeAddShader")
    links.new(vol.outputs[0], add.inputs[0])
    links.new(absorb.outputs[0], add.inputs[1])
    links.new(add.outputs[0], out.inputs["Volume"])
    C.box("B", (2.0, 2.0, 2.0), (0, 0, 0), mat)
    res = export_current()
    v = _material(res, "Cloud")["volume"]
    assert "density_reg" not in v
    assert any("Add/Mix" in w for w in res.warnings)


@pytest.mark.slow
def test_noise_cloud_matches_cycles(tmp_path):
    """blend_scenes/volume_noise at 48×32, 128 spp each: the cloud's region mean within 2 % and
    the whole image's within 1 % of Cycles."""
    import compare_cycles as cc
    import volume_noise

    ensure_registered()
    scene = volume_noise.build()
    scene.render.resolution_x, scene.render.resolution_y = 48, 32
    scene.render.resolution_percentage = 100
    cyc = cc.render(scene, "CYCLES", 128, str(tmp_path / "c.exr"))
    drt = cc.render(scene, "DRT", 128, str(tmp_path / "d.exr"))
    assert np.all(np.isfinite(drt))
    np.testing.assert_allclose(drt.mean((0, 1)), cyc.mean((0, 1)), rtol=0.01)
    np.testing.assert_allclose(drt[4:24, 14:34].mean((0, 1)), cyc[4:24, 14:34].mean((0, 1)), rtol=0.02)


@pytest.mark.slow
def test_noise_cloud_with_textured_colour_matches_cycles(tmp_path):
    """The noise cloud with its Color from a second Noise Texture's colour (heterogeneous albedo
    and absorption, chromatic): 48×32, 128 spp each, image and cloud means within 1 % / 2 %."""
    import compare_cycles as cc
    import volume_noise

    ensure_registered()
    scene = volume_noise.build()
    mat = bpy.data.materials["Cloud"]
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    vol = next(n for n in nodes if n.bl_idname == "ShaderNodeVolumePrincipled")
    tint = nodes.new("ShaderNodeTexNoise")
    tint.inputs["Scale"].default_value = 1.5
    links.new(tint.outputs["Color"], vol.inputs["Color"])
    scene.render.resolution_x, scene.render.resolution_y = 48, 32
    scene.render.resolution_percentage = 100
    cyc = cc.render(scene, "CYCLES", 128, str(tmp_path / "c.exr"))
    drt = cc.render(scene, "DRT", 128, str(tmp_path / "d.exr"))
    assert np.all(np.isfinite(drt))
    np.testing.assert_allclose(drt.mean((0, 1)), cyc.mean((0, 1)), rtol=0.01)
    np.testing.assert_allclose(drt[4:24, 14:34].mean((0, 1)), cyc[4:24, 14:34].mean((0, 1)), rtol=0.02)
