"""Lambertian (Cycles's Diffuse BSDF at roughness 0): f = color / π; and its transmitting twin,
Cycles's Translucent BSDF: f = color / π for wi on the *other* side of the surface from wo.

Frame-free: every direction is a unit vector in the *local shading frame* (z = shading normal on
the geometric front side, see docs/architecture.md). ``wo`` points away from the surface toward
where the path came from, ``wi`` away from the surface toward the next vertex.

The lobe is two-sided: it reflects on whichever side ``wo`` is (the computation is mirrored when
``wo.z < 0``); a ``wi`` on the other side from ``wo`` gets 0. The functions here are colourless
(the colour multiplies outside, in the material table).

The translucent lobe (``translucent_eval`` / ``translucent_sample``) is the same cosine lobe
mirrored through the surface (Cycles's ``bsdf_translucent``: a cosine hemisphere about −N, N on
wo's side); it is a diffuse *transmission* (Cycles's label TRANSMIT | DIFFUSE).

``diffuse_eval`` / ``diffuse_sample`` are the scalar kernels (3-tuples, one sample);
``eval_diffuse`` / ``sample_diffuse`` apply them to (n, 3) arrays.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import kernel
from ..kernels.vec3 import load, store
from ..sampling.warps import cosine_hemisphere
from .ggx import f64_array, vec3_rows

INV_PI = 1.0 / math.pi


@kernel
def diffuse_eval(wo, wi):
    """wo, wi: local unit 3-tuples. Returns (f·|cos θi| for a white lobe, pdf per unit solid
    angle of ``diffuse_sample``); both 0 when wi is not on wo's side of the surface."""
    if wo[2] * wi[2] > 0.0:
        value = abs(wi[2]) * INV_PI
        return value, value
    return 0.0, 0.0


@kernel
def diffuse_sample(wo, u0, u1):
    """wo: local unit 3-tuple; (u0, u1) in [0, 1)². Returns wi cosine-distributed on wo's side
    (pdf |cos θi| / π, weight f·|cos θi| / pdf = 1 for a white lobe)."""
    wi = cosine_hemisphere(u0, u1)
    if wo[2] < 0.0:
        return (wi[0], wi[1], -wi[2])
    return wi


@kernel
def translucent_eval(wo, wi):
    """wo, wi: local unit 3-tuples. Returns (f·|cos θi| for a white lobe, pdf per unit solid
    angle of ``translucent_sample``); both 0 unless wi is on the other side from wo."""
    if wo[2] * wi[2] < 0.0:
        value = abs(wi[2]) * INV_PI
        return value, value
    return 0.0, 0.0


@kernel
def translucent_sample(wo, u0, u1):
    """wo: local unit 3-tuple; (u0, u1) in [0, 1)². Returns wi cosine-distributed on the side
    opposite wo (pdf |cos θi| / π, weight 1 for a white lobe)."""
    wi = cosine_hemisphere(u0, u1)
    if wo[2] > 0.0:
        return (wi[0], wi[1], -wi[2])
    return wi


@kernel
def _eval_diffuse_rows(wo, wi, value, pdf):
    for i in range(wo.shape[0]):
        v, p = diffuse_eval(load(wo, i), load(wi, i))
        value[i] = v
        pdf[i] = p


@kernel
def _sample_diffuse_rows(wo, u2, wi):
    for i in range(wo.shape[0]):
        store(wi, i, diffuse_sample(load(wo, i), u2[i, 0], u2[i, 1]))


def eval_diffuse(wo: np.ndarray, wi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """wo, wi: (n, 3) local. Returns (f·|cos θi| (n,) for a white lobe, pdf (n,) per unit solid
    angle of ``sample_diffuse``). Both are 0 when wi is not on wo's side of the surface."""
    wo = vec3_rows(wo)
    wi = vec3_rows(wi)
    value = np.empty(wo.shape[0])
    pdf = np.empty(wo.shape[0])
    _eval_diffuse_rows(wo, wi, value, pdf)
    return value, pdf


def sample_diffuse(wo: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """wo: (n, 3) local, u2: (n, 2) in [0, 1)². Returns wi (n, 3) cosine-distributed on wo's side
    (pdf |cos θi| / π, weight f·|cos θi| / pdf = 1 for a white lobe)."""
    wo = vec3_rows(wo)
    u2 = f64_array(u2)
    wi = np.empty((wo.shape[0], 3))
    _sample_diffuse_rows(wo, u2, wi)
    return wi
