"""Motion blur of several moving objects against an analytic answer, in DRT and in Cycles.

Emissive squares (emission 1) over a black world, seen straight down by an orthographic camera
with a 0.01-pixel filter: each pixel shows the fraction of the shutter during which its centre
lies inside a square. The squares translate, turn and grow with linear keys, so the fraction is
known from the transforms alone (T · Rz · S with each part linear in time: Blender's object
matrix, and the rigid motion both renderers interpolate). With four moving objects DRT's tracer
queries them as one Embree scene of instances (drt.trace). Slow: two 48 × 48 renders at 256
samples.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytestmark = [pytest.mark.slow, pytest.mark.blender]

SPP = 256
#: per square: centre (x, y) at shutter open, its move over the shutter, turn (degrees) over
#: the shutter, scale at open and at close; the squares are 0.5 wide before scaling
SQUARES = [
    ((-0.55, 0.5), (0.3, 0.0), 0.0, 1.0, 1.0),      # slides
    ((0.5, 0.5), (0.0, 0.0), 90.0, 1.0, 1.0),       # turns a quarter
    ((-0.5, -0.5), (0.0, 0.0), 0.0, 0.8, 1.5),      # grows
    ((0.45, -0.55), (0.1, 0.15), 60.0, 0.7, 1.1),   # all three
]
OPEN, CLOSE = 4.75, 5.25   # frame 5, shutter 0.5 frames, centred (Blender's defaults)
KEYS = (1.0, 9.0)          # linear keys this far apart: the shutter sees 1/16 of each change


def _value_at(frame, at_open, at_close):
    """A linearly keyed property's value at ``frame``, given its values at shutter open and
    close (the keys at KEYS are placed so that these hold)."""
    w = (frame - OPEN) / (CLOSE - OPEN)
    return at_open + w * (at_close - at_open)


def expected_coverage(w: int, h: int, steps: int = 2000) -> np.ndarray:
    """(h, w) fraction of the shutter each pixel centre spends inside a square (top row first)."""
    x = -1.0 + (np.arange(w) + 0.5) * 2.0 / w
    y = 1.0 - (np.arange(h) + 0.5) * 2.0 / h
    px, py = np.meshgrid(x, y)
    covered = np.zeros((h, w))
    for tau in (np.arange(steps) + 0.5) / steps:
        inside = np.zeros((h, w), dtype=bool)
        for (cx, cy), (mx, my), turn, s0, s1 in SQUARES:
            ox, oy = cx + tau * mx, cy + tau * my
            a = math.radians(tau * turn)
            s = s0 + tau * (s1 - s0)
            # the point in the square's own frame: rotate back by a, divide by the scale
            lx = (math.cos(a) * (px - ox) + math.sin(a) * (py - oy)) / s
            ly = (-math.sin(a) * (px - ox) + math.cos(a) * (py - oy)) / s
            inside |= (np.abs(lx) < 0.25) & (np.abs(ly) < 0.25)
        covered += inside
    return covered / steps


def _scene():
    from _common import make_linear  # blend_scenes/, on the path through node_parity
    from node_parity import setup_scene

    sc = setup_scene(3)  # 48 × 48 pixels over [−1, 1]², 0.01-pixel filter, no bounces
    sc.cycles.samples = SPP
    sc.drt.samples = SPP
    sc.render.use_motion_blur = True
    sc.render.motion_blur_shutter = 0.5
    sc.render.motion_blur_position = "CENTER"
    glow = bpy.data.materials.new("glow")
    nt = glow.node_tree
    nt.nodes.clear()
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 1.0
    nt.links.new(em.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    for (cx, cy), (mx, my), turn, s0, s1 in SQUARES:
        bpy.ops.mesh.primitive_plane_add(size=0.5, location=(cx, cy, 0))
        obj = bpy.context.object
        obj.data.materials.append(glow)
        # keys at frames 1 and 9 on the lines through the shutter's open and close values
        at = {"location": ((cx, cy, 0.0), (cx + mx, cy + my, 0.0)),
              "rotation_euler": ((0.0, 0.0, 0.0), (0.0, 0.0, math.radians(turn))),
              "scale": ((s0, s0, 1.0), (s1, s1, 1.0))}
        for frame in KEYS:
            for prop, (v0, v1) in at.items():
                setattr(obj, prop, tuple(_value_at(frame, a, b) for a, b in zip(v0, v1)))
                obj.keyframe_insert(prop, frame=frame)
        make_linear(obj)  # (new keys ease in and out by default, whatever the preference says)
    sc.frame_set(5)
    return sc


def test_moving_squares_cover_each_pixel_for_their_share_of_the_shutter(tmp_path, monkeypatch):
    """F12 in both engines (the add-on exports the motion at shutter open and close); DRT's
    tracer uses its scene of instances."""
    import drt.trace as trace_mod
    from node_parity import f12_in_both

    built = []

    def recorded(tracer, device):
        built.append(instances(tracer, device))
        return built[-1]

    instances = trace_mod._instances
    monkeypatch.setattr(trace_mod, "_instances", recorded)
    sc = _scene()
    images = {engine: np.asarray(chans["ViewLayer.Combined"], np.float64).reshape(48, 48, -1)
              for engine, chans, _ in f12_in_both(sc, tmp_path)}
    assert built and all(b is not None for b in built)
    drt, cycles = images["DRT"], images["CYCLES"]
    p = expected_coverage(48, 48)
    blurred = (p > 0.05) & (p < 0.95)
    assert blurred.sum() > 150  # the motion shows: many pixels are partly covered
    # a pixel's value is the mean of SPP coverage samples (0 or 1) at its centre: within five
    # binomial standard deviations of the fraction, plus a little for the tiny filter
    tol = 5.0 * np.sqrt(p * (1.0 - p) / SPP) + 0.01
    for name, img in (("DRT", drt), ("Cycles", cycles)):
        got = img[..., 0]
        bad = np.abs(got - p) > tol
        assert bad.sum() <= 2, (name, bad.sum(), np.abs(got - p).max())
        # and on average over the blurred pixels, well inside the mean's error
        err = (got - p)[blurred].mean()
        assert abs(err) < 4.0 * np.sqrt((p * (1 - p))[blurred].sum() / SPP) / blurred.sum() + 2e-3, (name, err)
