"""BSDF lobes and the material table.

``MaterialTable`` (table.py) is what the integrator uses: its ``data`` (a ``MaterialData``) is
the first argument of the compiled kernels ``bsdf_eval(md, m, wo, wi) -> (f, pdf)`` and
``bsdf_sample(md, m, wo, u_lobe, u0, u1) -> (wi, weight, pdf, lobe_kind, is_delta, valid)``.
The lobe modules (diffuse.py, ggx.py, dielectric.py) are frame-free, colourless building blocks
working in the local shading frame: scalar kernels on 3-tuples, and array functions that apply
them row by row.
"""

from .dielectric import (
    IOR_ONE_EPS,
    eval_glass,
    fresnel,
    fresnel_dielectric,
    glass_eval,
    glass_sample,
    refract,
    refract_through,
    sample_glass,
)
from .diffuse import diffuse_eval, diffuse_sample, eval_diffuse, sample_diffuse
from .ggx import (
    ALPHA_SQ_SINGULAR,
    eval_glossy,
    ggx_d,
    ggx_lambda,
    ggx_ndf,
    ggx_smith_lambda,
    ggx_vndf_sample,
    glossy_eval,
    glossy_sample,
    sample_glossy,
    sample_vndf,
)
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
    MaterialData,
    MaterialTable,
    NO_BUMP,
    bsdf_eval,
    bsdf_eval_bump,
    bsdf_sample,
    bsdf_sample_bump,
)

__all__ = [
    "ALPHA_SQ_SINGULAR", "BSDF_DIFFUSE", "BSDF_GLASS", "BSDF_GLOSSY", "BSDF_NONE", "BSDFSample",
    "IOR_ONE_EPS", "LOBE_DIFFUSE", "LOBE_GLOSSY", "LOBE_NONE", "LOBE_TRANSMISSION",
    "MaterialData", "MaterialTable", "NO_BUMP", "bsdf_eval", "bsdf_eval_bump", "bsdf_sample",
    "bsdf_sample_bump", "diffuse_eval",
    "diffuse_sample", "eval_diffuse", "eval_glass", "eval_glossy", "fresnel",
    "fresnel_dielectric", "ggx_d", "ggx_lambda", "ggx_ndf", "ggx_smith_lambda",
    "ggx_vndf_sample", "glass_eval", "glass_sample", "glossy_eval", "glossy_sample", "refract",
    "refract_through", "sample_diffuse", "sample_glass", "sample_glossy", "sample_vndf",
]
