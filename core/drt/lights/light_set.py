"""LightSet: every light of a scene behind one interface (see docs/architecture.md and
docs/lights.md): light selection, next-event sampling, and ray intersection / pdfs for MIS.

Selection ("strategies", in this order): the header's lights (same indices as ``scene["lights"]``),
then all emissive triangles as one entry, then the world. Each is picked with probability ∝ its
estimated luminance flux (`power`): point P, spot P·(1 − cos(size/2))/2, area P (watts × color
luminance); emissive triangles 2π·Σ A·lum(L) (two-sided); sun S·πR² and world 4π²R²·lum(L), with
R the scene radius (pbrt's flux estimates for distant lights). The triangle within the emissive
group is then picked ∝ area × luminance with the remainder of the same random number.

Selection modes (``selection=``):

- ``"DISTANCE"`` (default): per shading point, ∝ an estimate of the irradiance each strategy
  delivers there: a local light's flux over the squared distance to its centre, floored at the
  square of its bounding radius (the cheap bound: it never explodes near or inside a light),
  P/(4π·max(d², r²)) for points and spots, P/(π·max(d², r²)) for area lights (zero behind their
  one-sided plane, where they give no light), 2πΣAL/(2π·max(d², r²)) for the emissive group
  around its bounding sphere; the distant lights' flux over πR² (sun: S, world: π·L). The same
  function of the point is evaluated by `intersect` / `emissive_pdf` / `world_pdf` (at the ray
  origin) so MIS pdfs agree with `sample`.
- ``"POWER"``: ∝ flux alone, the same everywhere.
- ``"UNIFORM"``: every strategy alike (for comparison).

With a single strategy nothing is computed: its probability is exactly 1.

The maths is in scalar ``@kernel`` functions (the interface the compiled integrator calls, see
docs/kernels.md): `light_sample`, `selection_prob`, `shape_intersect`, `shape_emission`,
`sun_in_cone`, `sun_emission`, `world_radiance`, `world_pdf`, `emissive_pdf`, all taking
``LightSet.data`` (a `drt.lights.common.LightData`) first. The `LightSet` methods are thin
wrappers: a compiled loop over the rows calling them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .area import AreaLight, area_hit_radiance, area_intersect, area_pdf, area_sample
from ..kernels import inline_kernel
from .common import AREA, SUN, LightData, build_light_data, scalar_kernel, selection_tables
from .emissive import (EmissiveGroup, EmissiveTriangles, emissive_dir_pdf, emissive_local_index,
                       emissive_sample)
from .point import PointLight, point_hit_radiance, point_intersect, point_pdf, point_sample
from .selection import (ShadingHint, hint_arrays, hint_known, row_hint, select_in,
                        select_strategy, selection_prob, selection_totals, strategy_prob)
from .spot import SpotLight
from .sun import SunLight, sun_contains, sun_pdf_dir, sun_sample
from .world import WorldLight, world_dir_pdf, world_pdf_dir, world_sample
from ..kernels import kernel
from ..kernels.vec3 import dot, load, store, sub
from .common import I_IS_DELTA, I_KIND, L_RADIANCE  # noqa: F401 (table columns)
from ..kernels.vec3 import load_col3

__all__ = ["LightData", "LightHit", "LightSample", "LightSet", "emissive_pdf", "light_sample",
           "light_sample_full",
           "select", "select_rows", "selection_distribution", "selection_prob", "shape_emission",
           "shape_intersect", "sun_emission", "sun_in_cone", "world_pdf", "world_radiance"]

_INF = math.inf
_ZERO3 = (0.0, 0.0, 0.0)


@dataclass
class LightSample:
    """Next-event sample at n shading points (world space, unit ``wi`` toward the light).

    ``radiance`` is the radiance arriving along −wi (delta lights: already divided by d², the sun:
    its irradiance S), ``pdf`` the solid-angle pdf × selection probability (delta lights: the
    selection probability), so ``f · |cos θ| · radiance / pdf`` is the estimate for every light.
    ``dist`` is the distance to the sampled point (inf for sun/world): shadow rays use it as tmax.
    ``light`` is the strategy index (header light index; ``n_lights`` = emissive group,
    ``n_lights + 1`` or ``n_lights`` = world) and ``prim`` the global triangle id for emissive
    samples (−1 otherwise).
    """
    wi: np.ndarray
    dist: np.ndarray
    radiance: np.ndarray
    pdf: np.ndarray
    is_delta: np.ndarray
    valid: np.ndarray
    light: np.ndarray
    prim: np.ndarray


@dataclass
class LightHit:
    """Nearest visible light shape along rays: ``hit`` (n,) bool, ``t`` (n,) (inf on a miss or
    for a sun), ``radiance`` (n, 3) arriving at the ray origin, ``pdf`` (n,) the solid-angle pdf ×
    selection probability that `LightSet.sample` gives this direction from the ray origin (for
    MIS), ``light`` (n,) header light index (−1 on a miss)."""
    hit: np.ndarray
    t: np.ndarray
    radiance: np.ndarray
    pdf: np.ndarray
    light: np.ndarray


# ------------------------------------------------------------------------ the scalar interface
@inline_kernel
def _strategy_sample(ld, s, p, n, u0, u1, u_rem):
    """Strategy s from p: (wi, dist, radiance, pdf, is_delta, valid, prim) (pdf without the
    selection probability; prim: the global triangle id for the emissive group, else −1)."""
    if s < ld.n_lights:
        kind = ld.li[s, I_KIND]
        if kind == SUN:
            wi, dist, radiance, pdf, valid = sun_sample(ld, s, u0, u1)
        elif kind == AREA:
            wi, dist, radiance, pdf, valid = area_sample(ld, s, p, u0, u1)
        else:
            wi, dist, radiance, pdf, valid = point_sample(ld, s, p, u0, u1)
        return wi, dist, radiance, pdf, (ld.li[s, I_IS_DELTA] != 0), valid, -1
    if s == ld.emissive_index:
        wi, dist, radiance, pdf, valid, prim = emissive_sample(ld, p, u0, u1, u_rem)
        return wi, dist, radiance, pdf, False, valid, prim
    wi, dist, radiance, pdf, valid = world_sample(ld, p, n, u0, u1)
    return wi, dist, radiance, pdf, False, valid, -1


@inline_kernel
def light_sample_full(ld, p, n, hint, u_sel, u0, u1):
    """`light_sample` plus the strategy chosen and the emissive triangle's global id (−1)."""
    if ld.n_strategies == 0:
        return _ZERO3, 0.0, _ZERO3, 0.0, False, False, -1, -1
    s, prob, u_rem = select_strategy(ld, p, hint, u_sel)
    wi, dist, radiance, pdf, is_delta, valid, prim = _strategy_sample(ld, s, p, n, u0, u1, u_rem)
    pdf = pdf * prob
    return wi, dist, radiance, pdf, is_delta, valid and pdf > 0.0, s, prim


