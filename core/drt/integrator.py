"""The wavefront distribution ray tracer: every camera sample integrates, by Monte Carlo, over
pixel area (filter), lens area (depth of field), shutter time (motion blur), light area (soft
shadows: next-event estimation) and the BSDF (glossy, transmission, diffuse interreflection),
each from its own well-stratified sample dimension (Cook 1984; estimators from Veach 1997).

A batch of paths is a set of numpy arrays; each loop iteration is one bounce for all live paths
(Python overhead per batch, not per ray). Per bounce:

1. trace closest hits; add emission of what the rays hit (lights, emissive triangles, the world),
   MIS-weighted against the light sampling done at the previous vertex;
2. next-event estimation: sample a light, evaluate the BSDF, trace a shadow ray; weight by the
   power heuristic against BSDF sampling;
3. sample the BSDF to continue; count bounces the way Cycles does (a path exceeding a limit
   still collects emission at its next hit, then stops); Russian roulette after
   ``RR_START_BOUNCE`` bounces ("sample less with greater depth of recursion").

Sample dimensions (each a 2-D point from ``Sampler.sample_2d``):

| dim | use |
|---|---|
| 0 | pixel filter offset |
| 1 | lens position |
| 2 | (shutter time, unused) |
| 3 + 4b | (light selection, BSDF lobe selection) at bounce b |
| 4 + 4b | light sample position |
| 5 + 4b | BSDF direction |
| 6 + 4b | (Russian roulette, unused) |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import Camera
from .film import SampleBatch
from .geometry import SceneGeometry
from .lights import LightSet, ShadingHint
from .motion import invert_linear
from .materials import LOBE_DIFFUSE, LOBE_GLOSSY, LOBE_TRANSMISSION, MaterialTable
from .sampling.pixel_filter import PixelFilter
from .sampling.sequences import Sampler
from .sampling.warps import build_frame, square_to_cosine_hemisphere, square_to_uniform_hemisphere, to_local, to_world
from . import scene as scene_module
from .scene import RenderSettings
from .trace import Tracer, offset_origin
from .vecmath import row_norm

D_PIXEL, D_LENS, D_TIME, D_BOUNCE0, DIMS_PER_BOUNCE = 0, 1, 2, 3, 4
RR_START_BOUNCE = 3
SHADOW_EPSILON = 1e-4  # relative shortening of shadow rays so they stop before the light's surface
# largest radiance a sample may carry: its square (the variance pass) still fits float32
MAX_SAMPLE_RADIANCE = 1e18


def power_heuristic(pdf_a: np.ndarray, pdf_b: np.ndarray) -> np.ndarray:
    """Veach's power heuristic (β = 2) weight of strategy a; 0 where both pdfs are 0."""
    a2 = pdf_a * pdf_a
    denom = a2 + pdf_b * pdf_b
    return np.where(denom > 0, a2 / np.where(denom > 0, denom, 1.0), 0.0)


def balance_heuristic(pdf_a: np.ndarray, pdf_b: np.ndarray) -> np.ndarray:
    """Veach's balance heuristic weight of strategy a; 0 where both pdfs are 0."""
    denom = pdf_a + pdf_b
    return np.where(denom > 0, pdf_a / np.where(denom > 0, denom, 1.0), 0.0)


# How direct light is estimated at each path vertex (selectable for study; MIS_POWER is best):
# LIGHT: next-event estimation only; BSDF: only BSDF-sampled rays that hit emitters;
# MIS_*: both, combined by the balance or power heuristic.
DIRECT_STRATEGIES = scene_module.DIRECT_STRATEGIES
# How the path continues: by importance-sampling the BSDF (best), or cosine-weighted / uniform
# over the hemisphere on wo's side (materials with refraction always use their BSDF).
INDIRECT_STRATEGIES = scene_module.INDIRECT_STRATEGIES


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


