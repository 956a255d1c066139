"""Area lights: one-sided Lambertian emitters (rectangle, square, disk, ellipse) with Cycles's spread.

Power P (× color) watts leaves the *front* side, which faces the light's local −Z. The radiance is
L = P / (π A), where A uses the object-scaled sizes: ``size`` along local X and ``size_y`` along
local Y (SQUARE and DISK use ``size`` for both), A = a·b for rectangles and π·a·b/4 for disks and
ellipses (the sizes are diameters). The back side emits nothing but still stops light rays
(`intersect` hits it from both sides, radiance 0).

``spread`` s < π narrows the emission: L(θ) = L · max(tan h − tan θ, 0) / (tan h − h), h = s/2,
θ the angle from the emission normal; Cycles normalizes it so that the power is preserved.

Sampling: rectangles with s = π by solid angle (Ureña, Fajardo, King 2013, "An area-preserving
parametrization for spherical rectangles"; its solid angle by one atan2 and its angle k
algebraically, see `_spherical_rect`), falling back to area sampling when the subtended
solid angle is below 1e-7 sr (where the spherical-rectangle formulas lose precision); everything
else (disks, ellipses, spread < π) uniformly by area. `pdf` applies exactly the same rule.
"""

from __future__ import annotations

import math

import numpy as np

from . import _warps
from .common import AREA, T_EPSILON, camera_visible, light_frame, luminance, scalar_kernel, unit
from ..kernels.vec3 import dot, sub
from .common import I_IS_ELLIPSE, I_PLAIN, I_SOLID_ANGLE, L_AREA, L_CORNER, L_EX, L_EY, L_EZ, L_HALF_SPREAD, L_LEN_X, L_LEN_Y, L_NORMAL, L_POS, L_RADIANCE, L_SPREAD_NORM, L_TAN_HALF  # noqa: F401 (table columns)
from ..kernels.vec3 import load_col3
from ..sampling.trig import sincos

#: Below this solid angle (sr) rectangles are sampled by area instead of solid angle.
MIN_SOLID_ANGLE = 1e-7

_INF = math.inf
_TWO_PI = 2.0 * np.pi


class AreaLight:
    """A Blender AREA light."""

    kind = AREA

    def __init__(self, light: dict, origin_shift=(0.0, 0.0, 0.0)):
        self.center, basis = light_frame(light["matrix_world"], origin_shift)
        shape = str(light.get("shape", "SQUARE")).upper()
        size = float(light.get("size", 1.0))
        size_y = float(light.get("size_y", size))
        scale_x = float(np.linalg.norm(basis[:, 0]))
        scale_y = float(np.linalg.norm(basis[:, 1]))
        self.ex = unit(basis[:, 0])
        ey = basis[:, 1] - (basis[:, 1] @ self.ex) * self.ex      # orthogonalize (shear ignored)
        self.ey = unit(ey)
        self.ez = np.cross(self.ex, self.ey)
        self.normal = -unit(basis[:, 2])                           # emission direction
        self.is_ellipse = shape in ("DISK", "ELLIPSE")
        self.len_x = size * scale_x
        self.len_y = (size if shape in ("SQUARE", "DISK") else size_y) * scale_y
        self.area = (np.pi * 0.25 if self.is_ellipse else 1.0) * self.len_x * self.len_y
        self.color = np.asarray(light.get("color", (1.0, 1.0, 1.0)), dtype=np.float64)
        power = float(light.get("power", 0.0))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a zero- or denormal-size light: inf, never hit
            self.radiance = self.color * power / (np.pi * self.area)   # W/(m² sr) on the normal
        spread = float(light.get("spread", np.pi))
        self.plain = spread >= np.pi - 1e-6
        self.half_spread = 0.5 * spread
        self.tan_half = self.spread_norm = 0.0
        if not self.plain and self.half_spread > 1e-6:
            self.tan_half = float(np.tan(self.half_spread))
            self.spread_norm = 1.0 / (self.tan_half - self.half_spread)
        self.solid_angle_sampling = self.plain and not self.is_ellipse
        # the corner the spherical-rectangle sampler starts from
        self.corner = self.center - 0.5 * self.len_x * self.ex - 0.5 * self.len_y * self.ey
        self.is_delta = False
        self.visible_to_camera = camera_visible(light)
        self.power = float(power * luminance(self.color))

    def _store(self, a: dict, i: int) -> None:
        """Write this light's parameters into row i of the `LightData` arrays."""
        a["kind"][i] = AREA
        a["is_delta"][i] = False
        a["visible_camera"][i] = self.visible_to_camera
        a["pos"][i] = self.center
        a["radiance"][i] = self.radiance
        for name in ("ex", "ey", "ez", "normal", "corner", "len_x", "len_y", "area",
                     "is_ellipse", "plain", "half_spread", "tan_half", "spread_norm"):
            a[name][i] = getattr(self, name)
        a["solid_angle"][i] = self.solid_angle_sampling

    # --- the per-light protocol (thin wrappers over the kernels, see common.py) -------------
    def sample(self, p, n, u2):
        from .light_set import header_light_sample
        return header_light_sample(self, p, n, u2)

    def intersect(self, o, d):
        from .light_set import header_light_intersect
        return header_light_intersect(self, o, d)

    def hit_radiance(self, o, d, t):
        from .light_set import header_light_hit_radiance
        return header_light_hit_radiance(self, o, d, t)

    def pdf(self, o, d, t):
        from .light_set import header_light_pdf
        return header_light_pdf(self, o, d, t)


