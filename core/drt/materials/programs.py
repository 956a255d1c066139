"""Material programs: the interpreter half of docs/materials.md (Cycles's SVM as the model).

A material whose node tree has textures is exported with a *program*: a flat list of operations
over a register file, plus the registers that give, per lobe, its colour (weight) and roughness
and the material's emission. At a shading point ``eval_material`` runs the program and writes
the results into that material's row of a *per-thread copy* of ``MaterialData`` (lobe colour,
alpha, selection probabilities, emission and the derived flags), so that ``bsdf_eval`` /
``bsdf_sample`` and the rest of the shade stage run unchanged. The light-selection summary stays
the material's constant one (a hint; NEE and BSDF-hit MIS must see the same one).

Registers hold three float64; a float is stored replicated in all three. One operation is a row
of ``ops`` (int64):

    [opcode, mode, out0, out1, in0, in1, in2, in3, in4, in5, param]

ins/outs are register indices (−1: unused); ``param`` indexes ``data`` (colour-ramp tables) or
the image table, or carries a flag (clamp). Every node is evaluated as Cycles's SVM evaluates it
(``intern/cycles/kernel/svm/*.h``), in float64 instead of float32.

Images: ``img_info`` (I, 5) int64 rows [width, height, offset, is_float, srgb]; byte images live
in ``img_u8`` (uint8 RGBA, bottom row first), float images in ``img_f32``. sRGB images (8-bit,
or float tagged sRGB) are interpolated sRGB-encoded and converted to linear after the lookup,
as Cycles does (``NODE_IMAGE_COMPRESS_AS_SRGB``).

Geometry inputs (per global triangle, per corner, interpolated with Embree's barycentrics):
``uv`` (T, 3, 2) the active render UV map, ``generated`` (T, 3, 3) Blender's Generated
coordinates (texture space → [0, 1]³), ``objco`` (T, 3, 3) object-space positions; (0, 3, k)
when no program reads them.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import inline_kernel, kernel
from .dielectric import IOR_ONE_EPS
from .dielectric_specular import glass_select_weight, specular_eta_f0
from .ggx import ALPHA_SQ_SINGULAR
from .procedural import floor64, procedural_op
from .program_format import (LUMINANCE, POINT_GENERATED, POINT_I, POINT_MISC, POINT_N, POINT_NG, POINT_NSMOOTH,
                             POINT_OBJECT, POINT_UV, POINT_XFORM, OP_FRESNEL, OP_LAYER_WEIGHT,
                             OP_BUMP, OP_BUMP_OFFSET, OP_CAMERA_COORDS, OP_NORMAL_MAP, OP_OBJECT_INFO, OP_POINT, POINT_P, OP_AVERAGE, OP_BRIGHT_CONTRAST, OP_CHECKER, OP_CLAMP,
                             OP_COMBINE, OP_COMPONENT, OP_GAMMA, OP_GENERATED, OP_GRADIENT,
                             OP_HSV, OP_HSV_TO_RGB, OP_IMAGE, OP_INVERT, OP_MAP_RANGE,
                             OP_ATTRIBUTE, OP_MAPPING, OP_MATH, OP_MIX, OP_OBJECT, OP_RAMP, OP_RGB_TO_HSV,
                             OP_TO_GRAY, OP_UV, OP_VMATH, RAMP_TABLE_SIZE, OP_ENVIRONMENT, OP_IMAGE_BOX,
                             IMAGE_PROJECTION_STRIDE,
                             ENV_PROJECTION_STRIDE, OP_DISPLACEMENT, OP_SET_NORMAL, OP_TEXCO_NORMAL,
                             OP_VECTOR_DISPLACEMENT, POINT_OBJECT_XFORM)
from ..sampling.spherical_maps import direction_to_uv


# --- helpers (Cycles's util/math.h semantics) ---------------------------------------------------

@kernel
def safe_divide(a, b):
    return a / b if b != 0.0 else 0.0


@kernel
def fract(x):
    return x - floor64(x)


@kernel
def compatible_pow(x, y):
    if x < 0.0:
        if np.fmod(-y, 2.0) == 0.0:
            return math.pow(-x, y)
        return -math.pow(-x, y)
    if x == 0.0:
        return 0.0
    return math.pow(x, y)


@kernel
def safe_pow(a, b):
    if a < 0.0 and b != float(int(b)):
        return 0.0
    return compatible_pow(a, b)


@kernel
def safe_log(a, b):
    if a <= 0.0 or b <= 0.0:
        return 0.0
    return safe_divide(math.log(a), math.log(b))


@kernel
def safe_modulo(a, b):
    return np.fmod(a, b) if b != 0.0 else 0.0


@kernel
def wrapf(value, vmax, vmin):
    r = vmax - vmin
    return value - r * floor64((value - vmin) / r) if r != 0.0 else vmin


@kernel
def pingpong(a, b):
    return abs(fract((a - b) / (b * 2.0)) * b * 2.0 - b) if b != 0.0 else 0.0


@kernel
def smoothmin(a, b, c):
    if c != 0.0:
        h = max(c - abs(a - b), 0.0) / c
        return min(a, b) - h * h * h * c * (1.0 / 6.0)
    return min(a, b)


@kernel
def saturate(x):
    return min(max(x, 0.0), 1.0)


@kernel
def math_op(op, a, b, c):
    """Cycles's ``svm_math`` (NodeMathType in Blender's enum order)."""
    if op == 0:
        return a + b
    if op == 1:
        return a - b
    if op == 2:
        return a * b
    if op == 3:
        return safe_divide(a, b)
    if op == 4:
        return a * b + c
    if op == 5:
        return safe_pow(a, b)
    if op == 6:
        return safe_log(a, b)
    if op == 7:
        return math.sqrt(a) if a > 0.0 else 0.0
    if op == 8:
        return 1.0 / math.sqrt(a) if a > 0.0 else 0.0
    if op == 9:
        return abs(a)
    if op == 10:
        return math.exp(a)
    if op == 11:
        return min(a, b)
    if op == 12:
        return max(a, b)
    if op == 13:
        return 1.0 if a < b else 0.0
    if op == 14:
        return 1.0 if a > b else 0.0
    if op == 15:
        return 1.0 if a > 0.0 else (-1.0 if a < 0.0 else 0.0)
    if op == 16:
        return 1.0 if (a == b or abs(a - b) <= max(c, 1.1920929e-07)) else 0.0
    if op == 17:
        return smoothmin(a, b, c)
    if op == 18:
        return -smoothmin(-a, -b, c)
    if op == 19:
        return floor64(a + 0.5)
    if op == 20:
        return floor64(a)
    if op == 21:
        return np.ceil(a)
    if op == 22:
        return floor64(a) if a >= 0.0 else np.ceil(a)
    if op == 23:
        return a - floor64(a)
    if op == 24:
        return safe_modulo(a, b)
    if op == 25:
        return a - floor64(a / b) * b if b != 0.0 else 0.0
    if op == 26:
        return wrapf(a, b, c)
    if op == 27:
        return floor64(safe_divide(a, b)) * b
    if op == 28:
        return pingpong(a, b)
    if op == 29:
        return math.sin(a)
    if op == 30:
        return math.cos(a)
    if op == 31:
        return math.tan(a)
    if op == 32:
        return math.asin(min(max(a, -1.0), 1.0))
    if op == 33:
        return math.acos(min(max(a, -1.0), 1.0))
    if op == 34:
        return math.atan(a)
    if op == 35:
        return math.atan2(a, b)
    if op == 36:
        return math.sinh(a)
    if op == 37:
        return math.cosh(a)
    if op == 38:
        return math.tanh(a)
    if op == 39:
        return a * (math.pi / 180.0)
    if op == 40:
        return a * (180.0 / math.pi)
    return 0.0


@kernel
def _safe_div3(a, b):
    return (safe_divide(a[0], b[0]), safe_divide(a[1], b[1]), safe_divide(a[2], b[2]))


@kernel
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@kernel
def _len(a):
    return math.sqrt(_dot(a, a))


@kernel
def _normalize(a):
    n = _len(a)
    return (a[0] / n, a[1] / n, a[2] / n) if n != 0.0 else (0.0, 0.0, 0.0)


@kernel
def _sign(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@kernel
def vmath_op(op, a, b, c, s):
    """Cycles's ``svm_vector_math`` (NodeVectorMathType in Blender's enum order); a float result
    is returned replicated."""
    if op == 0:
        return (a[0] + b[0], a[1] + b[1], a[2] + b[2])
    if op == 1:
        return (a[0] - b[0], a[1] - b[1], a[2] - b[2])
    if op == 2:
        return (a[0] * b[0], a[1] * b[1], a[2] * b[2])
    if op == 3:
        return _safe_div3(a, b)
    if op == 4:
        return (a[0] * b[0] + c[0], a[1] * b[1] + c[1], a[2] * b[2] + c[2])
    if op == 5:
        return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    if op == 6:
        bb = _dot(b, b)
        f = _dot(a, b) / bb if bb != 0.0 else 0.0
        return (b[0] * f, b[1] * f, b[2] * f)
    if op == 7:
        n = _normalize(b)
        d = 2.0 * _dot(a, n)
        return (a[0] - d * n[0], a[1] - d * n[1], a[2] - d * n[2])
    if op == 8:
        d = _dot(a, b)
        return (d, d, d)
    if op == 9:
        d = _len((a[0] - b[0], a[1] - b[1], a[2] - b[2]))
        return (d, d, d)
    if op == 10:
        d = _len(a)
        return (d, d, d)
    if op == 11:
        return (a[0] * s, a[1] * s, a[2] * s)
    if op == 12:
        return _normalize(a)
    if op == 13:
        return (abs(a[0]), abs(a[1]), abs(a[2]))
    if op == 14:
        return (min(a[0], b[0]), min(a[1], b[1]), min(a[2], b[2]))
    if op == 15:
        return (max(a[0], b[0]), max(a[1], b[1]), max(a[2], b[2]))
    if op == 16:
        return (floor64(a[0]), floor64(a[1]), floor64(a[2]))
    if op == 17:
        return (np.ceil(a[0]), np.ceil(a[1]), np.ceil(a[2]))
    if op == 18:
        return (fract(a[0]), fract(a[1]), fract(a[2]))
    if op == 19:
        return (safe_modulo(a[0], b[0]), safe_modulo(a[1], b[1]), safe_modulo(a[2], b[2]))
    if op == 20:
        return (wrapf(a[0], b[0], c[0]), wrapf(a[1], b[1], c[1]), wrapf(a[2], b[2], c[2]))
    if op == 21:
        return (floor64(safe_divide(a[0], b[0])) * b[0], floor64(safe_divide(a[1], b[1])) * b[1],
                floor64(safe_divide(a[2], b[2])) * b[2])
    if op == 22:
        return (math.sin(a[0]), math.sin(a[1]), math.sin(a[2]))
    if op == 23:
        return (math.cos(a[0]), math.cos(a[1]), math.cos(a[2]))
    if op == 24:
        return (math.tan(a[0]), math.tan(a[1]), math.tan(a[2]))
    if op == 25:
        return (safe_pow(a[0], b[0]), safe_pow(a[1], b[1]), safe_pow(a[2], b[2]))
    if op == 26:
        return (_sign(a[0]), _sign(a[1]), _sign(a[2]))
    return (0.0, 0.0, 0.0)


@kernel
def rgb_to_hsv(rgb):
    r, g, b = rgb
    cmax = max(r, max(g, b))
    cmin = min(r, min(g, b))
    cdelta = cmax - cmin
    v = cmax
    h = 0.0
    s = cdelta / cmax if cmax != 0.0 else 0.0
    if s != 0.0:
        cr, cg, cb = (cmax - r) / cdelta, (cmax - g) / cdelta, (cmax - b) / cdelta
        if r == cmax:
            h = cb - cg
        elif g == cmax:
            h = 2.0 + cr - cb
        else:
            h = 4.0 + cg - cr
        h /= 6.0
        if h < 0.0:
            h += 1.0
    return (h, s, v)


@kernel
def hsv_to_rgb(hsv):
    h, s, v = hsv
    if s == 0.0:
        return (v, v, v)
    if h == 1.0:
        h = 0.0
    h *= 6.0
    i = floor64(h)
    f = h - i
    p = v * (1.0 - s)
    q = v * (1.0 - s * f)
    t = v * (1.0 - s * (1.0 - f))
    if i == 0.0:
        return (v, t, p)
    if i == 1.0:
        return (q, v, p)
    if i == 2.0:
        return (p, v, t)
    if i == 3.0:
        return (p, q, v)
    if i == 4.0:
        return (t, p, v)
    return (v, p, q)


@kernel
def _lerp3(a, b, t):
    return ((1.0 - t) * a[0] + t * b[0], (1.0 - t) * a[1] + t * b[1], (1.0 - t) * a[2] + t * b[2])


@kernel
def _dodge(c1, c2, t):
    if c1 != 0.0:
        tmp = 1.0 - t * c2
        if tmp <= 0.0:
            return 1.0
        tmp = c1 / tmp
        return 1.0 if tmp > 1.0 else tmp
    return c1


@kernel
def _burn(c1, c2, t):
    tmp = (1.0 - t) + t * c2
    if tmp <= 0.0:
        return 0.0
    tmp = 1.0 - (1.0 - c1) / tmp
    if tmp < 0.0:
        return 0.0
    return 1.0 if tmp > 1.0 else tmp


@kernel
def _overlay(c1, c2, t):
    tm = 1.0 - t
    if c1 < 0.5:
        return c1 * (tm + 2.0 * t * c2)
    return 1.0 - (tm + 2.0 * t * (1.0 - c2)) * (1.0 - c1)


@kernel
def _divide(c1, c2, t):
    return (1.0 - t) * c1 + t * c1 / c2 if c2 != 0.0 else c1


@kernel
def _soft_light(c1, c2, t):
    scr = 1.0 - (1.0 - c2) * (1.0 - c1)
    return (1.0 - t) * c1 + t * ((1.0 - c1) * c2 * c1 + c1 * scr)


@kernel
def mix_blend(mode, t, c1, c2):
    """Cycles's ``svm_mix`` colour blend modes (NodeMix in Blender's enum order), factor t."""
    tm = 1.0 - t
    if mode == 0:
        return _lerp3(c1, c2, t)
    if mode == 1:
        return _lerp3(c1, (min(c1[0], c2[0]), min(c1[1], c2[1]), min(c1[2], c2[2])), t)
    if mode == 2:
        return (c1[0] * (tm + t * c2[0]), c1[1] * (tm + t * c2[1]), c1[2] * (tm + t * c2[2]))
    if mode == 3:
        return (_burn(c1[0], c2[0], t), _burn(c1[1], c2[1], t), _burn(c1[2], c2[2], t))
    if mode == 4:
        return _lerp3(c1, (max(c1[0], c2[0]), max(c1[1], c2[1]), max(c1[2], c2[2])), t)
    if mode == 5:
        return (1.0 - (tm + t * (1.0 - c2[0])) * (1.0 - c1[0]),
                1.0 - (tm + t * (1.0 - c2[1])) * (1.0 - c1[1]),
                1.0 - (tm + t * (1.0 - c2[2])) * (1.0 - c1[2]))
    if mode == 6:
        return (_dodge(c1[0], c2[0], t), _dodge(c1[1], c2[1], t), _dodge(c1[2], c2[2], t))
    if mode == 7:
        return (c1[0] + t * c2[0], c1[1] + t * c2[1], c1[2] + t * c2[2])
    if mode == 8:
        return (_overlay(c1[0], c2[0], t), _overlay(c1[1], c2[1], t), _overlay(c1[2], c2[2], t))
    if mode == 9:
        return (_soft_light(c1[0], c2[0], t), _soft_light(c1[1], c2[1], t),
                _soft_light(c1[2], c2[2], t))
    if mode == 10:
        return (c1[0] + t * (2.0 * c2[0] - 1.0), c1[1] + t * (2.0 * c2[1] - 1.0),
                c1[2] + t * (2.0 * c2[2] - 1.0))
    if mode == 11:
        return (tm * c1[0] + t * abs(c1[0] - c2[0]), tm * c1[1] + t * abs(c1[1] - c2[1]),
                tm * c1[2] + t * abs(c1[2] - c2[2]))
    if mode == 12:
        return (max(tm * c1[0] + t * (c1[0] + c2[0] - 2.0 * c1[0] * c2[0]), 0.0),
                max(tm * c1[1] + t * (c1[1] + c2[1] - 2.0 * c1[1] * c2[1]), 0.0),
                max(tm * c1[2] + t * (c1[2] + c2[2] - 2.0 * c1[2] * c2[2]), 0.0))
    if mode == 13:
        return (c1[0] - t * c2[0], c1[1] - t * c2[1], c1[2] - t * c2[2])
    if mode == 14:
        return (_divide(c1[0], c2[0], t), _divide(c1[1], c2[1], t), _divide(c1[2], c2[2], t))
    if mode == 15:  # hue
        hsv = rgb_to_hsv(c2)
        if hsv[1] != 0.0:
            hsv2 = rgb_to_hsv(c1)
            return _lerp3(c1, hsv_to_rgb((hsv[0], hsv2[1], hsv2[2])), t)
        return c1
    if mode == 16:  # saturation
        hsv = rgb_to_hsv(c1)
        if hsv[1] != 0.0:
            hsv2 = rgb_to_hsv(c2)
            return hsv_to_rgb((hsv[0], tm * hsv[1] + t * hsv2[1], hsv[2]))
        return c1
    if mode == 17:  # value
        hsv = rgb_to_hsv(c1)
        hsv2 = rgb_to_hsv(c2)
        return hsv_to_rgb((hsv[0], hsv[1], tm * hsv[2] + t * hsv2[2]))
    if mode == 18:  # color
        hsv2 = rgb_to_hsv(c2)
        if hsv2[1] != 0.0:
            hsv = rgb_to_hsv(c1)
            return _lerp3(c1, hsv_to_rgb((hsv2[0], hsv2[1], hsv[2])), t)
        return c1
    return c1


@kernel
def euler_rotate(r, v, transposed):
    """Cycles's ``euler_to_transform`` (XYZ Euler, R = Rz·Ry·Rx) applied to v (or Rᵀ)."""
    cx, cy, cz = math.cos(r[0]), math.cos(r[1]), math.cos(r[2])
    sx, sy, sz = math.sin(r[0]), math.sin(r[1]), math.sin(r[2])
    m00, m01, m02 = cy * cz, sy * sx * cz - cx * sz, sy * cx * cz + sx * sz
    m10, m11, m12 = cy * sz, sy * sx * sz + cx * cz, sy * cx * sz - sx * cz
    m20, m21, m22 = -sy, cy * sx, cy * cx
    if transposed:
        return (m00 * v[0] + m10 * v[1] + m20 * v[2], m01 * v[0] + m11 * v[1] + m21 * v[2],
                m02 * v[0] + m12 * v[1] + m22 * v[2])
    return (m00 * v[0] + m01 * v[1] + m02 * v[2], m10 * v[0] + m11 * v[1] + m12 * v[2],
            m20 * v[0] + m21 * v[1] + m22 * v[2])


