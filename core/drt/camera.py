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

One ray is the scalar kernel ``camera_ray(cd, px, py, ul0, ul1, tau)`` with ``cd = Camera.data``
(a ``CameraData``); ``Camera.generate`` applies it to arrays.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from .kernels import inline_kernel, kernel
from .motion import RigidMotion, apply_rows, invert_affine, motion_at, static_motion_data
from .panorama import PANO_SIZE, PANORAMA_TYPES, panorama_direction, panorama_lens, pano_parameters, to_blender_camera
from .sampling.warps import disk_concentric, polygon
from .scene import CameraSpec, RenderSettings

PROJECTION_PERSP, PROJECTION_ORTHO, PROJECTION_PANO = 0, 1, 2  # CameraData.projection

CameraData = namedtuple("CameraData", [
    "projection", "width", "height", "plane_w", "plane_h", "shift_x", "shift_y",
    "lens_radius", "focus_distance", "blades", "rotation", "ratio", "clip_start", "clip_end",
    "matrix", "moving", "motion", "forward", "pano_type", "pano"])
CameraData.__doc__ = """The camera for the kernels.  projection: int64 (0 PERSP, 1 ORTHO, 2 PANO); width,
height: float64 image size in pixels; plane_w, plane_h: float64 extent of the image on the plane
at distance 1 (perspective) or in scene units (ortho); shift_x, shift_y: float64 in the same
units; lens_radius (float64, 0 = pinhole), focus_distance (float64), blades (int64, ≥ 3 for a
polygonal aperture), rotation (float64, radians), ratio (float64): the aperture; clip_start,
clip_end: float64; matrix: (4, 4) float64 camera → (shifted) world; moving: bool; motion: a
``drt.motion.MotionData`` of the (shifted) camera transform over the shutter (identity if not
moving); forward: (x, y, z) float64, the unit view axis (−Z of ``matrix``) of a camera that does
not move; pano_type: int64 (drt.panorama.PANORAMA_TYPES' index), pano: (PANO_SIZE,) float64 its
parameters (drt.panorama.pano_parameters; zeros for other projections)."""


@kernel
def lens_offset(cd, ul0, ul1):
    """A point (x, y) of the aperture (camera space, metres) for uniforms (ul0, ul1)."""
    if cd.blades >= 3:
        x, y = polygon(ul0, ul1, float(cd.blades), cd.rotation)
    else:
        x, y = disk_concentric(ul0, ul1)
    return x * cd.lens_radius / cd.ratio, y * cd.lens_radius


