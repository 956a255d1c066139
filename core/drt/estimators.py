"""The lecture's estimators of direct light at a shading point, written plainly.

Reflected radiance from direct light at a point p seen from direction wo (architecture.md:
``wo`` points away from the surface, toward the viewer):

    L(p, wo) = ∫_Ω f(wo, wi) L_e(p, −wi) |cos θi| dωi
             = ∫_0^{2π} ∫_0^{π/2} f L_e cos θ sin θ dθ dφ     (the lecture's (θ, φ) form)

Each function below estimates this integral at a batch of n shading points, with the lights of a
`LightSet` (area lights, sphere/disk point lights, suns, the world; emissive *triangles* are
only reachable through the integrator, which traces the scene) and the BSDFs of a
`MaterialTable`. An optional ``occluded(o, d, tmax) -> (m,) bool`` callback (e.g. a
`drt.trace.Tracer`'s) adds shadows; without it nothing blocks the light.

Methods (``METHODS``):

=============  =======================================================================
MIDPOINT       the lecture's uniform midpoint rule over (θ, φ): M×N cells, one direction at
               each cell centre, weight sin θ Δθ Δφ. Deterministic (biased for finite M, N).
UNIFORM        uniform random directions over the hemisphere on wo's side, pdf 1/(2π).
STRATIFIED     the lecture's stratified sampling: one jittered point in each (θ, φ) cell,
               weight sin θ Δθ Δφ (unbiased).
COSINE         cosine-weighted hemisphere directions, pdf cos θ/π.
BSDF           the material's importance sampling (``MaterialTable.sample``).
LIGHT          light sampling (``LightSet.sample``: power/distance selection, then solid
               angle for spheres and rectangles, area for disks and ellipses).
MIS_BALANCE    one light sample + one BSDF sample, balance heuristic (Veach 1997).
MIS_POWER      the same with the power heuristic (β = 2): the integrator's default.
=============  =======================================================================

The hemisphere methods (MIDPOINT .. COSINE) integrate only the hemisphere on wo's side (no
transmission) and do not see delta lights (zero-radius points, zero-angle suns): they have no
solid angle. ``direct_samples`` returns every sample's contribution, so tests and the bench can
measure variance; ``estimate_direct`` averages them. One MIS "sample" costs two rays (one light,
one BSDF), the others one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .lights.selection import ShadingHint
from .sampling.sequences import Sampler
from .sampling.warps import (
    build_frame,
    square_to_cosine_hemisphere,
    square_to_uniform_hemisphere,
    to_local,
    to_world,
)

METHODS = ("MIDPOINT", "UNIFORM", "STRATIFIED", "COSINE", "BSDF", "LIGHT", "MIS_BALANCE", "MIS_POWER")
#: rays traced per sample by each method (MIS traces a light and a BSDF ray)
RAYS_PER_SAMPLE = {m: (2 if m.startswith("MIS") else 1) for m in METHODS}

# sample dimensions used by the random methods (2-D each, as in the integrator)
D_SELECT, D_LIGHT, D_DIRECTION = 0, 1, 2


@dataclass
class ShadingPoints:
    """n shading points, world space: ``p`` (n, 3) positions, ``n`` (n, 3) unit shading normals
    (front side), ``wo`` (n, 3) unit directions toward the viewer, ``mat`` (n,) material ids."""

    p: np.ndarray
    n: np.ndarray
    wo: np.ndarray
    mat: np.ndarray

    def __post_init__(self):
        self.p = np.atleast_2d(np.asarray(self.p, dtype=np.float64))
        k = len(self.p)
        self.n = np.broadcast_to(np.asarray(self.n, dtype=np.float64), (k, 3)).copy()
        self.wo = np.broadcast_to(np.asarray(self.wo, dtype=np.float64), (k, 3)).copy()
        self.mat = np.broadcast_to(np.asarray(self.mat, dtype=np.intp), (k,)).copy()

    def __len__(self) -> int:
        return len(self.p)


def midpoint_grid_shape(count: int) -> tuple[int, int]:
    """(M, N) θ × φ cells with M·N ≤ count and cells close to square in solid angle near the
    horizon (Δφ ≈ Δθ, i.e. N ≈ 4M)."""
    m = max(1, int(round(np.sqrt(count / 4.0))))
    return m, max(1, count // m)


def theta_phi_cells(M: int, N: int, jitter: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Local directions (K, 3) (K = M·N, θ-major) and weights sin θ Δθ Δφ (K,) of the lecture's
    (θ, φ) grid over the upper hemisphere. jitter: None for the cell midpoints, else (..., K, 2)
    in [0, 1)² positions inside each cell (stratified sampling; directions broadcast)."""
    d_theta, d_phi = 0.5 * np.pi / M, 2.0 * np.pi / N
    i, j = np.meshgrid(np.arange(M), np.arange(N), indexing="ij")
    i, j = i.reshape(-1).astype(np.float64), j.reshape(-1).astype(np.float64)
    if jitter is None:
        jt, jp = 0.5, 0.5
    else:
        jt, jp = jitter[..., 0], jitter[..., 1]
    theta = (i + jt) * d_theta
    phi = (j + jp) * d_phi
    st = np.sin(theta)
    dirs = np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)
    return dirs, st * d_theta * d_phi


