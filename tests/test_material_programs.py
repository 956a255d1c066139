"""Material programs (docs/materials.md): node graphs compiled at export and evaluated by DRT,
against Cycles pixel by pixel (tests/node_parity.py: an emission tile per case seen by an
orthographic camera), plus unit tests of the compiler (no rendering).

Tolerance: 2e-3 absolute on atan-squashed values in (0, 1) (node_parity.squash). Cycles
evaluates in float32 and jitters its sample inside a 0.01-pixel filter; DRT in float64 with its
own jitter; 8-bit images are compared after Cycles's own sRGB decoding.
"""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import node_parity as P  # noqa: E402
from node_parity import centred, make_image, mapping, node  # noqa: E402

pytestmark = pytest.mark.blender

TOL = 2e-3


def _check(cases, n, tmp_path, tag, names):
    """Render and compare; a case whose name ends in '*' is discontinuous (checker edges,
    Closest texels, floor/step maths): one pixel whose centre lies within the 0.01-pixel sample
    jitter of an edge may differ."""
    cycles, drt, res = P.render_tiles(cases, n, tmp_path, tag)
    bad = {}
    for k in range(len(cases)):
        err = np.abs(P.tile(cycles, k, n) - P.tile(drt, k, n)).max(axis=2)
        allowed = 1 if names[k].endswith("*") else 0
        if np.count_nonzero(err > TOL) > allowed:
            bad[names[k]] = round(float(np.sort(err.ravel())[-1 - allowed]), 5)
    assert not bad, f"cases differing from Cycles (max abs error): {bad}"
    # every case really varies over its tile or is a deliberate constant, and is not black
    assert np.all(cycles[..., :3].mean(axis=(0, 1)) > 0.05)
    return res


# --- textures ------------------------------------------------------------------------------


def _image_case(path, space, interp, ext, scale=1.5, loc=-0.25):
    def case(nt, uv):
        img = bpy.data.images.load(path, check_existing=True)
        img.colorspace_settings.name = space
        vec = mapping(nt, uv, loc=(loc, loc, 0), scale=(scale, scale, 1))
        t = node(nt, "ShaderNodeTexImage", {"Vector": vec}, image=img, interpolation=interp, extension=ext)
        return t.outputs["Color"]
    return case


def _checker(use_uv, scale=5.0, rot=0.0):
    def case(nt, uv):
        ins = {"Scale": scale, "Color1": (0.9, 0.2, 0.1, 1), "Color2": (0.1, 0.3, 0.8, 1)}
        if use_uv:
            ins["Vector"] = mapping(nt, uv, rot=(0, 0, rot), kind="TEXTURE")
        return node(nt, "ShaderNodeTexChecker", ins).outputs["Color"]
    return case


def _gradient(kind, use_uv=True):
    def case(nt, uv):
        ins = {"Vector": centred(nt, uv)} if use_uv else {}
        return node(nt, "ShaderNodeTexGradient", ins, gradient_type=kind).outputs["Fac"]
    return case


def test_textures_match_cycles(tmp_path):
    srgb, data = str(tmp_path / "srgb.png"), str(tmp_path / "data.png")
    make_image("srgb", path=srgb)
    make_image("data", seed=2, path=data)
    cases, names = [], []
    for interp in ("Closest", "Linear"):
        for ext in ("REPEAT", "EXTEND", "CLIP", "MIRROR"):
            cases.append(_image_case(srgb, "sRGB", interp, ext))
            names.append(f"image {interp} {ext}" + ("*" if interp == "Closest" else ""))
    cases.append(_image_case(data, "Non-Color", "Linear", "REPEAT", 2.0, 0.1))
    names.append("image Non-Color")
    cases += [_checker(False), _checker(True, 3.0, 0.4)]
    names += ["checker generated*", "checker uv+mapping*"]
    for kind in ("LINEAR", "QUADRATIC", "EASING", "DIAGONAL", "SPHERICAL", "QUADRATIC_SPHERE", "RADIAL"):
        cases.append(_gradient(kind))
        names.append(f"gradient {kind}")
    res = _check(cases[:16], 4, tmp_path, "textures", names)
    assert [im["srgb"] for im in res.header["images"]] == [True, False]
    assert res.arrays["image0.pixels"].dtype == np.uint8
