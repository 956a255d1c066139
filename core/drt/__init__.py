"""DRT: a distribution ray tracer (Cook 1984) with a numpy + Embree core.

The package never imports bpy; the Blender add-on in ``addon/`` feeds it scenes.
See ``docs/architecture.md`` for the module map and conventions.
"""

__version__ = "0.1.0"