class DirectLight:
    """Direct-light estimators at shading points for one scene's lights and materials.

    lights: `drt.lights.LightSet`; materials: `drt.materials.MaterialTable`; occluded: optional
    ``(o (m,3), d (m,3), tmax (m,)) -> (m,) bool`` visibility test (o is offset by ``epsilon``
    along the normal before the call).
    """

    def __init__(self, lights, materials, occluded: Callable | None = None, epsilon: float = 1e-5):
        self.lights = lights
        self.materials = materials
        self.occluded = occluded
        self.epsilon = epsilon

    # ------------------------------------------------------------------ radiance along rays
    def incident(self, p, n, wi, hint=None, mis=None) -> tuple[np.ndarray, np.ndarray]:
        """Radiance arriving at p (m, 3) along −wi (m, 3): (from the lights (m, 3), from the
        world (m, 3)), no surfaces but the optional occluder. Lights are transparent emitters,
        as in the integrator: a ray sums every light it passes, and the world behind them.

        mis: None (plain sums) or (bsdf_pdf (m,), no_mis (m,) bool, heuristic): each light's and
        the world's radiance is weighted against light sampling's pdf with the points'
        `ShadingHint` ``hint`` (weight 1 where no_mis)."""
        m = len(p)
        light = np.zeros((m, 3))
        o = p + n * self.epsilon * np.sign(np.einsum("ij,ij->i", n, wi))[:, None]

        def weight(rows, lpdf):
            if mis is None:
                return np.ones(len(rows))
            bsdf_pdf, no_mis, heuristic = mis
            return np.where(no_mis[rows], 1.0, _mis(bsdf_pdf[rows], lpdf, heuristic))

        for rows, lh in self.lights.hits_along(p, wi, np.full(m, np.inf), hint=hint):
            r = rows[lh.hit]
            if not len(r):
                continue
            val = lh.radiance[lh.hit] * weight(r, lh.pdf[lh.hit])[:, None]
            if self.occluded is not None:
                t = lh.t[lh.hit]
                val[self.occluded(o[r], wi[r], np.where(np.isfinite(t), t * (1 - 1e-4), np.inf))] = 0.0
            light[r] += val
        world = self.lights.world_radiance(wi)
        if self.lights.world is not None:
            world *= weight(np.arange(m), self.lights.world_pdf(p, n, wi, hint))[:, None]
            if self.occluded is not None:
                world[self.occluded(o, wi, np.full(m, np.inf))] = 0.0
        return light, world

    def _frames(self, pts: ShadingPoints):
        t, b = build_frame(pts.n)
        wo_l = to_local(pts.wo, t, b, pts.n)
        side = np.where(wo_l[:, 2] >= 0, 1.0, -1.0)
        return t, b, wo_l, side

    def _visible(self, p, n_wo, wi, dist):
        if self.occluded is None:
            return np.ones(len(p), dtype=bool)
        o = p + n_wo * self.epsilon
        tmax = np.where(np.isfinite(dist), dist * (1 - 1e-4), np.inf)
        return ~self.occluded(o, wi, tmax)

    # ------------------------------------------------------------------ per-sample values
    def _hemisphere_values(self, pts, wi_l, weight):
        """f·L_e·weight for local hemisphere directions wi_l (n, K, 3) (upper, flipped to wo's
        side here) with per-direction weights (n, K) or (K,). Returns (n, K, 3)."""
        n, K = wi_l.shape[0], wi_l.shape[1]
        t, b, wo_l, side = self._frames(pts)
        wi_l = wi_l * np.stack([np.ones_like(side), np.ones_like(side), side], axis=-1)[:, None, :]
        rep = lambda a: np.repeat(a, K, axis=0)  # noqa: E731
        wi_flat = wi_l.reshape(-1, 3)
        f, _ = self.materials.eval(rep(pts.mat), rep(wo_l), wi_flat)
        wi_w = to_world(wi_flat, rep(t), rep(b), rep(pts.n))
        n_wo = rep(pts.n * side[:, None])
        rad, world = self.incident(rep(pts.p), n_wo, wi_w)
        w = np.broadcast_to(weight, (n, K)).reshape(-1)
        return (f * (rad + world) * w[:, None]).reshape(n, K, 3)

    def _light_values(self, pts, u_sel, u_l, heuristic):
        """One light sample per entry. u_sel (m,), u_l (m, 2) for the m = n·K rows of
        ``pts`` repeated K times. heuristic: None (pure light sampling), 'balance' or 'power'."""
        t, b, wo_l, side = self._frames(pts)
        n_wo = pts.n * side[:, None]
        ls = self.lights.sample(pts.p, n_wo, u_sel, u_l, ShadingHint.from_materials(self.materials, pts.mat, n_wo, pts.wo))
        wi_l = to_local(ls.wi, t, b, pts.n)
        f, pdf_b = self.materials.eval(pts.mat, wo_l, wi_l)
        ok = ls.valid & (ls.pdf > 0) & (wi_l[:, 2] * wo_l[:, 2] > 0)
        ok &= self._visible(pts.p, n_wo, ls.wi, ls.dist)
        w = np.ones(len(ok)) if heuristic is None else _mis(ls.pdf, pdf_b, heuristic)
        w = np.where(ls.is_delta, 1.0, w)
        val = f * ls.radiance * (w / np.where(ok, ls.pdf, 1.0))[:, None]
        return np.where(ok[:, None], val, 0.0)

    def _bsdf_values(self, pts, u_lobe, u_dir, heuristic):
        """One BSDF sample per row; emitters it reaches, MIS-weighted against light sampling."""
        t, b, wo_l, side = self._frames(pts)
        n_wo = pts.n * side[:, None]
        bs = self.materials.sample(pts.mat, wo_l, u_lobe, u_dir)
        wi = to_world(bs.wi, t, b, pts.n)
        hint = ShadingHint.from_materials(self.materials, pts.mat, n_wo, pts.wo)
        rad, world = self.incident(pts.p, n_wo, wi, hint,
                                   None if heuristic is None else (bs.pdf, bs.is_delta, heuristic))
        val = bs.weight * (rad + world)
        return np.where(bs.valid[:, None], val, 0.0)

    def direct_samples(self, method: str, pts: ShadingPoints, count: int, *, sampler: str = "RANDOM",
                       seed: int = 0, grid: tuple[int, int] | None = None, first_pixel: int = 0) -> np.ndarray:
        """Per-sample estimates (n, K, 3) of the reflected direct radiance at each point: their
        mean over K is the estimate. K = count, except for MIDPOINT and STRATIFIED, which use
        M·N cells (``grid``, default `midpoint_grid_shape(count)`). Random numbers come from
        ``Sampler(sampler, seed)`` with pixel id ``first_pixel + point index``, so points are
        decorrelated and everything is deterministic per seed."""
        method = method.upper()
        if method not in METHODS:
            raise ValueError(f"unknown estimator {method!r} (choose from {', '.join(METHODS)})")
        n = len(pts)
        if method in ("MIDPOINT", "STRATIFIED"):
            M, N = grid or midpoint_grid_shape(count)
            K = M * N
        else:
            K = int(count)
        gen = Sampler(sampler, seed, K)
        pix = np.repeat(np.arange(first_pixel, first_pixel + n, dtype=np.int64), K)
        idx = np.tile(np.arange(K, dtype=np.int64), n)
        u = lambda dim: gen.sample_2d(pix, idx, dim)  # noqa: E731

        if method == "MIDPOINT":
            dirs, w = theta_phi_cells(M, N)  # the rule sums over cells: K × weight per sample
            return self._hemisphere_values(pts, np.broadcast_to(dirs, (n, K, 3)), K * w)
        if method == "STRATIFIED":
            dirs, w = theta_phi_cells(M, N, u(D_DIRECTION).reshape(n, K, 2))
            return self._hemisphere_values(pts, dirs, K * w)
        if method == "UNIFORM":
            dirs = square_to_uniform_hemisphere(u(D_DIRECTION)).reshape(n, K, 3)
            return self._hemisphere_values(pts, dirs, 2.0 * np.pi)
        if method == "COSINE":
            dirs = square_to_cosine_hemisphere(u(D_DIRECTION)).reshape(n, K, 3)
            pdf = dirs[..., 2] / np.pi
            return self._hemisphere_values(pts, dirs, np.where(pdf > 0, 1.0 / np.where(pdf > 0, pdf, 1.0), 0.0))

        rep = ShadingPoints(np.repeat(pts.p, K, 0), np.repeat(pts.n, K, 0), np.repeat(pts.wo, K, 0),
                            np.repeat(pts.mat, K))
        u_sel = u(D_SELECT)
        heuristic = {"MIS_BALANCE": "balance", "MIS_POWER": "power"}.get(method)
        total = np.zeros((n * K, 3))
        if method != "BSDF":
            total += self._light_values(rep, u_sel[:, 0], u(D_LIGHT), heuristic)
        if method != "LIGHT":
            total += self._bsdf_values(rep, u_sel[:, 1], u(D_DIRECTION), heuristic)
        return total.reshape(n, K, 3)

    def estimate_direct(self, method: str, pts: ShadingPoints, count: int, **kw) -> np.ndarray:
        """(n, 3) estimate of the reflected direct radiance at each point (see direct_samples)."""
        return self.direct_samples(method, pts, count, **kw).mean(axis=1)