@inline_kernel
def light_sample(ld, p, n, hint, u_sel, u0, u1):
    """Next-event sample at p: choose a strategy with u_sel (BSDF-aware with `hint`), sample it
    with (u0, u1). n: normal of the hemisphere to light (the world samples cosine-weighted about
    it; zero = none: uniform sphere). (wi, dist, radiance, pdf, is_delta, valid), pdf = solid
    angle × selection probability (delta lights: the selection probability); see `LightSample`."""
    wi, dist, radiance, pdf, is_delta, valid, _, _ = light_sample_full(ld, p, n, hint, u_sel, u0, u1)
    return wi, dist, radiance, pdf, is_delta, valid


@scalar_kernel
def _light_intersect(ld, i, o, d):
    if ld.li[i, I_KIND] == AREA:
        return area_intersect(ld, i, o, d)
    if ld.li[i, I_KIND] == SUN:
        return _INF
    return point_intersect(ld, i, o, d)


@scalar_kernel
def _light_hit_radiance(ld, i, o, d):
    if ld.li[i, I_KIND] == AREA:
        return area_hit_radiance(ld, i, o, d)
    return point_hit_radiance(ld, i, o, d)


@scalar_kernel
def _light_pdf(ld, i, o, d, t):
    if ld.li[i, I_KIND] == AREA:
        return area_pdf(ld, i, o, d, t)
    return point_pdf(ld, i, o, d, t)


@inline_kernel
def shape_intersect(ld, k, o, d):
    """Distance along the unit ray o + t d to the k-th light with a visible shape (light
    ``ld.shapes[k]``), inf on a miss."""
    return _light_intersect(ld, ld.shapes[k], o, d)


@inline_kernel
def shape_emission(ld, k, o, d, t, origin, hint):
    """The k-th shape light hit at o + t d: (header light index, radiance arriving along −d,
    pdf = solid-angle pdf of sampling d from `origin` × selection probability at origin)."""
    i = ld.shapes[k]
    radiance = _light_hit_radiance(ld, i, o, d)
    # as seen from origin: the hit point o + t d lies at t + (o − origin)·d from it
    t_origin = t + dot(sub(o, origin), d)
    pdf = _light_pdf(ld, i, origin, d, t_origin) * selection_prob(ld, origin, hint, i)
    return i, radiance, pdf


@inline_kernel
def sun_in_cone(ld, d):
    """Header index of the first sun with an angle whose disk contains the unit direction d, or
    −1."""
    for j in range(ld.n_suns):
        i = ld.suns[j]
        if sun_contains(ld, i, d):
            return i
    return -1


