"""Blender's camera: primary rays for pixel positions, lens samples and shutter times.

Conventions (measured against Cycles, see ``docs/conventions.md``):

* camera space looks along −Z with +Y up; ``matrix`` maps camera to (shifted) world space;
* continuous pixel coordinates (u, v): u from the left edge, v from the **bottom** edge;
* the sensor fit picks which image side spans the sensor: AUTO uses ``sensor_width`` on the
  larger (aspect-corrected) side, HORIZONTAL ``sensor_width`` on the width, VERTICAL
  ``sensor_height`` on the height; shift is in units of the fitted side;
* depth of field follows Cycles: a lens point on a disk (or regular polygon for ≥ 3 blades,
  rotated by ``rotation``, x squeezed by ``ratio``) of radius lens·0.001/(2·fstop) metres, aimed
  at the point where the pinhole ray meets the focus *plane* at ``focus_distance``;
* rays start on the plane z = −clip_start and end at z = −clip_end (camera space).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .motion import RigidMotion, apply_linear
from .sampling.warps import square_to_disk_concentric, square_to_polygon
from .scene import CameraSpec, RenderSettings
from .vecmath import row_norm, transform_rows


@dataclass
class CameraRays:
    """Primary rays in the shifted world frame: origins (n,3), unit directions (n,3), the
    distance ``tmax`` (n,) to the far clip plane, and ``forward`` (n,3), the camera's view axis
    (for the depth pass: depth = t · dot(d, forward))."""

    o: np.ndarray
    d: np.ndarray
    tmax: np.ndarray
    forward: np.ndarray
    eye: np.ndarray  # (n, 3) the lens point each ray left from (depth is measured from it)


class Camera:
    def __init__(self, spec: CameraSpec, settings: RenderSettings, origin_shift: np.ndarray):
        self.spec = spec
        w, h = settings.width, settings.height
        ax, ay = settings.pixel_aspect
        self.width, self.height = w, h
        xa, ya = w * ax, h * ay  # aspect-corrected image extent
        fit = spec.sensor_fit
        if fit == "AUTO":
            horizontal = xa >= ya
            sensor = spec.sensor_width
        elif fit == "HORIZONTAL":
            horizontal, sensor = True, spec.sensor_width
        else:
            horizontal, sensor = False, spec.sensor_height
        # extent of the fitted side on the plane at distance 1 (perspective) or in scene units (ortho)
        fitted = spec.ortho_scale if spec.type == "ORTHO" else sensor / spec.lens
        if horizontal:
            self.plane_w, self.plane_h = fitted, fitted * ya / xa
        else:
            self.plane_w, self.plane_h = fitted * xa / ya, fitted
        self.shift = np.array([spec.shift_x, spec.shift_y]) * fitted
        self.lens_radius = spec.lens * 0.001 / (2.0 * spec.fstop) if spec.dof_use else 0.0
        m = np.array(spec.matrix, dtype=np.float64)
        m[:3, 3] -= origin_shift
        self.matrix = m
        self.motion = None
        shutter = settings.shutter
        # like objects (Scene.has_motion): no shutter or a zero-length one means no blur
        if spec.motion is not None and shutter is not None and shutter[1] > shutter[0]:
            m0 = np.array(spec.motion[0], dtype=np.float64)
            m1 = np.array(spec.motion[1], dtype=np.float64)
            m0[:3, 3] -= origin_shift
            m1[:3, 3] -= origin_shift
            self.motion = RigidMotion(m0, m1)

    def lens_offsets(self, u: np.ndarray) -> np.ndarray:
        """(n, 2) points on the aperture (camera-space x, y, metres) from (n, 2) uniforms."""
        s = self.spec
        if s.blades >= 3:
            p = square_to_polygon(u, s.blades, s.rotation)
        else:
            p = square_to_disk_concentric(u)
        p = p * self.lens_radius
        p[:, 0] /= s.ratio
        return p

    def generate(self, px: np.ndarray, py: np.ndarray, u_lens: np.ndarray, tau: np.ndarray) -> CameraRays:
        """Rays through continuous pixel positions ``px`` (from the left), ``py`` (from the bottom).

        u_lens: (n, 2) uniforms for the aperture; tau: (n,) shutter fractions.
        """
        s = self.spec
        x = (px / self.width - 0.5) * self.plane_w + self.shift[0]
        y = (py / self.height - 0.5) * self.plane_h + self.shift[1]
        n = len(px)
        if s.type == "ORTHO":
            o = np.stack([x, y, np.zeros(n)], axis=1)
            d = np.tile([0.0, 0.0, -1.0], (n, 1))
            if self.lens_radius > 0:
                lens = self.lens_offsets(u_lens)
                focus = o + d * s.focus_distance
                o = o + np.column_stack([lens, np.zeros(n)])
                d = focus - o
        else:
            d = np.stack([x, y, -np.ones(n)], axis=1)
            o = np.zeros((n, 3))
            if self.lens_radius > 0:
                lens = self.lens_offsets(u_lens)
                focus = d * s.focus_distance  # d.z = −1: the point on the focus plane
                o = np.column_stack([lens, np.zeros(n)])
                d = focus - o
        d /= row_norm(d)[:, None]
        # start on the near clip plane, stop at the far one (planes, not spheres, like Cycles)
        cos_axis = -d[:, 2]
        t_near = np.where(cos_axis > 0, (s.clip_start + o[:, 2]) / np.maximum(cos_axis, 1e-12), 0.0)
        t_far = np.where(cos_axis > 0, (s.clip_end + o[:, 2]) / np.maximum(cos_axis, 1e-12), np.inf)
        eye = o
        o = o + d * t_near[:, None]
        tmax = np.maximum(t_far - t_near, 0.0)
        if self.motion is not None:
            lin, trans = self.motion.at(tau)
            o_w = apply_linear(lin, o) + trans
            eye_w = apply_linear(lin, eye) + trans
            d_w = apply_linear(lin, d)
            fwd = -lin[:, :, 2]
            fwd = fwd / row_norm(fwd)[:, None]
        else:
            lin = self.matrix[:3, :3]
            o_w = transform_rows(o, lin) + self.matrix[:3, 3]
            eye_w = transform_rows(eye, lin) + self.matrix[:3, 3]
            d_w = transform_rows(d, lin)
            axis = -self.matrix[:3, 2]
            fwd = np.broadcast_to(axis / np.linalg.norm(axis), (n, 3))
        scale = row_norm(d_w)
        d_w /= scale[:, None]
        # a scaled camera object scales distances too: keep tmax in world units
        return CameraRays(o_w, d_w, tmax * scale, fwd, eye_w)