@inline_kernel
def camera_ray(cd, px, py, ul0, ul1, tau):
    """The primary ray through continuous pixel position (px from the left, py from the bottom)
    with aperture uniforms (ul0, ul1) at shutter fraction tau, in the shifted world frame:
    (o, d, tmax, eye, forward) — origin on the near clip plane, unit direction, distance to the
    far clip plane, the lens point the ray left from and the camera's unit view axis."""
    if cd.projection == 2:  # PANO
        return _panorama_ray(cd, px, py, ul0, ul1, tau)
    # (reciprocals, not divisions: a division costs ~5× a multiply, and 1/width is the same for
    # every ray of a stage, which LLVM computes once for the loop)
    x = (px * (1.0 / cd.width) - 0.5) * cd.plane_w + cd.shift_x
    y = (py * (1.0 / cd.height) - 0.5) * cd.plane_h + cd.shift_y
    # In camera space the ray leaves the lens point e (on z = 0) along v, unnormalised, whose z
    # is −depth for every ray of the camera: 1 without depth of field, the focus distance with
    # it (v then ends on the focus plane, at the pinhole ray's point there).
    fd = cd.focus_distance
    if cd.lens_radius > 0:
        lx, ly = lens_offset(cd, ul0, ul1)
        depth = fd
        if cd.projection == 1:  # ORTHO
            ex, ey = x + lx, y + ly
            v = (-lx, -ly, -fd)
        else:
            ex, ey = lx, ly
            v = (x * fd - lx, y * fd - ly, -fd)
    else:
        depth = 1.0
        if cd.projection == 1:  # ORTHO
            ex, ey = x, y
            v = (0.0, 0.0, -1.0)
        else:
            ex, ey = 0.0, 0.0
            v = (x, y, -1.0)
    r0, r1, r2, t, fwd = _camera_frame(cd, tau)
    el = apply_rows(r0, r1, r2, (ex, ey, 0.0))
    eye_w = (el[0] + t[0], el[1] + t[1], el[2] + t[2])
    # Everything follows from the world-space v: one square root and one division a ray. The
    # clip planes z = −clip_start and z = −clip_end (planes, not spheres, like Cycles) lie at
    # e + v·clip/depth; a scaled camera object scales v and so keeps tmax in world units.
    vw = apply_rows(r0, r1, r2, v)
    length = math.sqrt(vw[0] * vw[0] + vw[1] * vw[1] + vw[2] * vw[2])
    inv_len = 1.0 / length
    d_w = (vw[0] * inv_len, vw[1] * inv_len, vw[2] * inv_len)
    if depth > 0.0:
        near = cd.clip_start / depth
        o_w = (eye_w[0] + vw[0] * near, eye_w[1] + vw[1] * near, eye_w[2] + vw[2] * near)
        tmax = max((cd.clip_end - cd.clip_start) / depth, 0.0) * length
    else:  # a focus distance of 0: v lies in the lens plane, no clip plane ahead
        o_w = eye_w
        tmax = np.inf
    return o_w, d_w, tmax, eye_w, fwd


@inline_kernel
def _camera_frame(cd, tau):
    """The camera → (shifted) world transform at shutter fraction tau: rows r0, r1, r2 of its
    linear part, its translation t, and the unit view axis (camera −Z) in the world."""
    if cd.moving:
        r0, r1, r2, t = motion_at(cd.motion, tau)
        fwd = (-r0[2], -r1[2], -r2[2])
        inv_fn = 1.0 / math.sqrt(fwd[0] * fwd[0] + fwd[1] * fwd[1] + fwd[2] * fwd[2])
        return r0, r1, r2, t, (fwd[0] * inv_fn, fwd[1] * inv_fn, fwd[2] * inv_fn)
    m = cd.matrix
    r0 = (m[0, 0], m[0, 1], m[0, 2])
    r1 = (m[1, 0], m[1, 1], m[1, 2])
    r2 = (m[2, 0], m[2, 1], m[2, 2])
    t = (m[0, 3], m[1, 3], m[2, 3])
    return r0, r1, r2, t, cd.forward


@inline_kernel
def _panorama_ray(cd, px, py, ul0, ul1, tau):
    """``camera_ray`` of a panoramic camera (drt.panorama, Cycles's camera_sample_panorama):
    the ray leaves the lens point along the projection's direction, from clip_start along it
    to clip_end (spherical clipping: there is no image plane), and ``forward`` is the ray's own
    direction, so that the depth pass is the distance from the camera, as Cycles's. A position
    the projection has no ray for: ``tmax`` −1 (the camera stage drops the sample)."""
    r0, r1, r2, t, _ = _camera_frame(cd, tau)
    dc = panorama_direction(cd.pano_type, cd.pano, px * (1.0 / cd.width), py * (1.0 / cd.height))
    if dc[0] == 0.0 and dc[1] == 0.0 and dc[2] == 0.0:
        return t, (0.0, 0.0, -1.0), -1.0, t, (0.0, 0.0, -1.0)
    e = (0.0, 0.0, 0.0)
    if cd.lens_radius > 0:
        lx, ly = lens_offset(cd, ul0, ul1)
        e, dc = panorama_lens(dc, lx, ly, cd.focus_distance)
    el = apply_rows(r0, r1, r2, to_blender_camera(cd.pano_type, e))
    eye_w = (el[0] + t[0], el[1] + t[1], el[2] + t[2])
    vw = apply_rows(r0, r1, r2, to_blender_camera(cd.pano_type, dc))
    inv_len = 1.0 / math.sqrt(vw[0] * vw[0] + vw[1] * vw[1] + vw[2] * vw[2])
    d_w = (vw[0] * inv_len, vw[1] * inv_len, vw[2] * inv_len)
    cs = cd.clip_start
    o_w = (eye_w[0] + d_w[0] * cs, eye_w[1] + d_w[1] * cs, eye_w[2] + d_w[2] * cs)
    return o_w, d_w, max(cd.clip_end - cs, 0.0), eye_w, d_w