@kernel
def mapping(mode, v, loc, rot, scale):
    """Cycles's ``svm_mapping``: POINT, TEXTURE, VECTOR, NORMAL."""
    if mode == 0:
        p = euler_rotate(rot, (v[0] * scale[0], v[1] * scale[1], v[2] * scale[2]), False)
        return (p[0] + loc[0], p[1] + loc[1], p[2] + loc[2])
    if mode == 1:
        p = euler_rotate(rot, (v[0] - loc[0], v[1] - loc[1], v[2] - loc[2]), True)
        return _safe_div3(p, scale)
    if mode == 2:
        return euler_rotate(rot, (v[0] * scale[0], v[1] * scale[1], v[2] * scale[2]), False)
    return _normalize(euler_rotate(rot, _safe_div3(v, scale), False))


@kernel
def checker(p):
    """Cycles's ``svm_checker``: 1 or 0."""
    x = (p[0] + 0.000001) * 0.999999
    y = (p[1] + 0.000001) * 0.999999
    z = (p[2] + 0.000001) * 0.999999
    xi = abs(int(floor64(x)))
    yi = abs(int(floor64(y)))
    zi = abs(int(floor64(z)))
    return 1.0 if ((xi % 2 == yi % 2) == (zi % 2 == 1)) else 0.0