def _mis(pdf_a, pdf_b, heuristic: str) -> np.ndarray:
    """MIS weight of strategy a against b (0 where both pdfs are 0)."""
    if heuristic == "power":
        a, b = pdf_a * pdf_a, pdf_b * pdf_b
    else:
        a, b = pdf_a, pdf_b
    s = a + b
    return np.where(s > 0, a / np.where(s > 0, s, 1.0), 0.0)


# ---------------------------------------------------------------------------------- closed forms


def polygon_irradiance(radiance: float, corners, p=(0.0, 0.0, 0.0), n=(0.0, 0.0, 1.0)) -> float:
    """Irradiance at p (normal n) from a Lambertian polygon of constant radiance whose corners
    (k, 3) lie entirely above p's tangent plane (Lambert's formula): E = L/2 Σ Θ_i n·γ̂_i."""
    p, n = np.asarray(p, float), np.asarray(n, float)
    r = [np.asarray(c, float) - p for c in corners]
    r = [v / np.linalg.norm(v) for v in r]
    e = 0.0
    for i in range(len(r)):
        a, b = r[i], r[(i + 1) % len(r)]
        g = np.cross(a, b)
        e += np.arccos(np.clip(np.dot(a, b), -1, 1)) * np.dot(n, g / np.linalg.norm(g))
    return abs(radiance * e / 2.0)
