"""Cycles's side rules for smooth (interpolated) normals, checked on a one-quad scene against
closed forms (docs/lights.md, "Smooth normals: which side shades").

A white Lambert quad in the plane z = 0 (geometric normal +z) whose corner normals are all
n = (−sin 60°, 0, cos 60°): tilted away from an orthographic camera looking down
wo = (sin 60°, 0, cos 60°), so the camera sees the facet's front (wo·Ng > 0) but from below its
smooth normal (wo·n = −0.5) — what a camera sees on a low-poly smooth mesh near a silhouette.
A delta sun (angle 0, strength E) gives each pixel exactly E·max(n·L, 0)/π under Cycles's
rules: the diffuse closure's normal is sd->N (the smooth normal on wo's geometric side) and it
accepts light above that normal whichever side wo is on; a light sample is tested against the
smooth side only, and its shadow ray skips the own facet (kernel/closure/bsdf_diffuse.h,
kernel/integrator/shade_surface.h, kernel/light/sample.h). Before, DRT shaded wo's side of the
smooth normal (light below n) and dropped light samples on the other geometric side.
"""

import math

import numpy as np
import pytest

from drt.render import render
from drt.scene import scene_from_dict
from scene_builders import add_material, add_mesh, base_header, look_at, quad

E = 3.0
S60, C60 = math.sin(math.radians(60)), math.cos(math.radians(60))
N_SMOOTH = np.array([-S60, 0.0, C60])
WO = np.array([S60, 0.0, C60])


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def render_quad(to_light, smooth=True, material=None):
    """Mean pixel value of the quad under a delta sun shining from direction ``to_light``."""
    h = base_header(4, 4, 4, max_bounces=0, diffuse_bounces=0,
                    camera={"type": "ORTHO", "matrix_world": look_at(3.0 * WO, (0, 0, 0)),
                            "ortho_scale": 0.01, "clip_start": 0.01, "clip_end": 100.0})
    a = {}
    m = add_material(h, "white", material or [{"type": "DIFFUSE", "color": [1.0, 1.0, 1.0]}])
    pos, tri = quad((0, 0, 0), (5, 0, 0), (0, 5, 0))
    normals = np.broadcast_to(N_SMOOTH, (len(tri), 3, 3)) if smooth else None
    add_mesh(h, a, "quad", pos, tri, material=m, normals=normals)
    h["lights"].append({"type": "SUN", "matrix_world": look_at(5.0 * unit(to_light), (0, 0, 0)),
                        "color": [1, 1, 1], "strength": E, "angle": 0.0})
    img = render(scene_from_dict(h, a), threads=1).combined[..., :3]
    assert np.ptp(img) < 1e-5 * max(img.max(), 1.0)  # a delta sun: every pixel the same
    return float(img[..., 0].mean())


@pytest.mark.parametrize("to_light", [
    (-0.5, 0.0, 0.866),   # above the facet and above n, wo below n: lit by n·L (was 0)
    (-1.0, 0.0, -0.1),    # below the facet's plane, above n: the shadow ray passes the own facet
    (0.866, 0.0, 0.5),    # above the facet, below n (wo's side of n): dark (was lit by |n·L|)
    (0.3, 0.6, 0.74),     # above both
], ids=["above-n", "below-facet", "below-n", "above-both"])
def test_smooth_lambert_shades_above_the_smooth_normal(to_light):
    L = unit(to_light)
    expected = E * max(float(N_SMOOTH @ L), 0.0) / math.pi
    assert render_quad(L) == pytest.approx(expected, rel=1e-4, abs=1e-6)


def test_flat_quad_is_lit_by_the_geometric_normal():
    L = unit((-0.5, 0.0, 0.866))
    assert render_quad(L, smooth=False) == pytest.approx(E * L[2] / math.pi, rel=1e-4)
    assert render_quad(unit((-1.0, 0.0, -0.1)), smooth=False) == 0.0