@kernel
def _camera_rows(cd, px, py, u_lens, tau, o, d, tmax, fwd, eye):
    for k in range(px.shape[0]):
        ro, rd, rt, re, rf = camera_ray(cd, px[k], py[k], u_lens[k, 0], u_lens[k, 1], tau[k])
        for j in range(3):
            o[k, j] = ro[j]
            d[k, j] = rd[j]
            eye[k, j] = re[j]
            fwd[k, j] = rf[j]
        tmax[k] = rt


@kernel
def _lens_rows(cd, u, out):
    for k in range(u.shape[0]):
        out[k, 0], out[k, 1] = lens_offset(cd, u[k, 0], u[k, 1])


def _f64(a) -> np.ndarray:
    """float64, C-contiguous, writeable: one compiled signature serves every call."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


def _view_axis(m: np.ndarray) -> tuple:
    """The unit view axis, camera −Z, of the camera-to-world matrix m (world frame); (0, 0, −1)
    for a degenerate matrix."""
    axis = -np.asarray(m, np.float64)[:3, 2]
    norm = float(np.linalg.norm(axis))
    if not (norm > 0.0 and np.isfinite(norm)):
        return (0.0, 0.0, -1.0)
    return tuple(float(c) for c in axis / norm)


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
        self.origin_shift = np.asarray(origin_shift, np.float64).reshape(3).copy()
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
        # the sensor (mm) as the equisolid and polynomial fisheyes see it (Cycles fits it so too)
        pano_horizontal = xa > ya if fit == "AUTO" else horizontal
        if pano_horizontal:
            self.sensor_mm = (sensor, sensor * ya / xa)
        else:
            self.sensor_mm = (sensor * xa / ya, sensor)
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
        pano = spec.panorama if spec.type == "PANO" else None
        projection = {"ORTHO": PROJECTION_ORTHO, "PANO": PROJECTION_PANO}.get(spec.type, PROJECTION_PERSP)
        self.data = CameraData(
            projection=int(projection),
            width=float(w), height=float(h),
            plane_w=float(self.plane_w), plane_h=float(self.plane_h),
            shift_x=float(self.shift[0]), shift_y=float(self.shift[1]),
            lens_radius=float(self.lens_radius), focus_distance=float(spec.focus_distance),
            blades=int(spec.blades), rotation=float(spec.rotation), ratio=float(spec.ratio),
            clip_start=float(spec.clip_start), clip_end=float(spec.clip_end),
            matrix=_f64(m).copy(), moving=self.motion is not None,
            motion=self.motion.data if self.motion is not None else static_motion_data(),
            forward=_view_axis(m),
            pano_type=int(PANORAMA_TYPES.index(pano.type)) if pano is not None else 0,
            pano=(np.array(pano_parameters(pano, *self.sensor_mm), np.float64) if pano is not None
                  else np.zeros(PANO_SIZE)))

    def pixel_footprint(self) -> np.ndarray:
        """(4, 3) float64 world vectors [right abs, right rel, up abs, up rel]: one pixel's step
        to the right / up at a point at ray length t is abs + t·rel (orthographic: abs only;
        perspective: rel only) — the ray differentials the Bump node needs (at shutter open)."""
        cd = self.data
        m = np.asarray(cd.matrix, np.float64)
        right = m[:3, 0] / max(np.linalg.norm(m[:3, 0]), 1e-300)
        up = m[:3, 1] / max(np.linalg.norm(m[:3, 1]), 1e-300)
        px, py = cd.plane_w / cd.width, cd.plane_h / cd.height
        if cd.projection == PROJECTION_PANO:
            # the angle one pixel spans at the image's centre (a panorama's varies over it)
            c = np.array([cd.width, cd.height]) * 0.5
            rays = self.generate(np.array([c[0], c[0] + 1, c[0]]), np.array([c[1], c[1], c[1] + 1]),
                                 np.full((3, 2), 0.5), np.zeros(3))
            dots = np.clip(rays.d[1:] @ rays.d[0], -1.0, 1.0)
            px, py = np.where(rays.tmax[1:] >= 0.0, np.arccos(dots), 0.0)
        ortho = cd.projection == PROJECTION_ORTHO
        z = np.zeros(3)
        return np.array([right * px if ortho else z, z if ortho else right * px,
                         up * py if ortho else z, z if ortho else up * py], np.float64)

    def texture_space(self) -> np.ndarray:
        """(5, 4) float64 for the Texture Coordinate node's Camera and Window outputs: rows 0–2
        map a Blender-world point to camera space (scale removed, as Cycles does), row 3
        [ortho, plane_w, plane_h, 0], row 4 [shift_x, shift_y, 0, 0] (see ``camera_ray``)."""
        cd = self.data
        m = np.array(cd.matrix, np.float64)
        for j in range(3):
            m[:3, j] /= max(np.linalg.norm(m[:3, j]), 1e-300)
        m[:3, 3] += self.origin_shift  # the tracer's frame is shifted; programs see Blender's
        inv = invert_affine(m)
        if inv is None or not np.all(np.isfinite(inv)):  # degenerate: no camera coordinates
            return np.zeros((5, 4))
        out = np.zeros((5, 4))
        out[:3] = inv[:3]
        out[3, :3] = (float(cd.projection == PROJECTION_ORTHO), cd.plane_w, cd.plane_h)
        out[4, :2] = (cd.shift_x, cd.shift_y)
        return out

    def lens_offsets(self, u: np.ndarray) -> np.ndarray:
        """(n, 2) points on the aperture (camera-space x, y, metres) from (n, 2) uniforms."""
        u = _f64(np.asarray(u, dtype=np.float64).reshape(-1, 2))
        out = np.empty_like(u)
        _lens_rows(self.data, u, out)
        return out

    def generate(self, px: np.ndarray, py: np.ndarray, u_lens: np.ndarray, tau: np.ndarray) -> CameraRays:
        """Rays through continuous pixel positions ``px`` (from the left), ``py`` (from the bottom).

        u_lens: (n, 2) uniforms for the aperture; tau: (n,) shutter fractions.
        """
        px = _f64(np.asarray(px, dtype=np.float64).reshape(-1))
        n = px.shape[0]
        py = _f64(np.broadcast_to(np.asarray(py, dtype=np.float64).reshape(-1), (n,)))
        u_lens = np.zeros((n, 2)) if u_lens is None else _f64(
            np.broadcast_to(np.asarray(u_lens, dtype=np.float64).reshape(-1, 2), (n, 2)))
        tau = np.zeros(n) if tau is None else _f64(
            np.broadcast_to(np.asarray(tau, dtype=np.float64).reshape(-1), (n,)))
        o = np.empty((n, 3))
        d = np.empty((n, 3))
        eye = np.empty((n, 3))
        fwd = np.empty((n, 3))
        tmax = np.empty(n)
        _camera_rows(self.data, px, py, u_lens, tau, o, d, tmax, fwd, eye)
        return CameraRays(o, d, tmax, fwd, eye)
