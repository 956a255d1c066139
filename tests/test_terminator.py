"""Cycles's shadow terminator geometry offset (drt.terminator) against Cycles (bpy 5.0.1).

A low-poly smooth-shaded sphere under a grazing sun, direct light only: Cycles lifts shadow-ray
origins of smooth triangles near the terminator toward the smooth surface (per object,
``Object.shadow_terminator_geometry_offset``, default 0.1), so facets there are less
self-shadowed. DRT must match Cycles with the offset at 0.1 and at 0, and a flat-shaded sphere
must render exactly as without the feature.
"""

from __future__ import annotations

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
from addon.export import export_depsgraph  # noqa: E402
from test_addon import ensure_registered  # noqa: E402

pytestmark = pytest.mark.blender

RES = 40
SUN = (60.0, -50.0)  # sun rotation (x, z) in degrees: from the camera side, grazing the head


def sphere_scene(offset=0.1, smooth=True, shape="SUZANNE"):
    """Unsubdivided Suzanne (or a 12×6 UV sphere; diffuse 0.8) lit by a sun from the side, so
    that much of the visible surface lies near the terminator; no world, no bounces. On a convex
    sphere the offset changes nothing (a facet facing the light is never shadowed by others)."""
    scene = C.reset()
    mat = C.diffuse("White", (0.8, 0.8, 0.8))
    if shape == "SUZANNE":
        bpy.ops.mesh.primitive_monkey_add(size=2.0, location=(0, 0, 0), rotation=(0.0, 0.0, 0.0))
        ball = bpy.context.active_object
        ball.name = "Ball"
        ball.data.materials.append(mat)
        ball.data.polygons.foreach_set("use_smooth", [True] * len(ball.data.polygons))
        ball.data.update()
    elif shape == "TORUS":
        bpy.ops.mesh.primitive_torus_add(major_segments=16, minor_segments=8, major_radius=1.2,
                                         minor_radius=0.45, location=(0, 0, 0), rotation=(C.deg(70), 0.0, 0.0))
        ball = bpy.context.active_object
        ball.name = "Ball"
        ball.data.materials.append(mat)
        ball.data.polygons.foreach_set("use_smooth", [True] * len(ball.data.polygons))
        ball.data.update()
    else:
        ball = C.uv_sphere("Ball", 1.0, (0, 0, 0), mat, segments=12, rings=6)
    if not smooth:
        ball.data.polygons.foreach_set("use_smooth", [False] * len(ball.data.polygons))
        ball.data.update()
    ball.shadow_terminator_geometry_offset = offset
    C.light("Sun", "SUN", (0, 0, 5), rotation=(C.deg(SUN[0]), 0.0, C.deg(SUN[1])), energy=3.0)
    C.camera((0.0, -5.5, 0.0), (0.0, 0.0, 0.0), lens=50.0)
    r = scene.render
    r.resolution_x = r.resolution_y = RES
    r.resolution_percentage = 100
    C.reference_settings(scene)
    ensure_registered()
    scene.drt.max_bounces = scene.drt.diffuse_bounces = 0
    return scene


def drt_render(spp):
    from drt.render import render
    from drt.scene import scene_from_dict

    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    film = render(scene_from_dict(res.header, res.arrays), spp=spp)
    return film.combined[..., :3].astype(np.float64), res.header


def cycles_render(scene, spp, path, monkeypatch):
    from compare_cycles import render as bpy_render

    orig = C.reference_settings

    def direct_only(sc, samples=1024):  # what compare_cycles.render applies before Cycles renders
        orig(sc, samples)
        sc.cycles.max_bounces = sc.cycles.diffuse_bounces = 0

    monkeypatch.setattr(C, "reference_settings", direct_only)
    return bpy_render(scene, "CYCLES", spp, str(path))


def test_export_carries_the_offsets():
    sphere_scene(0.25)
    bpy.data.objects["Ball"].shadow_terminator_shading_offset = 0.5
    ensure_registered()
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    (o,) = res.header["objects"]
    assert o["shadow_terminator"]["geometry_offset"] == pytest.approx(0.25)
    assert o["shadow_terminator"]["shading_offset"] == pytest.approx(0.5)


def test_scene_validation_names_the_field():
    from drt.scene import SceneError, scene_from_dict

    sphere_scene()
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    res.header["objects"][0]["shadow_terminator"] = {"geometry_offset": 1.5}
    with pytest.raises(SceneError, match=r"objects\[0\]\.shadow_terminator\.geometry_offset"):
        scene_from_dict(res.header, res.arrays)
    res.header["objects"][0]["shadow_terminator"] = 0.1
    with pytest.raises(SceneError, match=r"objects\[0\]\.shadow_terminator"):
        scene_from_dict(res.header, res.arrays)


