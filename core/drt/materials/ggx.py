"""GGX microfacet reflection: Cycles's Glossy BSDF (distribution "GGX", single scattering).

    f(wo, wi) = color · D(h) · G2(wo, wi) / (4 |cos θo| |cos θi|),   h = normalize(wo + wi)

with the isotropic GGX (Trowbridge-Reitz) D, alpha = roughness² (Blender's mapping, done by the
material table), the height-correlated Smith G2 = 1 / (1 + Λ(wo) + Λ(wi)), and **no Fresnel**:
the colour multiplies directly, as in Cycles (``bsdf_microfacet_ggx_setup``, fresnel NONE).
Single-scatter GGX loses energy at high roughness; that is what Cycles's "GGX" does too
(its "Multiscatter GGX" is not modelled here).

Sampling uses the distribution of visible normals (Heitz 2018, "Sampling the GGX Distribution of
Visible Normals", JCGT 7(4)), so pdf(wi) = G1(wo) D(h) / (4 |cos θo|) and the sample weight of a
white lobe is G2 / G1(wo).

Frames: every direction is a unit vector in the local shading frame (z = shading normal on the
geometric front side); ``wo`` points toward where the path came from, ``wi`` toward the next
vertex. The lobe is two-sided: it reflects on whichever side ``wo`` is (everything is mirrored
through the tangent plane when ``wo.z < 0``); ``wi`` on the other side from ``wo`` gives 0.

Delta limit: when alpha² ≤ ``ALPHA_SQ_SINGULAR`` (2e-10, Cycles's ``BSDF_ROUGHNESS_SQ_THRESH``,
i.e. roughness ≤ 0.00376) the lobe is a perfect mirror: it cannot be evaluated, only sampled.

Scalar kernels (one sample, 3-tuples): ``ggx_ndf``, ``ggx_smith_lambda``, ``ggx_vndf_sample``,
``reflect_about``, ``microfacet_normal``, ``glossy_eval``, ``glossy_sample``. The array functions
(``ggx_d``, ``ggx_lambda``, ``sample_vndf``, ``reflect``, ``eval_glossy``, ``sample_glossy``, …)
apply them row by row.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import kernel
from ..kernels.vec3 import cross, dot, load, store
from ..sampling.warps import disk_concentric

#: alpha² at or below which a microfacet lobe is a delta (mirror / smooth dielectric). Cycles 5.0:
#: ``BSDF_ROUGHNESS_SQ_THRESH = 2e-10`` compared with alpha_x·alpha_y.
ALPHA_SQ_SINGULAR = 2e-10


# ---------------------------------------------------------------------------------------------
# scalar kernels
# ---------------------------------------------------------------------------------------------


@kernel
def is_singular_alpha(alpha):
    """True when a GGX lobe of this alpha is treated as a delta."""
    return alpha * alpha <= ALPHA_SQ_SINGULAR


@kernel
def ggx_ndf(cos_h, alpha):
    """Isotropic GGX normal distribution D(h), per unit solid angle of h, normalised so that
    ∫ D(h) cos θh dω_h = 1 over the upper hemisphere; cos_h: cosine of h with the normal
    (0 when h is below it)."""
    if not cos_h > 0.0:
        return 0.0
    a2 = alpha * alpha
    c2 = cos_h * cos_h
    d = (1.0 - c2) + a2 * c2
    return a2 / (math.pi * d * d)


@kernel
def ggx_smith_lambda(cos_v, alpha):
    """Smith Λ for GGX (Heitz 2014 eq. 72) of a direction with cosine cos_v to the normal (sign
    ignored: Λ depends on tan² θ only)."""
    # The floor keeps a direction in the tangent plane finite (Λ huge, G → 0) instead of inf/nan.
    c2 = max(cos_v * cos_v, 1e-300)
    tan2 = max(1.0 / c2 - 1.0, 0.0)
    return 0.5 * (math.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


@kernel
def ggx_vndf_sample(wo, alpha, u0, u1):
    """Heitz 2018 visible-normal sampling. wo: local unit 3-tuple with wo.z > 0 (the *upper*
    frame); (u0, u1) in [0, 1)². Returns a microfacet normal h, h.z ≥ 0, distributed with density
    D_wo(h) = G1(wo) max(0, wo·h) D(h) / wo.z."""
    vx = wo[0] * alpha
    vy = wo[1] * alpha
    vz = wo[2]
    vn = math.sqrt(vx * vx + vy * vy + vz * vz)
    v = (vx / vn, vy / vn, vz / vn)
    lensq = v[0] * v[0] + v[1] * v[1]
    if lensq > 1e-14:
        inv = 1.0 / math.sqrt(lensq)
        t1 = (-v[1] * inv, v[0] * inv, 0.0)
    else:  # wo along the normal: any tangent will do
        t1 = (1.0, 0.0, 0.0)
    t2 = cross(v, t1)
    d0, d1 = disk_concentric(u0, u1)
    s = 0.5 * (1.0 + v[2])
    p1 = d0
    p2 = (1.0 - s) * math.sqrt(max(0.0, 1.0 - p1 * p1)) + s * d1
    p3 = math.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    hx = alpha * (p1 * t1[0] + p2 * t2[0] + p3 * v[0])
    hy = alpha * (p1 * t1[1] + p2 * t2[1] + p3 * v[1])
    hz = max(p1 * t1[2] + p2 * t2[2] + p3 * v[2], 0.0)
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    return (hx / hn, hy / hn, hz / hn)


@kernel
def reflect_about(wo, h):
    """Mirror wo about the unit normal h: 2 (wo·h) h − wo."""
    k = 2.0 * dot(wo, h)
    return (k * h[0] - wo[0], k * h[1] - wo[1], k * h[2] - wo[2])


@kernel
def microfacet_normal(wo_u, alpha, u0, u1):
    """Microfacet normal for wo_u on the upper side: a visible-normal sample, or the macro normal
    z when alpha is singular (a perfect mirror / smooth interface)."""
    if is_singular_alpha(alpha):
        return (0.0, 0.0, 1.0)
    return ggx_vndf_sample(wo_u, alpha, u0, u1)


@kernel
def glossy_eval(wo, wi, alpha):
    """White GGX reflection lobe. wo, wi: local unit 3-tuples; alpha above the singular
    threshold. Returns (f·|cos θi|, pdf per unit solid angle of ``glossy_sample``)."""
    # Mirror both through the tangent plane when wo is below: the lobe is two-sided.
    sign = -1.0 if wo[2] < 0.0 else 1.0
    cos_o = wo[2] * sign
    cos_i = wi[2] * sign
    if not (cos_o > 0.0 and cos_i > 0.0):
        return 0.0, 0.0
    hx = wo[0] + wi[0]
    hy = wo[1] + wi[1]
    hz = cos_o + cos_i
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if not hn > 0.0:
        return 0.0, 0.0
    d = ggx_ndf(hz / hn, alpha)
    lam_o = ggx_smith_lambda(cos_o, alpha)
    lam_i = ggx_smith_lambda(cos_i, alpha)
    common = d / (4.0 * cos_o)
    return common / (1.0 + lam_o + lam_i), common / (1.0 + lam_o)


@kernel
def glossy_sample(wo, alpha, u0, u1):
    """wo: local unit 3-tuple (either side); (u0, u1) in [0, 1)². Returns wi on wo's side by
    visible-normal sampling, or the perfect mirror direction where alpha is singular. A sample
    may land on the other side of the surface (wi.z·wo.z ≤ 0): the caller discards it (its
    probability is exactly the mass the pdf misses)."""
    wo_u = (wo[0], wo[1], abs(wo[2]))
    wi = reflect_about(wo_u, microfacet_normal(wo_u, alpha, u0, u1))
    if wo[2] < 0.0:
        return (wi[0], wi[1], -wi[2])
    return wi


# ---------------------------------------------------------------------------------------------
# array wrappers: one row per sample. Inputs become contiguous writeable float64 so that a single
# compiled signature serves every call; the helpers are shared by the other lobe modules and the
# material table.
# ---------------------------------------------------------------------------------------------


def f64_array(a) -> np.ndarray:
    """a as a C-contiguous, writeable float64 array (numba compiles a separate variant for
    read-only arrays, e.g. broadcast views)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