@kernel
def gradient(mode, p):
    """Cycles's ``svm_gradient`` (before its saturate)."""
    x, y, z = p
    if mode == 0:
        return x
    if mode == 1:
        r = max(x, 0.0)
        return r * r
    if mode == 2:
        r = min(max(x, 0.0), 1.0)
        t = r * r
        return 3.0 * t - 2.0 * t * r
    if mode == 3:
        return (x + y) * 0.5
    if mode == 6:
        return math.atan2(y, x) / (2.0 * math.pi) + 0.5
    r = max(0.999999 - math.sqrt(x * x + y * y + z * z), 0.0)
    if mode == 5:
        return r * r
    return r


@kernel
def smoothstep(e0, e1, x):
    if x < e0:
        return 0.0
    if x >= e1:
        return 1.0
    t = (x - e0) / (e1 - e0)
    return t * t * (3.0 - 2.0 * t)


@kernel
def map_range(mode, clamp, value, fmin, fmax, tmin, tmax, steps):
    """Cycles's ``svm_node_map_range`` for floats."""
    if mode == 0:
        f = safe_divide(value - fmin, fmax - fmin)
    elif mode == 1:
        f = safe_divide(value - fmin, fmax - fmin)
        f = floor64(f * (steps + 1.0)) / steps if steps > 0.0 else 0.0
    elif mode == 2:
        f = 1.0 - smoothstep(fmax, fmin, value) if fmin > fmax else smoothstep(fmin, fmax, value)
    else:
        if fmin > fmax:
            x = saturate(safe_divide(value - fmax, fmin - fmax))
            f = 1.0 - x * x * x * (x * (x * 6.0 - 15.0) + 10.0)
        else:
            x = saturate(safe_divide(value - fmin, fmax - fmin))
            f = x * x * x * (x * (x * 6.0 - 15.0) + 10.0)
    r = tmin + f * (tmax - tmin)
    if clamp and mode <= 1:
        r = min(max(r, tmax), tmin) if tmin > tmax else min(max(r, tmin), tmax)
    return r


@kernel
def srgb_to_linear(c):
    if c < 0.04045:
        return 0.0 if c < 0.0 else c * (1.0 / 12.92)
    return math.pow((c + 0.055) * (1.0 / 1.055), 2.4)


@kernel
def _texel(img_info, img_u8, img_f32, img, x, y, c):
    info = img_info[img]
    w = info[0]
    k = info[2] + (y * w + x) * 4 + c
    if info[3]:
        return float(img_f32[k])
    return img_u8[k] * (1.0 / 255.0)


@kernel
def _wrap(i, n, ext):
    """Texel index i in [0, n) by extension (REPEAT, EXTEND, CLIP → −1 outside, MIRROR)."""
    if ext == 0:
        r = i % n
        return r + n if r < 0 else r
    if ext == 1:
        return min(max(i, 0), n - 1)
    if ext == 2:
        return i if 0 <= i < n else -1
    # mirror: period 2n
    m = i % (2 * n)
    if m < 0:
        m += 2 * n
    return m if m < n else 2 * n - 1 - m


@kernel
def _bspline(t, k):
    """Weight of texel k (0..3, from ix − 1) of the uniform cubic B-spline at fraction t
    (Cycles's SET_CUBIC_SPLINE_WEIGHTS)."""
    if k == 0:
        return (((-1.0 / 6.0) * t + 0.5) * t - 0.5) * t + 1.0 / 6.0
    if k == 1:
        return ((0.5 * t - 1.0) * t) * t + 2.0 / 3.0
    if k == 2:
        return ((-0.5 * t + 0.5) * t + 0.5) * t + 1.0 / 6.0
    return (1.0 / 6.0) * t * t * t


@kernel
def image_projection(proj, co):
    """(u, v) of the Image Texture's Sphere (1) and Tube (2) projections of vector ``co``
    (Cycles's ``svm_node_tex_image_mapping``: [0, 1]³ remapped to [−1, 1]³, then
    ``map_to_sphere`` / ``map_to_tube``); Flat (0) is (x, y)."""
    if proj == 0:
        return co[0], co[1]
    x, y, z = 2.0 * (co[0] - 0.5), 2.0 * (co[1] - 0.5), 2.0 * (co[2] - 0.5)
    if proj == 2:
        if x * x + y * y > 0.0:
            return (1.0 - np.arctan2(x, y) / np.pi) * 0.5, (z + 1.0) * 0.5
        return 0.0, 0.0
    l2 = x * x + y * y + z * z
    if not l2 > 0.0:
        return 0.0, 0.0
    u = 0.0 if (x == 0.0 and y == 0.0) else 0.5 - np.arctan2(x, y) / (2.0 * np.pi)
    c = min(max(z / np.sqrt(l2), -1.0), 1.0)
    return u, 1.0 - np.arccos(c) / np.pi