def test_offset_brightens_smooth_sphere_and_leaves_flat_unchanged():
    """The offset (0.1, Blender's default) lights more of a 12×6 smooth sphere than offset 0
    (same samples, same pattern: the only difference is shadow-ray origins); a flat-shaded
    sphere renders bit-identically with offsets 0.1 and 0."""
    sphere_scene(0.1)
    on, _ = drt_render(16)
    sphere_scene(0.0)
    off, header = drt_render(16)
    assert "shadow_terminator" not in header["objects"][0]  # offset 0: nothing exported
    assert on.mean() > off.mean() * 1.03, (on.mean(), off.mean())
    sphere_scene(0.1, smooth=False)
    flat_on, header = drt_render(8)
    assert "shadow_terminator" not in header["objects"][0]  # flat mesh: nothing exported
    sphere_scene(0.0, smooth=False)
    flat_off, _ = drt_render(8)
    assert np.array_equal(flat_on, flat_off)


def test_terminator_arrays_only_for_smooth_faces():
    from drt.geometry import build_geometry
    from drt.scene import scene_from_dict
    from drt.terminator import terminator_arrays

    sphere_scene(0.1, smooth=False)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    cut, positions, triangles = terminator_arrays(build_geometry(scene_from_dict(res.header, res.arrays)))
    assert cut.shape == (0,) and positions.shape == (0, 3) and triangles.shape == (0, 3)
    sphere_scene(0.1)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    geom = build_geometry(scene_from_dict(res.header, res.arrays))
    cut, positions, triangles = terminator_arrays(geom)
    assert cut.shape == (geom.triangle_count,) and np.all(cut == np.float32(0.1))
    # the tracer's own arrays, not copies
    assert positions is geom.static_positions and triangles is geom.static_triangles


def test_suzanne_matches_cycles(tmp_path, monkeypatch):
    """Unsubdivided smooth Suzanne, direct light only, 64 spp each, 40×40. With offset 0.1 and
    0 DRT's image mean is within 1 % of Cycles's (measured 0.9936 and 0.9939), and the offset's
    gain (offset 0.1 over 0) equals Cycles's within 0.5 % (measured 1.0473 vs 1.0477; without
    the offset DRT's gain is exactly 1)."""
    means = {}
    for offset in (0.1, 0.0):
        scene = sphere_scene(offset)
        drt, _ = drt_render(64)
        cyc = cycles_render(scene, 64, tmp_path / f"cycles{offset}.exr", monkeypatch)
        means[offset] = drt.mean(), cyc.mean()
        ratio = drt.mean() / cyc.mean()
        assert abs(ratio - 1.0) < 0.01, (offset, ratio)
    drt_gain = means[0.1][0] / means[0.0][0]
    cyc_gain = means[0.1][1] / means[0.0][1]
    assert cyc_gain > 1.03, cyc_gain  # the scene exercises the offset
    assert abs(drt_gain / cyc_gain - 1.0) < 0.005, (drt_gain, cyc_gain)


def test_glossy_smooth_normal_correction_matches_cycles(tmp_path):
    """Cycles bends a glossy closure's *smooth* normal (not only a mapped one) so that the
    mirror direction stays above the facet (maybe_ensure_valid_specular_reflection: any N ≠ Ng).
    A 16×8 smooth Glossy sphere (roughness 0.05) in a white world, 40×40, 128 spp each: the
    disk's mean within 0.25 % of Cycles (measured +0.02 %; without the correction −0.58 %)."""
    from compare_cycles import render as bpy_render

    scene = C.reset()
    mat = C.glossy("G", (0.8, 0.8, 0.8), 0.05)
    C.uv_sphere("Ball", 1.0, (0, 0, 0), mat, segments=16, rings=8)
    C.set_world(scene.world, (1.0, 1.0, 1.0), 1.0)
    C.camera((0.0, -5.5, 0.0), (0.0, 0.0, 0.0), lens=50.0)
    scene.render.resolution_x = scene.render.resolution_y = RES
    C.reference_settings(scene)
    ensure_registered()
    drt, _ = drt_render(128)
    cyc = bpy_render(scene, "CYCLES", 128, str(tmp_path / "cycles.exr"))
    y, x = np.mgrid[0:RES, 0:RES]
    disk = (x - 19.5) ** 2 + (y - 19.5) ** 2 < 11.5 ** 2
    ratio = drt[disk].mean() / cyc[disk].mean()
    assert abs(ratio - 1.0) < 0.0025, ratio


def test_shading_offset_matches_cycles(tmp_path, monkeypatch):
    """Shading offset 0.5 (Cycles's cos(kθ)/cos θ softening, k = 1/(1 − 0.25)) on a smooth UV
    sphere under the sun, direct light only, 64 spp: the offset darkens both alike (the ratio to
    offset 0 within 0.5 %; measured 0.6259 vs 0.6260). Image means within 1.5 % of Cycles's
    (measured 0.9915 / 0.9917: the remaining smooth-sphere gap of docs/lights.md, unrelated to
    the offsets)."""
    means = []
    for shading in (0.5, 0.0):
        scene = sphere_scene(0.1, shape="SPHERE")
        bpy.data.objects["Ball"].shadow_terminator_shading_offset = shading
        drt, _ = drt_render(64)
        cyc = cycles_render(scene, 64, tmp_path / f"cycles{shading}.exr", monkeypatch)
        assert abs(drt.mean() / cyc.mean() - 1.0) < 0.015, (shading, drt.mean() / cyc.mean())
        means.append((drt.mean(), cyc.mean()))
    drt_gain, cyc_gain = means[0][0] / means[1][0], means[0][1] / means[1][1]
    assert cyc_gain < 0.97, cyc_gain  # the scene exercises the offset
    assert abs(drt_gain / cyc_gain - 1.0) < 0.005, (drt_gain, cyc_gain)