def vec3_rows(a) -> np.ndarray:
    """(n, 3) C-contiguous float64 view or copy of a."""
    return f64_array(a).reshape(-1, 3)


def scalar_rows(a, n: int) -> np.ndarray:
    """(n,) C-contiguous float64 (a scalar or (n,) array broadcast to n rows)."""
    a = np.asarray(a, dtype=np.float64)
    return f64_array(a if a.shape == (n,) else np.broadcast_to(a, (n,)))


def elementwise(row_kernel, *arrays) -> np.ndarray:
    """Broadcast the arrays, run row_kernel(*flat_inputs, out) and return out in their shape."""
    arrays = [np.asarray(a, dtype=np.float64) for a in arrays]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    flat = [f64_array(a if a.shape == shape else np.broadcast_to(a, shape)).reshape(-1)
            for a in arrays]
    out = np.empty(flat[0].shape[0])
    row_kernel(*flat, out)
    return out.reshape(shape)


@kernel
def _is_singular_rows(alpha, out):
    for i in range(alpha.shape[0]):
        out[i] = is_singular_alpha(alpha[i])


@kernel
def _ggx_d_rows(cos_h, alpha, out):
    for i in range(cos_h.shape[0]):
        out[i] = ggx_ndf(cos_h[i], alpha[i])


