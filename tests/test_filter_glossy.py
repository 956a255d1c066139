"""Filter Glossy (Cycles's Light Paths > Caustics > Filter Glossy): after an unlikely bounce a
path's glossy lobes are widened to at least ½·sqrt(1 − min_pdf / Filter Glossy)
(``drt.path_stages.glossy_blur``, ``drt.materials.table.filtered_alpha``).

Lobe level: a blurred lobe evaluates and samples exactly as the same lobe made that rough, with
its own multiscatter compensation. Renderer: the blur never exceeds 0.5, so a scene of rougher
lobes renders bit-identically with and without it, and it turns a point light's unreachable
caustic into a blurred one. (bpy) The exporter reads Cycles's own setting, and a caustic scene
renders as Cycles's at its default 1.0.
"""

import dataclasses
import math

import numpy as np
import pytest

from drt.materials.table import BSDFSample, MaterialTable
from drt.render import render
from drt.scene import SceneError, scene_from_dict
from scene_builders import add_material, add_mesh, base_header, look_at, quad, uv_sphere, with_render

BLUR = 0.25  # a GGX alpha (0.5², exact: the rough lobe below has roughness 0.5)


_FIELDS = [f.name for f in dataclasses.fields(BSDFSample)]


def _table(*lobes):
    return MaterialTable.from_scene([{"name": f"m{i}", "lobes": [lobe]} for i, lobe in enumerate(lobes)])


def _rows(n, seed, below=False):
    rng = np.random.default_rng(seed)
    wo = rng.normal(size=(n, 3))
    wo /= np.linalg.norm(wo, axis=1)[:, None]
    wo[:, 2] = np.abs(wo[:, 2]) * (-1 if below else 1)
    wi = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1)[:, None]
    return wo, wi, rng.random(n), rng.random((n, 2))


def _sharp_and_rough(kind, extra, multiscatter):
    """The lobe smooth (with ``multiscatter`` on) and at roughness sqrt(BLUR) (off: a blurred
    lobe keeps the compensation of its own alpha, which is none for a smooth lobe)."""
    sharp = {"type": kind, "color": [0.9, 0.7, 0.5], "roughness": 0.0, **extra}
    rough = {"type": kind, "color": [0.9, 0.7, 0.5], "roughness": math.sqrt(BLUR), **extra}
    if multiscatter is not None:
        sharp.update(multiscatter)
        rough.update({k: (False if v is True else [0.0, 0.0, 0.0]) for k, v in multiscatter.items()})
    return _table(sharp, rough)


@pytest.mark.parametrize("kind, extra, multiscatter, below", [
    ("GLOSSY", {}, {"multiscatter_tint": [0.9, 0.7, 0.5]}, False),
    ("GLASS", {"ior": 1.45}, {"multiscatter_tint": [1.0, 1.0, 1.0]}, False),
    ("GLASS", {"ior": 1.45}, {"multiscatter_tint": [1.0, 1.0, 1.0]}, True),
    ("REFRACTION", {"ior": 1.33}, None, False),
    ("REFRACTION", {"ior": 1.33}, None, True),
    ("METALLIC", {"tint": [0.8, 0.9, 1.0], "weight": 1.0}, {"multiscatter": True}, False),
    ("DIELECTRIC_SPECULAR", {"ior": 1.5}, {"multiscatter": True}, False),
])
def test_a_blurred_smooth_lobe_is_the_rough_lobe(kind, extra, multiscatter, below):
    """Eval (f and pdf) and sample (direction, weight, pdf, kind) of a smooth lobe blurred to
    alpha 0.25 equal the same lobe at roughness 0.5 from both sides (bit for bit but for the
    smooth lobe's multiscatter factor, 1 up to its table's rounding); unblurred
    the smooth lobe is a delta (nothing to evaluate)."""
    t = _sharp_and_rough(kind, extra, multiscatter)
    n = 3000
    wo, wi, u_lobe, u2 = _rows(n, 4, below)
    mats = (np.zeros(n, int), np.ones(n, int))
    f_s, p_s = t.eval(mats[0], wo, wi, blur=BLUR)
    f_r, p_r = t.eval(mats[1], wo, wi)
    # (f: the compensation a smooth lobe keeps is its table's 1 ± 1e-8)
    assert np.array_equal(p_s, p_r) and np.allclose(f_s, f_r, rtol=1e-6, atol=0)
    assert (p_s > 0).mean() > 0.2
    f_0, p_0 = t.eval(mats[0], wo, wi)
    assert not f_0.any() and not p_0.any()
    s_s = t.sample(mats[0], wo, u_lobe, u2, blur=BLUR)
    s_r = t.sample(mats[1], wo, u_lobe, u2)
    for field in _FIELDS:
        a, b = getattr(s_s, field), getattr(s_r, field)
        assert (np.allclose(a, b, rtol=1e-6, atol=0) if field == "weight" else np.array_equal(a, b)), field
    assert s_s.valid.mean() > 0.3 and not s_s.is_delta.any()  # (from inside: much TIR)
    s_0 = t.sample(mats[0], wo, u_lobe, u2)
    assert s_0.valid.any() and s_0.is_delta[s_0.valid].all()


