"""Shared pieces of the light types: colours, matrices, the compiled per-scene data (`LightData`)
and the per-light protocol.

Every light is described by flat per-light arrays in a `LightData` (built once, in Python, by
`build_light_data`) and evaluated by scalar ``@kernel`` functions of one sample each
(``point.py``, ``area.py``, ``sun.py``, ``world.py``, ``emissive.py``; selection in
``selection.py``; the scene-level interface the integrator calls in ``light_set.py``). The light
classes parse and validate the header's dicts, keep their parameters as attributes and offer the
same protocol vectorized over m shading points / rays, as thin wrappers over those kernels:

- ``sample(p, n, u2) -> (wi, dist, radiance, pdf, valid)``: ``wi`` (m, 3) unit, world space, from
  ``p`` toward the light; ``dist`` (m,) to the sampled point (``inf`` for distant lights);
  ``radiance`` (m, 3) is the *radiance* arriving along ``-wi`` (for delta lights the irradiance-like
  term ``I/d²`` or the sun's ``S``); ``pdf`` (m,) solid angle, *without* the selection
  probability (1 for delta lights).
- ``intersect(o, d) -> t`` (m,): distance to the light's visible shape along unit rays, ``inf``
  on a miss (delta lights never hit).
- ``hit_radiance(o, d, t)`` and ``pdf(o, d, t)``: radiance arriving at ``o`` from the shape hit
  at ``o + t d`` and the solid-angle pdf with which ``sample(o, ·)`` would produce ``d``.
- ``power``: scalar flux estimate (luminance-weighted watts) used for light selection.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from ..kernels import kernel

#: Rec.709 / sRGB luminance weights (Blender's default scene-linear space).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: Self-intersection guard for ray–shape tests (metres).
T_EPSILON = 1e-9

#: `LightData.kind` codes (int64) of the header's lights.
POINT, SPOT, AREA, SUN = 0, 1, 2, 3


def luminance(rgb) -> np.ndarray:
    """Luminance of linear RGB (..., 3). Plain arithmetic, not ``rgb @ LUMINANCE``: that is a
    BLAS call, which OpenBLAS runs on its own threads for a large image or emissive mesh, and
    they spin on beside the render's (docs/decisions.md)."""
    rgb = np.asarray(rgb, dtype=np.float64)
    return LUMINANCE[0] * rgb[..., 0] + LUMINANCE[1] * rgb[..., 1] + LUMINANCE[2] * rgb[..., 2]