# ----------------------------------------------------------------------------------- kernels
@scalar_kernel
def _emission(ld, i, cos_e):
    """Radiance factor of light i for a direction leaving it at cos θ = cos_e."""
    front = cos_e > 0.0
    if (ld.li[i, I_PLAIN] != 0):
        return 1.0 if front else 0.0
    if ld.lf[i, L_HALF_SPREAD] <= 1e-6:
        return 0.0          # spread 0 (a collimated beam) is not supported
    if not front:
        return 0.0
    tan_e = math.sqrt(max(1.0 - cos_e * cos_e, 0.0)) / cos_e
    return max(ld.lf[i, L_TAN_HALF] - tan_e, 0.0) * ld.lf[i, L_SPREAD_NORM]


@scalar_kernel
def _clip(x, lo, hi):
    """np.clip for one value (NaN stays NaN)."""
    if x < lo:
        x = lo
    if x > hi:
        x = hi
    return x


@scalar_kernel
def _rect_local(ld, i, o):
    """The rectangle in its frame seen from o: (x0, y0, z0, x1, y1, zsign), o at the origin,
    the rectangle in the plane z = z0 ≤ 0 spanning [x0, x1] × [y0, y1]; zsign maps that local z
    back to the light's ez (Ureña et al.'s frame: local z points away from the rectangle)."""
    dv = sub(load_col3(ld.lf, i, L_CORNER), o)
    x0 = dot(dv, load_col3(ld.lf, i, L_EX))
    y0 = dot(dv, load_col3(ld.lf, i, L_EY))
    z0 = dot(dv, load_col3(ld.lf, i, L_EZ))
    zsign = -1.0 if z0 > 0.0 else 1.0
    z0 = -abs(z0)
    return x0, y0, z0, x0 + ld.lf[i, L_LEN_X], y0 + ld.lf[i, L_LEN_Y], zsign