@inline_kernel
def sun_emission(ld, light, origin, d, hint):
    """(radiance, pdf × selection at origin) of sun `light` seen along d."""
    pdf = sun_pdf_dir(ld, light, d) * selection_prob(ld, origin, hint, light)
    return load_col3(ld.lf, light, L_RADIANCE), pdf


@inline_kernel
def world_radiance(ld, d):
    """World radiance arriving along −d (constant; zero without a world)."""
    return (ld.world_color[0], ld.world_color[1], ld.world_color[2])


@inline_kernel
def world_pdf(ld, p, n, d, hint):
    """Solid-angle pdf × selection probability of the world producing d at p with normal n
    (zero: uniform sphere), as `light_sample` would; 0 without a world."""
    if not ld.has_world:
        return 0.0
    return world_pdf_dir(ld, n, d) * selection_prob(ld, p, hint, ld.world_index)


@inline_kernel
def emissive_pdf(ld, prim, o, p_hit, ng_hit, hint):
    """MIS pdf (solid angle × selection) of sampling p_hit on emissive triangle `prim` (global
    id) from o; 0 for non-emissive triangles."""
    if not ld.has_emissive:
        return 0.0
    pdf = emissive_dir_pdf(ld, prim, o, p_hit, ng_hit)
    if pdf == 0.0:
        return 0.0
    return pdf * selection_prob(ld, o, hint, ld.emissive_index)


# ------------------------------------------------------------------------- row-loop wrappers
@kernel
def _sample_rows(ld, p, n, hn, hwo, hs, u_sel, u2, wi, dist, radiance, pdf, is_delta, valid,
                 light, prim):
    for r in range(p.shape[0]):
        out = light_sample_full(ld, load(p, r), load(n, r), row_hint(hn, hwo, hs, r), u_sel[r],
                                u2[r, 0], u2[r, 1])
        store(wi, r, out[0])
        dist[r] = out[1]
        store(radiance, r, out[2])
        pdf[r] = out[3]
        is_delta[r] = out[4]
        valid[r] = out[5]
        light[r] = out[6]
        prim[r] = out[7]


@kernel
def _intersect_rows(ld, o, d, tmax, origin, hn, hwo, hs, exclude, use_exclude, t_out, radiance,
                    pdf, light):
    for r in range(o.shape[0]):
        o_r, d_r = load(o, r), load(d, r)
        best_t = tmax[r]
        best, best_k = -1, -1
        for k in range(ld.n_shapes):
            if use_exclude and exclude[r, ld.shapes[k]]:
                continue          # a light this ray already passed
            t = shape_intersect(ld, k, o_r, d_r)
            if t < best_t:
                best_t, best, best_k = t, ld.shapes[k], k
        t_out[r] = best_t if best >= 0 else _INF
        if best < 0 and math.isinf(tmax[r]):
            best = sun_in_cone(ld, d_r)
        light[r] = best
        if best < 0:
            continue
        hint = row_hint(hn, hwo, hs, r)
        if best_k >= 0:
            _, rad, pdf_r = shape_emission(ld, best_k, o_r, d_r, best_t, load(origin, r), hint)
        else:
            rad, pdf_r = sun_emission(ld, best, load(origin, r), d_r, hint)
        store(radiance, r, rad)
        pdf[r] = pdf_r


@kernel
def _selection_pmf_rows(ld, p, hn, hwo, hs, out):
    from_pt = ld.per_point
    for r in range(p.shape[0]):
        hint = row_hint(hn, hwo, hs, r)
        p_r = load(p, r)
        if from_pt:
            guided = hint_known(hint)
            totals = selection_totals(ld, p_r, hint, guided)
            for j in range(ld.n_strategies):
                out[r, j] = strategy_prob(ld, j, p_r, hint, guided, totals)
        else:
            for j in range(ld.n_strategies):
                out[r, j] = ld.pmf[j]


@kernel
def _selection_prob_rows(ld, p, hn, hwo, hs, index, out):
    for r in range(p.shape[0]):
        out[r] = selection_prob(ld, load(p, r), row_hint(hn, hwo, hs, r), index[r])


@kernel
def _world_pdf_rows(ld, p, n, d, hn, hwo, hs, out):
    for r in range(p.shape[0]):
        out[r] = world_pdf(ld, load(p, r), load(n, r), load(d, r), row_hint(hn, hwo, hs, r))


@kernel
def _emissive_pdf_rows(ld, prim, o, p_hit, ng, hn, hwo, hs, out):
    for r in range(o.shape[0]):
        out[r] = emissive_pdf(ld, prim[r], load(o, r), load(p_hit, r), load(ng, r),
                              row_hint(hn, hwo, hs, r))