def test_blur_only_widens_and_leaves_other_lobes_alone():
    """A blur below a lobe's own alpha changes nothing, nor does any blur change diffuse-class
    lobes; an IOR-1 glass stays a straight (delta) pass."""
    t = _table({"type": "GLOSSY", "color": [1, 1, 1], "roughness": 0.8},
               {"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]},
               {"type": "SHEEN", "color": [0.5, 0.5, 0.5], "roughness": 0.3},
               {"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": 1.0})
    n = 2000
    wo, wi, u_lobe, u2 = _rows(n, 9)
    for m in range(3):
        mat = np.full(n, m)
        assert all(np.array_equal(a, b) for a, b in zip(t.eval(mat, wo, wi, blur=0.5), t.eval(mat, wo, wi)))
        s_b, s_0 = t.sample(mat, wo, u_lobe, u2, blur=0.5), t.sample(mat, wo, u_lobe, u2)
        assert all(np.array_equal(getattr(s_b, f), getattr(s_0, f)) for f in _FIELDS)
    s = t.sample(np.full(n, 3), wo, u_lobe, u2, blur=0.5)
    assert s.is_delta.all() and np.allclose(s.wi, -wo)


def _caustic_scene(spp=64, glossy_roughness=0.0, glass_roughness=0.0):
    """A diffuse floor, a glass ball and a mirror ball beside it, a point light low on the left:
    the floor right of the balls is in their shadow, reached only through them."""
    h = base_header(32, 32, spp, camera={"type": "PERSP", "matrix_world": look_at((0.6, -3.5, 3.0), (0.6, 0, 0)),
                                         "lens": 50.0})
    floor = add_material(h, "floor", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
    glass = add_material(h, "glass", [{"type": "GLASS", "color": [1, 1, 1], "roughness": glass_roughness,
                                       "ior": 1.45}])
    mirror = add_material(h, "mirror", [{"type": "GLOSSY", "color": [0.9, 0.8, 0.6],
                                         "roughness": glossy_roughness}])
    arrays = {}
    add_mesh(h, arrays, "floor", *quad((0, 0, 0), (2.5, 0, 0), (0, 2.5, 0)), floor)
    add_mesh(h, arrays, "glass", *uv_sphere(0.4, (0, 0.6, 0.5))[:2], glass)
    add_mesh(h, arrays, "mirror", *uv_sphere(0.4, (0, -0.6, 0.5))[:2], mirror)
    h["lights"].append({"type": "POINT", "matrix_world": [[1, 0, 0, -1.0], [0, 1, 0, 0], [0, 0, 1, 0.6],
                                                          [0, 0, 0, 1]], "power": 200.0, "radius": 0.0})
    return h, arrays


def _render(h, arrays, filter_glossy):
    return np.asarray(render(scene_from_dict(with_render(h, filter_glossy=filter_glossy), arrays),
                             threads=2).combined, np.float64)


def test_lobes_rougher_than_any_blur_render_bit_identically():
    """The blur is at most ½ (min_pdf → 0), so a scene whose glossy lobes are all rougher
    (alpha 0.5625) renders the same image bit for bit with Filter Glossy 1 and off."""
    h, arrays = _caustic_scene(spp=16, glossy_roughness=0.75, glass_roughness=0.75)
    assert np.array_equal(_render(h, arrays, 1.0), _render(h, arrays, 0.0))


def test_filter_glossy_lights_a_point_lights_caustic():
    """Through smooth glass a point light's caustic is unreachable unblurred (no path can hit a
    point); blurred after the floor's diffuse bounce, next-event estimation reaches the light
    through the glass ball, and the floor in its shadow brightens (measured at 64 samples:
    0.0073 → 0.055); a Filter Glossy so small that no bounce's pdf is below it changes nothing."""
    h, arrays = _caustic_scene()
    off, on, tiny = (_render(h, arrays, fg) for fg in (0.0, 1.0, 1e-9))
    shadow = (slice(5, 11), slice(16, 32))  # the floor right of the glass ball (32 × 32 image)
    print("glass shadow", off[shadow][..., :3].mean(), on[shadow][..., :3].mean())
    assert on[shadow][..., :3].mean() > 4 * off[shadow][..., :3].mean()
    assert np.array_equal(tiny, off)


def test_filter_glossy_is_read_and_checked():
    h, arrays = _caustic_scene(spp=1)
    assert scene_from_dict(h, arrays).render.filter_glossy == 0.0
    assert scene_from_dict(with_render(h, filter_glossy=2.5), arrays).render.filter_glossy == 2.5
    for bad in (-1.0, 11.0, "1"):
        with pytest.raises(SceneError, match="filter_glossy"):
            scene_from_dict(with_render(h, filter_glossy=bad), arrays)


# ------------------------------------------------------------------------------ Blender
def _blender_caustic_scene(blur_glossy, spp):
    """node_parity's orthographic view down on a diffuse floor with a smooth glass ball and a
    smooth GGX mirror ball, a point light low on the left (their shadows to the right)."""
    import bpy

    from node_parity import node, setup_scene

    sc = setup_scene(2)
    sc.cycles.samples = sc.drt.samples = spp
    sc.cycles.max_bounces = sc.drt.max_bounces = 8
    sc.cycles.sample_clamp_indirect = 0.0
    if blur_glossy is not None:
        sc.cycles.blur_glossy = blur_glossy
    floor = bpy.data.materials.new("floor")
    nt = floor.node_tree
    nt.nodes.clear()
    d = node(nt, "ShaderNodeBsdfDiffuse", {"Color": (0.8, 0.8, 0.8, 1)})
    nt.links.new(d.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    bpy.ops.mesh.primitive_plane_add(size=2.2, location=(0, 0, -1))
    bpy.context.object.data.materials.append(floor)
    for name, y, kind, inputs in (("glass", 0.4, "ShaderNodeBsdfGlass", {"Roughness": 0.0, "IOR": 1.45}),
                                  ("mirror", -0.4, "ShaderNodeBsdfAnisotropic",
                                   {"Roughness": 0.0, "Color": (0.9, 0.7, 0.4, 1)})):
        mat = bpy.data.materials.new(name)
        nt = mat.node_tree
        nt.nodes.clear()
        b = node(nt, kind, inputs)
        b.distribution = "GGX"
        nt.links.new(b.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(0, y, -0.5), segments=48, ring_count=24)
        bpy.ops.object.shade_smooth()
        bpy.context.object.data.materials.append(mat)
    add_low_point_light(sc)
    return sc


def add_low_point_light(sc):
    """The caustic scenes' light: a 60 W point (radius 0) low on the left of node_parity's view."""
    import bpy

    lamp = bpy.data.lights.new("p", "POINT")
    lamp.energy, lamp.shadow_soft_size = 60.0, 0.0
    obj = bpy.data.objects.new("p", lamp)
    obj.location = (-0.8, 0.0, 0.0)
    sc.collection.objects.link(obj)


def test_filter_glossy_is_cycles_setting():
    """The exporter writes Cycles's Filter Glossy (Light Paths > Caustics): a new file's 1.0,
    a changed value, nothing when it is 0 (off); the viewport's settings too."""
    pytest.importorskip("bpy")
    import bpy

    from addon.export import export_depsgraph
    from addon.export.scene_parts import render_settings

    sc = _blender_caustic_scene(None, 1)
    assert sc.cycles.blur_glossy == 1.0  # (Cycles's default)
    for value, expected in ((1.0, 1.0), (2.5, 2.5), (0.0, None)):
        sc.cycles.blur_glossy = value
        res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
        assert res.header["render"].get("filter_glossy") == expected
        assert render_settings(sc, preview=True).get("filter_glossy") == expected


def test_caustics_through_filter_glossy_match_cycles(tmp_path):
    """At Cycles's default Filter Glossy (1.0) the point light's caustics of a smooth glass
    ball and a smooth mirror ball (unreachable without it) light the floor in their shadows;
    DRT's floor there within 4 % of Cycles's, the whole image within 1.5 % (1024 samples;
    measured at 64 × 64: −1.1 % / +0.3 % in the shadows, −0.1 % over the glass ball)."""
    pytest.importorskip("bpy")
    from node_parity import render_rgba_both

    sc = _blender_caustic_scene(1.0, 1024)
    cycles, drt = (img[..., :3] for img in render_rgba_both(sc, tmp_path / "caustics.exr"))
    regions = {"glass shadow": (slice(4, 15), slice(20, 32)), "mirror shadow": (slice(18, 28), slice(20, 32)),
               "image": (slice(None), slice(None))}
    for name, r in regions.items():
        a, b = cycles[r].mean(), drt[r].mean()
        print(name, "Cycles", a, "DRT", b)
        assert abs(b / a - 1) < (0.015 if name == "image" else 0.04), (name, a, b)
    sc = _blender_caustic_scene(0.0, 64)  # (Cycles without it: the shadows are far darker)
    off = render_rgba_both(sc, tmp_path / "off.exr")[0][..., :3]
    assert cycles[regions["glass shadow"]].mean() > 1.5 * off[regions["glass shadow"]].mean()