@scalar_kernel
def _rect_solid_angle(ld, i, x0, y0, z0, x1, y1):
    """(S, R00, R01): the solid angle (sr) of the rectangle [x0, x1] × [y0, y1] at z = z0 seen
    from the origin, and the distances to its corners (x0, y0) and (x0, y1).

    Van Oosterom & Strackee (1983) for its two triangles (v00, v10, v11) and (v00, v11, v01):
    tan(Ω/2) = N / D with N = |det(a, b, c)| = |z0|·lx·ly for both and
    D = |a||b||c| + (a·b)|c| + (a·c)|b| + (b·c)|a|; the half angles add as the arguments of
    D + iN, and S/2 < π (a convex polygon on one side of a plane), so one atan2 gives S exactly
    — the same value as Ureña et al.'s g0 + g1 + g2 + g3 − 2π (four acos) without its
    cancellation for small S."""
    z2 = z0 * z0
    r00 = math.sqrt(x0 * x0 + y0 * y0 + z2)
    r10 = math.sqrt(x1 * x1 + y0 * y0 + z2)
    r11 = math.sqrt(x1 * x1 + y1 * y1 + z2)
    r01 = math.sqrt(x0 * x0 + y1 * y1 + z2)
    d_00_10 = x0 * x1 + y0 * y0 + z2
    d_00_11 = x0 * x1 + y0 * y1 + z2
    d_10_11 = x1 * x1 + y0 * y1 + z2
    d_00_01 = x0 * x0 + y0 * y1 + z2
    d_11_01 = x0 * x1 + y1 * y1 + z2
    big_n = -z0 * ld.lf[i, L_LEN_X] * ld.lf[i, L_LEN_Y]
    d1 = r00 * r10 * r11 + d_00_10 * r11 + d_00_11 * r10 + d_10_11 * r00
    d2 = r00 * r11 * r01 + d_00_11 * r01 + d_00_01 * r11 + d_11_01 * r00
    half = math.atan2(big_n * (d1 + d2), d1 * d2 - big_n * big_n)
    if half < 0.0:
        # S/2 ∈ (0, π): a negative result is round-off of the imaginary part (or −0.0) at
        # S/2 ≈ π (a point just off the light's plane, inside its outline): −π + ε → π + ε
        half += _TWO_PI
    return 2.0 * half, r00, r01


@scalar_kernel
def _spherical_rect(ld, i, o):
    """The rectangle seen from o (Ureña, Fajardo, King 2013): (x0, y0, z0, x1, y1, zsign, b0, b1,
    cos k, sin k, S) with S its solid angle and k = 2π − g2 − g3 (g the spherical rectangle's
    inner angles), all algebraic but S (one atan2, `_rect_solid_angle`): with the normals
    n0 = (0, z0, −y0)/r_y0, n2 = (0, −z0, y1)/r_y1, n3 = (z0, 0, −x0)/r_x0 of the paper,
    b0 = n0.z, b1 = n2.z, cos g = −n·n', sin g = |n × n'| = |z0|·|corner|/(r·r')."""
    x0, y0, z0, x1, y1, zsign = _rect_local(ld, i, o)
    solid_angle, r00, r01 = _rect_solid_angle(ld, i, x0, y0, z0, x1, y1)
    z2 = z0 * z0
    ry0 = math.sqrt(y0 * y0 + z2)
    ry1 = math.sqrt(y1 * y1 + z2)
    rx0_2 = x0 * x0 + z2
    # e^{i(g2 + g3)} with cos g2 = x0·y1/(r_y1 r_x0), sin g2 = |z0|·r01/(r_y1 r_x0),
    # cos g3 = −x0·y0/(r_x0 r_y0), sin g3 = |z0|·r00/(r_x0 r_y0); k = 2π − (g2 + g3)
    inv = 1.0 / (ry0 * ry1 * rx0_2)
    az = -z0
    cos_k = (-(x0 * x0) * y0 * y1 - z2 * r00 * r01) * inv
    sin_k = -(az * x0 * (y1 * r00 - y0 * r01)) * inv
    return (x0, y0, z0, x1, y1, zsign, -y0 / ry0, y1 / ry1, cos_k, sin_k, solid_angle)


@scalar_kernel
def _use_solid_angle(solid_angle, z0):
    return solid_angle > MIN_SOLID_ANGLE and z0 < 0.0


