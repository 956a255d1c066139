"""The Metallic BSDF node (Cycles 4.0+): its F82 mode is the Principled BSDF's metallic lobe,
its Physical Conductor mode that lobe fitted to the conductor's Fresnel
(``addon.export.materials.conductor_f82``). Tiles lit by a delta sun, no bounces (exact at one
sample in both engines), against Cycles; the fit against the exact Fresnel."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

try:  # the Blender tests' fixture: a reset scene with the add-on registered
    from test_material_programs import fresh  # noqa: F401
except pytest.skip.Exception:  # no bpy: the fit's own test still runs
    pass

#: measured metals' (n, k) at R, G, B (the node's default, gold, copper)
METALS = {"default": ((2.757, 2.513, 2.231), (3.867, 3.404, 3.009)),
          "gold": ((0.18, 0.42, 1.37), (3.42, 2.35, 1.77)),
          "copper": ((0.27, 0.68, 1.22), (3.60, 2.60, 2.30))}


def test_conductor_f82_meets_the_fresnel_at_both_ends_and_stays_close_between():
    from addon.export.materials import conductor_f82, conductor_fresnel

    mu = np.linspace(1e-3, 1.0, 2000)[:, None]
    for name, (n, k) in METALS.items():
        n, k = np.array(n), np.array(k)
        f0, tint = conductor_f82(n, k)
        np.testing.assert_allclose(f0, conductor_fresnel(1.0, n, k))
        f = 6.0 / 7.0
        b = (f0 + (1 - f0) * f ** 5) * (7.0 / f ** 6) * (1 - tint)  # Cycles's F82-tint B
        model = f0 + (1 - f0) * (1 - mu) ** 5 - b * mu * (1 - mu) ** 6
        exact = conductor_fresnel(mu, n, k)
        np.testing.assert_allclose(model[np.argmin(np.abs(mu - 1 / 7))], exact[np.argmin(np.abs(mu - 1 / 7))],
                                   rtol=2e-3)
        assert np.abs(model / exact - 1).max() < (0.06 if name == "gold" else 0.025), name
    # a dielectric-like n, k: F0 of a glass, and the tint clamped to [0, 1]
    f0, tint = conductor_f82(np.array([1.5, 1.5, 1.5]), np.zeros(3))
    np.testing.assert_allclose(f0, 0.04)
    assert np.all((tint >= 0) & (tint <= 1))


def _cases():
    from node_parity import node

    def metallic(rough, dist="MULTI_GGX", base=(0.9, 0.6, 0.3, 1), tint=(1, 1, 1, 1), metal=None,
                 textured=None):
        def case(nt, uv):
            ins = {"Base Color": base, "Edge Tint": tint, "Roughness": rough}
            if textured is not None:
                ck = node(nt, "ShaderNodeTexChecker", {"Vector": uv, "Scale": 3.0, "Color1": (0.9, 0.5, 0.2, 1),
                                                       "Color2": (0.2, 0.4, 0.9, 1)})
                ins[textured] = ck.outputs["Color"]
            n = node(nt, "ShaderNodeBsdfMetallic", ins, distribution=dist)
            if metal is not None:
                n.fresnel_type = "PHYSICAL_CONDUCTOR"
                n.inputs["IOR"].default_value, n.inputs["Extinction"].default_value = METALS[metal]
            return n.outputs[0]
        return case

    return [metallic(0.4), metallic(0.3, "GGX", base=(0.8, 0.8, 0.8, 1), tint=(0.5, 0.7, 0.9, 1)),
            metallic(0.7), metallic(0.5, textured="Base Color"), metallic(0.35, "GGX", textured="Edge Tint"),
            metallic(0.4, metal="default"), metallic(0.3, "GGX", metal="gold"), metallic(0.6, metal="copper"),
            metallic(0.2, "GGX", metal="copper")]


@pytest.mark.parametrize("shape", ["plane", "sphere"])
def test_metallic_bsdf_under_a_sun_matches_cycles(tmp_path, shape):
    """Each tile's channel means within 1 % of Cycles's for the F82 mode (the Principled metal's
    own lobe; measured ≤ 0.5 %), 2 % for Physical Conductor (the F82 fit; spheres show every
    angle; measured ≤ 1.1 %)."""
    pytest.importorskip("bpy")
    from node_parity import render_tiles, tile

    cases = _cases()
    cycles, drt, res = render_tiles(cases, 3, tmp_path, shader=True, sun=(3.0, (0.6, 0.2, 0.3)), shape=shape)
    assert not res.warnings, res.warnings
    errs = []
    for k in range(len(cases)):
        a, b = tile(cycles, k, 3).mean((0, 1)), tile(drt, k, 3).mean((0, 1))
        assert a.min() > 1e-3, k  # lit
        errs.append(b / a - 1)
    errs = np.abs(np.array(errs))
    print(shape, "channel mean errors (%):\n", np.round(100 * errs, 2))
    tol = np.array([0.01] * 5 + [0.02] * 4)
    assert np.all(errs.max(axis=1) < tol), np.round(100 * errs, 2)


@pytest.mark.skipif(importlib.util.find_spec("bpy") is None, reason="needs bpy")
def test_metallic_bsdf_exports_the_principled_metal_lobe(fresh):
    """F82 mode: the same METALLIC lobe as a Principled BSDF with Metallic 1 (F0 = the clamped
    base colour, F82 tint = the clamped Edge Tint); Beckmann, anisotropy and thin film warn."""
    from node_parity import node
    from test_material_programs import _export, _mat, _material_dict, _plane

    mat, nodes, out = _mat("Metal")
    n = node(mat.node_tree, "ShaderNodeBsdfMetallic", {"Base Color": (1.2, 0.5, 0.2, 1),
                                                       "Edge Tint": (0.4, 1.5, 0.8, 1), "Roughness": 0.3})
    mat.node_tree.links.new(n.outputs[0], out.inputs[0])
    _plane(mat)
    lobe = _material_dict(_export(), "Metal")["lobes"][0]
    assert lobe["type"] == "METALLIC" and lobe["color"] == pytest.approx([1.0, 0.5, 0.2])
    assert lobe["tint"] == pytest.approx([0.4, 1.0, 0.8]) and lobe["multiscatter"] is True
    assert lobe["roughness"] == pytest.approx(0.3)
    n.distribution = "BECKMANN"
    n.inputs["Anisotropy"].default_value = 0.5
    n.inputs["Thin Film Thickness"].default_value = 300.0
    warnings = " | ".join(_export().warnings)
    assert "BECKMANN rendered as GGX" in warnings and "anisotropy ignored" in warnings and "thin film" in warnings