@kernel
def box_weights(n, blend):
    """The Image Texture's Box projection weights (x, y, z faces) for the object-space normal
    ``n`` and Blend (Cycles's ``svm_node_tex_image_box``): with the normal's |components|
    summing to 1 as barycentric coordinates of a triangle whose corners are the three faces,
    one face near a corner, two along an edge band, three in the middle band, the bands as wide
    as ``blend``."""
    ax, ay, az = abs(n[0]), abs(n[1]), abs(n[2])
    s = ax + ay + az
    if not s > 0.0:
        return 1.0, 0.0, 0.0
    ax, ay, az = ax / s, ay / s, az / s
    limit = 0.5 * (1.0 + blend)
    if ax > limit * (ax + ay) and ax > limit * (ax + az):
        return 1.0, 0.0, 0.0
    if ay > limit * (ax + ay) and ay > limit * (ay + az):
        return 0.0, 1.0, 0.0
    if az > limit * (ax + az) and az > limit * (ay + az):
        return 0.0, 0.0, 1.0
    if not blend > 0.0:
        return 1.0, 0.0, 0.0  # (Cycles: no valid choice, one side)
    if az < (1.0 - limit) * (ay + ax):
        wx = min(max((ax / (ax + ay) - 0.5 * (1.0 - blend)) / blend, 0.0), 1.0)
        return wx, 1.0 - wx, 0.0
    if ax < (1.0 - limit) * (ay + az):
        wy = min(max((ay / (ay + az) - 0.5 * (1.0 - blend)) / blend, 0.0), 1.0)
        return 0.0, wy, 1.0 - wy
    if ay < (1.0 - limit) * (ax + az):
        wx = min(max((ax / (ax + az) - 0.5 * (1.0 - blend)) / blend, 0.0), 1.0)
        return wx, 0.0, 1.0 - wx
    k = 2.0 * limit - 1.0
    return (((2.0 - limit) * ax + (limit - 1.0)) / k, ((2.0 - limit) * ay + (limit - 1.0)) / k,
            ((2.0 - limit) * az + (limit - 1.0)) / k)


@kernel
def image_box(img_info, img_u8, img_f32, img, mode, co, n, blend):
    """RGBA of the Image Texture's Box projection at vector ``co`` for object-space normal
    ``n``: up to three lookups (yz, xz, yx planes, flipped by the normal's sign so that no face
    is mirrored, as Cycles maps them) weighted by ``box_weights``."""
    wx, wy, wz = box_weights(n, blend)
    r = g = b = a = 0.0
    if wx > 0.0:
        c = image_lookup(img_info, img_u8, img_f32, img, mode, 1.0 - co[1] if n[0] < 0.0 else co[1], co[2])
        r, g, b, a = r + wx * c[0], g + wx * c[1], b + wx * c[2], a + wx * c[3]
    if wy > 0.0:
        c = image_lookup(img_info, img_u8, img_f32, img, mode, 1.0 - co[0] if n[1] > 0.0 else co[0], co[2])
        r, g, b, a = r + wy * c[0], g + wy * c[1], b + wy * c[2], a + wy * c[3]
    if wz > 0.0:
        c = image_lookup(img_info, img_u8, img_f32, img, mode, 1.0 - co[1] if n[2] > 0.0 else co[1], co[0])
        r, g, b, a = r + wz * c[0], g + wz * c[1], b + wz * c[2], a + wz * c[3]
    return r, g, b, a


@kernel
def image_lookup(img_info, img_u8, img_f32, img, mode, u, v):
    """RGBA of image img at texture coordinate (u, v) (origin bottom-left), Cycles's CPU image
    interpolation: mode = interpolation·8 + extension (Closest 0 / Linear 1 / Cubic 2; REPEAT 0,
    EXTEND 1, CLIP 2, MIRROR 3). CLIP reads texels outside the image as 0 (so Linear fades over
    half a texel beyond the border, as in Cycles). The image table's three arrays come apart
    (ProgramData.img_info / img_u8 / img_f32), not the whole ProgramData: numba passes every
    array of a namedtuple as separate arguments, ~300 words a call for ProgramData."""
    info = img_info[img]
    w, h = info[0], info[1]
    interp = mode // 8
    ext = mode % 8
    r = g = b = a = 0.0
    if interp == 0:
        ix = _wrap(int(floor64(u * w)), w, ext)
        iy = _wrap(int(floor64(v * h)), h, ext)
        if ix >= 0 and iy >= 0:
            r, g, b, a = (_texel(img_info, img_u8, img_f32, img, ix, iy, 0), _texel(img_info, img_u8, img_f32, img, ix, iy, 1),
                          _texel(img_info, img_u8, img_f32, img, ix, iy, 2), _texel(img_info, img_u8, img_f32, img, ix, iy, 3))
    elif interp == 2:
        # Cycles's bicubic: uniform cubic B-spline weights over 4×4 texels around (u, v)
        tx = u * w - 0.5
        ty = v * h - 0.5
        fx0 = floor64(tx)
        fy0 = floor64(ty)
        x0, y0 = int(fx0) - 1, int(fy0) - 1
        for dy in range(4):
            wy = _bspline(ty - fy0, dy)
            iy = _wrap(y0 + dy, h, ext)
            for dx in range(4):
                ix = _wrap(x0 + dx, w, ext)
                if ix < 0 or iy < 0:
                    continue
                wgt = _bspline(tx - fx0, dx) * wy
                r += wgt * _texel(img_info, img_u8, img_f32, img, ix, iy, 0)
                g += wgt * _texel(img_info, img_u8, img_f32, img, ix, iy, 1)
                b += wgt * _texel(img_info, img_u8, img_f32, img, ix, iy, 2)
                a += wgt * _texel(img_info, img_u8, img_f32, img, ix, iy, 3)
    else:
        tx = u * w - 0.5
        ty = v * h - 0.5
        fx0 = floor64(tx)
        fy0 = floor64(ty)
        fx = tx - fx0
        fy = ty - fy0
        x0, y0 = int(fx0), int(fy0)
        for dy in range(2):
            wy = fy if dy else 1.0 - fy
            iy = _wrap(y0 + dy, h, ext)
            for dx in range(2):
                wx = fx if dx else 1.0 - fx
                ix = _wrap(x0 + dx, w, ext)
                if ix < 0 or iy < 0:
                    continue
                wgt = wx * wy
                r += wgt * _texel(img_info, img_u8, img_f32, img, ix, iy, 0)
                g += wgt * _texel(img_info, img_u8, img_f32, img, ix, iy, 1)
                b += wgt * _texel(img_info, img_u8, img_f32, img, ix, iy, 2)
                a += wgt * _texel(img_info, img_u8, img_f32, img, ix, iy, 3)
    if info[4]:
        r, g, b = srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b)
    return r, g, b, a


@kernel
def ramp_lookup(data, off, interpolate, f):
    """Cycles's ``rgb_ramp_lookup`` on a RAMP_TABLE_SIZE-entry RGBA table at data[off]
    (``ProgramData.data``)."""
    f = min(max(f, 0.0), 1.0) * (RAMP_TABLE_SIZE - 1)
    i = min(max(int(f), 0), RAMP_TABLE_SIZE - 1)
    t = f - i
    k = off + 4 * i
    r, g, b, a = data[k], data[k + 1], data[k + 2], data[k + 3]
    if interpolate and t > 0.0:
        r = (1.0 - t) * r + t * data[k + 4]
        g = (1.0 - t) * g + t * data[k + 5]
        b = (1.0 - t) * b + t * data[k + 6]
        a = (1.0 - t) * a + t * data[k + 7]
    return r, g, b, a


@kernel
def fresnel_dielectric_cos(cosi, eta):
    """Unpolarised Fresnel reflectance for relative IOR eta at |cos| cosi (Cycles's
    ``fresnel_dielectric_cos``; 1 under total internal reflection)."""
    c = abs(cosi)
    g = eta * eta - 1.0 + c * c
    if g > 0.0:
        g = math.sqrt(g)
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        return 0.5 * a * a * (1.0 + b * b)
    return 1.0


@kernel
def _row(point, r):
    return (point[r, 0], point[r, 1], point[r, 2])


