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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .area import AreaLight
from .emissive import EmissiveGroup, EmissiveTriangles
from .point import PointLight
from .selection import ShadingHint, bsdf_factor, mix_with_defensive, normalise_rows
from .spot import SpotLight
from .sun import SunLight
from .world import WorldLight


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


def selection_distribution(power) -> tuple[np.ndarray, np.ndarray]:
    """pmf and cdf (both (k,)) for choosing among k strategies ∝ power. Zero total → uniform.
    With one strategy the pmf is exactly [1.0]."""
    power = np.maximum(np.asarray(power, dtype=np.float64), 0.0)
    if len(power) == 0:
        return power, power
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
    idx = np.searchsorted(cdf, u, side="right")
    idx = np.minimum(idx, len(cdf) - 1)
    prob = pmf[idx]
    # never land on a zero-probability strategy through round-off at the top of the cdf
    if (prob == 0.0).any():
        last = int(np.flatnonzero(pmf > 0.0)[-1])
        idx = np.where(prob == 0.0, last, idx)
        prob = pmf[idx]
    lo = cdf[idx] - pmf[idx]
    u_rem = np.clip((u - lo) / prob, 0.0, np.nextafter(1.0, 0.0))
    return idx, prob, u_rem


def select_rows(pmf, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Like `select`, with a separate distribution per row: pmf (m, k), u (m,) in [0, 1)."""
    m, k = pmf.shape
    cdf = np.cumsum(pmf, axis=1)
    cdf[:, -1] = 1.0
    idx = np.minimum((u[:, None] >= cdf).sum(axis=1), k - 1)
    rows = np.arange(m)
    prob = pmf[rows, idx]
    if (prob == 0.0).any():  # round-off at the top of a row's cdf: take its last non-zero entry
        last = k - 1 - np.argmax(pmf[:, ::-1] > 0.0, axis=1)
        idx = np.where(prob == 0.0, last, idx)
        prob = pmf[rows, idx]
    lo = cdf[rows, idx] - prob
    u_rem = np.clip((u - lo) / np.where(prob > 0, prob, 1.0), 0.0, np.nextafter(1.0, 0.0))
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
    """

    def __init__(self, lights: list[dict], world_color=(0.0, 0.0, 0.0),
                 emissive: EmissiveTriangles | None = None, *, origin_shift=(0.0, 0.0, 0.0),
                 scene_radius: float | None = None, selection: str = "DISTANCE"):
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
        self.world = WorldLight(world_color, self.scene_radius) if (world_color > 0).any() else None
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
        self._setup_distance_selection()
        self.visible_to_camera = np.array([lt.visible_to_camera for lt in self.lights], dtype=bool)
        self._shapes = [i for i, lt in enumerate(self.lights)
                        if isinstance(lt, (AreaLight, PointLight)) and not lt.is_delta]
        self._suns = [i for i, lt in enumerate(self.lights)
                      if isinstance(lt, SunLight) and not lt.is_delta]

    # ------------------------------------------------------------------------------ selection
    def _setup_distance_selection(self) -> None:
        """Per-strategy arrays for `selection_pmf`: centre (k, 3), squared bounding radius (k,),
        irradiance scale (k,) (flux × 1/(4π), 1/π, ...), local (k,) bool, one-sided normal
        (k, 3) (zero: two-sided)."""
        k = len(self.strategies)
        self._per_point = self.selection == "DISTANCE" and k > 1
        if not self._per_point:
            return
        centre = np.zeros((k, 3))
        radius2 = np.zeros(k)
        scale = np.zeros(k)
        local = np.zeros(k, dtype=bool)
        facing = np.zeros((k, 3))
        # for the BSDF factor: direction to a sun (its centre seen at distance 1)
        sun_dir = np.zeros((k, 3))
        sun_sin2 = np.zeros(k)
        for i, strat in enumerate(self.strategies):
            if isinstance(strat, AreaLight):
                centre[i], local[i] = strat.center, True
                radius2[i] = 0.25 * (strat.len_x ** 2 + strat.len_y ** 2)
                scale[i] = strat.power / np.pi
                facing[i] = strat.normal
            elif isinstance(strat, PointLight):  # and spot lights
                centre[i], local[i] = strat.position, True
                radius2[i] = strat.radius ** 2
                scale[i] = strat.power / (4.0 * np.pi)
            elif strat is self.emissive:
                g = strat
                pts = np.concatenate([g.v0, g.v0 + g.e1, g.v0 + g.e2])
                lo, hi = pts.min(axis=0), pts.max(axis=0)
                centre[i], local[i] = 0.5 * (lo + hi), True
                radius2[i] = 0.25 * float(np.sum((hi - lo) ** 2))
                scale[i] = strat.power / (2.0 * np.pi)
            else:  # sun, world: flux over the scene's disk πR²
                scale[i] = strat.power / (np.pi * self.scene_radius ** 2)
                if isinstance(strat, SunLight):
                    sun_dir[i] = strat.to_sun
                    sun_sin2[i] = min(strat.one_minus_cos * (2.0 - strat.one_minus_cos), 1.0)
        self._sel_centre, self._sel_radius2, self._sel_scale = centre, radius2, scale
        self._sel_sun_dir, self._sel_sun_sin2 = sun_dir, sun_sin2
        self._sel_is_sun = np.any(sun_dir != 0.0, axis=1)
        self._sel_is_world = np.zeros(k, dtype=bool)
        if self.world is not None:
            self._sel_is_world[self.world_index] = True
        self._sel_local, self._sel_facing = local, facing
        self._sel_one_sided = np.any(facing != 0.0, axis=1)

    def selection_pmf(self, p, hint: ShadingHint | None = None) -> np.ndarray:
        """(m, k) probability of choosing each strategy at points p (m, 3) (see the module
        docstring). Rows whose estimates are all zero fall back to the power distribution.
        With a `ShadingHint` (normal, wo, material of each point), the distance estimate is
        weighted by the BSDF's guessed response to each light (`drt.lights.selection`)."""
        p = np.asarray(p, dtype=np.float64)
        if not self._per_point:
            return np.broadcast_to(self.pmf, (len(p), len(self.pmf)))
        rel = p[:, None, :] - self._sel_centre[None, :, :]
        d2 = np.einsum("mkj,mkj->mk", rel, rel)
        w = np.where(self._sel_local, self._sel_scale / np.maximum(d2, np.maximum(self._sel_radius2, 1e-12)),
                     self._sel_scale)
        if self._sel_one_sided.any():
            behind = np.einsum("mkj,kj->mk", rel, self._sel_facing) <= 0.0
            w = np.where(self._sel_one_sided & behind, 0.0, w)
        pmf = normalise_rows(w, self.pmf[None, :])
        if hint is None:
            return pmf
        return mix_with_defensive(w * self._bsdf_factor(rel, hint), pmf)

    def _bsdf_factor(self, rel, hint: ShadingHint) -> np.ndarray:
        """(m, k) `bsdf_factor` for every strategy; rel (m, k, 3) = point − light centre. Local
        lights and suns have a direction; the world gets the hemisphere average of f·cos."""
        m, k = rel.shape[0], rel.shape[1]
        aimed = self._sel_local | self._sel_is_sun
        cols = np.flatnonzero(aimed)
        b = np.empty((m, k))
        if len(cols):
            sun = self._sel_is_sun[cols]
            to_light = -rel if len(cols) == k else -rel[:, cols]
            if sun.any():
                to_light = np.where(sun[None, :, None], self._sel_sun_dir[cols][None], to_light)
            radius2 = np.where(sun, self._sel_sun_sin2[cols], self._sel_radius2[cols])
            b[:, cols] = bsdf_factor(to_light, radius2, hint)
        if self._sel_is_world.any():  # albedo / 4π: the world's E estimate is 4πL
            b[:, self._sel_is_world] = ((hint.kd + hint.kg + hint.kt) / (4.0 * np.pi))[:, None]
        return b

    def selection_prob(self, p, index, hint: ShadingHint | None = None) -> np.ndarray:
        """(m,) probability that `sample` at points p (m, 3) with the same ``hint`` chooses
        strategy ``index`` (int or (m,) ints)."""
        index = np.broadcast_to(np.asarray(index), (len(p),))
        if not self._per_point:
            return self.pmf[index]
        return self.selection_pmf(p, hint)[np.arange(len(p)), index]

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
        """p (m,3) shading points; n (m,3) normals of the hemisphere to light (or None);
        u_select (m,), u2 (m,2) in [0, 1); hint: the points' BSDFs, for selection (MIS pdfs of
        `intersect` / `world_pdf` / `emissive_pdf` must then get the same hint)."""
        p = np.asarray(p, dtype=np.float64)
        m = len(p)
        out = LightSample(wi=np.zeros((m, 3)), dist=np.zeros(m), radiance=np.zeros((m, 3)),
                          pdf=np.zeros(m), is_delta=np.zeros(m, dtype=bool),
                          valid=np.zeros(m, dtype=bool), light=np.full(m, -1),
                          prim=np.full(m, -1))
        if not self.strategies or m == 0:
            return out
        u_select = np.asarray(u_select, dtype=np.float64)
        if self._per_point:
            idx, prob, u_rem = select_rows(self.selection_pmf(p, hint), u_select)
        else:
            idx, prob, u_rem = select(self.pmf, self.cdf, u_select)
        u2 = np.asarray(u2, dtype=np.float64)
        for s, strat in enumerate(self.strategies):
            sel = idx == s
            if not sel.any():
                continue
            every = sel.all()
            ps = p if every else p[sel]
            ns = None if n is None else (n if every else n[sel])
            us = u2 if every else u2[sel]
            if s == self.emissive_index:
                wi, dist, rad, pdf, valid, prim = strat.sample(ps, ns, us, u_rem if every else u_rem[sel])
                out.prim[sel] = prim
            else:
                wi, dist, rad, pdf, valid = strat.sample(ps, ns, us)
            out.wi[sel], out.dist[sel], out.radiance[sel] = wi, dist, rad
            out.pdf[sel], out.valid[sel] = pdf, valid
            out.is_delta[sel] = strat.is_delta
            out.light[sel] = s
        out.pdf *= prob
        out.valid &= out.pdf > 0.0
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
        d = np.asarray(d, dtype=np.float64)
        origin = o if origin is None else np.asarray(origin, dtype=np.float64)
        m = len(o)
        tmax = np.broadcast_to(np.asarray(tmax, dtype=np.float64), (m,))
        best_t = np.array(tmax, dtype=np.float64, copy=True)
        best = np.full(m, -1)
        for i in self._shapes:
            t = self.lights[i].intersect(o, d)
            if exclude is not None:  # (m, n_lights) bool: lights this ray already passed
                t = np.where(exclude[:, i], np.inf, t)
            closer = t < best_t
            best_t = np.where(closer, t, best_t)
            best = np.where(closer, i, best)
        hit = best >= 0
        t_out = np.where(hit, best_t, np.inf)
        radiance = np.zeros((m, 3))
        pdf = np.zeros(m)
        open_sky = ~hit & np.isinf(tmax)
        for i in self._suns:
            sel = open_sky & (best < 0) & self.lights[i].in_cone(d)
            if sel.any():
                best[sel] = i
        found = np.flatnonzero(best >= 0)
        if len(found) == 0:
            return LightHit(hit=best >= 0, t=t_out, radiance=radiance, pdf=pdf, light=best)
        # selection probabilities of the lights found, all rows at once (one pmf evaluation)
        sel_prob = np.zeros(m)
        sel_prob[found] = self.selection_prob(origin[found], best[found], _rows(hint, found))
        for i in self._shapes:
            sel = best == i
            if sel.any():
                lt = self.lights[i]
                radiance[sel] = lt.hit_radiance(o[sel], d[sel], t_out[sel])
                # as seen from origin: the hit point o + t d lies at t + (o − origin)·d from it
                t_origin = t_out[sel] + np.einsum("ij,ij->i", o[sel] - origin[sel], d[sel])
                pdf[sel] = lt.pdf(origin[sel], d[sel], t_origin) * sel_prob[sel]
        for i in self._suns:
            sel = best == i
            if sel.any():
                radiance[sel] = self.lights[i].radiance
                pdf[sel] = self.lights[i].pdf_dir(d[sel]) * sel_prob[sel]
        return LightHit(hit=best >= 0, t=t_out, radiance=radiance, pdf=pdf, light=best)

    def world_radiance(self, d) -> np.ndarray:
        """(m, 3) world radiance arriving along −d (constant)."""
        color = self.world.radiance if self.world is not None else np.zeros(3)
        return np.broadcast_to(color, (len(d), 3)).copy()

    def world_pdf(self, p, n, d, hint: ShadingHint | None = None) -> np.ndarray:
        """(m,) solid-angle pdf × selection probability of the world producing direction d at p
        with normal n (None → uniform sphere), as `sample` would."""
        if self.world is None:
            return np.zeros(len(d))
        return (self.world.pdf(n, np.asarray(d, dtype=np.float64))
                * self.selection_prob(p, self.world_index, hint))

    def emissive_pdf(self, tri, o, p_hit, ng_hit, hint: ShadingHint | None = None) -> np.ndarray:
        """(m,) MIS pdf (solid angle × selection) of sampling p_hit on emissive triangle `tri`
        (global id) from o; 0 for non-emissive triangles."""
        if self.emissive is None:
            return np.zeros(len(o))
        pdf = self.emissive.pdf(tri, np.asarray(o, dtype=np.float64),
                                np.asarray(p_hit, dtype=np.float64),
                                np.asarray(ng_hit, dtype=np.float64))
        return pdf * self.selection_prob(o, self.emissive_index, hint)


def _rows(hint: ShadingHint | None, rows) -> ShadingHint | None:
    return None if hint is None else hint.subset(rows)
