"""Cycles's Multiscatter GGX energy compensation of the glass lobe (``microfacet_ggx_preserve_
energy`` for CLOSURE_BSDF_MICROFACET_GGX_GLASS_ID): a GLASS lobe whose material asks for it
(``multiscatter_tint`` Fss, the Glass BSDF's colour or the Principled transmission's
sqrt(base colour)) scales its whole BSDF, reflection and refraction, per channel by

    k(wo) = 1 + Fms·(1 − E)/E,    Fms = Fss·E_avg / (1 − Fss·(1 − E_avg))

E = E(r, cos θo, z) the albedo of the white single-scatter GGX glass and E_avg(r, z) its cosine
average (tables from scripts/make_glass_tables.py; r = sqrt(alpha), z = sqrt(|η − 1|/(η + 1))
of the relative index η > 1; seen from the denser side (η < 1) the "inv" tables of 1/η). With
Fss = 0 (a lobe without compensation) k = 1. Smooth (delta) glass: E = 1, k = 1.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..kernels import kernel
from .dielectric_specular import table_2d, table_3d

_TABLES = np.load(os.path.join(os.path.dirname(__file__), "glass_ms_tables.npz"))
#: (16, 16, 16) albedo of white GGX glass E[z, mu, r], η > 1 (entering the denser side)
GLASS_E = np.ascontiguousarray(_TABLES["ggx_glass_E"], dtype=np.float64)
#: (16, 16) its cosine average E_avg[z, r]
GLASS_EAVG = np.ascontiguousarray(_TABLES["ggx_glass_Eavg"], dtype=np.float64)
#: the same seen from the denser side (η → 1/η)
GLASS_INV_E = np.ascontiguousarray(_TABLES["ggx_glass_inv_E"], dtype=np.float64)
GLASS_INV_EAVG = np.ascontiguousarray(_TABLES["ggx_glass_inv_Eavg"], dtype=np.float64)


@kernel
def glass_energy_factor(alpha, ior, cos_o, fss):
    """k(wo) per channel (3-tuple) of a GLASS lobe with GGX alpha and IOR ``ior`` (entering when
    cos_o > 0), seen at cos θo = cos_o, with Multiscatter tint ``fss`` (3-tuple in [0, 1])."""
    eta = ior if cos_o >= 0.0 else 1.0 / ior
    inside = eta < 1.0
    if inside:
        eta = 1.0 / eta
    rough = math.sqrt(alpha)
    mu = abs(cos_o)
    z = math.sqrt(abs((eta - 1.0) / (eta + 1.0)))
    if inside:
        e = table_3d(GLASS_INV_E, rough, mu, z)
        e_avg = table_2d(GLASS_INV_EAVG, rough, z)
    else:
        e = table_3d(GLASS_E, rough, mu, z)
        e_avg = table_2d(GLASS_EAVG, rough, z)
    e = max(e, 1e-6)
    missing = (1.0 - e) / e
    return (_channel(fss[0], e_avg, missing), _channel(fss[1], e_avg, missing),
            _channel(fss[2], e_avg, missing))


@kernel
def _channel(fss, e_avg, missing):
    fms = fss * e_avg / (1.0 - fss * (1.0 - e_avg))
    return 1.0 + fms * missing