@kernel
def normal_map(space, strength, color, tangent, sign, point):
    """Cycles's ``svm_node_normal_map`` for a surface hit: the perturbed shading normal, world
    space, on the side the ray came from (zero when it cannot be formed: the caller keeps N).
    Tangent space: ``tangent``/``sign`` are the interpolated MikkTSpace tangent (world space for
    static objects, local for moving ones: ``POINT_XFORM`` maps it) and bitangent sign; the base
    normal is the unnormalised interpolated vertex normal (the true normal when flat)."""
    c = (2.0 * (color[0] - 0.5), 2.0 * (color[1] - 0.5), 2.0 * (color[2] - 0.5))
    backfacing = point[POINT_MISC, 2] != 0.0
    lerp_strength = space != 0
    if space == 0:
        if tangent[0] == 0.0 and tangent[1] == 0.0 and tangent[2] == 0.0:
            return (0.0, 0.0, 0.0)  # no tangents (no UV map): Cycles keeps the unperturbed N
        # strength acts in tangent space (Blender 5): tilt scaled, z blended toward 1
        c = (c[0] * strength, c[1] * strength, 1.0 + (c[2] - 1.0) * min(max(strength, 0.0), 1.0))
        x = point[POINT_XFORM:POINT_XFORM + 3]
        tl = math.sqrt(tangent[0] * tangent[0] + tangent[1] * tangent[1] + tangent[2] * tangent[2])
        t = (x[0, 0] * tangent[0] + x[0, 1] * tangent[1] + x[0, 2] * tangent[2],
             x[1, 0] * tangent[0] + x[1, 1] * tangent[1] + x[1, 2] * tangent[2],
             x[2, 0] * tangent[0] + x[2, 1] * tangent[1] + x[2, 2] * tangent[2])
        tw = _len(t)
        if tw > 0.0:
            t = (t[0] * tl / tw, t[1] * tl / tw, t[2] * tl / tw)
        n = _row(point, POINT_NSMOOTH)
        b = (sign * (n[1] * t[2] - n[2] * t[1]), sign * (n[2] * t[0] - n[0] * t[2]),
             sign * (n[0] * t[1] - n[1] * t[0]))
        nm = _normalize((c[0] * t[0] + c[1] * b[0] + c[2] * n[0], c[0] * t[1] + c[1] * b[1] + c[2] * n[1],
                         c[0] * t[2] + c[1] * b[2] + c[2] * n[2]))
        if backfacing:
            nm = (-nm[0], -nm[1], -nm[2])
    else:
        if space >= 3:  # Blender's object/world spaces: y and z flipped
            c = (c[0], -c[1], -c[2])
        nm = _normalize(c)
        if space == 1 or space == 3:  # object space: through the object's normal transform
            x = point[POINT_OBJECT_XFORM:POINT_OBJECT_XFORM + 3]
            nm = _normalize((x[0, 0] * nm[0] + x[0, 1] * nm[1] + x[0, 2] * nm[2],
                             x[1, 0] * nm[0] + x[1, 1] * nm[1] + x[1, 2] * nm[2],
                             x[2, 0] * nm[0] + x[2, 1] * nm[1] + x[2, 2] * nm[2]))
        if backfacing:
            nm = (-nm[0], -nm[1], -nm[2])
    n0 = _row(point, POINT_N)
    if lerp_strength and strength != 1.0:
        s = max(strength, 0.0)
        nm = _normalize((n0[0] + (nm[0] - n0[0]) * s, n0[1] + (nm[1] - n0[1]) * s, n0[2] + (nm[2] - n0[2]) * s))
    if not (math.isfinite(nm[0]) and math.isfinite(nm[1]) and math.isfinite(nm[2])):
        return (0.0, 0.0, 0.0)
    return nm


@kernel
def object_inverse(point):
    """M ᵀ (world → object normals; its transpose maps object directions to world) as nine
    row-major values, from the hit object's normal transform inv(M)ᵀ in ``point``
    (``POINT_OBJECT_XFORM``): the inverse of that 3×3 matrix (identity if singular)."""
    a = point[POINT_OBJECT_XFORM:POINT_OBJECT_XFORM + 3]
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    if det == 0.0 or not math.isfinite(det):
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    k = 1.0 / det
    return (c00 * k, (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) * k, (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) * k,
            c01 * k, (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) * k, (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) * k,
            c02 * k, (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) * k, (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) * k)


@kernel
def world_to_object_normal(point, n):
    """Cycles's ``object_inverse_normal_transform``: normalize(Mᵀ n)."""
    b = object_inverse(point)
    return _normalize((b[0] * n[0] + b[1] * n[1] + b[2] * n[2], b[3] * n[0] + b[4] * n[1] + b[5] * n[2],
                       b[6] * n[0] + b[7] * n[1] + b[8] * n[2]))


@kernel
def object_to_world_dir(point, v):
    """Cycles's ``object_dir_transform``: M v (M = (Mᵀ)ᵀ from ``object_inverse``)."""
    b = object_inverse(point)
    return (b[0] * v[0] + b[3] * v[1] + b[6] * v[2], b[1] * v[0] + b[4] * v[1] + b[7] * v[2],
            b[2] * v[0] + b[5] * v[1] + b[8] * v[2])


@kernel
def tangent_displacement(n_static, prim, point, dv, tangent, sign):
    """Vector Displacement's tangent space (Cycles's ``svm_node_vector_displacement``): dv's x,
    y, z along the tangent, the normal and the signed bitangent, all in object space. A static
    hit's tangent is stored in world space (by the normal transform, length kept): it is brought
    back by Mᵀ (``n_static``: the number of static triangles); a moving hit's is local already.
    No tangent (no UV map): the y part only."""
    n = world_to_object_normal(point, _row(point, POINT_N))
    tl = _len(tangent)
    t = tangent
    if prim < n_static and tl > 0.0:
        u = world_to_object_normal(point, tangent)
        t = (u[0] * tl, u[1] * tl, u[2] * tl)
    b = _normalize((n[1] * t[2] - n[2] * t[1], n[2] * t[0] - n[0] * t[2], n[0] * t[1] - n[1] * t[0]))
    return (t[0] * dv[0] + n[0] * dv[1] + b[0] * sign * dv[2], t[1] * dv[0] + n[1] * dv[1] + b[1] * sign * dv[2],
            t[2] * dv[0] + n[2] * dv[1] + b[2] * sign * dv[2])


@kernel
def make_orthonormals(n):
    """Cycles's ``make_orthonormals``: tangents (a, b) of unit n, a = normalize((1,1,1) × n)
    (or (−1,1,1) × n when n's components are equal), b = n × a."""
    if n[0] != n[1] or n[0] != n[2]:
        a = _normalize((n[2] - n[1], n[0] - n[2], n[1] - n[0]))
    else:
        a = _normalize((n[2] - n[1], n[0] + n[2], -n[1] - n[0]))
    return a, (n[1] * a[2] - n[2] * a[1], n[2] * a[0] - n[0] * a[2], n[0] * a[1] - n[1] * a[0])


@kernel
def bump_step(positions, triangles, footprint, prim, mode, point, fw):
    """(world offset, barycentric steps db1, db2) of the Bump node's evaluation ``mode`` (1, 2)
    at a hit of static triangle ``prim``, as Cycles's compact ray differentials give it: a step
    of fw × |dP| along ``make_orthonormals(Ng)``'s first (mode 1) or second (mode 2) tangent,
    |dP| the pixel's footprint at the hit's ray length (mean of its right and up extents,
    ``ProgramData.footprint``; ``positions`` / ``triangles``: its static mesh arrays, passed apart
    as the image helpers' are). Moving triangles (no vertex positions here) get no step."""
    zero = ((0.0, 0.0, 0.0), 0.0, 0.0)
    if prim < 0 or prim >= triangles.shape[0] or footprint.shape[0] < 4:
        return zero
    t = max(point[POINT_MISC, 1], 0.0)
    f = footprint
    wx = _len((f[0, 0] + t * f[1, 0], f[0, 1] + t * f[1, 1], f[0, 2] + t * f[1, 2]))
    wy = _len((f[2, 0] + t * f[3, 0], f[2, 1] + t * f[3, 1], f[2, 2] + t * f[3, 2]))
    m = fw * 0.5 * (wx + wy)
    ta, tb = make_orthonormals(_row(point, POINT_NG))
    tv = ta if mode == 1 else tb
    step = (tv[0] * m, tv[1] * m, tv[2] * m)
    tri = triangles[prim]
    a = positions[tri[0]]
    b = positions[tri[1]]
    c = positions[tri[2]]
    e1 = (float(b[0]) - float(a[0]), float(b[1]) - float(a[1]), float(b[2]) - float(a[2]))
    e2 = (float(c[0]) - float(a[0]), float(c[1]) - float(a[1]), float(c[2]) - float(a[2]))
    g11, g12, g22 = _dot(e1, e1), _dot(e1, e2), _dot(e2, e2)
    det = g11 * g22 - g12 * g12
    if not det > 0.0:
        return zero
    r1, r2 = _dot(step, e1), _dot(step, e2)
    return step, (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det


@kernel
def bump_normal(positions, triangles, footprint, prim, point, nin, h_c, h_x, h_y, strength, distance, invert, fw):
    """Cycles's ``svm_node_set_bump``: the normal of the surface displaced by distance × height
    along ``nin`` (world, on the side the ray came from), from the heights at the hit and one
    step (``bump_step``) along each of two tangents; blended toward ``nin`` by strength. With steps of
    fw·dP this is Cycles's formula (its fw·|det|·N − scale·sign(det)·∇h, both sides ÷ fw)."""
    dx, _, _ = bump_step(positions, triangles, footprint, prim, 1, point, fw)
    dy, _, _ = bump_step(positions, triangles, footprint, prim, 2, point, fw)
    rx = (dy[1] * nin[2] - dy[2] * nin[1], dy[2] * nin[0] - dy[0] * nin[2], dy[0] * nin[1] - dy[1] * nin[0])
    ry = (nin[1] * dx[2] - nin[2] * dx[1], nin[2] * dx[0] - nin[0] * dx[2], nin[0] * dx[1] - nin[1] * dx[0])
    det = _dot(dx, rx)
    scale = -distance if invert else distance
    gx, gy = h_x - h_c, h_y - h_c
    sg = 1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0)
    ad = abs(det)
    out = _normalize((ad * nin[0] - scale * sg * (gx * rx[0] + gy * ry[0]),
                      ad * nin[1] - scale * sg * (gx * rx[1] + gy * ry[1]),
                      ad * nin[2] - scale * sg * (gx * rx[2] + gy * ry[2])))
    if out[0] == 0.0 and out[1] == 0.0 and out[2] == 0.0:
        return nin
    st = max(strength, 0.0)
    return _normalize((st * out[0] + (1.0 - st) * nin[0], st * out[1] + (1.0 - st) * nin[1],
                       st * out[2] + (1.0 - st) * nin[2]))


