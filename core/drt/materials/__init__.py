"""BSDF lobes and the material table.

``MaterialTable`` (table.py) is what the integrator uses; the lobe modules (diffuse.py, ggx.py,
dielectric.py) are frame-free, colourless building blocks working in the local shading frame.
"""

from .dielectric import IOR_ONE_EPS, eval_glass, fresnel_dielectric, refract, sample_glass
from .diffuse import eval_diffuse, sample_diffuse
from .ggx import ALPHA_SQ_SINGULAR, eval_glossy, ggx_d, ggx_lambda, sample_glossy, sample_vndf
from .table import (
    BSDF_DIFFUSE,
    BSDF_GLASS,
    BSDF_GLOSSY,
    BSDF_NONE,
    LOBE_DIFFUSE,
    LOBE_GLOSSY,
    LOBE_NONE,
    LOBE_TRANSMISSION,
    BSDFSample,
    MaterialTable,
)

__all__ = [
    "ALPHA_SQ_SINGULAR", "BSDF_DIFFUSE", "BSDF_GLASS", "BSDF_GLOSSY", "BSDF_NONE", "BSDFSample",
    "IOR_ONE_EPS", "LOBE_DIFFUSE", "LOBE_GLOSSY", "LOBE_NONE", "LOBE_TRANSMISSION",
    "MaterialTable", "eval_diffuse", "eval_glass", "eval_glossy", "fresnel_dielectric", "ggx_d",
    "ggx_lambda", "refract", "sample_diffuse", "sample_glass", "sample_glossy", "sample_vndf",
]
