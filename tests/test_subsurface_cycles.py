"""Subsurface scattering against Cycles (bpy 5.0.1): export of the Principled subsurface inputs
and of the Subsurface Scattering node, and DRT vs Cycles renders of an SSS sphere.

The renders are slow (``pytest -m slow tests/test_subsurface_cycles.py``); the export checks
are not.
"""

from __future__ import annotations

import math
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
from addon.export import export_depsgraph  # noqa: E402
from test_addon import ensure_registered  # noqa: E402

pytestmark = pytest.mark.blender


def sss_scene(method="RANDOM_WALK", spec=0.0, node=False, scale=0.5):
    """A smooth sphere (radius 1) with a Principled SSS material (or the Subsurface Scattering
    node) under a sun, no world."""
    scene = C.reset()
    mat, nodes, out = C._new_material("Skin")
    if node:
        n = nodes.new("ShaderNodeSubsurfaceScattering")
        n.inputs["Color"].default_value = (0.8, 0.5, 0.3, 1.0)
        n.inputs["Scale"].default_value = scale
        n.inputs["Roughness"].default_value = 0.25
        n.falloff = method
    else:
        n = nodes.new("ShaderNodeBsdfPrincipled")
        n.inputs["Base Color"].default_value = (0.8, 0.5, 0.3, 1.0)
        n.inputs["Specular IOR Level"].default_value = spec
        n.inputs["Subsurface Weight"].default_value = 1.0
        n.inputs["Subsurface Scale"].default_value = scale
        n.inputs["Subsurface Anisotropy"].default_value = 0.3
        n.subsurface_method = method
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    C.uv_sphere("Ball", 1.0, (0, 0, 0), mat, segments=64, rings=32)
    C.light("Sun", "SUN", (0, 0, 5), rotation=(C.deg(50), 0.0, C.deg(-35)), energy=3.0)
    C.camera((0.0, -5.5, 0.0), (0.0, 0.0, 0.0), lens=50.0)
    r = scene.render
    r.resolution_x = r.resolution_y = 48
    r.resolution_percentage = 100
    C.reference_settings(scene)
    return scene


def exported_lobes():
    ensure_registered()
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    assert res.header["version"] == 2
    return res.header["materials"][0]["lobes"]


def test_export_principled_subsurface():
    sss_scene("RANDOM_WALK_SKIN", spec=0.5)
    (lobe,) = [lb for lb in exported_lobes() if lb["type"] == "SUBSURFACE"]
    np.testing.assert_allclose(lobe["radius"], [0.5, 0.1, 0.05], rtol=1e-6)
    assert lobe["method"] == "RANDOM_WALK_SKIN" and lobe["ior"] == pytest.approx(1.4)  # Subsurface IOR
    assert lobe["anisotropy"] == pytest.approx(0.3) and lobe["roughness"] == pytest.approx(0.5)
    # colour = clamped base × (1 − F) × weight, with the scalar factor recorded in "weight"
    np.testing.assert_allclose(np.array(lobe["color"]) / lobe["weight"], [0.8, 0.5, 0.3], rtol=1e-6)


def test_export_random_walk_ior_follows_specular_level():
    """Random Walk enters through the specular layer's IOR: level 0 → IOR 1, level 0.5 → IOR."""
    sss_scene("RANDOM_WALK", spec=0.0)
    assert exported_lobes()[0]["ior"] == pytest.approx(1.0)
    sss_scene("RANDOM_WALK", spec=0.5)
    (lobe,) = [lb for lb in exported_lobes() if lb["type"] == "SUBSURFACE"]
    assert lobe["ior"] == pytest.approx(1.5)


def test_export_subsurface_node():
    sss_scene("RANDOM_WALK", node=True)
    (lobe,) = exported_lobes()
    assert lobe["type"] == "SUBSURFACE" and lobe["weight"] == 1.0
    np.testing.assert_allclose(lobe["radius"], [0.5, 0.1, 0.05], rtol=1e-6)
    assert lobe["roughness"] == pytest.approx(math.sqrt(0.25))  # Cycles: alpha = the input
    assert lobe["ior"] == pytest.approx(1.4)


def _render_both(scene, tmp_path, spp):
    from drt.render import render
    from drt.scene import scene_from_dict
    from compare_cycles import render as bpy_render  # noqa: F401 (scripts/ on the path below)

    ensure_registered()
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    film = render(scene_from_dict(res.header, res.arrays), spp=spp)
    cyc = bpy_render(scene, "CYCLES", spp, str(tmp_path / "cycles.exr"))
    return film.combined[..., :3].astype(np.float64), cyc