@kernel
def camera_coords(camera, window, p):
    """Texture Coordinate's Camera output (camera space, +z forward as Cycles's) or Window
    output (the image's [0, 1]² with (0, 0) bottom left, z 0) of Blender-world point p
    (``camera``: ``ProgramData.camera``)."""
    if camera.shape[0] < 5:
        return (0.0, 0.0, 0.0)
    c = camera
    x = c[0, 0] * p[0] + c[0, 1] * p[1] + c[0, 2] * p[2] + c[0, 3]
    y = c[1, 0] * p[0] + c[1, 1] * p[1] + c[1, 2] * p[2] + c[1, 3]
    z = -(c[2, 0] * p[0] + c[2, 1] * p[1] + c[2, 2] * p[2] + c[2, 3])
    if not window:
        return (x, y, z)
    if c[3, 0] == 0.0:  # perspective: the point's position on the plane at distance 1
        if z == 0.0:
            return (0.0, 0.0, 0.0)
        x, y = x / z, y / z
    return ((x - c[4, 0]) / c[3, 1] + 0.5, (y - c[4, 1]) / c[3, 2] + 0.5, 0.0)


@inline_kernel
def _reg(regs, r):
    return (regs[r, 0], regs[r, 1], regs[r, 2])


@inline_kernel
def _set(regs, r, v):
    regs[r, 0] = v[0]
    regs[r, 1] = v[1]
    regs[r, 2] = v[2]


@inline_kernel
def _set1(regs, r, x):
    regs[r, 0] = x
    regs[r, 1] = x
    regs[r, 2] = x


@inline_kernel
def _corner3(arr, prim, b0, b1, b2):
    c = arr[prim]
    return (b0 * c[0, 0] + b1 * c[1, 0] + b2 * c[2, 0], b0 * c[0, 1] + b1 * c[1, 1] + b2 * c[2, 1],
            b0 * c[0, 2] + b1 * c[1, 2] + b2 * c[2, 2])


@inline_kernel
def _coordinate(corners, point, row, prim, b0, b1, b2):
    """A per-corner coordinate input at a hit (zero when no mesh stores it), or row ``row`` of
    ``point`` at a shading point off any triangle (prim < 0)."""
    if prim < 0:
        return (point[row, 0], point[row, 1], point[row, 2])
    if corners.shape[0]:
        return _corner3(corners, prim, b0, b1, b2)
    return (0.0, 0.0, 0.0)


