"""Blender's panoramic camera (Camera > Type > Panoramic): image position → ray direction.

As Cycles (kernel/camera/projection.h, camera_sample_panorama): the image position (u, v) is
the pixel position over the whole image, u from the left, v from the **bottom**, both in
[0, 1] (a panoramic camera has no shift or zoom). Each projection maps it to a direction in
Cycles's panoramic camera space, where +x is the view axis, +y points left and +z up (the
mirror ball: −y is the view axis, +x right, +z up); ``to_blender_camera`` turns that into
Blender's camera space (view along −Z, +Y up). A position outside the projection's image (the
fisheyes' and the mirror ball's disc, the polynomial lens's field of view) has no ray: the
direction (0, 0, 0), which the camera stage turns into a sample that carries nothing (black,
alpha 1), as Cycles's camera ray with ``tmax`` 0.

The parameters (``PanoramaSpec``) are Blender's, in its units: angles in radians, the
fisheye lens and the sensor in millimetres. The sensor fit for the equisolid and polynomial
fisheyes is the perspective camera's (``sensor_size``).
"""

from __future__ import annotations

import math

from .kernels import inline_kernel

#: Blender's panorama types DRT renders, in the order of ``CameraData.pano_type``
PANORAMA_TYPES = ("EQUIRECTANGULAR", "EQUIANGULAR_CUBEMAP_FACE", "MIRRORBALL", "FISHEYE_EQUIDISTANT",
                  "FISHEYE_EQUISOLID", "FISHEYE_LENS_POLYNOMIAL")
(PANO_EQUIRECTANGULAR, PANO_CUBEMAP_FACE, PANO_MIRRORBALL, PANO_FISHEYE_EQUIDISTANT,
 PANO_FISHEYE_EQUISOLID, PANO_FISHEYE_POLYNOMIAL) = range(len(PANORAMA_TYPES))

#: the layout of ``CameraData.pano`` (float64): Cycles's equirectangular range (4), the fisheye
#: field of view (radians), the fisheye lens and the sensor's width and height (mm), and the
#: polynomial lens's k0 … k4
PANO_RANGE, PANO_FOV, PANO_LENS, PANO_SENSOR_W, PANO_SENSOR_H, PANO_K = 0, 4, 5, 6, 7, 8
PANO_SIZE = 13


def pano_parameters(spec, sensor_w: float, sensor_h: float) -> list[float]:
    """``CameraData.pano`` for a ``drt.scene.PanoramaSpec`` and the fitted sensor (mm)."""
    out = [0.0] * PANO_SIZE
    # Cycles's range: phi = range[0]·u + range[1], theta (from +z) = range[2]·v + range[3]
    out[0:4] = [spec.longitude_min - spec.longitude_max, -spec.longitude_min,
                spec.latitude_min - spec.latitude_max, -spec.latitude_min + 0.5 * math.pi]
    out[PANO_FOV], out[PANO_LENS] = spec.fisheye_fov, spec.fisheye_lens
    out[PANO_SENSOR_W], out[PANO_SENSOR_H] = sensor_w, sensor_h
    out[PANO_K:PANO_K + 5] = list(spec.polynomial)
    return [float(x) for x in out]


@inline_kernel
def _fisheye_direction(theta, u, v, r):
    """The direction at angle theta from the view axis (+x) toward image offset (u, v) ≠ 0."""
    c = u / r if r != 0.0 else 0.0
    phi = math.acos(min(max(c, -1.0), 1.0))
    if v < 0.0:
        phi = -phi
    st = math.sin(theta)
    return math.cos(theta), -math.cos(phi) * st, math.sin(phi) * st


