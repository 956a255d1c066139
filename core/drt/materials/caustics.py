"""Cycles's Caustics switches (Light Paths > Caustics > Reflective / Refractive).

With a switch off, Cycles builds a shader without the closures the switch names whenever the ray
that reached it left a diffuse bounce (svm/closure.h, ``PATH_RAY_VISIBILITY_DIFFUSE``: the last
scattering event was diffuse reflection or translucency; a transparent pass keeps it, a volume
scatter clears it). The closures are simply absent: neither light sampling nor BSDF sampling
sees them, and the layers under a dropped one are not darkened by it. So a smooth floor lit
through glass loses the caustic, and the glass's refraction still shows from the camera.

What Cycles drops, per closure (``reflective`` / ``refractive`` False means that switch is off):

- Glossy BSDF, Metallic BSDF, the Principled's metal, specular layer and coat: reflective. A
  dropped specular layer or coat no longer takes its albedo from the lobes under it; a coat
  still tints them (its absorption is applied whether or not its closure exists).
- Refraction BSDF: refractive.
- Glass BSDF and the Principled's transmission: the reflection by reflective, the refraction by
  refractive, the whole closure when both are off.
- Diffuse, Translucent, Sheen, Velvet, subsurface, Transparent (and alpha: DRT's IOR-1 glass),
  Holdout and emission: never.

DRT renders this with a second material row per affected material, its *twin*: the same material
(and program) with those lobes taken out, which ``shade`` uses instead of the material's own
row at a hit whose path's last bounce was diffuse (``MaterialData.caustic_row``). The twin is
built here from the scene's material descriptions (scene-format.md), so the material table
treats it like any other material: a dropped lobe becomes a black one (which the table drops,
passing the lobes under a dropped layer to the layer above), a tinted coat becomes a layer of
albedo 0 that keeps its tint (``TINT_ONLY``, the table's BSDF_COAT_TINT), and a glass keeps only
its refraction (reflection weight 0) or only its reflection (colour 0; a Glass BSDF's reflection
tint is then the mean of its colour, which per channel only a tinted Glass BSDF differs from).
A glass that keeps one half still samples the other by its Fresnel choice, with weight 0: unbiased,
and noisier than Cycles, which samples the kept half only.
"""

from __future__ import annotations

import numpy as np

from .dielectric import IOR_ONE_EPS

#: a DIELECTRIC_SPECULAR lobe's key (set here, never in a file) that keeps only its coat tint
TINT_ONLY = "_tint_only"

#: what a dropped lobe that is no layer becomes: a black lobe, which the table drops, keeping
#: the file's lobe indices ("layer", "emission_layer", a program's registers) valid
_DROPPED = {"type": "DIFFUSE", "color": [0.0, 0.0, 0.0]}

#: a lobe's per-hit registers (drt.materials.program_format) a twin must not let overwrite what
#: it changed: a dropped layer's or glass half's colour / reflection weight
_COLOR_REG = "color_reg"
_WEIGHT_REG = "weight_reg"


def _tinted(lobe: dict) -> bool:
    """A coat whose tint absorbs (a non-white ``coat_tint`` or a textured one)."""
    return "coat_tint_reg" in lobe or bool(np.any(np.asarray(lobe.get("coat_tint", 1.0), np.float64) != 1.0))


def _straight(lobe: dict) -> bool:
    """An IOR-1 GLASS lobe: the Transparent BSDF or a Principled Alpha (drt.materials.transparency),
    which no switch drops (nor does Cycles drop its Transparent closure)."""
    return "ior_reg" not in lobe and abs(float(lobe.get("ior", 1.5)) - 1.0) < IOR_ONE_EPS


def _well_formed(material) -> bool:
    """Whether a twin can be read off ``material``: anything else is left to the material
    table, which names what is wrong with it (a twin is never built from a bad description)."""
    try:
        lobes = material["lobes"]
        for lobe in lobes:
            _tinted(lobe)
            _straight(lobe)
            np.mean(np.asarray(lobe["color"], np.float64))
        return isinstance(lobes, (list, tuple))
    except (KeyError, TypeError, ValueError, AttributeError):
        return False


def twin_lobe(lobe: dict, reflective: bool, refractive: bool) -> dict:
    """``lobe`` as Cycles builds it after a diffuse bounce with the switches as given: the lobe
    itself (unchanged: the same dict), a black lobe (dropped), a tint-only coat, or a glass
    with one half weighted 0."""
    kind = lobe.get("type")
    if kind in ("GLOSSY", "METALLIC") and not reflective:
        return dict(_DROPPED)
    if kind == "REFRACTION" and not refractive:
        return dict(_DROPPED)
    if kind == "DIELECTRIC_SPECULAR" and not reflective:
        if lobe.get("layer_weight", 1.0) != 0.0 and _tinted(lobe):
            return {**lobe, TINT_ONLY: True}
        # (kept as a black layer: lobes under it name it, and the table passes them up)
        return {k: v for k, v in lobe.items() if k != _COLOR_REG} | {"color": [0.0, 0.0, 0.0]}
    if kind == "GLASS" and not (reflective and refractive) and not _straight(lobe):
        if not (reflective or refractive):
            return dict(_DROPPED)
        if not reflective:  # the refraction alone
            return {k: v for k, v in lobe.items() if k != _WEIGHT_REG} | {"reflection_weight": 0.0}
        # the reflection alone: a Principled's by its reflection weight, a Glass BSDF's by its colour
        weight = lobe.get("reflection_weight", float(np.mean(lobe["color"])))
        return {k: v for k, v in lobe.items() if k != _COLOR_REG} | {"color": [0.0, 0.0, 0.0],
                                                                      "reflection_weight": weight}
    return lobe


def caustics_twin(material: dict, reflective: bool, refractive: bool) -> dict | None:
    """The twin of one material (scene-format.md's material object), or None when the switches
    drop nothing of it."""
    if not _well_formed(material):
        return None
    lobes = material["lobes"]
    twin = [twin_lobe(lobe, reflective, refractive) for lobe in lobes]
    if all(a is b for a, b in zip(twin, lobes)):
        return None
    return {**material, "name": f"{material.get('name', '')} (caustics)", "lobes": twin}


def with_caustics_twins(materials: list[dict], reflective: bool,
                        refractive: bool) -> tuple[list[dict], np.ndarray]:
    """(materials followed by their twins, twin row per material (−1: none; (M,) int64, M the
    length of the extended list))."""
    out = list(materials)
    twin_of = []
    for mat in materials:
        twin = caustics_twin(mat, reflective, refractive) if isinstance(mat, dict) else None
        if twin is None:
            twin_of.append(-1)
        else:
            twin_of.append(len(out))
            out.append(twin)
    return out, np.array(twin_of + [-1] * (len(out) - len(materials)), np.int64)