@kernel
def run_program(pd, regs, prog, prim, b1, b2, point):
    """Run program ``prog`` at barycentrics (b1, b2) of global triangle ``prim``; results stay
    in ``regs`` (R, 3) float64. A shading point that is not on a triangle (``prim`` < 0: a
    point in a volume, a direction of the world) takes its coordinate inputs from ``point``
    (rows ``POINT_GENERATED``, ``POINT_OBJECT``, ``POINT_UV``; filled by the caller); a
    surface hit never reads ``point``."""
    b0 = 1.0 - b1 - b2
    b1_hit, b2_hit = b1, b2
    p_hit = (0.0, 0.0, 0.0)
    for k in range(pd.const_start[prog], pd.const_start[prog + 1]):
        r = pd.const_reg[k]
        regs[r, 0] = pd.const_val[k, 0]
        regs[r, 1] = pd.const_val[k, 1]
        regs[r, 2] = pd.const_val[k, 2]
    for k in range(pd.op_start[prog], pd.op_start[prog + 1]):
        op = pd.ops[k, 0]
        mode = pd.ops[k, 1]
        o0 = pd.ops[k, 2]
        o1 = pd.ops[k, 3]
        i0, i1, i2, i3, i4, i5 = pd.ops[k, 4], pd.ops[k, 5], pd.ops[k, 6], pd.ops[k, 7], pd.ops[k, 8], pd.ops[k, 9]
        param = pd.ops[k, 10]
        if op == OP_UV:
            if prim < 0:
                _set(regs, o0, (point[POINT_UV, 0], point[POINT_UV, 1], point[POINT_UV, 2]))
            elif pd.uv.shape[0]:
                c = pd.uv[prim]
                _set(regs, o0, (b0 * c[0, 0] + b1 * c[1, 0] + b2 * c[2, 0],
                                b0 * c[0, 1] + b1 * c[1, 1] + b2 * c[2, 1], 0.0))
            else:
                _set1(regs, o0, 0.0)
        elif op == OP_GENERATED:
            _set(regs, o0, _coordinate(pd.generated, point, POINT_GENERATED, prim, b0, b1, b2))
        elif op == OP_ATTRIBUTE:
            if prim >= 0 and param < pd.attrs.shape[0]:
                _set(regs, o0, _corner3(pd.attrs[param], prim, b0, b1, b2))
            else:
                _set1(regs, o0, 0.0)
        elif op == OP_OBJECT:
            _set(regs, o0, _coordinate(pd.objco, point, POINT_OBJECT, prim, b0, b1, b2))
        elif op == OP_POINT:
            if param >= 0:
                _set1(regs, o0, point[mode, param])
            else:
                _set(regs, o0, (point[mode, 0], point[mode, 1], point[mode, 2]))
        elif op == OP_FRESNEL:
            nrm = _reg(regs, i1) if i1 >= 0 else _row(point, POINT_N)
            eta = max(regs[i0, 0], 1e-5)
            if point[POINT_MISC, 2] != 0.0:
                eta = 1.0 / eta
            _set1(regs, o0, fresnel_dielectric_cos(_dot(_row(point, POINT_I), nrm), eta))
        elif op == OP_LAYER_WEIGHT:
            nrm = _reg(regs, i1) if i1 >= 0 else _row(point, POINT_N)
            blend = regs[i0, 0]
            cos_i = _dot(_row(point, POINT_I), nrm)
            eta = max(1.0 - blend, 1e-5)
            if point[POINT_MISC, 2] == 0.0:
                eta = 1.0 / eta
            _set1(regs, o0, fresnel_dielectric_cos(cos_i, eta))
            f = abs(cos_i)
            if blend != 0.5:
                bl = min(max(blend, 0.0), 1.0 - 1e-5)
                bl = 2.0 * bl if bl < 0.5 else 0.5 / (1.0 - bl)
                f = math.pow(f, bl)
            _set1(regs, o1, 1.0 - f)
        elif op == OP_NORMAL_MAP:
            nm = normal_map(mode, regs[i0, 0], _reg(regs, i1), _reg(regs, i2) if i2 >= 0 else (0.0, 0.0, 0.0),
                            regs[i3, 0] if i3 >= 0 else 1.0, point)
            if nm[0] == 0.0 and nm[1] == 0.0 and nm[2] == 0.0:
                nm = _row(point, POINT_N)
            _set(regs, o0, nm)
        elif op == OP_BUMP_OFFSET:
            # the Bump node's height sub-graph runs again at P + dP (mode 1: along the first
            # edge, 2: the second; 0: back at the hit); every coordinate input moves with it
            if mode == 0:
                b1, b2 = b1_hit, b2_hit
                _set(point, POINT_P, p_hit)
            else:
                if b1 == b1_hit and b2 == b2_hit:
                    p_hit = _row(point, POINT_P)
                e, db1, db2 = bump_step(pd.positions, pd.triangles, pd.footprint, prim, mode, point, regs[i0, 0])
                b1 = b1_hit + db1
                b2 = b2_hit + db2
                _set(point, POINT_P, (p_hit[0] + e[0], p_hit[1] + e[1], p_hit[2] + e[2]))
            b0 = 1.0 - b1 - b2
        elif op == OP_BUMP:
            nin = _reg(regs, i5) if i5 >= 0 else _row(point, POINT_N)
            # param = 2 × (filter width register) + invert
            _set(regs, o0, bump_normal(pd.positions, pd.triangles, pd.footprint, prim, point, nin, regs[i0, 0], regs[i1, 0], regs[i2, 0],
                                       regs[i3, 0], regs[i4, 0], param % 2 != 0, regs[param // 2, 0]))
        elif op == OP_CAMERA_COORDS:
            _set(regs, o0, camera_coords(pd.camera, mode, _row(point, POINT_P)))
        elif op == OP_OBJECT_INFO:
            if prim >= 0 and pd.object_of.shape[0]:
                info = pd.object_info[pd.object_of[prim]]
                if mode <= 1:  # location, colour
                    _set(regs, o0, (info[3 * mode], info[3 * mode + 1], info[3 * mode + 2]))
                else:  # alpha, pass index, random
                    _set1(regs, o0, info[4 + mode])
            else:
                _set1(regs, o0, 0.0)
        elif op == OP_VMATH:
            c = _reg(regs, i2) if i2 >= 0 else (0.0, 0.0, 0.0)
            s = regs[i3, 0] if i3 >= 0 else 1.0
            _set(regs, o0, vmath_op(mode, _reg(regs, i0), _reg(regs, i1), c, s))
        elif op == OP_MATH:
            x = math_op(mode, regs[i0, 0], regs[i1, 0], regs[i2, 0])
            _set1(regs, o0, saturate(x) if param else x)
        elif op == OP_MIX:
            fac = _reg(regs, i0)
            a = _reg(regs, i1)
            b = _reg(regs, i2)
            if mode == 0 and (fac[0] != fac[1] or fac[1] != fac[2]):  # non-uniform vector mix
                _set(regs, o0, ((1.0 - fac[0]) * a[0] + fac[0] * b[0], (1.0 - fac[1]) * a[1] + fac[1] * b[1],
                                (1.0 - fac[2]) * a[2] + fac[2] * b[2]))
            else:
                _set(regs, o0, mix_blend(mode, fac[0], a, b))
        elif op == OP_MAPPING:
            _set(regs, o0, mapping(mode, _reg(regs, i0), _reg(regs, i1), _reg(regs, i2), _reg(regs, i3)))
        elif op == OP_IMAGE:  # mode = projection·IMAGE_PROJECTION_STRIDE + interpolation·8 + extension
            u, vv = image_projection(mode // IMAGE_PROJECTION_STRIDE, _reg(regs, i0))
            r, g, b, a = image_lookup(pd.img_info, pd.img_u8, pd.img_f32, param, mode % IMAGE_PROJECTION_STRIDE, u, vv)
            _set(regs, o0, (r, g, b))
            _set1(regs, o1, a)
        elif op == OP_IMAGE_BOX:  # in0 the vector, in1 the Blend
            r, g, b, a = image_box(pd.img_info, pd.img_u8, pd.img_f32, param, mode, _reg(regs, i0),
                                   world_to_object_normal(point, _row(point, POINT_N)), regs[i1, 0])
            _set(regs, o0, (r, g, b))
            _set1(regs, o1, a)
        elif op == OP_ENVIRONMENT:
            v = _reg(regs, i0)
            u, vv = direction_to_uv(mode // ENV_PROJECTION_STRIDE, v[0], v[1], v[2])
            r, g, b, a = image_lookup(pd.img_info, pd.img_u8, pd.img_f32, param, mode % ENV_PROJECTION_STRIDE, u, vv)
            _set(regs, o0, (r, g, b))
            _set1(regs, o1, a)
        elif op == OP_CHECKER:
            v = _reg(regs, i0)
            s = regs[i3, 0]
            f = checker((v[0] * s, v[1] * s, v[2] * s))
            _set(regs, o0, _reg(regs, i1) if f == 1.0 else _reg(regs, i2))
            _set1(regs, o1, f)
        elif op == OP_GRADIENT:
            f = saturate(gradient(mode, _reg(regs, i0)))
            _set1(regs, o0, f)
            _set1(regs, o1, f)
        elif op == OP_RAMP:
            r, g, b, a = ramp_lookup(pd.data, param, mode, regs[i0, 0])
            _set(regs, o0, (r, g, b))
            _set1(regs, o1, a)
        elif op == OP_MAP_RANGE:
            _set1(regs, o0, map_range(mode, param, regs[i0, 0], regs[i1, 0], regs[i2, 0], regs[i3, 0],
                                      regs[i4, 0], regs[i5, 0]))
        elif op == OP_CLAMP:
            x, lo, hi = regs[i0, 0], regs[i1, 0], regs[i2, 0]
            if mode == 1 and lo > hi:
                lo, hi = hi, lo
            _set1(regs, o0, min(max(x, lo), hi))
        elif op == OP_INVERT:
            f = regs[i0, 0]
            c = _reg(regs, i1)
            _set(regs, o0, (f * (1.0 - c[0]) + (1.0 - f) * c[0], f * (1.0 - c[1]) + (1.0 - f) * c[1],
                            f * (1.0 - c[2]) + (1.0 - f) * c[2]))
        elif op == OP_GAMMA:
            c = _reg(regs, i0)
            gm = regs[i1, 0]
            _set(regs, o0, (math.pow(c[0], gm) if c[0] > 0.0 else c[0],
                            math.pow(c[1], gm) if c[1] > 0.0 else c[1],
                            math.pow(c[2], gm) if c[2] > 0.0 else c[2]))
        elif op == OP_BRIGHT_CONTRAST:
            c = _reg(regs, i0)
            a = 1.0 + regs[i2, 0]
            b = regs[i1, 0] - regs[i2, 0] * 0.5
            _set(regs, o0, (max(a * c[0] + b, 0.0), max(a * c[1] + b, 0.0), max(a * c[2] + b, 0.0)))
        elif op == OP_HSV:
            c = _reg(regs, i4)
            hsv = rgb_to_hsv(c)
            rgb = hsv_to_rgb((fract(hsv[0] + regs[i0, 0] + 0.5), saturate(hsv[1] * regs[i1, 0]),
                              hsv[2] * regs[i2, 0]))
            f = regs[i3, 0]
            _set(regs, o0, (max(f * rgb[0] + (1.0 - f) * c[0], 0.0), max(f * rgb[1] + (1.0 - f) * c[1], 0.0),
                            max(f * rgb[2] + (1.0 - f) * c[2], 0.0)))
        elif op == OP_COMPONENT:
            _set1(regs, o0, regs[i0, mode])
        elif op == OP_COMBINE:
            _set(regs, o0, (regs[i0, 0], regs[i1, 0], regs[i2, 0]))
        elif op == OP_TO_GRAY:
            c = _reg(regs, i0)
            _set1(regs, o0, LUMINANCE[0] * c[0] + LUMINANCE[1] * c[1] + LUMINANCE[2] * c[2])
        elif op == OP_AVERAGE:
            c = _reg(regs, i0)
            _set1(regs, o0, (c[0] + c[1] + c[2]) * (1.0 / 3.0))
        elif op == OP_RGB_TO_HSV:
            _set(regs, o0, rgb_to_hsv(_reg(regs, i0)))
        elif op == OP_HSV_TO_RGB:
            _set(regs, o0, hsv_to_rgb(_reg(regs, i0)))
        elif op == OP_TEXCO_NORMAL:  # Texture Coordinate Normal: N in object space
            _set(regs, o0, world_to_object_normal(point, _row(point, POINT_N)))
        elif op == OP_DISPLACEMENT:  # Cycles's svm_node_displacement
            nrm = _reg(regs, i3) if i3 >= 0 else _row(point, POINT_N)
            k_d = (regs[i0, 0] - regs[i1, 0]) * regs[i2, 0]
            if mode == 1:
                nrm = world_to_object_normal(point, nrm)
                _set(regs, o0, object_to_world_dir(point, (nrm[0] * k_d, nrm[1] * k_d, nrm[2] * k_d)))
            else:
                _set(regs, o0, (nrm[0] * k_d, nrm[1] * k_d, nrm[2] * k_d))
        elif op == OP_VECTOR_DISPLACEMENT:  # svm_node_vector_displacement
            v = _reg(regs, i0)
            mid = regs[i1, 0]
            sc = regs[i2, 0]
            dv = ((v[0] - mid) * sc, (v[1] - mid) * sc, (v[2] - mid) * sc)
            if mode == 0:  # tangent space: (T, N, B) in object space, then to world
                dv = tangent_displacement(pd.triangles.shape[0], prim, point, dv, _reg(regs, i3), regs[i4, 0])
            _set(regs, o0, object_to_world_dir(point, dv) if mode != 2 else dv)
        elif op == OP_SET_NORMAL:  # the displacement's bump becomes the shading point's N
            nm = _normalize(_reg(regs, i0))
            if nm[0] == 0.0 and nm[1] == 0.0 and nm[2] == 0.0:
                nm = _row(point, POINT_N)
            _set(point, POINT_N, nm)
            _set(regs, o0, nm)
        elif 50 <= op < 70:  # procedural textures and curves (drt.materials.procedural)
            procedural_op(pd.procedural, regs, pd.data, op, mode, o0, o1, i0, i1, i2, i3, i4, i5, param)


@inline_kernel
def fresnel_from_registers(md, regs, m, l, ir, lr, tr):
    """Write slot l's per-hit Fresnel parameters from registers (Cycles's svm_node_closure
    Principled code; docs/materials.md "Textured IOR and tint"). DIELECTRIC_SPECULAR (the
    specular layer or a coat; ir, lr, tr all given): eta and F0 from IOR (≥ 1) and Specular IOR
    Level (``specular_eta_f0``), f0·tint clamped to [0, 1] — the layer-albedo and energy tables
    then read this hit's eta and f0·tint in bsdf_eval. METALLIC: the F82 tint min(max(tint, 0),
    1). GLASS: IOR ≥ 1 (as the exporter clamps); REFRACTION: IOR ≥ 1e-5."""
    t = md.lobe_type[m, l]
    if t == 5:  # BSDF_DIELECTRIC_SPECULAR
        eta, f0 = specular_eta_f0(max(regs[ir, 0], 1.0), max(regs[lr, 0], 0.0))
        md.lobe_ior[m, l] = eta
        md.lobe_fresnel[m, l, 0] = min(max(f0 * regs[tr, 0], 0.0), 1.0)
        md.lobe_fresnel[m, l, 1] = min(max(f0 * regs[tr, 1], 0.0), 1.0)
        md.lobe_fresnel[m, l, 2] = min(max(f0 * regs[tr, 2], 0.0), 1.0)
    elif t == 6:  # BSDF_METALLIC: F82 tint
        if tr >= 0:
            md.lobe_fresnel[m, l, 0] = min(max(regs[tr, 0], 0.0), 1.0)
            md.lobe_fresnel[m, l, 1] = min(max(regs[tr, 1], 0.0), 1.0)
            md.lobe_fresnel[m, l, 2] = min(max(regs[tr, 2], 0.0), 1.0)
    elif t == 3:  # BSDF_GLASS
        if ir >= 0:
            md.lobe_ior[m, l] = max(regs[ir, 0], 1.0)
    elif t == 8:  # BSDF_REFRACTION
        if ir >= 0:
            md.lobe_ior[m, l] = max(regs[ir, 0], 1e-5)


#: cosine-weighted average albedo per unit weight of a METALLIC lobe with F0 = 0 and a white
#: F82 tint, 2∫(1 − μ)⁵ μ dμ = 1/21: the floor of a metal's selection weight per unit k (a
#: textured base colour may be black at a hit, where the lobe still reflects at grazing angles
#: and must stay pickable)
BLACK_METAL_ALBEDO = 1.0 / 21.0


@inline_kernel
def constant_select_weight(md, m, l):
    """Lobe l's selection weight from this hit's row (as ``MaterialTable`` computes
    ``lobe_select``): the mean of its colour × ``lobe_avg``; a Principled glass's by
    ``glass_select_weight``; a metal's at least ``BLACK_METAL_ALBEDO`` × its weight k."""
    w = (md.lobe_color[m, l, 0] * md.lobe_avg[m, l, 0] + md.lobe_color[m, l, 1] * md.lobe_avg[m, l, 1]
         + md.lobe_color[m, l, 2] * md.lobe_avg[m, l, 2]) * (1.0 / 3.0)
    if md.lobe_type[m, l] == 3 and md.lobe_fresnel[m, l, 3] > 0.0:  # (3: BSDF_GLASS)
        w = glass_select_weight(w, md.lobe_fresnel[m, l, 4], md.lobe_ior[m, l])
    elif md.lobe_type[m, l] == 6:  # (6: BSDF_METALLIC) at least a black metal's F82 albedo
        w = max(w, BLACK_METAL_ALBEDO * md.lobe_fresnel[m, l, 4])
    return w


@inline_kernel
def eval_material(pd, md, regs, m, prim, b1, b2, point):
    """Run material m's program at a hit and write its per-hit parameters into row m of ``md``
    (which must be this thread's private copy): lobe colours and alphas, the lobe selection
    probabilities and CDF, delta flags, albedo and emission. ``point`` holds the shading-point
    rows the caller filled when ``pd.reads_point[m]`` (else it is not read)."""
    run_program(pd, regs, pd.prog_of[m], prim, b1, b2, point)
    count = md.lobe_count[m]
    total = 0.0
    for l in range(count):
        r = pd.lobe_color_reg[m, l]
        if r >= 0:
            md.lobe_color[m, l, 0] = max(regs[r, 0], 0.0)
            md.lobe_color[m, l, 1] = max(regs[r, 1], 0.0)
            md.lobe_color[m, l, 2] = max(regs[r, 2], 0.0)
        wr = pd.lobe_weight_reg[m, l]
        if wr >= 0:  # a textured METALLIC weight / Principled glass reflection weight
            md.lobe_fresnel[m, l, 4] = max(regs[wr, 0], 0.0)
        ir = pd.lobe_ior_reg[m, l, 0]
        tr = pd.lobe_ior_reg[m, l, 2]
        if ir >= 0 or tr >= 0:  # a textured IOR / Specular IOR Level / specular tint
            fresnel_from_registers(md, regs, m, l, ir, pd.lobe_ior_reg[m, l, 1], tr)
        rr = pd.lobe_rough_reg[m, l]
        if rr >= 0 or ir >= 0:
            if rr >= 0:
                rough = saturate(regs[rr, 0])
                md.lobe_alpha[m, l] = rough * rough
            alpha = md.lobe_alpha[m, l]
            t = md.lobe_type[m, l]
            # (as MaterialTable: Lambert (1), translucent (7), sheen (9) and velvet (10) never,
            # glass (3) and refraction (8) also at IOR ≈ 1, a holdout (11) and a coat tint (12) always)
            md.lobe_delta[m, l] = t == 11 or t == 12 or (t != 1 and t != 7 and t != 9 and t != 10 and (alpha * alpha <= ALPHA_SQ_SINGULAR or (
                (t == 3 or t == 8) and abs(md.lobe_ior[m, l] - 1.0) < IOR_ONE_EPS)))
        kr = pd.lobe_layer_reg[m, l, 0]
        if kr >= 0:  # a textured coat / sheen weight: k = the register's largest component
            md.lobe_coat[m, l, 0] = max(regs[kr, 0], regs[kr, 1], regs[kr, 2], 0.0)
        ctr = pd.lobe_layer_reg[m, l, 1]
        if ctr >= 0:  # a textured coat tint
            md.lobe_coat[m, l, 1] = max(regs[ctr, 0], 0.0)
            md.lobe_coat[m, l, 2] = max(regs[ctr, 1], 0.0)
            md.lobe_coat[m, l, 3] = max(regs[ctr, 2], 0.0)
        total += constant_select_weight(md, m, l)
    cdf = 0.0
    delta_only = True
    trans_delta = False
    a0 = a1 = a2 = 0.0
    for l in range(count):
        # weighted by the lobe's average share (a specular layer's albedo, what its base keeps)
        w = constant_select_weight(md, m, l)
        p = w / total if total > 0.0 else 0.0
        md.lobe_select[m, l] = p
        cdf += p
        md.lobe_cdf[m, l] = 1.0 if l == count - 1 else cdf
        if not md.lobe_delta[m, l]:
            delta_only = False
        t = md.lobe_type[m, l]
        if (md.lobe_delta[m, l] and t != 12) or t == 3 or t == 7 or t == 8:  # transmitting or delta
            trans_delta = True
        a0 += md.lobe_color[m, l, 0] * md.lobe_avg[m, l, 0]
        a1 += md.lobe_color[m, l, 1] * md.lobe_avg[m, l, 1]
        a2 += md.lobe_color[m, l, 2] * md.lobe_avg[m, l, 2]
    md.delta_only[m] = delta_only
    md.transmission_or_delta[m] = trans_delta
    md.albedo[m, 0] = a0
    md.albedo[m, 1] = a1
    md.albedo[m, 2] = a2
    e = pd.emission_reg[m]
    if e >= 0:
        md.emission[m, 0] = max(regs[e, 0], 0.0)
        md.emission[m, 1] = max(regs[e, 1], 0.0)
        md.emission[m, 2] = max(regs[e, 2], 0.0)
        md.has_emission[m] = md.emission[m, 0] > 0.0 or md.emission[m, 1] > 0.0 or md.emission[m, 2] > 0.0