@kernel
def _strategy_sample_rows(ld, s, p, n, u2, u_tri, wi, dist, radiance, pdf, valid, prim):
    for r in range(p.shape[0]):
        out = _strategy_sample(ld, s, load(p, r), load(n, r), u2[r, 0], u2[r, 1], u_tri[r])
        store(wi, r, out[0])
        dist[r] = out[1]
        store(radiance, r, out[2])
        pdf[r] = out[3]
        valid[r] = out[5]
        prim[r] = out[6]


@kernel
def _light_query_rows(ld, i, o, d, t, t_out, radiance, pdf):
    """Light i along each ray: its intersection distance, hit radiance and pdf at distance t."""
    for r in range(o.shape[0]):
        o_r, d_r = load(o, r), load(d, r)
        t_out[r] = _light_intersect(ld, i, o_r, d_r)
        store(radiance, r, _light_hit_radiance(ld, i, o_r, d_r))
        pdf[r] = _light_pdf(ld, i, o_r, d_r, t[r])


@kernel
def _sun_rows(ld, i, d, in_cone, pdf):
    for r in range(d.shape[0]):
        d_r = load(d, r)
        in_cone[r] = sun_contains(ld, i, d_r)
        pdf[r] = sun_pdf_dir(ld, i, d_r)


@kernel
def _world_dir_pdf_rows(n, d, out):
    for r in range(d.shape[0]):
        out[r] = world_dir_pdf(load(n, r), load(d, r))


@kernel
def _emissive_rows(ld, tri, o, p_hit, ng, local, pdf):
    for r in range(tri.shape[0]):
        local[r] = emissive_local_index(ld, tri[r])
        pdf[r] = emissive_dir_pdf(ld, tri[r], load(o, r), load(p_hit, r), load(ng, r))


@kernel
def _select_rows(pmf, cdf, use_cdf, per_row, u, idx, prob, u_rem):
    for r in range(u.shape[0]):
        if per_row:
            out = select_in(pmf[r], pmf[r], u[r], False)
        else:
            out = select_in(pmf[0], cdf, u[r], use_cdf)
        idx[r] = out[0]
        prob[r] = out[1]
        u_rem[r] = out[2]


# ------------------------------------------------------------------------- array conversions
def _vec(a, m: int) -> np.ndarray:
    """(m, 3) C-contiguous writeable float64 rows (None → zeros)."""
    if a is None:
        return np.zeros((m, 3))
    return np.array(np.broadcast_to(np.asarray(a, dtype=np.float64), (m, 3)), dtype=np.float64,
                    order="C", copy=True)


def _col(a, m: int, dtype=np.float64) -> np.ndarray:
    """(m,) C-contiguous writeable rows of `dtype`."""
    return np.array(np.broadcast_to(np.asarray(a, dtype=dtype), (m,)), dtype=dtype, order="C",
                    copy=True)


def _uv(u2, m: int) -> np.ndarray:
    return np.array(np.broadcast_to(np.asarray(u2, dtype=np.float64), (m, 2)), dtype=np.float64,
                    order="C", copy=True)


# ------------------------------------------------------------ wrappers of the light classes
def strategy_sample_rows(ld: LightData, s: int, p, n, u2, u_tri=None):
    """Strategy s of `ld` sampled from points p (m, 3) with normals n (None: zero) and u2 (m, 2)
    (u_tri: the emissive triangle choice): (wi, dist, radiance, pdf, valid, prim), pdf without
    selection."""
    p = np.asarray(p, dtype=np.float64)
    m = len(p)
    wi, radiance = np.zeros((m, 3)), np.zeros((m, 3))
    dist, pdf = np.zeros(m), np.zeros(m)
    valid, prim = np.zeros(m, dtype=bool), np.full(m, -1, dtype=np.int64)
    u_tri = np.zeros(m) if u_tri is None else _col(u_tri, m)
    _strategy_sample_rows(ld, int(s), _vec(p, m), _vec(n, m), _uv(u2, m), u_tri, wi, dist,
                          radiance, pdf, valid, prim)
    return wi, dist, radiance, pdf, valid, prim


def _single(light) -> LightData:
    """The `LightData` of one header light alone (cached on the light)."""
    ld = getattr(light, "_ld", None)
    if ld is None:
        ld = light._ld = build_light_data([light])
    return ld


def header_light_sample(light, p, n, u2):
    wi, dist, radiance, pdf, valid, _ = strategy_sample_rows(_single(light), 0, p, n, u2)
    return wi, dist, radiance, pdf, valid


def _light_query(light, o, d, t=None):
    o = np.asarray(o, dtype=np.float64)
    m = len(o)
    t_out, radiance, pdf = np.zeros(m), np.zeros((m, 3)), np.zeros(m)
    _light_query_rows(_single(light), 0, _vec(o, m), _vec(d, m),
                      np.zeros(m) if t is None else _col(t, m), t_out, radiance, pdf)
    return t_out, radiance, pdf