@pytest.mark.parametrize("shape, sun", [("TORUS", (-80.0, 0.0)), ("SUZANNE", (-60.0, 20.0))])
def test_back_lit_silhouettes_match_cycles(shape, sun, tmp_path, monkeypatch):
    """A sun behind the mesh lights only its rim, where the camera sees facets whose smooth
    normal faces away from it (wo above the facet, below the smooth normal). Cycles turns the
    closure normal to wo's geometric side there and its diffuse lobe lights every direction
    above it; DRT's diffuse lobe follows the same side (materials.table.facing_front). Image
    means within 3 % of Cycles, 128 spp (measured −0.9 % and −1.9 %; before, DRT reflected on
    wo's side of the smooth normal: −57 % and −15 %)."""
    monkeypatch.setattr(sys.modules[__name__], "SUN", sun)
    scene = sphere_scene(0.1, shape=shape)
    drt, _ = drt_render(128)
    cyc = cycles_render(scene, 128, tmp_path / "cycles.exr", monkeypatch)
    assert cyc.mean() > 1e-4, cyc.mean()  # the rim is lit
    assert abs(drt.mean() / cyc.mean() - 1.0) < 0.03, (drt.mean(), cyc.mean())


@pytest.mark.slow
@pytest.mark.parametrize("shape, sun", [("SUZANNE", (60.0, -70.0)), ("SUZANNE", (40.0, -60.0)),
                                        ("SUZANNE", (65.0, -60.0)), ("TORUS", (45.0, -100.0)),
                                        ("TORUS", (60.0, 70.0))])
def test_offset_gain_sweep_matches_cycles(shape, sun, tmp_path, monkeypatch):
    """Converged (256 spp) sweep of sun directions: the geometry offset's gain (0.1 over 0)
    equals Cycles's within 0.5 % (measured at 64 spp within 0.2 %, gains 1.005–1.09). Back-lit
    suns: ``test_back_lit_silhouettes_match_cycles``."""
    monkeypatch.setattr(sys.modules[__name__], "SUN", sun)
    means = []
    for offset in (0.1, 0.0):
        scene = sphere_scene(offset, shape=shape)
        drt, _ = drt_render(256)
        cyc = cycles_render(scene, 256, tmp_path / f"cycles{offset}.exr", monkeypatch)
        means.append((drt.mean(), cyc.mean()))
    drt_gain, cyc_gain = means[0][0] / means[1][0], means[0][1] / means[1][1]
    assert abs(drt_gain / cyc_gain - 1.0) < 0.005, (drt_gain, cyc_gain)


def _principled_sheen():
    """Principled BSDF: grey base (roughness 0.5), Sheen Weight 1 at roughness 0.5, no
    specular layer (Specular IOR Level 0): the sheen and the diffuse base under it."""
    mat, nodes, out = C._new_material("Sheen")
    p = nodes.new("ShaderNodeBsdfPrincipled")
    mat.node_tree.links.new(p.outputs[0], out.inputs["Surface"])
    p.inputs["Base Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    p.inputs["Roughness"].default_value = 0.5
    p.inputs["Sheen Weight"].default_value = 1.0
    p.inputs["Sheen Roughness"].default_value = 0.5
    p.inputs["Specular IOR Level"].default_value = 0.0
    return mat


@pytest.mark.parametrize("shape, sun", [("TORUS", (-80.0, 0.0)), ("SPHERE", (-70.0, 30.0))])
def test_back_lit_sheen_rims_match_cycles(shape, sun, tmp_path, monkeypatch):
    """The back-lit rims of a Principled sheen over a diffuse base: Cycles's sheen lobe, like its
    diffuse one, lights every direction above N' and reads its LTC tables, and the albedo that
    darkens the base under it, at cos θo clamped to 0 where wo is below N'
    (materials.table.sheen_facing, layer_factor). Image means within 2.5 % of Cycles, 128 spp
    (measured −1.7 % and +1.6 %; before, with the sheen on wo's side and its albedo at |cos θo|:
    −35 % and −16 %)."""
    monkeypatch.setattr(sys.modules[__name__], "SUN", sun)
    scene = sphere_scene(0.1, shape=shape)
    ball = bpy.data.objects["Ball"]
    ball.data.materials.clear()
    ball.data.materials.append(_principled_sheen())
    drt, _ = drt_render(128)
    cyc = cycles_render(scene, 128, tmp_path / "cycles.exr", monkeypatch)
    assert cyc.mean() > 1e-4, cyc.mean()
    assert abs(drt.mean() / cyc.mean() - 1.0) < 0.025, (drt.mean(), cyc.mean())
