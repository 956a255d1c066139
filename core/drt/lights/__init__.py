"""Lights in Cycles's units: sampling, selection, intersection for MIS (see docs/lights.md)."""

from .area import AreaLight
from .emissive import EmissiveGroup, EmissiveTriangles
from .light_set import LightHit, LightSample, LightSet, select, selection_distribution
from .point import PointLight
from .selection import ShadingHint
from .spot import SpotLight
from .sun import SunLight
from .world import WorldLight

__all__ = ["AreaLight", "EmissiveGroup", "EmissiveTriangles", "LightHit", "LightSample",
           "LightSet", "PointLight", "ShadingHint", "SpotLight", "SunLight", "WorldLight", "select",
           "selection_distribution"]
