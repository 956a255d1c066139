"""Participating media (issue 14): homogeneous media inside closed meshes and as the world
volume, in Cycles's units and semantics (docs/volumes.md).

* ``media``: the scene's media as arrays (``MediumData``), validation of the scene file's
  ``volume`` dicts, and the conversions of Blender's volume nodes to coefficients;
* ``phase``: the Henyey-Greenstein phase function (eval, sample);
* ``distance``: distance (exponential) and equiangular sampling of a point on a ray segment;
* ``stack``: the per-path volume stack (enter on front-face crossings, leave on back-face
  ones), the summed coefficients of a stack, and the camera's initial stack;
* ``stage``: what the path tracer's ``shade`` calls per ray segment (absorption, emission,
  scattering with next-event estimation) and the shadow-ray transmittance stage.
"""