@dataclass
class PathState:
    """Live paths of a batch (all arrays indexed alike). ``path`` maps to the batch slot."""

    path: np.ndarray
    o: np.ndarray
    d: np.ndarray
    tmax: np.ndarray
    tau: np.ndarray
    throughput: np.ndarray
    prev_pdf: np.ndarray  # solid-angle pdf of the BSDF sample that made this ray (for MIS)
    prev_delta: np.ndarray  # the ray came from the camera or a specular bounce: no MIS
    prev_p: np.ndarray
    prev_n: np.ndarray
    prev_wo: np.ndarray  # with prev_n and prev_mat: the light-selection hint of the last vertex
    prev_mat: np.ndarray
    bounce: np.ndarray
    diffuse: np.ndarray
    glossy: np.ndarray
    transmission: np.ndarray
    terminate_next: np.ndarray  # only collect emission at the next hit (a bounce limit is reached)

    def select(self, keep: np.ndarray) -> "PathState":
        """The paths where ``keep`` (n,) bool is True (self when all are)."""
        if keep.all():
            return self
        rows = np.flatnonzero(keep)  # one mask-to-index pass instead of one per field
        return PathState(**{k: v[rows] for k, v in self.__dict__.items()})


class Integrator:
    """Renders batches of camera samples. Thread-safe: holds only read-only scene data."""

    def __init__(
        self,
        settings: RenderSettings,
        geom: SceneGeometry,
        tracer: Tracer,
        materials: MaterialTable,
        lights: LightSet,
        camera: Camera,
        sampler: Sampler,
        pixel_filter: PixelFilter,
        direct: str = "MIS_POWER",
        indirect: str = "BSDF",
    ):
        if direct not in DIRECT_STRATEGIES:
            raise ValueError(f"unknown direct-light strategy {direct!r} (choose from {', '.join(DIRECT_STRATEGIES)})")
        if indirect not in INDIRECT_STRATEGIES:
            raise ValueError(f"unknown indirect strategy {indirect!r} (choose from {', '.join(INDIRECT_STRATEGIES)})")
        self.direct = direct
        self.indirect = indirect
        self.s = settings
        self.geom = geom
        self.tracer = tracer
        self.materials = materials
        self.lights = lights
        self.camera = camera
        self.sampler = sampler
        self.filter = pixel_filter
        self.motion = bool(geom.moving) or camera.motion is not None
        self.max_depth = settings.max_bounces + 1

    # ------------------------------------------------------------------ helpers
    def _shading_normal(self, prim, b1, b2, ng, linear) -> np.ndarray:
        g = self.geom
        ns = ng.copy()
        if g.normals is None:
            return ns
        smooth = g.has_normals[prim]
        if not np.any(smooth):
            return ns
        nc = g.normals[prim[smooth]].astype(np.float64)  # (m, 3, 3) per-corner
        w1, w2 = b1[smooth, None], b2[smooth, None]
        n = (1 - w1 - w2) * nc[:, 0] + w1 * nc[:, 1] + w2 * nc[:, 2]
        if linear is not None:
            inv_t = invert_linear(linear[smooth])
            n = np.einsum("nji,nj->ni", inv_t, n)
        length = row_norm(n)
        ok = length > 1e-12
        n[ok] /= length[ok, None]
        n[~ok] = ng[smooth][~ok]
        # shading normals live on the geometric front side (inverted normals are flipped back)
        flip = _dot(n, ng[smooth]) < 0
        n[flip] = -n[flip]
        ns[smooth] = n
        return ns

    def _hint(self, mat, n_wo, wo, rows=None) -> ShadingHint | None:
        """The light-selection hint of shading points (None when selection ignores it)."""
        if not self.lights.uses_hint:
            return None
        if rows is not None:
            mat, n_wo, wo = mat[rows], n_wo[rows], wo[rows]
        return ShadingHint.from_materials(self.materials, mat, n_wo, wo)

    def _hit_weight(self, prev_delta, bsdf_pdf, light_pdf):
        """MIS weight of an emitter found by a BSDF-sampled ray (1 after camera/specular rays)."""
        if self.direct == "BSDF":
            w = np.ones(len(bsdf_pdf))
        elif self.direct == "LIGHT":
            # next-event estimation already counted it, unless NEE could not have sampled it
            w = np.where(light_pdf > 0, 0.0, 1.0)
        elif self.direct == "MIS_BALANCE":
            w = balance_heuristic(bsdf_pdf, light_pdf)
        else:
            w = power_heuristic(bsdf_pdf, light_pdf)
        return np.where(prev_delta, 1.0, w)

    def _nee_weight(self, is_delta, light_pdf, bsdf_pdf):
        if self.direct == "LIGHT":
            w = np.ones(len(light_pdf))
        elif self.direct == "MIS_BALANCE":
            w = balance_heuristic(light_pdf, bsdf_pdf)
        else:
            w = power_heuristic(light_pdf, bsdf_pdf)
        return np.where(is_delta, 1.0, w)

    # Clamping follows Cycles: light found at the first vertex (by next-event estimation there,
    # or by the BSDF ray leaving it, whose path has bounce 1) is "direct"; deeper is "indirect".
    def _clamp(self, contrib: np.ndarray, indirect: np.ndarray) -> np.ndarray:
        limits = np.where(indirect, self.s.clamp_indirect, self.s.clamp_direct)
        if not np.any(limits > 0):
            return contrib
        peak = contrib.max(axis=1)
        scale = np.where((limits > 0) & (peak > limits), limits / np.where(peak > 0, peak, 1.0), 1.0)
        return contrib * scale[:, None]

    def _hemisphere_continuation(self, bs, mat, wo_l, u):
        """Replace the BSDF sample by a cosine-weighted or uniform direction on wo's side of the
        surface (the lecture's estimators), for materials without refraction or mirrors."""
        k = np.nonzero(~self.materials.has_transmission_or_delta(mat))[0]
        if not len(k):
            return
        if self.indirect == "COSINE":
            wi = square_to_cosine_hemisphere(u[k])
            pdf = wi[:, 2] / np.pi
        else:
            wi = square_to_uniform_hemisphere(u[k])
            pdf = np.full(len(k), 1.0 / (2.0 * np.pi))
        side = np.where(wo_l[k, 2] >= 0, 1.0, -1.0)
        wi[:, 2] *= side
        f, _ = self.materials.eval(mat[k], wo_l[k], wi)
        ok = pdf > 0
        bs.wi[k] = wi
        bs.pdf[k] = pdf
        bs.weight[k] = np.where(ok[:, None], f / np.where(ok, pdf, 1.0)[:, None], 0.0)
        bs.is_delta[k] = False
        bs.valid[k] = ok
        bs.lobe_kind[k] = np.where(self.materials.has_diffuse(mat[k]), LOBE_DIFFUSE, LOBE_GLOSSY)

    # ------------------------------------------------------------------ main entry
    def render_batch(self, x: np.ndarray, row: np.ndarray, index: np.ndarray) -> SampleBatch:
        """Trace one camera path per entry. x: (n,) pixel column from the left; row: (n,) pixel
        row from the TOP; index: (n,) sample number within the pixel. Returns per-path results."""
        s, W, H = self.s, self.s.width, self.s.height
        n = len(x)
        pixel = (row.astype(np.int64) * W + x).astype(np.int64)
        pid = pixel.astype(np.uint32)
        idx = index.astype(np.uint32)
        off = self.filter.sample(self.sampler.sample_2d(pid, idx, D_PIXEL))
        px = x + 0.5 + off[:, 0]
        py = (H - 1 - row) + 0.5 + off[:, 1]  # camera wants v from the bottom
        u_lens = self.sampler.sample_2d(pid, idx, D_LENS)
        tau = self.sampler.sample_2d(pid, idx, D_TIME)[:, 0] if self.motion else np.zeros(n)
        rays = self.camera.generate(px, py, u_lens, tau)

        radiance = np.zeros((n, 3))
        alpha = np.ones(n)
        depth = np.full(n, np.inf)
        normal = np.zeros((n, 3))
        albedo = np.zeros((n, 3))

        st = PathState(
            path=np.arange(n),
            o=rays.o,
            d=rays.d,
            tmax=rays.tmax,
            tau=tau,
            throughput=np.ones((n, 3)),
            prev_pdf=np.zeros(n),
            prev_delta=np.ones(n, dtype=bool),
            prev_p=rays.o.copy(),
            prev_n=np.zeros((n, 3)),
            prev_wo=np.zeros((n, 3)),
            prev_mat=np.full(n, -1, dtype=np.intp),
            bounce=np.zeros(n, dtype=np.int32),
            diffuse=np.zeros(n, dtype=np.int32),
            glossy=np.zeros(n, dtype=np.int32),
            transmission=np.zeros(n, dtype=np.int32),
            terminate_next=np.zeros(n, dtype=bool),
        )

        for depth_i in range(self.max_depth + 1):
            if len(st.path) == 0:
                break
            camera_ray = depth_i == 0
            hits = self.tracer.intersect(st.o, st.d, st.tau, st.tmax)
            t_geom = hits.t

            # --- emitters hit by this ray: light shapes, emissive triangles, the world
            # MIS pdfs of emitters this ray finds: light sampling's at the vertex it left
            prev_hint = self._hint(st.prev_mat, st.prev_n, st.prev_wo)
            # Lights are transparent emitters (as in Cycles): the ray collects each light it
            # passes and goes on to the surface behind, or the world.
            for rows, lh in self.lights.hits_along(st.o, st.d, t_geom, origin=st.prev_p, hint=prev_hint):
                light_hit = lh.hit
                if camera_ray and np.any(light_hit):
                    light_hit = light_hit & self.lights.visible_to_camera[np.maximum(lh.light, 0)]
                if np.any(light_hit):
                    r = rows[light_hit]
                    w = self._hit_weight(st.prev_delta[r], st.prev_pdf[r], lh.pdf[light_hit])
                    c = st.throughput[r] * lh.radiance[light_hit] * w[:, None]
                    np.add.at(radiance, st.path[r], self._clamp(c, st.bounce[r] > 1))
            miss = ~hits.hit
            if np.any(miss):
                paths = st.path[miss]
                if camera_ray and s.film_transparent:
                    alpha[paths] = 0.0
                else:
                    le = self.lights.world_radiance(st.d[miss])
                    wpdf = self.lights.world_pdf(st.prev_p[miss], st.prev_n[miss], st.d[miss],
                                                 None if prev_hint is None else prev_hint.subset(miss))
                    w = self._hit_weight(st.prev_delta[miss], st.prev_pdf[miss], wpdf)
                    c = st.throughput[miss] * le * w[:, None]
                    radiance[paths] += self._clamp(c, st.bounce[miss] > 1)

            surf = hits.hit
            # emission of hit surfaces (also for paths that stop here at a bounce limit)
            si = np.nonzero(surf)[0]
            mat_all = self.geom.material[hits.prim[si]]
            em = self.materials.has_emission[mat_all]
            if np.any(em):
                e = si[em]
                le = self.materials.emission[mat_all[em]]
                lpdf = self.lights.emissive_pdf(hits.prim[e], st.prev_p[e], hits.p[e], hits.ng[e],
                                                None if prev_hint is None else prev_hint.subset(e))
                w = self._hit_weight(st.prev_delta[e], st.prev_pdf[e], lpdf)
                c = st.throughput[e] * le * w[:, None]
                radiance[st.path[e]] += self._clamp(c, st.bounce[e] > 1)

            # --- paths that reached a bounce limit stop here (after collecting emission)
            go = surf & ~st.terminate_next
            st = st.select(go)
            if len(st.path) == 0:
                break
            prim = hits.prim[go]
            p = hits.p[go]
            ng = hits.ng[go]
            linear = hits.moving_linear[go] if hits.moving_linear is not None else None
            ns = self._shading_normal(prim, hits.b1[go], hits.b2[go], ng, linear)
            mat = self.geom.material[prim]
            wo = -st.d

            if camera_ray:  # nothing terminates before the first hit: go == surf here
                paths = st.path
                depth[paths] = np.maximum(_dot(p - rays.eye[paths], rays.forward[paths]), 0.0)
                normal[paths] = ns
                albedo[paths] = self.materials.albedo(mat)

            base = D_BOUNCE0 + DIMS_PER_BOUNCE * int(depth_i)
            pid_b = pixel[st.path].astype(np.uint32)
            idx_b = idx[st.path]
            u_sel = self.sampler.sample_2d(pid_b, idx_b, base)

            # local frame: z = shading normal on the front side
            t_ax, b_ax = build_frame(ns)
            wo_l = to_local(wo, t_ax, b_ax, ns)
            # lights are sampled over the hemisphere wo is in (cosine-weighted world sampling
            # there); transmitted light stays reachable by BSDF sampling, whose MIS weight is 1
            n_wo = ns * np.where(wo_l[:, 2] >= 0, 1.0, -1.0)[:, None]

            # --- next-event estimation with MIS
            can_nee = ~self.materials.is_delta_only(mat)
            if self.direct != "BSDF" and np.any(can_nee) and self.lights.strategies:
                k = np.nonzero(can_nee)[0]
                u_l = self.sampler.sample_2d(pid_b[k], idx_b[k], base + 1)
                ls = self.lights.sample(p[k], n_wo[k], u_sel[k, 0], u_l, self._hint(mat, n_wo, wo, k))
                wi = ls.wi
                wi_l = to_local(wi, t_ax[k], b_ax[k], ns[k])
                f, pdf_b = self.materials.eval(mat[k], wo_l[k], wi_l)
                # the geometric and shading normals must agree on reflection vs transmission
                same_geo = _dot(wi, ng[k]) * _dot(wo[k], ng[k]) > 0
                same_sh = wi_l[:, 2] * wo_l[k, 2] > 0
                ok = ls.valid & (ls.pdf > 0) & (same_geo == same_sh) & np.any(f > 0, axis=1)
                if np.any(ok):
                    k2 = k[ok]
                    w = self._nee_weight(ls.is_delta[ok], ls.pdf[ok], pdf_b[ok])
                    contrib = st.throughput[k2] * f[ok] * ls.radiance[ok] * (w / ls.pdf[ok])[:, None]
                    o_sh = offset_origin(p[k2], ng[k2], wi[ok])
                    dist = ls.dist[ok]
                    tmax = np.where(np.isfinite(dist), dist * (1 - SHADOW_EPSILON), np.inf)
                    blocked = self.tracer.occluded(o_sh, wi[ok], tmax, st.tau[k2])
                    vis = ~blocked
                    c = self._clamp(contrib[vis], st.bounce[k2][vis] > 0)
                    np.add.at(radiance, st.path[k2][vis], c)

            # --- continue the path by sampling the BSDF
            u_b = self.sampler.sample_2d(pid_b, idx_b, base + 2)
            bs = self.materials.sample(mat, wo_l, u_sel[:, 1], u_b)
            if self.indirect != "BSDF":
                self._hemisphere_continuation(bs, mat, wo_l, u_b)
            wi = to_world(bs.wi, t_ax, b_ax, ns)
            refl_geo = _dot(wi, ng) * _dot(wo, ng) > 0
            refl_sh = bs.wi[:, 2] * wo_l[:, 2] > 0
            alive = bs.valid & (refl_geo == refl_sh) & np.any(bs.weight > 0, axis=1)
            throughput = st.throughput * bs.weight

            bounce = st.bounce + 1
            diffuse = st.diffuse + (bs.lobe_kind == LOBE_DIFFUSE)
            glossy = st.glossy + (bs.lobe_kind == LOBE_GLOSSY)
            transmission = st.transmission + (bs.lobe_kind == LOBE_TRANSMISSION)
            limit = (
                (bounce > s.max_bounces)
                | (diffuse > s.diffuse_bounces)
                | (glossy > s.glossy_bounces)
                | (transmission > s.transmission_bounces)
            )

            if depth_i + 1 >= RR_START_BOUNCE:
                u_rr = self.sampler.sample_2d(pid_b, idx_b, base + 3)[:, 0]
                q = np.clip(throughput.max(axis=1), 0.0, 1.0)
                survive = u_rr < q
                throughput = throughput / np.where(q > 0, q, 1.0)[:, None]
                alive &= survive

            st = PathState(
                path=st.path,
                o=offset_origin(p, ng, wi),
                d=wi,
                tmax=np.full(len(st.path), np.inf),
                tau=st.tau,
                throughput=throughput,
                prev_pdf=bs.pdf,
                prev_delta=bs.is_delta,
                prev_p=p,
                prev_n=n_wo,
                prev_wo=wo,
                prev_mat=mat,
                bounce=bounce,
                diffuse=diffuse.astype(np.int32),
                glossy=glossy.astype(np.int32),
                transmission=transmission.astype(np.int32),
                terminate_next=limit,
            ).select(alive)

        # a NaN/Inf sample is counted, dropped (it does not enter its pixel's mean) and reported;
        # so is one beyond MAX_SAMPLE_RADIANCE, which would overflow the float32 passes
        good = np.all(np.isfinite(radiance) & (np.abs(radiance) <= MAX_SAMPLE_RADIANCE), axis=1)
        nan_count = int(n - good.sum())
        if nan_count:
            pixel, radiance, alpha, depth = pixel[good], radiance[good], alpha[good], depth[good]
            normal, albedo = normal[good], albedo[good]
        return SampleBatch(pixel, radiance, alpha, depth, normal, albedo, nan_count)