def header_light_intersect(light, o, d):
    return _light_query(light, o, d)[0]


def header_light_hit_radiance(light, o, d, t):
    return _light_query(light, o, d, t)[1]


def header_light_pdf(light, o, d, t):
    return _light_query(light, o, d, t)[2]


def header_sun_query(light, d):
    """(in_cone (m,) bool, pdf_dir (m,)) of a sun for unit directions d."""
    d = np.asarray(d, dtype=np.float64)
    m = len(d)
    in_cone, pdf = np.zeros(m, dtype=bool), np.zeros(m)
    _sun_rows(_single(light), 0, _vec(d, m), in_cone, pdf)
    return in_cone, pdf


def world_dir_pdf_rows(ld: LightData, n, d) -> np.ndarray:
    d = np.asarray(d, dtype=np.float64)
    m = len(d)
    out = np.zeros(m)
    _world_dir_pdf_rows(_vec(n, m), _vec(d, m), out)
    return out


def _emissive_query(ld: LightData, tri, o=None, p_hit=None, ng=None):
    tri = _col(np.reshape(np.asarray(tri, dtype=np.int64), -1), np.size(tri), np.int64)
    m = len(tri)
    local, pdf = np.zeros(m, dtype=np.int64), np.zeros(m)
    _emissive_rows(ld, tri, _vec(o, m), _vec(p_hit, m), _vec(ng, m), local, pdf)
    return local, pdf


def emissive_local_rows(ld: LightData, tri) -> np.ndarray:
    local = _emissive_query(ld, tri)[0]
    return local.reshape(np.shape(tri))


def emissive_dir_pdf_rows(ld: LightData, tri, o, p_hit, ng) -> np.ndarray:
    return _emissive_query(ld, tri, o, p_hit, ng)[1]


# ------------------------------------------------------------------------------- selection
def selection_distribution(power) -> tuple[np.ndarray, np.ndarray]:
    """pmf and cdf (both (k,)) for choosing among k strategies ∝ power. Zero total → uniform;
    infinite powers → uniform over the infinite ones.
    With one strategy the pmf is exactly [1.0]."""
    power = np.maximum(np.asarray(power, dtype=np.float64), 0.0)
    if len(power) == 0:
        return power, power
    if np.isinf(power).any():  # emission at float64's limit: the limit of the pmf, uniform over those
        power = np.isinf(power).astype(np.float64)
    total = power.sum()
    pmf = power / total if total > 0.0 else np.full(len(power), 1.0 / len(power))
    if len(pmf) == 1:
        pmf = np.ones(1)
    cdf = np.cumsum(pmf)
    cdf[-1] = 1.0
    return pmf, cdf