@inline_kernel
def panorama_direction(kind, pano, u, v):
    """The unit direction (Cycles's panoramic camera space, see the module docstring) for image
    position (u, v) in [0, 1]², or (0, 0, 0) where the projection has no ray."""
    if kind == PANO_EQUIRECTANGULAR:
        phi = pano[0] * u + pano[1]
        theta = pano[2] * v + pano[3]
        st = math.sin(theta)
        return st * math.cos(phi), st * math.sin(phi), math.cos(theta)
    if kind == PANO_CUBEMAP_FACE:
        a = math.tan((0.5 - u) * 0.5 * math.pi)
        b = math.tan((v - 0.5) * 0.5 * math.pi)
        inv = 1.0 / math.sqrt(1.0 + a * a + b * b)
        return inv, a * inv, b * inv
    if kind == PANO_MIRRORBALL:
        x = 2.0 * u - 1.0
        z = 2.0 * v - 1.0
        if x * x + z * z > 1.0:
            return 0.0, 0.0, 0.0
        y = -math.sqrt(max(1.0 - x * x - z * z, 0.0))
        # the view ray I = (0, −1, 0) reflected about the ball's normal n = (x, y, z): 2·(n·I)·n − I
        k = -2.0 * y
        return k * x, k * y + 1.0, k * z
    if kind == PANO_FISHEYE_EQUIDISTANT:
        x = (u - 0.5) * 2.0
        y = (v - 0.5) * 2.0
        r = math.sqrt(x * x + y * y)
        if r > 1.0:
            return 0.0, 0.0, 0.0
        return _fisheye_direction(r * pano[PANO_FOV] * 0.5, x, y, r)
    x = (u - 0.5) * pano[PANO_SENSOR_W]
    y = (v - 0.5) * pano[PANO_SENSOR_H]
    r = math.sqrt(x * x + y * y)
    if kind == PANO_FISHEYE_EQUISOLID:
        lens = pano[PANO_LENS]
        if r > 2.0 * lens * math.sin(pano[PANO_FOV] * 0.25):
            return 0.0, 0.0, 0.0
        return _fisheye_direction(2.0 * math.asin(min(r / (2.0 * lens), 1.0)), x, y, r)
    # the polynomial lens: theta = −(k0 + k1·r + k2·r² + k3·r³ + k4·r⁴), r in mm
    r2 = r * r
    theta = -(pano[PANO_K] + pano[PANO_K + 1] * r + pano[PANO_K + 2] * r2 + pano[PANO_K + 3] * r2 * r
              + pano[PANO_K + 4] * r2 * r2)
    if abs(theta) > 0.5 * pano[PANO_FOV]:
        return 0.0, 0.0, 0.0
    return _fisheye_direction(theta, x, y, r)


@inline_kernel
def panorama_lens(d, lx, ly, focus):
    """Depth of field of a panoramic camera, as Cycles's: the lens point (lx, ly) lies in the
    plane through the camera perpendicular to the pinhole direction ``d`` (unit, panoramic
    camera space), on axes (U, V) with U the +x axis made perpendicular to ``d``; the ray aims
    at d·focus. Returns (origin, unit direction) in panoramic camera space."""
    ux, uy, uz = 1.0 - d[0] * d[0], -d[0] * d[1], -d[0] * d[2]
    n = math.sqrt(ux * ux + uy * uy + uz * uz)
    if n < 1e-12:  # d along ±x: any perpendicular axis will do
        ux, uy, uz, n = 0.0, 1.0, 0.0, 1.0
    ux, uy, uz = ux / n, uy / n, uz / n
    vx = d[1] * uz - d[2] * uy
    vy = d[2] * ux - d[0] * uz
    vz = d[0] * uy - d[1] * ux
    n = math.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx / n, vy / n, vz / n
    px, py, pz = ux * lx + vx * ly, uy * lx + vy * ly, uz * lx + vz * ly
    wx, wy, wz = d[0] * focus - px, d[1] * focus - py, d[2] * focus - pz
    n = 1.0 / math.sqrt(wx * wx + wy * wy + wz * wz)
    return (px, py, pz), (wx * n, wy * n, wz * n)


@inline_kernel
def to_blender_camera(kind, a):
    """A vector of Cycles's panoramic camera space in Blender's camera space (Cycles's
    ``blender_camera_matrix``: the view axis +x, or −y for the mirror ball, becomes −Z)."""
    if kind == PANO_MIRRORBALL:
        return a[0], a[2], a[1]
    return -a[1], a[2], -a[0]
