"""Lights in Cycles's units: sampling, selection, intersection for MIS (see docs/lights.md).

The scalar kernels the compiled integrator calls (docs/kernels.md) take ``LightSet.data`` (a
`LightData`) first: `light_sample` (`light_sample_full` also returns the strategy and the
emissive triangle id), `selection_prob`, `shape_intersect`, `shape_emission`, `sun_in_cone`,
`sun_emission`, `world_radiance`, `world_pdf`, `emissive_pdf`.
"""

from .area import AreaLight
from .common import LightData
from .emissive import EmissiveGroup, EmissiveTriangles
from .light_set import (LightHit, LightSample, LightSet, emissive_pdf, light_sample,
                        light_sample_full, select, select_rows, selection_distribution,
                        shape_emission, shape_intersect, sun_emission, sun_in_cone, world_pdf,
                        world_radiance)
from .point import PointLight
from .selection import ShadingHint, selection_prob
from .spot import SpotLight
from .sun import SunLight
from .world import WorldLight

__all__ = ["AreaLight", "EmissiveGroup", "EmissiveTriangles", "LightData", "LightHit",
           "LightSample", "LightSet", "PointLight", "ShadingHint", "SpotLight", "SunLight",
           "WorldLight", "emissive_pdf", "light_sample", "light_sample_full", "select",
           "select_rows", "selection_distribution", "selection_prob", "shape_emission", "shape_intersect",
           "sun_emission", "sun_in_cone", "world_pdf", "world_radiance"]
