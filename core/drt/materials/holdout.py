"""Holdout: the part of a material that cuts the surface out of the image (Cycles's Holdout
shader, exported as HOLDOUT lobes whose grey colour is the holdout weight).

As Cycles's ``integrate_surface_holdout``: where a *camera* ray (still one after transparent
bounces) hits the surface, the film's alpha loses average(holdout weight × throughput), with or
without a transparent film; the holdout adds no light, and a full holdout (weight 1) ends the
path (no emission). Other rays see only the material's other lobes (a pure holdout is black and
opaque to them). The lobes are never sampled or evaluated (``drt.materials.table``).
"""

from __future__ import annotations

import numpy as np

from ..kernels import inline_kernel
from .table import BSDF_HOLDOUT


@inline_kernel
def holdout_weight(md, m):
    """Material m's holdout weight: the average of its HOLDOUT lobes' colours (0: none)."""
    h = 0.0
    for s in range(md.lobe_count[m]):
        if md.lobe_type[m, s] == BSDF_HOLDOUT:
            h += (md.lobe_color[m, s, 0] + md.lobe_color[m, s, 1] + md.lobe_color[m, s, 2]) * (1.0 / 3.0)
    return h


def holdout_materials(md) -> np.ndarray:
    """(M,) bool: materials with a holdout lobe."""
    return np.any(md.lobe_type == BSDF_HOLDOUT, axis=1)