@scalar_kernel
def _sample_spherical_rect(ld, i, u0, u1, sr):
    """A direction toward the rectangle by solid angle (Ureña et al.), from the frame `_spherical_rect`
    gave: (wi, dist), wi the unit world-space direction from the shading point, dist the distance
    to the rectangle along it.

    The sampled point's local coordinates (xu, yv, z0) are never added to the shading point to be
    subtracted again: wi comes straight from the paper's quantities. Its y component is hv (the
    sine of the point's elevation over the xz plane), its xz part points along (xu, z0) with
    length √(1 − hv²), and dist = dd/√(1 − hv²) with dd = |(xu, z0)|. Every square root and
    division here waits for the one before (~15–20 cycles each in double precision); this way
    the chain has five of them where the paper's point followed by a normalisation had nine."""
    x0, y0, z0, x1, y1, zsign, b0, b1, cos_k, sin_k, solid_angle = sr
    # au = u0·S + k by the angle sum: one sincos instead of cos and sin of k + u0·S
    s_u, c_u = sincos(u0 * solid_angle)
    cos_au = c_u * cos_k - s_u * sin_k
    sin_au = s_u * cos_k + c_u * sin_k
    # fu = num/den (the paper's); the paper's cu = sign/√(fu² + b0²) and xu = −cu·z0/√(1 − cu²)
    # fold into one root with 1 − b0² = z0²/(y0² + z0²): xu = −sign·z0/√(fu² − z0²/(y0² + z0²)),
    # and multiplying through by den² takes fu's division off the chain
    num = cos_au * b0 - b1
    den = sin_au
    if num > 0.0:
        sign = 1.0
    elif num < 0.0:
        sign = -1.0
    else:
        sign = 0.0   # fu = 0 (or NaN): xu = 0
    if den < 0.0:
        sign = -sign
    q = num * num - (z0 * z0 / (y0 * y0 + z0 * z0)) * (den * den)
    if q > 0.0:
        xu = -(sign * z0) * abs(den) / math.sqrt(q)
    else:
        xu = -(sign * z0) * 1e300  # |cu| ≥ 1: the edge the paper clips cu to
    if xu != xu:
        xu = 0.0
    xu = _clip(xu, x0, x1)
    dd2 = xu * xu + z0 * z0
    inv_dd = 1.0 / math.sqrt(dd2)  # (beside the chain: z0 < 0, so dd > 0)
    h0 = y0 / math.sqrt(dd2 + y0 ** 2)
    h1 = y1 / math.sqrt(dd2 + y1 ** 2)
    hv = h0 + u1 * (h1 - h0)
    hv2 = hv * hv
    if hv2 < 1.0 - 1e-12:
        c = math.sqrt(1.0 - hv2)
        s = c * inv_dd
        lx, ly, lz = xu * s, hv, z0 * zsign * s
        dist = dd2 * inv_dd / c
    else:  # the paper's yv = y1 at |hv| → 1
        dist = math.sqrt(dd2 + y1 * y1)
        inv = 1.0 / dist
        lx, ly, lz = xu * inv, y1 * inv, z0 * zsign * inv
    return ((lx * ld.lf[i, L_EX + 0] + ly * ld.lf[i, L_EY + 0] + lz * ld.lf[i, L_EZ + 0],
             lx * ld.lf[i, L_EX + 1] + ly * ld.lf[i, L_EY + 1] + lz * ld.lf[i, L_EZ + 1],
             lx * ld.lf[i, L_EX + 2] + ly * ld.lf[i, L_EY + 2] + lz * ld.lf[i, L_EZ + 2]), dist)


@scalar_kernel
def _area_point(ld, i, u0, u1):
    if (ld.li[i, I_IS_ELLIPSE] != 0):
        x, y = _warps.disk_concentric(u0, u1)
        x *= 0.5 * ld.lf[i, L_LEN_X]
        y *= 0.5 * ld.lf[i, L_LEN_Y]
    else:
        x = (u0 - 0.5) * ld.lf[i, L_LEN_X]
        y = (u1 - 0.5) * ld.lf[i, L_LEN_Y]
    return (ld.lf[i, L_POS + 0] + x * ld.lf[i, L_EX + 0] + y * ld.lf[i, L_EY + 0],
            ld.lf[i, L_POS + 1] + x * ld.lf[i, L_EX + 1] + y * ld.lf[i, L_EY + 1],
            ld.lf[i, L_POS + 2] + x * ld.lf[i, L_EX + 2] + y * ld.lf[i, L_EY + 2])


@scalar_kernel
def _pdf_given(ld, i, d, t, use_sr, solid_angle):
    if use_sr:
        return 1.0 / solid_angle
    cos_l = abs(dot(d, load_col3(ld.lf, i, L_NORMAL)))
    return t * t / (ld.lf[i, L_AREA] * cos_l)