def light_frame(matrix_world, origin_shift) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) and the 3×3 linear part (columns = local x, y, z in world space) of a
    Blender ``matrix_world`` (4×4 row-major), with ``origin_shift`` subtracted from the position."""
    m = np.asarray(matrix_world, dtype=np.float64).reshape(4, 4)
    return m[:3, 3] - np.asarray(origin_shift, dtype=np.float64), m[:3, :3]


def unit(v: np.ndarray) -> np.ndarray:
    """A single 3-vector normalized (raises on a zero vector: a degenerate light transform)."""
    length = float(np.linalg.norm(v))
    if not length > 0.0:
        raise ValueError("degenerate light transform (zero-length axis)")
    return np.asarray(v, dtype=np.float64) / length


def camera_visible(light: dict) -> bool:
    """The light's camera-ray visibility: ``visible_camera`` (scene format), or the add-on's
    ``visible_to_camera``; False by default, as for Blender 5.0 light objects."""
    return bool(light.get("visible_camera", light.get("visible_to_camera", False)))


# ------------------------------------------------------------------------------- scalar helpers
def scalar_kernel(fn):
    """The light kernels' decorator: `drt.kernels.kernel` (see drt/kernels/__init__.py, which
    also explains why no kernel uses numba's reference-counting runtime). The entry points the
    integrator calls are `drt.kernels.inline_kernel`s."""
    return kernel(fn)


@scalar_kernel
def clip01(x):
    """x clamped to [0, 1] (NaN stays NaN, as np.clip)."""
    if x < 0.0:
        return 0.0
    if x > 1.0:
        return 1.0
    return x


@scalar_kernel
def smoothstep01(x):
    """3x² − 2x³ of x clamped to [0, 1]."""
    x = clip01(x)
    return x * x * (3.0 - 2.0 * x)


@scalar_kernel
def one_minus_cos_from_sin2(sin2):
    """1 − cos θ from sin²θ without cancellation (θ ≤ π/2)."""
    return sin2 / (1.0 + math.sqrt(max(1.0 - sin2, 0.0)))


# ------------------------------------------------------------------------------- per-scene data
#: Everything the light kernels read, packed into a few tables (numba passes every array of a
#: namedtuple to a call as ~7 scalars, so ~60 separate arrays made each call copy ~4 KB and
#: compile slowly). Columns are named by the constants below.
#:
#: ``lf`` (n_lights, L_COLUMNS) float64, per header light (fields a type does not use are 0):
#:   L_POS: point/spot position, area centre (3); L_RADIANCE: a shape's (point with a radius,
#:   area) or a sun disk's radiance (3); L_INTENSITY: a point/spot's I = P/(4π), a delta sun's
#:   irradiance S (3); L_RADIUS; L_SPOT_DIR (3), L_SPOT_WIDTH = (1 − cos_half)·blend;
#:   L_COS_HALF (spot: cos(size/2), sun: cos of its half-angle); area: L_EX, L_EY, L_EZ,
#:   L_NORMAL (emission direction), L_CORNER (centre − ½a·ex − ½b·ey) (3 each), L_LEN_X,
#:   L_LEN_Y, L_AREA, L_HALF_SPREAD, L_TAN_HALF, L_SPREAD_NORM; sun: L_TO_SUN (3),
#:   L_ONE_MINUS_COS.
#: ``li`` (n_lights, I_COLUMNS) int64: I_KIND (POINT, SPOT, AREA, SUN) and the flags (0/1)
#:   I_IS_DELTA, I_VISIBLE_CAMERA, I_IS_SPHERE, I_IS_ELLIPSE, I_PLAIN (spread = π),
#:   I_SOLID_ANGLE (rectangle sampled by solid angle).
#: Lists: shapes (n_shapes,) int64 light indices with a visible shape (non-delta point, spot,
#:   area), suns (n_suns,) int64 non-delta suns, in header order.
#: Strategies (n_strategies = lights, then the emissive group, then the world): pmf, cdf (k,);
#:   per_point bool (DISTANCE selection with k > 1); emissive_index, world_index (−1: none);
#:   ``sf`` (k, S_COLUMNS) float64: S_CENTRE (3), S_RADIUS2, S_SCALE, S_FACING (3), S_SUN_DIR (3),
#:   S_SUN_SIN2 and the flags (0.0/1.0) S_LOCAL, S_ONE_SIDED, S_IS_SUN, S_IS_WORLD.
#: Emissive triangles (K rows): ``tf`` (K, T_COLUMNS) float64: T_V0, T_E1, T_E2, T_NG,
#:   T_RADIANCE (3 each), T_AREA; tri_pmf, tri_cdf (K,); tri_ids int64 (global ids),
#:   tri_sorted_ids int64, tri_sorted_local int64 (sorted ids → local index); n_tris.
#: World: world_color (3,) (zeros without a world), has_world bool. A textured world
#:   (``drt.lights.world_map``): world_prog, the index of its program in the integrator's
#:   ``ProgramData`` (−1: constant world), world_reg its radiance register, and the importance
#:   map wm_cond (H, W + 1, 2), wm_marg (H + 1, 2) (zero-size without a map).
LightData = namedtuple("LightData", [
    "n_lights", "n_strategies", "n_shapes", "n_suns", "n_tris", "emissive_index", "world_index",
    "has_world", "has_emissive", "per_point",
    "lf", "li", "shapes", "suns",
    "pmf", "cdf", "sf",
    "tf", "tri_pmf", "tri_cdf", "tri_ids", "tri_sorted_ids", "tri_sorted_local",
    "world_color",
    "world_prog", "world_reg", "wm_cond", "wm_marg",
])

_VEC_FIELDS = ("pos", "radiance", "intensity", "spot_dir", "ex", "ey", "ez", "normal", "corner",
               "to_sun")
_FLOAT_FIELDS = ("radius", "spot_width", "cos_half", "len_x", "len_y", "area", "half_spread",
                 "tan_half", "spread_norm", "one_minus_cos")
_BOOL_FIELDS = ("is_delta", "visible_camera", "is_sphere", "is_ellipse", "plain", "solid_angle")
_SEL_VEC_FIELDS = ("sel_centre", "sel_facing", "sel_sun_dir")
_SEL_FLOAT_FIELDS = ("sel_radius2", "sel_scale", "sel_sun_sin2", "sel_local", "sel_one_sided",
                     "sel_is_sun", "sel_is_world")
_TRI_VEC_FIELDS = ("tri_v0", "tri_e1", "tri_e2", "tri_ng", "tri_radiance")
_TRI_FLOAT_FIELDS = ("tri_area",)


def _columns(vec_fields, scalar_fields, strip=""):
    """{FIELD: first column} for vectors (3 columns each) then scalars (1 each), and the total."""
    cols, c = {}, 0
    for name in vec_fields:
        cols[name.replace(strip, "").upper()] = c
        c += 3
    for name in scalar_fields:
        cols[name.replace(strip, "").upper()] = c
        c += 1
    return cols, c


_L, L_COLUMNS = _columns(_VEC_FIELDS, _FLOAT_FIELDS)
_I, I_COLUMNS = _columns((), ("kind",) + _BOOL_FIELDS)
_S, S_COLUMNS = _columns(_SEL_VEC_FIELDS, _SEL_FLOAT_FIELDS, strip="sel_")
_T, T_COLUMNS = _columns(_TRI_VEC_FIELDS, _TRI_FLOAT_FIELDS, strip="tri_")
(L_POS, L_RADIANCE, L_INTENSITY, L_SPOT_DIR, L_EX, L_EY, L_EZ, L_NORMAL, L_CORNER, L_TO_SUN,
 L_RADIUS, L_SPOT_WIDTH, L_COS_HALF, L_LEN_X, L_LEN_Y, L_AREA, L_HALF_SPREAD, L_TAN_HALF,
 L_SPREAD_NORM, L_ONE_MINUS_COS) = _L.values()
(I_KIND, I_IS_DELTA, I_VISIBLE_CAMERA, I_IS_SPHERE, I_IS_ELLIPSE, I_PLAIN, I_SOLID_ANGLE) = _I.values()
(S_CENTRE, S_FACING, S_SUN_DIR, S_RADIUS2, S_SCALE, S_SUN_SIN2, S_LOCAL, S_ONE_SIDED, S_IS_SUN,
 S_IS_WORLD) = _S.values()
(T_V0, T_E1, T_E2, T_NG, T_RADIANCE, T_AREA) = _T.values()


def _pack(fields: dict, columns: dict, n: int, total: int, strip: str = "", dtype=np.float64) -> np.ndarray:
    """The named per-row arrays of ``fields`` as one (n, total) table laid out by ``columns``."""
    out = np.zeros((n, total), dtype=dtype)
    for name, a in fields.items():
        c = columns[name.replace(strip, "").upper()]
        a = np.asarray(a, dtype=dtype)
        width = 3 if a.ndim == 2 else 1
        out[:, c:c + width] = a.reshape(n, width)
    return out


def _f64(a, shape) -> np.ndarray:
    """A fresh C-contiguous, writeable float64 array of `shape` (one numba type for all scenes)."""
    return np.array(np.broadcast_to(np.asarray(a, dtype=np.float64), shape), dtype=np.float64,
                    order="C", copy=True)


def selection_tables(k: int) -> dict:
    """Zeroed per-strategy selection arrays (`LightData.sel_*`) for k strategies."""
    return dict(sel_centre=np.zeros((k, 3)), sel_radius2=np.zeros(k), sel_scale=np.zeros(k),
                sel_local=np.zeros(k, dtype=bool), sel_facing=np.zeros((k, 3)),
                sel_one_sided=np.zeros(k, dtype=bool), sel_sun_dir=np.zeros((k, 3)),
                sel_sun_sin2=np.zeros(k), sel_is_sun=np.zeros(k, dtype=bool),
                sel_is_world=np.zeros(k, dtype=bool))


def build_light_data(lights, group=None, world_color=None, *, pmf=None, cdf=None,
                     per_point: bool = False, selection: dict | None = None,
                     world_program: tuple[int, int] = (-1, -1), world_map=None) -> LightData:
    """The `LightData` of header lights (objects with a ``_store(arrays, i)`` method), an
    optional `EmissiveGroup` and an optional world colour (None: no world). Without ``pmf`` the
    strategies are chosen uniformly (a single strategy: probability 1); ``selection`` holds the
    `selection_tables` arrays (zeros by default). A textured world: ``world_program`` =
    (program index, radiance register) and ``world_map`` = (wm_cond, wm_marg)."""
    n = len(lights)
    arrays = {f: np.zeros((n, 3)) for f in _VEC_FIELDS}
    arrays.update({f: np.zeros(n) for f in _FLOAT_FIELDS})
    arrays.update({f: np.zeros(n, dtype=bool) for f in _BOOL_FIELDS})
    arrays["kind"] = np.zeros(n, dtype=np.int64)
    for i, lt in enumerate(lights):
        lt._store(arrays, i)
    shapes = [i for i in range(n) if arrays["kind"][i] != SUN and not arrays["is_delta"][i]]
    suns = [i for i in range(n) if arrays["kind"][i] == SUN and not arrays["is_delta"][i]]
    k = n
    emissive_index = world_index = -1
    if group is not None:
        emissive_index, k = k, k + 1
    if world_color is not None:
        world_index, k = k, k + 1
    if pmf is None:
        pmf = np.full(k, 1.0 / k) if k else np.zeros(0)
        if k == 1:
            pmf = np.ones(1)
        cdf = np.cumsum(pmf)
        if k:
            cdf[-1] = 1.0
    tables = selection_tables(k)
    if selection is not None:
        tables.update(selection)
    if group is not None:
        tri = dict(tri_v0=group.v0, tri_e1=group.e1, tri_e2=group.e2, tri_ng=group.ng,
                   tri_area=group.area, tri_radiance=group.radiance, tri_pmf=group.pmf,
                   tri_cdf=group.cdf, tri_ids=group.ids, tri_sorted_ids=group.sorted_ids,
                   tri_sorted_local=group.sorted_local)
    else:
        tri = dict(tri_v0=np.zeros((0, 3)), tri_e1=np.zeros((0, 3)), tri_e2=np.zeros((0, 3)),
                   tri_ng=np.zeros((0, 3)), tri_area=np.zeros(0), tri_radiance=np.zeros((0, 3)),
                   tri_pmf=np.zeros(0), tri_cdf=np.zeros(0), tri_ids=np.zeros(0, np.int64),
                   tri_sorted_ids=np.zeros(0, np.int64), tri_sorted_local=np.zeros(0, np.int64))
    n_tris = len(tri["tri_area"])

    if world_map is None:
        cond, marg = np.zeros((0, 1, 2)), np.zeros((1, 2))
    else:
        cond, marg = (np.asarray(a, dtype=np.float64) for a in world_map)

    def ints(a):
        return np.array(a, dtype=np.int64, order="C", copy=True).reshape(-1)

    return LightData(
        n_lights=int(n), n_strategies=int(k), n_shapes=len(shapes), n_suns=len(suns),
        n_tris=int(n_tris), emissive_index=int(emissive_index), world_index=int(world_index),
        has_world=world_color is not None, has_emissive=group is not None,
        per_point=bool(per_point),
        lf=_pack({f: arrays[f] for f in _VEC_FIELDS + _FLOAT_FIELDS}, _L, n, L_COLUMNS),
        li=_pack({f: arrays[f] for f in ("kind",) + _BOOL_FIELDS}, _I, n, I_COLUMNS, dtype=np.int64),
        shapes=ints(shapes), suns=ints(suns),
        pmf=_f64(pmf, (k,)), cdf=_f64(cdf, (k,)),
        sf=_pack({f: tables[f] for f in _SEL_VEC_FIELDS + _SEL_FLOAT_FIELDS}, _S, k, S_COLUMNS, "sel_"),
        tf=_pack({f: tri[f] for f in _TRI_VEC_FIELDS + _TRI_FLOAT_FIELDS}, _T, n_tris, T_COLUMNS, "tri_"),
        tri_pmf=_f64(tri["tri_pmf"], (n_tris,)), tri_cdf=_f64(tri["tri_cdf"], (n_tris,)),
        tri_ids=ints(tri["tri_ids"]), tri_sorted_ids=ints(tri["tri_sorted_ids"]),
        tri_sorted_local=ints(tri["tri_sorted_local"]),
        world_color=_f64(world_color if world_color is not None else np.zeros(3), (3,)),
        world_prog=int(world_program[0]), world_reg=int(world_program[1]),
        wm_cond=_f64(cond, cond.shape), wm_marg=_f64(marg, marg.shape))
