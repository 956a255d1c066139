"""The material table: every material of the scene as flat arrays, and the vectorised
eval / sample / pdf of a material (= the sum of its lobes) for batches of hits.

A material is a sum of lobes (scene-format.md): DIFFUSE (Lambert), GLOSSY (GGX reflection, no
Fresnel) and GLASS (GGX dielectric), each with its own colour; a Mix shader arrives as lobes whose
colours carry the mix weight. Arrays, M materials × L lobe slots (L = most lobes in one material;
lobes whose average colour is below 1e-5 are dropped, like Cycles's CLOSURE_WEIGHT_CUTOFF, and
the remaining lobes are packed into the first slots):

    lobe_type   (M, L) int8     BSDF_NONE / BSDF_DIFFUSE / BSDF_GLOSSY / BSDF_GLASS
    lobe_color  (M, L, 3)       linear RGB weight of the lobe
    lobe_alpha  (M, L)          GGX alpha = roughness² (0 for diffuse)
    lobe_ior    (M, L)          index of refraction of GLASS lobes (1 otherwise)
    lobe_delta  (M, L) bool     lobe is a delta (mirror / smooth glass: alpha² ≤ 2e-10)
    lobe_select (M, L)          probability of picking the lobe when sampling
    lobe_count  (M,)            number of used slots
    emission    (M, 3)          emitted radiance W/(m²·sr) (colour × strength)
    has_emission (M,) bool

Directions are unit vectors in the *local shading frame* (z = shading normal on the geometric
front side, see docs/architecture.md): ``wo`` points toward where the path came from, ``wi``
toward the next vertex. Diffuse and glossy lobes reflect on whichever side wo is; glass enters
when wo.z > 0 and exits when wo.z < 0.

Lobe selection, as Cycles's closure selection (``bsdf_alloc``: ``sample_weight =
average(weight)``): probability ∝ the *average* of the lobe colour's RGB channels. The pdf
reported for a non-delta sample is the whole material's, Σ_l p_l pdf_l over the non-delta lobes
(one-sample MIS over lobes), and its weight is (Σ_l f_l)·|cos θi| / that pdf, so that an
estimator using sample() is unbiased for every mix. A delta sample (mirror, smooth glass) has
weight color_l / p_l (the Fresnel choice cancels the Fresnel factor, as in Cycles) and is_delta;
its ``pdf`` is then the *discrete* probability of the event (p_l × Fresnel choice), not a
density: consumers must not use it for MIS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .dielectric import IOR_ONE_EPS, eval_glass, fresnel_dielectric, sample_glass
from .diffuse import eval_diffuse, sample_diffuse
from .ggx import ALPHA_SQ_SINGULAR, eval_glossy, sample_glossy

# lobe_type values
BSDF_NONE = 0
BSDF_DIFFUSE = 1
BSDF_GLOSSY = 2
BSDF_GLASS = 3
BSDF_TYPES = {"DIFFUSE": BSDF_DIFFUSE, "GLOSSY": BSDF_GLOSSY, "GLASS": BSDF_GLASS}

#: lobes whose average colour is below this are dropped (Cycles's CLOSURE_WEIGHT_CUTOFF).
CLOSURE_WEIGHT_CUTOFF = 1e-5

# BSDFSample.lobe_kind values, for Cycles's bounce counting
LOBE_NONE = 0
LOBE_DIFFUSE = 1
LOBE_GLOSSY = 2          # glossy reflection and glass reflection
LOBE_TRANSMISSION = 3    # glass refraction


@dataclass
class BSDFSample:
    """A batch of n BSDF samples, local frame.

    wi (n, 3): sampled direction, away from the surface. weight (n, 3): f·|cos θi| / pdf, the
    throughput multiplier (0 where invalid). pdf (n,): solid-angle pdf of the whole material
    (selection-weighted, for MIS); for delta samples the discrete probability of the event.
    lobe_kind (n,) int8: LOBE_DIFFUSE / LOBE_GLOSSY / LOBE_TRANSMISSION (LOBE_NONE if invalid).
    is_delta (n,) bool: specular event (no MIS, no NEE). valid (n,) bool."""

    wi: np.ndarray
    weight: np.ndarray
    pdf: np.ndarray
    lobe_kind: np.ndarray
    is_delta: np.ndarray
    valid: np.ndarray


def _fail(where: str, msg: str) -> ValueError:
    return ValueError(f"{where}: {msg}")


def _number(value, where: str, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _fail(where, f"{field} must be a finite number, got {value!r}")
    return float(value)


def _rgb(value, where: str, field: str) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise _fail(where, f"{field} must be a list of 3 numbers, got {value!r}")
    rgb = np.array([_number(v, where, field) for v in value])
    if np.any(rgb < 0.0):
        raise _fail(where, f"{field} must be >= 0, got {list(value)!r}")
    return rgb


class MaterialTable:
    """All materials of a scene; see the module docstring for the arrays."""

    def __init__(self, names, lobe_type, lobe_color, lobe_alpha, lobe_ior, emission):
        self.names = list(names)
        self.lobe_type = np.asarray(lobe_type, dtype=np.int8)
        self.lobe_color = np.asarray(lobe_color, dtype=np.float64)
        self.lobe_alpha = np.asarray(lobe_alpha, dtype=np.float64)
        self.lobe_ior = np.asarray(lobe_ior, dtype=np.float64)
        self.emission = np.asarray(emission, dtype=np.float64)
        m, n_slots = self.lobe_type.shape
        used = self.lobe_type != BSDF_NONE
        self.lobe_count = used.sum(axis=1)
        self.lobe_delta = used & (self.lobe_type != BSDF_DIFFUSE) & (
            (self.lobe_alpha ** 2 <= ALPHA_SQ_SINGULAR)
            | ((self.lobe_type == BSDF_GLASS) & (np.abs(self.lobe_ior - 1.0) < IOR_ONE_EPS)))
        w = np.where(used, self.lobe_color.mean(axis=2), 0.0)
        total = w.sum(axis=1, keepdims=True)
        self.lobe_select = np.divide(w, total, out=np.zeros_like(w), where=total > 0)
        cdf = np.cumsum(self.lobe_select, axis=1)
        cdf[~used] = np.inf
        last = np.maximum(self.lobe_count - 1, 0)
        rows = np.nonzero(self.lobe_count > 0)[0]
        cdf[rows, last[rows]] = 1.0
        self._lobe_cdf = cdf
        self.has_emission = np.any(self.emission > 0.0, axis=1)
        self._albedo = np.where(used[..., None], self.lobe_color, 0.0).sum(axis=1) if n_slots \
            else np.zeros((m, 3))
        self._delta_only = ~np.any(used & ~self.lobe_delta, axis=1)
        # (slot, type) pairs present in the table, non-delta only: eval visits nothing else.
        self._eval_pairs = [(s, t) for s in range(n_slots)
                            for t in (BSDF_DIFFUSE, BSDF_GLOSSY, BSDF_GLASS)
                            if np.any((self.lobe_type[:, s] == t) & ~self.lobe_delta[:, s])]
        self._types_present = {int(t) for t in np.unique(self.lobe_type[used])}
        self._lobe_summary = self._summarise_lobes(used)
        self._pure_diffuse = (self.lobe_count == 1) & (self.lobe_type[:, 0] == BSDF_DIFFUSE) \
            if n_slots else np.zeros(m, dtype=bool)

    def _summarise_lobes(self, used):
        """Per material, what light selection needs to guess where the BSDF is large (see
        `lobe_summary`): weights of the non-delta diffuse, glossy and glass lobes and the
        weight-averaged alpha of the glossy ones."""
        weight = np.where(used & ~self.lobe_delta, self.lobe_color.mean(axis=2), 0.0) \
            if self.lobe_type.shape[1] else np.zeros(self.lobe_type.shape)
        kd = np.where(self.lobe_type == BSDF_DIFFUSE, weight, 0.0).sum(axis=1)
        wg = np.where(self.lobe_type == BSDF_GLOSSY, weight, 0.0)
        kg = wg.sum(axis=1)
        alpha = np.divide((wg * self.lobe_alpha).sum(axis=1), kg, out=np.ones_like(kg), where=kg > 0)
        kt = np.where(self.lobe_type == BSDF_GLASS, weight, 0.0).sum(axis=1)
        return kd, kg, alpha, kt

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_scene(cls, materials: list[dict]) -> "MaterialTable":
        """Build from the header's ``materials`` list (scene-format.md). Raises ValueError naming
        the material and field, e.g. ``material 'Glass' lobe 1: ior must be > 0, got -1.0``.
        Roughness is Blender's (alpha = roughness²) and must lie in [0, 1]; a DIFFUSE lobe's
        roughness, if present, is ignored (Lambert only)."""
        if not isinstance(materials, (list, tuple)):
            raise ValueError(f"materials must be a list, got {type(materials).__name__}")
        names, parsed, emissions = [], [], []
        for i, mat in enumerate(materials):
            if not isinstance(mat, dict):
                raise ValueError(f"material {i}: must be an object, got {type(mat).__name__}")
            name = mat.get("name", f"#{i}")
            if not isinstance(name, str):
                raise ValueError(f"material {i}: name must be a string, got {name!r}")
            where = f"material {name!r}"
            lobes = mat.get("lobes", [])
            if not isinstance(lobes, (list, tuple)):
                raise _fail(where, f"lobes must be a list, got {type(lobes).__name__}")
            emissions.append(_rgb(mat.get("emission", [0.0, 0.0, 0.0]), where, "emission"))
            rows = []
            for j, lobe in enumerate(lobes):
                lw = f"{where} lobe {j}"
                if not isinstance(lobe, dict):
                    raise _fail(lw, f"must be an object, got {type(lobe).__name__}")
                kind = lobe.get("type")
                if kind not in BSDF_TYPES:
                    raise _fail(lw, f"type must be one of {sorted(BSDF_TYPES)}, got {kind!r}")
                if "color" not in lobe:
                    raise _fail(lw, "color is missing")
                color = _rgb(lobe["color"], lw, "color")
                alpha, ior = 0.0, 1.0
                if kind in ("GLOSSY", "GLASS"):
                    if "roughness" not in lobe:
                        raise _fail(lw, "roughness is missing")
                    r = _number(lobe["roughness"], lw, "roughness")
                    if not 0.0 <= r <= 1.0:
                        raise _fail(lw, f"roughness must be in [0, 1], got {r!r}")
                    alpha = r * r
                if kind == "GLASS":
                    if "ior" not in lobe:
                        raise _fail(lw, "ior is missing")
                    ior = _number(lobe["ior"], lw, "ior")
                    if ior <= 0.0:
                        raise _fail(lw, f"ior must be > 0, got {ior!r}")
                if color.mean() >= CLOSURE_WEIGHT_CUTOFF:
                    rows.append((BSDF_TYPES[kind], color, alpha, ior))
            names.append(name)
            parsed.append(rows)
        m = len(parsed)
        n_slots = max((len(r) for r in parsed), default=0)
        lobe_type = np.zeros((m, n_slots), np.int8)
        lobe_color = np.zeros((m, n_slots, 3))
        lobe_alpha = np.zeros((m, n_slots))
        lobe_ior = np.ones((m, n_slots))
        for i, rows in enumerate(parsed):
            for j, (t, c, a, eta) in enumerate(rows):
                lobe_type[i, j], lobe_color[i, j], lobe_alpha[i, j], lobe_ior[i, j] = t, c, a, eta
        emission = np.array(emissions).reshape(m, 3)
        return cls(names, lobe_type, lobe_color, lobe_alpha, lobe_ior, emission)

    # ------------------------------------------------------------------ queries
    def albedo(self, mat: np.ndarray) -> np.ndarray:
        """mat (n,) int; returns (n, 3) the sum of the lobe colours (for the albedo pass)."""
        return self._albedo[np.asarray(mat, dtype=np.intp)]

    def lobe_summary(self, mat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """mat (n,) int (−1: none); (kd, kg, alpha, kt), each (n,): the summed average colour of the
        material's diffuse, glossy and glass lobes (delta lobes excluded: next-event estimation
        cannot reach them) and the colour-weighted GGX alpha of its glossy lobes (1 if none).
        A rough description for light selection (`drt.lights.selection`), not for shading."""
        mat = np.asarray(mat, dtype=np.intp)
        known = (mat >= 0) & (mat < len(self.names))
        if known.all():
            return tuple(a[mat] for a in self._lobe_summary)
        # no material (camera rays, an empty table): nothing is known, all zero
        safe = np.where(known, mat, 0)
        return tuple(np.where(known, a[safe], 0.0) if len(a) else np.zeros(len(mat))
                     for a in self._lobe_summary)

    def is_delta_only(self, mat: np.ndarray) -> np.ndarray:
        """mat (n,) int; (n,) bool: no lobe can be evaluated, so no NEE (also True for
        materials without lobes)."""
        return self._delta_only[np.asarray(mat, dtype=np.intp)]

    def has_transmission_or_delta(self, mat: np.ndarray) -> np.ndarray:
        """mat (n,) int; (n,) bool: a glass lobe or a mirror-like (delta) lobe is present, so
        only the material's own sampling reaches all of its directions."""
        used = self.lobe_type != BSDF_NONE
        flag = np.any(used & ((self.lobe_type == BSDF_GLASS) | self.lobe_delta), axis=1)
        return flag[np.asarray(mat, dtype=np.intp)]

    def has_diffuse(self, mat: np.ndarray) -> np.ndarray:
        """mat (n,) int; (n,) bool: the material has a diffuse lobe."""
        return np.any(self.lobe_type == BSDF_DIFFUSE, axis=1)[np.asarray(mat, dtype=np.intp)]

    def eval(self, mat: np.ndarray, wo: np.ndarray,
             wi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """mat (n,) int; wo, wi (n, 3) local unit vectors. Returns (f·|cos θi| (n, 3) summed over
        the non-delta lobes, pdf (n,) per unit solid angle of wi, Σ p_l pdf_l, exactly what
        sample() reports for a non-delta sample)."""
        mat = np.asarray(mat, dtype=np.intp)
        wo = np.asarray(wo, dtype=np.float64)
        wi = np.asarray(wi, dtype=np.float64)
        n = mat.shape[0]
        f = np.zeros((n, 3))
        pdf = np.zeros(n)
        for slot, t in self._eval_pairs:
            mask = (self.lobe_type[mat, slot] == t) & ~self.lobe_delta[mat, slot]
            idx = np.nonzero(mask)[0]
            if idx.size == 0:
                continue
            mi = mat[idx]
            value, p = self._eval_lobe(t, wo[idx], wi[idx], self.lobe_alpha[mi, slot],
                                       self.lobe_ior[mi, slot])
            f[idx] += self.lobe_color[mi, slot] * value[:, None]
            pdf[idx] += self.lobe_select[mi, slot] * p
        return f, pdf

    @staticmethod
    def _eval_lobe(t, wo, wi, alpha, ior):
        if t == BSDF_DIFFUSE:
            return eval_diffuse(wo, wi)
        if t == BSDF_GLOSSY:
            return eval_glossy(wo, wi, alpha)
        return eval_glass(wo, wi, alpha, ior)

    def sample(self, mat: np.ndarray, wo: np.ndarray, u_lobe: np.ndarray,
               u2: np.ndarray) -> BSDFSample:
        """mat (n,) int; wo (n, 3) local; u_lobe (n,) in [0, 1) picks the lobe (and, rescaled
        inside the picked interval, glass's reflect/refract choice); u2 (n, 2) in [0, 1)² picks
        the direction. See BSDFSample and the module docstring for weight and pdf."""
        mat = np.asarray(mat, dtype=np.intp)
        wo = np.asarray(wo, dtype=np.float64)
        u_lobe = np.asarray(u_lobe, dtype=np.float64)
        u2 = np.asarray(u2, dtype=np.float64)
        n = mat.shape[0]
        wi = np.zeros((n, 3))
        weight = np.zeros((n, 3))
        pdf = np.zeros(n)
        kind = np.zeros(n, np.int8)
        is_delta = np.zeros(n, bool)
        refracted = np.zeros(n, bool)
        count = self.lobe_count[mat]
        has = (count > 0) & (wo[:, 2] != 0.0)
        if self.lobe_type.shape[1] == 0 or not np.any(has):
            return BSDFSample(wi, weight, pdf, kind, is_delta, np.zeros(n, bool))

        cdf = self._lobe_cdf[mat]
        slot = np.minimum(np.sum(u_lobe[:, None] >= cdf, axis=1), np.maximum(count - 1, 0))
        p_sel = self.lobe_select[mat, slot]
        cdf_lo = np.where(slot > 0, cdf[np.arange(n), np.maximum(slot - 1, 0)], 0.0)
        u_rest = np.clip((u_lobe - cdf_lo) / np.where(p_sel > 0, p_sel, 1.0), 0.0,
                         np.nextafter(1.0, 0.0))
        t_sel = np.where(has, self.lobe_type[mat, slot], BSDF_NONE)
        is_delta = has & self.lobe_delta[mat, slot]
        # alpha 0 makes the lobe functions take their delta path (also for glass with ior ≈ 1)
        alpha = np.where(is_delta, 0.0, self.lobe_alpha[mat, slot])
        ior = self.lobe_ior[mat, slot]

        for t in self._types_present:
            idx = np.nonzero(t_sel == t)[0]
            if idx.size == 0:
                continue
            if t == BSDF_DIFFUSE:
                wi[idx] = sample_diffuse(wo[idx], u2[idx])
                kind[idx] = LOBE_DIFFUSE
            elif t == BSDF_GLOSSY:
                wi[idx] = sample_glossy(wo[idx], alpha[idx], u2[idx])
                kind[idx] = LOBE_GLOSSY
            else:
                wi[idx], refracted[idx] = sample_glass(wo[idx], alpha[idx], ior[idx],
                                                       u_rest[idx], u2[idx])
                kind[idx] = np.where(refracted[idx], LOBE_TRANSMISSION, LOBE_GLOSSY)

        side = wo[:, 2] * wi[:, 2]
        valid = has & np.where(refracted, side < 0.0, side > 0.0)

        # Delta events: weight colour / p_sel; pdf = discrete probability of the event.
        d = np.nonzero(valid & is_delta)[0]
        if d.size:
            weight[d] = self.lobe_color[mat[d], slot[d]] / p_sel[d, None]
            pdf[d] = p_sel[d]
            g = d[t_sel[d] == BSDF_GLASS]
            if g.size:
                eta = np.where(wo[g, 2] < 0.0, 1.0 / ior[g], ior[g])
                fr = fresnel_dielectric(wo[g, 2], eta)
                pdf[g] *= np.where(refracted[g], 1.0 - fr, fr)

        # Non-delta events: the whole material's f and pdf at the sampled wi. A material that is
        # one Lambert lobe needs no evaluation: pdf = |cos θi|/π, weight = its colour.
        c = np.nonzero(valid & ~is_delta)[0]
        if c.size and self._pure_diffuse.any():
            pure = self._pure_diffuse[mat[c]]
            p_idx = c[pure]
            pdf[p_idx] = np.abs(wi[p_idx, 2]) * (1.0 / np.pi)
            ok = pdf[p_idx] > 0.0
            weight[p_idx] = np.where(ok[:, None], self.lobe_color[mat[p_idx], 0], 0.0)
            valid[p_idx] &= ok
            c = c[~pure]
        if c.size:
            f_c, pdf_c = self.eval(mat[c], wo[c], wi[c])
            ok = pdf_c > 0.0
            weight[c] = np.where(ok[:, None], f_c / np.where(ok, pdf_c, 1.0)[:, None], 0.0)
            pdf[c] = pdf_c
            valid[c] &= ok

        kind[~valid] = LOBE_NONE
        weight[~valid] = 0.0
        pdf[~valid] = 0.0
        is_delta &= valid
        return BSDFSample(wi, weight, pdf, kind, is_delta, valid)