@scalar_kernel
def area_sample(ld, i, p, u0, u1):
    """Area light i from p: (wi, dist, radiance, pdf, valid) (pdf without selection). Rectangles
    with spread π by solid angle (area sampling where it is tiny or edge-on), else by area."""
    use = False
    solid_angle = 0.0
    if (ld.li[i, I_SOLID_ANGLE] != 0):
        sr = _spherical_rect(ld, i, p)
        solid_angle = sr[10]
        use = _use_solid_angle(solid_angle, sr[2])
        if use:
            wi, dist = _sample_spherical_rect(ld, i, u0, u1, sr)
        else:
            wi, dist = _warps.normalize(sub(_area_point(ld, i, u0, u1), p))
    else:
        wi, dist = _warps.normalize(sub(_area_point(ld, i, u0, u1), p))
    pdf = _pdf_given(ld, i, wi, dist, use, solid_angle)
    cos_e = -dot(wi, load_col3(ld.lf, i, L_NORMAL))
    e = _emission(ld, i, cos_e)
    radiance = (ld.lf[i, L_RADIANCE + 0] * e, ld.lf[i, L_RADIANCE + 1] * e, ld.lf[i, L_RADIANCE + 2] * e)
    peak = max(radiance[0], max(radiance[1], radiance[2]))
    valid = (cos_e > 0.0 and peak > 0.0 and math.isfinite(pdf) and pdf > 0.0
             and radiance[0] == radiance[0] and radiance[1] == radiance[1]
             and radiance[2] == radiance[2])
    return wi, dist, radiance, pdf, valid


@scalar_kernel
def area_intersect(ld, i, o, d):
    """Distance to area light i along the unit ray, inf on a miss; like Cycles, an area light
    does not exist seen from behind: rays pass through it."""
    normal = load_col3(ld.lf, i, L_NORMAL)
    denom = dot(d, normal)
    # every shading point tests every shape light this way, so the common misses leave early:
    # a ray leaving the light's back side (half of all directions), then one behind the origin
    if not denom < 0.0:
        return _INF
    center = load_col3(ld.lf, i, L_POS)
    oc = sub(o, center)
    num = -dot(oc, normal)  # t = num/denom
    if not num < 0.0:  # the plane is behind the origin (or the origin is in it)
        return _INF
    # the hit point relative to the centre, times −denom > 0: −denom·(oc + t·d), so that a
    # miss (most rays) costs no division
    s = -denom
    x = (oc[0] * s - num * d[0], oc[1] * s - num * d[1], oc[2] * s - num * d[2])
    a = 2.0 * dot(x, load_col3(ld.lf, i, L_EX))
    b = 2.0 * dot(x, load_col3(ld.lf, i, L_EY))
    len_x = ld.lf[i, L_LEN_X] * s
    len_y = ld.lf[i, L_LEN_Y] * s
    if (ld.li[i, I_IS_ELLIPSE] != 0):
        lx = a / len_x
        ly = b / len_y
        inside = lx * lx + ly * ly <= 1.0
    else:  # |a / len| <= 1 without the two divisions
        inside = abs(a) <= len_x and abs(b) <= len_y and len_x > 0.0 and len_y > 0.0
    if not inside:
        return _INF
    t = num / denom
    return t if math.isfinite(t) and t > T_EPSILON else _INF


@scalar_kernel
def area_hit_radiance(ld, i, o, d):
    e = _emission(ld, i, -dot(d, load_col3(ld.lf, i, L_NORMAL)))
    return (ld.lf[i, L_RADIANCE + 0] * e, ld.lf[i, L_RADIANCE + 1] * e, ld.lf[i, L_RADIANCE + 2] * e)


@scalar_kernel
def area_pdf(ld, i, o, d, t):
    """Solid-angle pdf of `area_sample` from o producing d (the light hit at distance t)."""
    if (ld.li[i, I_SOLID_ANGLE] != 0):
        # only S is needed: four square roots and one atan2
        x0, y0, z0, x1, y1, _ = _rect_local(ld, i, o)
        solid_angle = _rect_solid_angle(ld, i, x0, y0, z0, x1, y1)[0]
        return _pdf_given(ld, i, d, t, _use_solid_angle(solid_angle, z0), solid_angle)
    return _pdf_given(ld, i, d, t, False, 0.0)