@kernel
def _ggx_lambda_rows(cos_v, alpha, out):
    for i in range(cos_v.shape[0]):
        out[i] = ggx_smith_lambda(cos_v[i], alpha[i])


@kernel
def _sample_vndf_rows(wo, alpha, u2, h):
    for i in range(wo.shape[0]):
        store(h, i, ggx_vndf_sample(load(wo, i), alpha[i], u2[i, 0], u2[i, 1]))


@kernel
def _reflect_rows(wo, h, out):
    for i in range(wo.shape[0]):
        store(out, i, reflect_about(load(wo, i), load(h, i)))


@kernel
def _microfacet_normal_rows(wo_u, alpha, u2, h):
    for i in range(wo_u.shape[0]):
        store(h, i, microfacet_normal(load(wo_u, i), alpha[i], u2[i, 0], u2[i, 1]))


@kernel
def _eval_glossy_rows(wo, wi, alpha, value, pdf):
    for i in range(wo.shape[0]):
        v, p = glossy_eval(load(wo, i), load(wi, i), alpha[i])
        value[i] = v
        pdf[i] = p


@kernel
def _sample_glossy_rows(wo, alpha, u2, wi):
    for i in range(wo.shape[0]):
        store(wi, i, glossy_sample(load(wo, i), alpha[i], u2[i, 0], u2[i, 1]))


def is_singular(alpha: np.ndarray) -> np.ndarray:
    """alpha: array of GGX alphas; True where the lobe is treated as a delta."""
    b = f64_array(alpha)
    out = np.empty(b.size, dtype=np.bool_)
    _is_singular_rows(b.reshape(-1), out)
    return out.reshape(b.shape)


def ggx_d(cos_h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Isotropic GGX normal distribution D(h), per unit solid angle of h, normalised so that
    ∫ D(h) cos θh dω_h = 1 over the upper hemisphere. cos_h: (n,) cosine of h with the normal
    (h on the normal's side); alpha: (n,)."""
    return elementwise(_ggx_d_rows, cos_h, alpha)


def ggx_lambda(cos_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith Λ for GGX (Heitz 2014 eq. 72) of a direction with cosine cos_v to the normal (sign is
    ignored: Λ depends on tan² θ only). Returns (n,)."""
    return elementwise(_ggx_lambda_rows, cos_v, alpha)


def sample_vndf(wo: np.ndarray, alpha: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Heitz 2018 visible-normal sampling. wo: (n, 3) local with wo.z > 0 (the *upper* frame);
    alpha: (n,); u2: (n, 2) in [0, 1)². Returns microfacet normals h (n, 3), h.z ≥ 0, distributed
    with density D_wo(h) = G1(wo) max(0, wo·h) D(h) / wo.z."""
    wo = vec3_rows(wo)
    h = np.empty_like(wo)
    _sample_vndf_rows(wo, scalar_rows(alpha, wo.shape[0]),
                      f64_array(u2), h)
    return h


def reflect(wo: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Mirror wo (n, 3) about the unit normal h (n, 3): 2 (wo·h) h − wo."""
    wo = vec3_rows(wo)
    out = np.empty_like(wo)
    _reflect_rows(wo, vec3_rows(h), out)
    return out


def sample_microfacet_normal(wo_u: np.ndarray, alpha: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Microfacet normals h (n, 3) for wo_u on the upper side: visible-normal samples, or the
    macro normal z where alpha is singular (a perfect mirror / smooth interface)."""
    wo_u = vec3_rows(wo_u)
    h = np.empty_like(wo_u)
    _microfacet_normal_rows(wo_u, scalar_rows(alpha, wo_u.shape[0]),
                            f64_array(u2), h)
    return h


def eval_glossy(wo: np.ndarray, wi: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """White GGX reflection lobe. wo, wi: (n, 3) local; alpha: (n,) > singular threshold.
    Returns (f·|cos θi| (n,), pdf (n,) per unit solid angle of ``sample_glossy``)."""
    wo = vec3_rows(wo)
    n = wo.shape[0]
    value = np.empty(n)
    pdf = np.empty(n)
    _eval_glossy_rows(wo, vec3_rows(wi), scalar_rows(alpha, n), value, pdf)
    return value, pdf


def sample_glossy(wo: np.ndarray, alpha: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """wo: (n, 3) local (either side), alpha: (n,), u2: (n, 2). Returns wi (n, 3) on wo's side
    by visible-normal sampling, or the perfect mirror direction where alpha is singular. A sample
    may land on the other side of the surface (wi.z·wo.z ≤ 0): the caller discards it (its
    probability is exactly the mass the pdf misses)."""
    wo = vec3_rows(wo)
    wi = np.empty_like(wo)
    _sample_glossy_rows(wo, scalar_rows(alpha, wo.shape[0]),
                        f64_array(u2), wi)
    return wi