@pytest.mark.slow
@pytest.mark.parametrize("method, node", [("RANDOM_WALK", False), ("RANDOM_WALK_SKIN", False),
                                          ("RANDOM_WALK", True)])
def test_sphere_matches_cycles(method, node, tmp_path):
    """Equal samples (256): the lit sphere's channel means within 1.5 % of Cycles's (measured
    within 0.6 %)."""
    sys.path.insert(0, os.path.join(REPO, "scripts"))
    scene = sss_scene(method, node=node)
    drt, cyc = _render_both(scene, tmp_path, 256)
    y, x = np.mgrid[0:48, 0:48]
    disk = (x - 23.5) ** 2 + (y - 23.5) ** 2 < 14 ** 2
    ratio = drt[disk].mean(0) / cyc[disk].mean(0)
    assert np.all(np.abs(ratio - 1) < 0.015), ratio


def checker_sss_scene():
    scene = sss_scene("RANDOM_WALK", scale=0.2)
    mat = bpy.data.materials["Skin"]
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    chk = nodes.new("ShaderNodeTexChecker")
    chk.inputs["Color1"].default_value = (0.9, 0.9, 0.9, 1.0)
    chk.inputs["Color2"].default_value = (0.1, 0.1, 0.1, 1.0)
    chk.inputs["Scale"].default_value = 2.0
    links.new(chk.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
    return scene


def test_textured_base_colour_drives_the_walk_albedo():
    """A Checker base colour: the SSS lobe's colour comes from a program register (its albedo =
    colour / weight at each hit); the scene renders, dark squares darker than light ones."""
    from drt.render import render
    from drt.scene import scene_from_dict

    checker_sss_scene()
    ensure_registered()
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    (lobe,) = res.header["materials"][0]["lobes"]
    assert lobe["type"] == "SUBSURFACE" and "color_reg" in lobe
    img = render(scene_from_dict(res.header, res.arrays), spp=16).combined[..., :3]
    assert np.isfinite(img).all()
    lit = img[10:38, 10:38, 1].ravel()
    assert np.percentile(lit, 90) > 3 * max(np.percentile(lit, 10), 1e-3)


@pytest.mark.slow
def test_textured_sphere_matches_cycles(tmp_path):
    """The checker SSS sphere at equal samples (256): lit-disk means within 1.5 % of Cycles's."""
    sys.path.insert(0, os.path.join(REPO, "scripts"))
    drt, cyc = _render_both(checker_sss_scene(), tmp_path, 256)
    y, x = np.mgrid[0:48, 0:48]
    disk = (x - 23.5) ** 2 + (y - 23.5) ** 2 < 14 ** 2
    ratio = drt[disk].mean(0) / cyc[disk].mean(0)
    assert np.all(np.abs(ratio - 1) < 0.015), ratio


@pytest.mark.slow
def test_bounce_counting_matches_cycles(tmp_path, monkeypatch):
    """Max bounces 0 under a uniform world: entering SSS is no bounce (Cycles's
    subsurface_bounce skips path_state_next), so the exit is still shaded and its diffuse ray,
    past the limit, still collects the world it hits. Counting the entry would stop the path
    before its exit: a black sphere. Lit-disk means within 1.5 % at 256 spp."""
    sys.path.insert(0, os.path.join(REPO, "scripts"))
    scene = sss_scene("RANDOM_WALK")
    bpy.data.objects.remove(bpy.data.objects["Sun"])
    C.set_world(scene.world, (1.0, 1.0, 1.0), 1.0)
    orig = C.reference_settings

    def one_bounce(sc, samples=1024):  # what compare_cycles.render applies before Cycles renders
        orig(sc, samples)
        sc.cycles.max_bounces = 0
        sc.cycles.diffuse_bounces = 0

    ensure_registered()
    scene.drt.max_bounces = scene.drt.diffuse_bounces = 0  # DRT's own settings (the export's)
    monkeypatch.setattr(C, "reference_settings", one_bounce)
    drt, cyc = _render_both(scene, tmp_path, 256)
    y, x = np.mgrid[0:48, 0:48]
    disk = (x - 23.5) ** 2 + (y - 23.5) ** 2 < 14 ** 2
    assert cyc[disk].mean() > 0.2
    ratio = drt[disk].mean(0) / cyc[disk].mean(0)
    assert np.all(np.abs(ratio - 1) < 0.015), ratio
