"""Transparency: the part of a material that lets light straight through (Principled Alpha,
the Transparent BSDF — exported as GLASS lobes of IOR 1, which do not bend or reflect).

Cycles treats it apart from the other closures: a ray that passes is a *transparent bounce*
(not a bounce; its own limit, default 8; the MIS state of the last real vertex is kept) and
shadow rays pass too, attenuated by the transparent colour ("transparent shadows"), so that
alpha cut-outs cast cut-out shadows. ``drt.path_stages`` and ``drt.volumes.stage`` do that;
this module says how transparent a material is.
"""

from __future__ import annotations

import numpy as np

from ..kernels import kernel
from .dielectric import IOR_ONE_EPS
from .table import BSDF_GLASS, pick_lobe_view


@kernel
def transparency(md, m):
    """(r, g, b) the colour with which material m lets light straight through: the sum of its
    IOR-1 GLASS lobes' colours (per hit for a textured material: ``md`` rewritten first)."""
    t0 = t1 = t2 = 0.0
    for s in range(md.lobe_type.shape[1]):
        if md.lobe_type[m, s] == BSDF_GLASS and abs(md.lobe_ior[m, s] - 1.0) < IOR_ONE_EPS:
            t0 += md.lobe_color[m, s, 0]
            t1 += md.lobe_color[m, s, 1]
            t2 += md.lobe_color[m, s, 2]
    return t0, t1, t2


@kernel
def straight_lobe(md, m, u_lobe, wo, nc_local, nv_local, front):
    """Whether ``u_lobe`` picks (as ``bsdf_sample_bump`` does at view wo, the normals as there)
    one of material m's IOR-1 GLASS lobes, through which a ray passes straight."""
    slot, _, _ = pick_lobe_view(md, m, u_lobe, wo, nc_local, nv_local, front)
    return md.lobe_type[m, slot] == BSDF_GLASS and abs(md.lobe_ior[m, slot] - 1.0) < IOR_ONE_EPS


def transparent_materials(md) -> np.ndarray:
    """(M,) bool: materials with a straight-through lobe (constant or textured colour)."""
    straight = (md.lobe_type == BSDF_GLASS) & (np.abs(md.lobe_ior - 1.0) < IOR_ONE_EPS)
    return np.any(straight, axis=1)