def select(pmf, cdf, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Choose strategies for u (n,) in [0, 1): index (n,), its probability (n,), and u rescaled to
    [0, 1) within the chosen interval (reusable for a second discrete choice)."""
    pmf = np.array(pmf, dtype=np.float64, order="C", ndmin=1)
    u = np.asarray(u, dtype=np.float64)
    m = u.size
    idx, prob, u_rem = np.zeros(m, dtype=np.int64), np.zeros(m), np.zeros(m)
    _select_rows(pmf[None, :].copy(), _col(cdf, len(pmf)), True, False, _col(u.reshape(-1), m),
                 idx, prob, u_rem)
    return idx.reshape(u.shape), prob.reshape(u.shape), u_rem.reshape(u.shape)


def select_rows(pmf, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Like `select`, with a separate distribution per row: pmf (m, k), u (m,) in [0, 1)."""
    pmf = np.array(pmf, dtype=np.float64, order="C")
    m = len(pmf)
    idx, prob, u_rem = np.zeros(m, dtype=np.int64), np.zeros(m), np.zeros(m)
    _select_rows(pmf, np.zeros(0), False, True, _col(u, m), idx, prob, u_rem)
    return idx, prob, u_rem


SELECTION_MODES = ("DISTANCE", "POWER", "UNIFORM")


def make_light(light: dict, origin_shift, scene_radius: float):
    kind = str(light.get("type", "POINT")).upper()
    if kind == "POINT":
        return PointLight(light, origin_shift)
    if kind == "SPOT":
        return SpotLight(light, origin_shift)
    if kind == "SUN":
        return SunLight(light, scene_radius)
    if kind == "AREA":
        return AreaLight(light, origin_shift)
    raise ValueError(f"unknown light type {kind!r}")


class LightSet:
    """All lights of a scene.

    lights: the header's light dicts (``docs/scene-format.md``; an optional ``visible_camera``
    bool, default False as in Blender 5.0). world_color: constant world radiance (3,).
    emissive: emissive triangles in the tracer's space, or None. origin_shift (3,): subtracted
    from every light position in ``lights`` (the integrator's re-centring; emissive vertices are
    taken as given). scene_radius: bounding radius of the scene for the sun/world selection
    weights (default: from the light positions and emissive vertices, at least 1 m).
    world_nee: the world is a next-event strategy (default). The renderer passes False for a
    constant-colour world, as Cycles does not sample a constant background either: BSDF rays
    find it with a pdf proportional to the integrand's, and a world strategy would only add the
    variance of choosing between it and the other lights (measured on a sun + grey world scene,
    64 spp: relMSE 3.7e-5 with world NEE, 6.9e-6 without; Cycles 3.8e-6, identical with its
    world sampling AUTOMATIC and NONE). Misses still see ``world_color``.

    ``data``: the `LightData` the kernels (and the compiled integrator) take.
    """

    def __init__(self, lights: list[dict], world_color=(0.0, 0.0, 0.0),
                 emissive: EmissiveTriangles | None = None, *, origin_shift=(0.0, 0.0, 0.0),
                 scene_radius: float | None = None, selection: str = "DISTANCE",
                 world_nee: bool = True, world_program: tuple[int, int] | None = None,
                 world_map=None):
        origin_shift = np.asarray(origin_shift, dtype=np.float64).reshape(3)
        group = EmissiveGroup(emissive) if emissive is not None else None
        if group is not None and len(group) == 0:
            group = None
        if scene_radius is None:
            scene_radius = self._default_radius(lights, origin_shift, group)
        self.scene_radius = float(scene_radius)
        self.lights = [make_light(d, origin_shift, self.scene_radius) for d in lights]
        self.n_lights = len(self.lights)
        self.emissive = group
        world_color = np.asarray(world_color, dtype=np.float64).reshape(3)
        # a textured world (drt.lights.world_map): its program's index and radiance register in
        # the integrator's ProgramData, and its importance map (wm_cond, wm_marg, average)
        self.world_program = world_program
        self.world_map = world_map
        if world_map is not None:
            self.world = WorldLight(world_color, self.scene_radius, world_map[2]) \
                if world_map[2] > 0.0 and world_nee else None
        else:
            self.world = WorldLight(world_color, self.scene_radius) if (world_color > 0).any() and world_nee else None
        self.world_color = world_color
        self.strategies = list(self.lights)
        self.emissive_index = self.world_index = -1
        if self.emissive is not None:
            self.emissive_index = len(self.strategies)
            self.strategies.append(self.emissive)
        if self.world is not None:
            self.world_index = len(self.strategies)
            self.strategies.append(self.world)
        selection = str(selection).upper()
        if selection not in SELECTION_MODES:
            raise ValueError(f"unknown light selection {selection!r} (choose from {', '.join(SELECTION_MODES)})")
        self.selection = selection
        powers = [s.power for s in self.strategies]
        if selection == "UNIFORM":
            powers = [1.0] * len(powers)
        self.pmf, self.cdf = selection_distribution(powers)
        self._per_point = self.selection == "DISTANCE" and len(self.strategies) > 1
        self.visible_to_camera = np.array([lt.visible_to_camera for lt in self.lights], dtype=bool)
        self._shapes = [i for i, lt in enumerate(self.lights)
                        if isinstance(lt, (AreaLight, PointLight)) and not lt.is_delta]
        self._suns = [i for i, lt in enumerate(self.lights)
                      if isinstance(lt, SunLight) and not lt.is_delta]
        self.data = build_light_data(
            self.lights, self.emissive, self.world.radiance if self.world is not None else None,
            pmf=self.pmf, cdf=self.cdf, per_point=self._per_point,
            selection=self._selection_tables(),
            world_program=world_program if world_program is not None else (-1, -1),
            world_map=world_map[:2] if world_map is not None else None)
        if self.world is None and (world_color > 0).any():  # seen by rays that miss, not sampled
            self.data = self.data._replace(world_color=np.array(world_color, dtype=np.float64))

    # ------------------------------------------------------------------------------ selection
    def _selection_tables(self) -> dict:
        """Per-strategy arrays for the DISTANCE selection (`LightData.sel_*`): centre (k, 3),
        squared bounding radius (k,), irradiance scale (k,) (flux × 1/(4π), 1/π, ...), local
        (k,) bool, one-sided normal (k, 3) (zero: two-sided), a sun's direction and sin² of its
        half-angle (for the BSDF factor: its centre seen at distance 1), world flags."""
        k = len(self.strategies)
        tab = selection_tables(k)
        centre, facing, sun_dir = tab["sel_centre"], tab["sel_facing"], tab["sel_sun_dir"]
        for i, strat in enumerate(self.strategies):
            if isinstance(strat, AreaLight):
                centre[i], tab["sel_local"][i] = strat.center, True
                tab["sel_radius2"][i] = 0.25 * (strat.len_x ** 2 + strat.len_y ** 2)
                tab["sel_scale"][i] = strat.power / np.pi
                facing[i] = strat.normal
            elif isinstance(strat, PointLight):  # and spot lights
                centre[i], tab["sel_local"][i] = strat.position, True
                tab["sel_radius2"][i] = strat.radius ** 2
                tab["sel_scale"][i] = strat.power / (4.0 * np.pi)
            elif strat is self.emissive:
                g = strat
                pts = np.concatenate([g.v0, g.v0 + g.e1, g.v0 + g.e2])
                lo, hi = pts.min(axis=0), pts.max(axis=0)
                centre[i], tab["sel_local"][i] = 0.5 * (lo + hi), True
                tab["sel_radius2"][i] = 0.25 * float(np.sum((hi - lo) ** 2))
                tab["sel_scale"][i] = strat.power / (2.0 * np.pi)
            else:  # sun, world: flux over the scene's disk πR²
                tab["sel_scale"][i] = strat.power / (np.pi * self.scene_radius ** 2)
                if isinstance(strat, SunLight):
                    sun_dir[i] = strat.to_sun
                    tab["sel_sun_sin2"][i] = min(strat.one_minus_cos * (2.0 - strat.one_minus_cos), 1.0)
        tab["sel_is_sun"][:] = np.any(sun_dir != 0.0, axis=1)
        if self.world is not None:
            tab["sel_is_world"][self.world_index] = True
        tab["sel_one_sided"][:] = np.any(facing != 0.0, axis=1)
        return tab

    def selection_pmf(self, p, hint: ShadingHint | None = None) -> np.ndarray:
        """(m, k) probability of choosing each strategy at points p (m, 3) (see the module
        docstring). Rows whose estimates are all zero fall back to the power distribution.
        With a `ShadingHint` (normal, wo, material of each point), the distance estimate is
        weighted by the BSDF's guessed response to each light (`drt.lights.selection`)."""
        p = np.asarray(p, dtype=np.float64)
        if not self._per_point:
            return np.broadcast_to(self.pmf, (len(p), len(self.pmf)))
        m = len(p)
        out = np.zeros((m, self.count))
        _selection_pmf_rows(self.data, _vec(p, m), *hint_arrays(hint, m), out)
        return out

    def selection_prob(self, p, index, hint: ShadingHint | None = None) -> np.ndarray:
        """(m,) probability that `sample` at points p (m, 3) with the same ``hint`` chooses
        strategy ``index`` (int or (m,) ints)."""
        index = np.broadcast_to(np.asarray(index), (len(p),))
        if not self._per_point:
            return self.pmf[index]
        m = len(p)
        out = np.zeros(m)
        _selection_prob_rows(self.data, _vec(p, m), *hint_arrays(hint, m),
                             _col(index, m, np.int64), out)
        return out

    @property
    def uses_hint(self) -> bool:
        """Selection depends on the shading point (several strategies, DISTANCE mode), so a
        `ShadingHint` changes it; otherwise callers may skip building one."""
        return self._per_point

    @property
    def count(self) -> int:
        """Number of selectable strategies (lights + emissive group + world); 0 = nothing to sample."""
        return len(self.strategies)

    @staticmethod
    def _default_radius(lights, origin_shift, group) -> float:
        pts = [np.asarray(d["matrix_world"], dtype=np.float64).reshape(4, 4)[:3, 3] - origin_shift
               for d in lights if str(d.get("type", "")).upper() != "SUN"]
        if group is not None:
            pts.extend([group.v0, group.v0 + group.e1, group.v0 + group.e2])
        if not pts:
            return 1.0
        pts = np.vstack([np.reshape(p, (-1, 3)) for p in pts])
        return max(1.0, 0.5 * float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))))

    # ------------------------------------------------------------------------------------------
    def sample(self, p, n, u_select, u2, hint: ShadingHint | None = None) -> LightSample:
        """p (m,3) shading points; n (m,3) normals of the hemisphere to light (or None; zero
        rows count as None); u_select (m,), u2 (m,2) in [0, 1); hint: the points' BSDFs, for
        selection (MIS pdfs of `intersect` / `world_pdf` / `emissive_pdf` must then get the same
        hint)."""
        p = np.asarray(p, dtype=np.float64)
        m = len(p)
        out = LightSample(wi=np.zeros((m, 3)), dist=np.zeros(m), radiance=np.zeros((m, 3)),
                          pdf=np.zeros(m), is_delta=np.zeros(m, dtype=bool),
                          valid=np.zeros(m, dtype=bool), light=np.full(m, -1, dtype=np.int64),
                          prim=np.full(m, -1, dtype=np.int64))
        if not self.strategies or m == 0:
            return out
        _sample_rows(self.data, _vec(p, m), _vec(n, m), *hint_arrays(hint, m), _col(u_select, m),
                     _uv(u2, m), out.wi, out.dist, out.radiance, out.pdf, out.is_delta, out.valid,
                     out.light, out.prim)
        return out

    def hits_along(self, o, d, tmax, origin=None, hint: ShadingHint | None = None):
        """Every light a ray passes before ``tmax``, nearest first, as Cycles sees them: a light
        is a transparent emitter, so a ray collects its radiance and goes on (to the next light,
        the surface behind, or the world). Yields ``(rows, LightHit)`` per layer: ``rows``
        indexes the input rays, the hit's ``t`` is from the original ``o``. A convex light is
        passed once (the far side of a sphere light is not hit again)."""
        o = np.asarray(o, dtype=np.float64)
        d = np.asarray(d, dtype=np.float64)
        origin = o if origin is None else np.asarray(origin, dtype=np.float64)
        m = len(o)
        tmax = np.broadcast_to(np.asarray(tmax, dtype=np.float64), (m,))
        rows = np.arange(m)
        t0 = np.zeros(m)
        exclude = None  # (len(rows), n_lights) bool after the first layer: lights passed
        while len(rows):
            if exclude is None:
                lh = self.intersect(o, d, tmax, origin, hint)
            else:
                o_k = o[rows] + t0[:, None] * d[rows]
                lh = self.intersect(o_k, d[rows], tmax[rows] - t0, origin[rows], _rows(hint, rows), exclude)
                lh.t = lh.t + t0
            yield rows, lh
            more = lh.hit & np.isfinite(lh.t)  # a sun disk ends the ray
            if not more.any():
                return
            exclude = np.zeros((int(more.sum()), self.n_lights), dtype=bool) if exclude is None \
                else exclude[more]
            exclude[np.arange(len(exclude)), lh.light[more]] = True
            rows, t0 = rows[more], lh.t[more]

    def intersect(self, o, d, tmax, origin=None, hint: ShadingHint | None = None,
                  exclude=None) -> LightHit:
        """Nearest light shape with t < tmax along unit rays o + t d (world/tracer space).
        MIS pdfs are those of `sample` at ``origin`` (default o: pass the exact shading point
        when o is offset from it) with ``hint``.
        Area lights are hit from both sides (radiance 0 from the back). Suns with an angle are
        reported (t = inf) for rays whose tmax is inf and that hit no shape; the integrator adds
        `world_radiance` separately. Camera rays should ignore hits where
        ``visible_to_camera[light]`` is False."""
        o = np.asarray(o, dtype=np.float64)
        m = len(o)
        origin = o if origin is None else origin
        t_out, radiance, pdf = np.zeros(m), np.zeros((m, 3)), np.zeros(m)
        light = np.full(m, -1, dtype=np.int64)
        use_exclude = exclude is not None
        exclude = (np.ascontiguousarray(exclude, dtype=bool) if use_exclude
                   else np.zeros((0, 0), dtype=bool))
        if not exclude.flags.writeable:
            exclude = exclude.copy()
        _intersect_rows(self.data, _vec(o, m), _vec(d, m), _col(tmax, m), _vec(origin, m),
                        *hint_arrays(hint, m), exclude, use_exclude, t_out, radiance, pdf, light)
        return LightHit(hit=light >= 0, t=t_out, radiance=radiance, pdf=pdf, light=light)

    def world_radiance(self, d) -> np.ndarray:
        """(m, 3) world radiance arriving along −d (constant)."""
        return np.broadcast_to(self.data.world_color, (len(d), 3)).copy()

    def world_pdf(self, p, n, d, hint: ShadingHint | None = None) -> np.ndarray:
        """(m,) solid-angle pdf × selection probability of the world producing direction d at p
        with normal n (None or zero rows → uniform sphere), as `sample` would."""
        m = len(d)
        out = np.zeros(m)
        if self.world is None:
            return out
        _world_pdf_rows(self.data, _vec(p, m), _vec(n, m), _vec(d, m), *hint_arrays(hint, m), out)
        return out

    def emissive_pdf(self, tri, o, p_hit, ng_hit, hint: ShadingHint | None = None) -> np.ndarray:
        """(m,) MIS pdf (solid angle × selection) of sampling p_hit on emissive triangle `tri`
        (global id) from o; 0 for non-emissive triangles."""
        m = len(o)
        out = np.zeros(m)
        if self.emissive is None:
            return out
        _emissive_pdf_rows(self.data, _col(tri, m, np.int64), _vec(o, m), _vec(p_hit, m),
                           _vec(ng_hit, m), *hint_arrays(hint, m), out)
        return out


def _rows(hint: ShadingHint | None, rows) -> ShadingHint | None:
    return None if hint is None else hint.subset(rows)
