"""The in-memory scene model and its validation.

``scene_from_dict(header, arrays)`` is the single entry point that turns an exported scene (the
JSON header and the named numpy arrays of ``docs/scene-format.md``) into a validated ``Scene``.
Both the file loader and the Blender add-on go through it, so a scene that renders from Blender
renders the same from a file.

Every problem raises ``SceneError`` naming the field, e.g.
``scene field 'camera.lens': must be a finite number > 0, got -5``.
Units: metres, radians, Blender world space (+Z up); matrices map local to world space.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .cryptomatte import CRYPTO_LAYERS, MAX_LEVELS, MIN_LEVELS

FORMAT_NAME = "drt-scene"
SUPPORTED_VERSIONS = (1, 2)  # 2: adds SUBSURFACE lobes (docs/scene-format.md)

LIGHT_TYPES = ("POINT", "SPOT", "SUN", "AREA")
AREA_SHAPES = ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE")
LOBE_TYPES = ("DIFFUSE", "GLOSSY", "GLASS", "SUBSURFACE", "DIELECTRIC_SPECULAR", "METALLIC", "TRANSLUCENT",
              "REFRACTION", "HOLDOUT", "SHEEN", "VELVET")
SSS_METHODS = ("RANDOM_WALK", "RANDOM_WALK_SKIN", "BURLEY")  # = drt.materials.subsurface_lobe
FILTER_TYPES = ("BLACKMAN_HARRIS", "GAUSSIAN", "BOX")
SAMPLER_KINDS = ("SOBOL", "STRATIFIED", "RANDOM")
DIRECT_STRATEGIES = ("MIS_POWER", "MIS_BALANCE", "LIGHT", "BSDF")
INDIRECT_STRATEGIES = ("BSDF", "COSINE", "UNIFORM")
SENSOR_FITS = ("AUTO", "HORIZONTAL", "VERTICAL")
CAMERA_TYPES = ("PERSP", "ORTHO", "PANO")

MAX_RESOLUTION = 65536
#: Cycles's per-object ray visibility (Object > Visibility > Ray Visibility), as bits of
#: ``ObjectSpec.visibility``: which rays see the object (a ray that does not passes through it)
RAY_VISIBILITY = ("camera", "diffuse", "glossy", "transmission", "volume_scatter", "shadow")
VIS_CAMERA, VIS_DIFFUSE, VIS_GLOSSY, VIS_TRANSMISSION, VIS_VOLUME_SCATTER, VIS_SHADOW = (1 << k for k in range(6))
VIS_ALL = (1 << len(RAY_VISIBILITY)) - 1
#: not a ray kind: the bit of a per-triangle visibility array (drt.geometry) that marks a
#: holdout object (``ObjectSpec.holdout``), which camera rays cut out of the image
VIS_HOLDOUT = 1 << len(RAY_VISIBILITY)
MAX_SPP = 1 << 24


class SceneError(ValueError):
    """A scene (file or in-memory export) is malformed; the message names the field."""

    def __init__(self, field_path: str, problem: str):
        self.field = field_path
        self.problem = problem
        super().__init__(f"scene field '{field_path}': {problem}")


# --------------------------------------------------------------------------- field readers


def _get(d: dict, key: str, path: str, default=...):
    if not isinstance(d, dict):
        raise SceneError(path, f"must be an object, got {type(d).__name__}")
    if key not in d or d[key] is None and default is not ...:
        if default is ...:
            raise SceneError(f"{path}.{key}" if path else key, "is missing")
        return default
    return d[key]


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


#: smallest lens, sensor size (mm) and ortho scale (m): a denormal lens made the field of view
#: infinite (fuzzing); Blender's own minimum lens is 1 mm
MIN_CAMERA_LENGTH = 1e-6

#: largest magnitude of any number in the header: beyond it values have no meaning in a Blender
#: scene and overflow float arithmetic (a strength of 1e308 squared or divided; fuzzing found
#: several), so they are refused with the field's name instead
MAX_MAGNITUDE = 1e30


def _number(d, key, path, default=..., lo=None, hi=None, lo_open=False, integer=False):
    p = _join(path, key)
    v = _get(d, key, path, default)
    # numpy scalars are accepted too: in-memory exports (the add-on) produce them
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise SceneError(p, f"must be a number, got {v!r}")
    v = float(v) if isinstance(v, np.floating) else int(v) if isinstance(v, np.integer) else v
    if isinstance(v, int) and abs(v) > 2**63:  # float(v) would overflow
        raise SceneError(p, f"must be a finite number, got an integer of {len(str(abs(v)))} digits")
    if integer and (not float(v).is_integer()):
        raise SceneError(p, f"must be an integer, got {v!r}")
    if not math.isfinite(v):
        raise SceneError(p, f"must be a finite number, got {v!r}")
    if abs(v) > MAX_MAGNITUDE and not integer:
        raise SceneError(p, f"must be within ±{MAX_MAGNITUDE:g}, got {v!r}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise SceneError(p, f"must be {'>' if lo_open else '>='} {lo}, got {v!r}")
    if hi is not None and v > hi:
        raise SceneError(p, f"must be <= {hi}, got {v!r}")
    return int(v) if integer else float(v)


def _bool(d, key, path, default=...):
    v = _get(d, key, path, default)
    if not isinstance(v, bool):
        raise SceneError(_join(path, key), f"must be true or false, got {v!r}")
    return v


def _enum(d, key, path, choices, default=...):
    v = _get(d, key, path, default)
    if v not in choices:
        raise SceneError(_join(path, key), f"must be one of {', '.join(choices)}, got {v!r}")
    return v


def _vector(d, key, path, n, default=..., lo=None):
    p = _join(path, key)
    v = _get(d, key, path, default)
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SceneError(p, f"must be a list of {n} finite numbers") from None
    if a.shape != (n,):
        raise SceneError(p, f"must be a list of {n} numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise SceneError(p, "must contain only finite numbers")
    if np.any(np.abs(a) > MAX_MAGNITUDE):
        raise SceneError(p, f"must contain numbers within ±{MAX_MAGNITUDE:g}")
    if lo is not None and np.any(a < lo):
        raise SceneError(p, f"must contain numbers >= {lo}")
    return a


#: largest absolute entry of a transform matrix: Blender scenes stay far below (float32 geometry
#: is meaningless past ~1e15 anyway), and squaring 1e308 overflows float64 (fuzzing found it)
MAX_TRANSFORM_ENTRY = 1e15


def _matrix(d, key, path, default=...):
    p = _join(path, key)
    v = _get(d, key, path, default)
    try:
        m = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SceneError(p, "must be a 4x4 list of numbers") from None
    if m.shape != (4, 4):
        raise SceneError(p, f"must be a 4x4 matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise SceneError(p, "must contain only finite numbers")
    if np.any(np.abs(m) > MAX_TRANSFORM_ENTRY):
        raise SceneError(p, f"entries must be within ±{MAX_TRANSFORM_ENTRY:g} (beyond it a transform "
                            "overflows when composed, and float32 geometry cannot hold the result)")
    if not np.allclose(m[3], [0, 0, 0, 1], atol=1e-6):
        raise SceneError(p, "last row must be [0, 0, 0, 1] (an affine transform)")
    return m


def _list(d, key, path):
    """A list-valued field (missing = empty)."""
    v = _get(d, key, path, [])
    if not isinstance(v, list):
        raise SceneError(_join(path, key), "must be a list")
    return v


def _motion(d, key, path):
    v = _get(d, key, path, None)
    if v is None:
        return None
    p = _join(path, key)
    return (_matrix(v, "matrix_open", p), _matrix(v, "matrix_close", p))


# --------------------------------------------------------------------------- model


@dataclass
class RenderSettings:
    """Film and integrator settings. Resolution in pixels; shutter in frames (None: no blur)."""

    width: int
    height: int
    pixel_aspect: tuple[float, float] = (1.0, 1.0)
    border: tuple[float, float, float, float] | None = None
    film_transparent: bool = False
    #: Cycles's Film > Transparent Glass (with a transparent film): the world seen through
    #: glass transmissions of roughness ≤ ``film_transparent_roughness`` is transparent too;
    #: None: off
    film_transparent_roughness: float | None = None
    #: Cycles's Film > Exposure: the film's radiance (not alpha, depth, normal or albedo) is
    #: multiplied by it, after clamping, as Cycles writes its passes
    exposure: float = 1.0
    filter_type: str = "BLACKMAN_HARRIS"
    filter_width: float = 1.5
    spp: int = 64
    seed: int = 0
    sampler: str = "SOBOL"
    max_bounces: int = 12
    diffuse_bounces: int = 4
    glossy_bounces: int = 4
    transmission_bounces: int = 12
    clamp_direct: float = 0.0
    clamp_indirect: float = 0.0
    #: Cycles's Filter Glossy (Light Paths > Caustics): after an unlikely bounce, glossy lobes are
    #: widened (drt.path_stages.glossy_blur), a bias that removes caustic fireflies. 0 = off,
    #: the unbiased estimator; Cycles's default is 1.0, which the add-on exports
    filter_glossy: float = 0.0
    #: Cycles's Light Paths > Caustics > Reflective / Refractive: off, a hit right after a diffuse
    #: bounce is shaded without the glossy reflection / refraction lobes (drt.materials.caustics)
    caustics_reflective: bool = True
    caustics_refractive: bool = True
    #: Cycles's Mist pass, wanted: (start, depth, falloff exponent) of the world's Mist Pass
    #: settings (falloff 2 quadratic, 1 linear, 0.5 inverse quadratic); None: no Mist pass
    mist: tuple[float, float, float] | None = None
    #: Cycles's data passes wanted, a subset of DATA_PASSES in that order ("object_index",
    #: "material_index", "position", "uv"); empty: none (drt.path_stages.write_data_passes)
    data_passes: tuple = ()
    #: the view layer's Alpha Threshold: a data pass skips a transparent surface whose alpha
    #: (1 − average transparency) is below it (0: every surface counts), as Cycles
    pass_alpha_threshold: float = 0.5
    #: Cycles's Emission, Environment and Diffuse Color passes wanted, a subset of LIGHT_PASSES;
    #: empty: none (drt.path_stages.add_light_passes, diffuse_color)
    light_passes: tuple = ()
    #: Cryptomatte layers wanted, a subset of drt.cryptomatte.CRYPTO_LAYERS ("object",
    #: "material", "asset"); empty: none. ``cryptomatte_levels``: Blender's Levels, the
    #: (id, coverage) pairs each pixel keeps per layer (2–16, rounded up to even)
    cryptomatte: tuple = ()
    cryptomatte_levels: int = 6
    #: metres an Ambient Occlusion pass ray looks for occluders (World > Ambient Occlusion >
    #: Distance; Blender's default 10); matters only with "ao" in ``light_passes``
    ao_distance: float = 10.0
    shutter: tuple[float, float] | None = None
    direct: str = "MIS_POWER"  # direct-light estimator (see integrator.DIRECT_STRATEGIES)
    indirect: str = "BSDF"  # continuation sampling (integrator.INDIRECT_STRATEGIES)
    adaptive_threshold: float = 0.0  # stop a pixel when its relative standard error falls below; 0 = off
    adaptive_min_samples: int = 0  # samples every pixel takes before it may stop; 0 = automatic
    volume_bounces: int = 0  # scatter events in media a path may have beyond the first (Cycles's)
    #: surfaces a path may pass straight through (alpha, Transparent BSDF); not counted as
    #: bounces, as Cycles's transparent bounces (default 8)
    transparent_bounces: int = 8


@dataclass
class CameraSpec:
    """Blender camera data. ``matrix``: camera to world (looks along local −Z, +Y up).
    lens, sensor sizes in mm; clip distances in scene units; rotation in radians."""

    type: str
    matrix: np.ndarray
    lens: float = 50.0
    sensor_width: float = 36.0
    sensor_height: float = 24.0
    sensor_fit: str = "AUTO"
    shift_x: float = 0.0
    shift_y: float = 0.0
    clip_start: float = 0.1
    clip_end: float = 1000.0
    ortho_scale: float = 7.0
    dof_use: bool = False
    focus_distance: float = 10.0
    fstop: float = 2.8
    blades: int = 0
    rotation: float = 0.0
    ratio: float = 1.0
    motion: tuple[np.ndarray, np.ndarray] | None = None
    #: the projection of a panoramic camera (type "PANO"; drt.panorama)
    panorama: PanoramaSpec | None = None


@dataclass
class PanoramaSpec:
    """Blender's panoramic camera settings (Camera > Lens with Type Panoramic; drt.panorama):
    ``type`` one of drt.panorama.PANORAMA_TYPES; angles in radians, ``fisheye_lens`` in mm;
    ``polynomial`` the polynomial lens's k0 … k4 (theta in radians of r in mm)."""

    type: str = "FISHEYE_EQUISOLID"
    fisheye_fov: float = math.pi
    fisheye_lens: float = 10.5
    latitude_min: float = -0.5 * math.pi
    latitude_max: float = 0.5 * math.pi
    longitude_min: float = -math.pi
    longitude_max: float = math.pi
    polynomial: tuple = (-1.1735143743862864e-05, -0.019988736137747765, -3.3525323033245513e-06,
                         3.0992753181635635e-06, -2.60646473293491e-08)


@dataclass
class MeshData:
    """A triangle mesh in its object's local space. ``normals``: per-corner (T,3,3) or None
    (flat shading); ``uvs`` per-corner (T,3,2) or None; ``positions_close`` for deforming meshes."""

    name: str
    positions: np.ndarray
    triangles: np.ndarray
    material_index: np.ndarray
    normals: np.ndarray | None = None
    uvs: np.ndarray | None = None
    positions_close: np.ndarray | None = None
    #: per-corner (T, 3, 3) float arrays material programs read: "generated", "object_coords"
    corner_attrs: dict = field(default_factory=dict)


@dataclass
class ObjectSpec:
    name: str
    mesh: int
    matrix: np.ndarray
    motion: tuple[np.ndarray, np.ndarray] | None = None
    #: Object Info values (only when a material program reads them): (6,) float64 — colour
    #: rgb, alpha, pass index, random in [0, 1] (the location is the matrix's translation)
    info: np.ndarray | None = None
    #: Cycles's shadow terminator offsets (Object properties; drt.terminator): ``geometry``
    #: moves NEE shadow-ray origins of smooth-shaded triangles toward the smooth surface
    #: (Blender's default 0.1; absent from the file: 0, no offset), ``shading`` softens the
    #: BSDF's cosine toward the terminator (0: off). Both in [0, 1].
    terminator_geometry: float = 0.0
    terminator_shading: float = 0.0
    #: VIS_* bits of the rays that see the object (VIS_ALL: every ray, Cycles's default)
    visibility: int = VIS_ALL
    #: Cycles's holdout (Object > Visibility > Mask > Holdout, or a holdout collection): where
    #: a camera ray (still one through transparent surfaces) hits the object, the film's alpha
    #: loses the hit's opaque part and no light is added; every other ray sees it as usual
    holdout: bool = False
    #: Object > Relations > Pass Index: the Object Index pass's value on the object's surfaces
    pass_index: int = 0
    #: the names Cryptomatte's object and asset layers hash (the add-on's: the object's own
    #: name, as Cycles, and its topmost parent's); default both ``name``
    crypto_object: str = ""
    crypto_asset: str = ""


@dataclass
class Scene:
    render: RenderSettings
    camera: CameraSpec
    world_color: np.ndarray
    materials: list[dict]
    lights: list[dict]
    meshes: list[MeshData]
    objects: list[ObjectSpec]
    header: dict = field(default_factory=dict, repr=False)
    arrays: dict = field(default_factory=dict, repr=False)
    #: images material programs read: (info dict, (H, W, 4) uint8 or float16 array)
    images: list = field(default_factory=list, repr=False)
    #: names of the named per-corner attributes programs read (e.g. "uv:UVMap.001")
    attributes: list = field(default_factory=list, repr=False)
    #: the world's homogeneous medium (``drt.volumes.media``), None: none
    world_volume: dict | None = None
    #: a textured world: its validated program dict plus "radiance_reg" (the register holding
    #: the radiance along −d) and "map_size" (importance map (W, H), (0, 0): none); None: constant
    world_program: dict | None = field(default=None, repr=False)

    @property
    def has_motion(self) -> bool:
        s = self.render.shutter
        if s is None or s[1] <= s[0]:
            return False
        return (
            self.camera.motion is not None
            or any(o.motion is not None for o in self.objects)
            or any(m.positions_close is not None for m in self.meshes)
        )

    @property
    def triangle_count(self) -> int:
        return int(sum(len(self.meshes[o.mesh].triangles) for o in self.objects))


# --------------------------------------------------------------------------- sections


#: the world's Mist Pass falloff (Blender's enum) → Cycles's exponent
MIST_FALLOFF = {"QUADRATIC": 2.0, "LINEAR": 1.0, "INVERSE_QUADRATIC": 0.5}


def _mist(r: dict, path: str):
    """``render.mist``: {"start": ≥ 0, "depth": ≥ 0 (scene units), "falloff": a MIST_FALLOFF key}
    → (start, depth, exponent), or None when absent."""
    m = _get(r, "mist", path, None)
    if m is None:
        return None
    p = _join(path, "mist")
    falloff = _enum(m, "falloff", p, tuple(MIST_FALLOFF), "QUADRATIC")
    return (_number(m, "start", p, 5.0, lo=0), _number(m, "depth", p, 25.0, lo=0), MIST_FALLOFF[falloff])


#: the data passes a scene may ask for (``render.data_passes``), in their column order
DATA_PASSES = ("object_index", "material_index", "position", "uv")


#: the light passes a scene may ask for (``render.light_passes``)
LIGHT_PASSES = ("emission", "environment", "diffuse_color", "ao")


def _pass_list(r: dict, path: str, key: str, known: tuple, kind: str) -> tuple:
    """``render.<key>``: a list of names from ``known`` (any order) → those names in known's
    order."""
    names = _get(r, key, path, [])
    p = _join(path, key)
    if not isinstance(names, (list, tuple)):
        raise SceneError(p, f"must be a list of {', '.join(known)}")
    unknown = [n for n in names if n not in known]
    if unknown:
        raise SceneError(p, f"{unknown[0]!r} is not a {kind} (one of {', '.join(known)})")
    return tuple(n for n in known if n in names)


def _render_settings(h: dict) -> RenderSettings:
    p = "render"
    r = _get(h, "render", "")
    res = _get(r, "resolution", p)
    if not isinstance(res, (list, tuple)) or len(res) != 2:
        raise SceneError("render.resolution", f"must be [width, height], got {res!r}")
    try:
        w = _number({"resolution": res[0]}, "resolution", "render", integer=True, lo=1, hi=MAX_RESOLUTION)
        hgt = _number({"resolution": res[1]}, "resolution", "render", integer=True, lo=1, hi=MAX_RESOLUTION)
    except SceneError as e:
        raise SceneError("render.resolution", f"width and height {e.problem}") from None
    aspect = _vector(r, "pixel_aspect", p, 2, default=[1.0, 1.0])
    if np.any(aspect <= 0):
        raise SceneError("render.pixel_aspect", "must be > 0")
    border = _get(r, "border", p, None)
    if border is not None:
        b = _vector(r, "border", p, 4)
        if not (0 <= b[0] < b[2] <= 1 and 0 <= b[1] < b[3] <= 1):
            raise SceneError("render.border", f"must be [xmin, ymin, xmax, ymax] within [0,1] with min < max, got {list(b)}")
        border = tuple(float(x) for x in b)
    filt = _get(r, "filter", p, {"type": "BLACKMAN_HARRIS", "width": 1.5})
    ftype = _enum(filt, "type", "render.filter", FILTER_TYPES, "BLACKMAN_HARRIS")
    fwidth = _number(filt, "width", "render.filter", 1.5, lo=0.01, hi=64)
    shutter = _get(r, "shutter", p, None)
    if shutter is not None:
        s = _vector(r, "shutter", p, 2)
        if s[1] < s[0]:
            raise SceneError("render.shutter", f"close must not be before open, got {list(s)}")
        shutter = (float(s[0]), float(s[1]))
    bounces = {
        k: _number(r, k, p, dflt, lo=0, hi=1024, integer=True)
        for k, dflt in (("max_bounces", 12), ("diffuse_bounces", 4), ("glossy_bounces", 4), ("transmission_bounces", 12),
                        ("volume_bounces", 0), ("transparent_bounces", 8))
    }
    return RenderSettings(
        width=w,
        height=hgt,
        pixel_aspect=(float(aspect[0]), float(aspect[1])),
        border=border,
        film_transparent=_bool(r, "film_transparent", p, False),
        film_transparent_roughness=(_number(r, "film_transparent_roughness", p, 0.1, lo=0, hi=1)
                                    if r.get("film_transparent_roughness") is not None else None),
        exposure=_number(r, "exposure", p, 1.0, lo=0, hi=2.0**32),
        filter_type=ftype,
        filter_width=fwidth,
        spp=_number(r, "spp", p, 64, lo=1, hi=MAX_SPP, integer=True),
        seed=_number(r, "seed", p, 0, lo=0, hi=2**31 - 1, integer=True),
        sampler=_enum(r, "sampler", p, SAMPLER_KINDS, "SOBOL"),
        clamp_direct=_number(r, "clamp_direct", p, 0.0, lo=0),
        clamp_indirect=_number(r, "clamp_indirect", p, 0.0, lo=0),
        filter_glossy=_number(r, "filter_glossy", p, 0.0, lo=0, hi=10),
        caustics_reflective=_bool(r, "caustics_reflective", p, True),
        caustics_refractive=_bool(r, "caustics_refractive", p, True),
        mist=_mist(r, p),
        data_passes=_pass_list(r, p, "data_passes", DATA_PASSES, "data pass"),
        light_passes=_pass_list(r, p, "light_passes", LIGHT_PASSES, "light pass"),
        cryptomatte=_pass_list(r, p, "cryptomatte", CRYPTO_LAYERS, "Cryptomatte layer"),
        cryptomatte_levels=_number(r, "cryptomatte_levels", p, 6, lo=MIN_LEVELS, hi=MAX_LEVELS, integer=True),
        ao_distance=_number(r, "ao_distance", p, 10.0, lo=0, lo_open=True),
        pass_alpha_threshold=_number(r, "pass_alpha_threshold", p, 0.5, lo=0, hi=1),
        shutter=shutter,
        direct=_enum(r, "direct", p, DIRECT_STRATEGIES, "MIS_POWER"),
        indirect=_enum(r, "indirect", p, INDIRECT_STRATEGIES, "BSDF"),
        adaptive_threshold=_number(r, "adaptive_threshold", p, 0.0, lo=0, hi=1),
        adaptive_min_samples=_number(r, "adaptive_min_samples", p, 0, lo=0, hi=MAX_SPP, integer=True),
        **bounces,
    )


def _panorama(c: dict, p: str) -> PanoramaSpec:
    """A panoramic camera's ``"panorama"`` object (absent fields: Blender's defaults)."""
    from .panorama import PANORAMA_TYPES

    pp = f"{p}.panorama"
    d = _get(c, "panorama", p, {})
    if not isinstance(d, dict):
        raise SceneError(pp, "must be an object")
    base = PanoramaSpec()
    pi, half = math.pi + 1e-6, 0.5 * math.pi + 1e-6  # (Blender stores π and π/2 as float32, a bit above)
    poly = _vector(d, "polynomial", pp, 5, default=list(base.polynomial))
    spec = PanoramaSpec(
        type=_enum(d, "type", pp, PANORAMA_TYPES, base.type),
        fisheye_fov=_number(d, "fisheye_fov", pp, base.fisheye_fov, lo=0, lo_open=True, hi=2 * pi),
        fisheye_lens=_number(d, "fisheye_lens", pp, base.fisheye_lens, lo=MIN_CAMERA_LENGTH),
        latitude_min=_number(d, "latitude_min", pp, base.latitude_min, lo=-half, hi=half),
        latitude_max=_number(d, "latitude_max", pp, base.latitude_max, lo=-half, hi=half),
        longitude_min=_number(d, "longitude_min", pp, base.longitude_min, lo=-pi, hi=pi),
        longitude_max=_number(d, "longitude_max", pp, base.longitude_max, lo=-pi, hi=pi),
        polynomial=tuple(float(k) for k in poly))
    return spec


def _camera(h: dict) -> CameraSpec:
    p = "camera"
    c = _get(h, "camera", "")
    dof = _get(c, "dof", p, {})
    dp = "camera.dof"
    cam = CameraSpec(
        type=_enum(c, "type", p, CAMERA_TYPES, "PERSP"),
        matrix=_matrix(c, "matrix_world", p),
        lens=_number(c, "lens", p, 50.0, lo=MIN_CAMERA_LENGTH),
        sensor_width=_number(c, "sensor_width", p, 36.0, lo=MIN_CAMERA_LENGTH),
        sensor_height=_number(c, "sensor_height", p, 24.0, lo=MIN_CAMERA_LENGTH),
        sensor_fit=_enum(c, "sensor_fit", p, SENSOR_FITS, "AUTO"),
        shift_x=_number(c, "shift_x", p, 0.0),
        shift_y=_number(c, "shift_y", p, 0.0),
        clip_start=_number(c, "clip_start", p, 0.1, lo=0),
        clip_end=_number(c, "clip_end", p, 1000.0, lo=0, lo_open=True),
        ortho_scale=_number(c, "ortho_scale", p, 7.0, lo=MIN_CAMERA_LENGTH),
        dof_use=_bool(dof, "use", dp, False),
        focus_distance=_number(dof, "focus_distance", dp, 10.0, lo=0),
        fstop=_number(dof, "fstop", dp, 2.8, lo=0, lo_open=True),
        blades=_number(dof, "blades", dp, 0, lo=0, hi=64, integer=True),
        rotation=_number(dof, "rotation", dp, 0.0),
        ratio=_number(dof, "ratio", dp, 1.0, lo=0, lo_open=True),
        motion=_motion(c, "motion", p),
        panorama=_panorama(c, p) if c.get("type") == "PANO" else None,
    )
    if cam.clip_end <= cam.clip_start:
        raise SceneError("camera.clip_end", f"must be greater than clip_start ({cam.clip_start}), got {cam.clip_end}")
    return cam


def _materials(h: dict, n_images: int = 0, n_attributes: int = 0, version: int = 2) -> list[dict]:
    from .materials.program_format import validate_program

    mats = _list(h, "materials", "")
    out = []
    for i, m in enumerate(mats):
        p = f"materials[{i}]"
        if not isinstance(m, dict):
            raise SceneError(p, "must be an object")
        lobes = _list(m, "lobes", p)
        clean = []
        for j, lobe in enumerate(lobes):
            lp = f"{p}.lobes[{j}]"
            t = _enum(lobe, "type", lp, LOBE_TYPES)
            entry = {"type": t, "color": _vector(lobe, "color", lp, 3, lo=0.0).tolist()}
            if t in ("GLOSSY", "GLASS", "DIELECTRIC_SPECULAR", "METALLIC", "REFRACTION", "SHEEN",
                     "VELVET"):
                entry["roughness"] = _number(lobe, "roughness", lp, 0.0 if t in ("GLASS", "REFRACTION") else 0.5,
                                             lo=0, hi=1)
            if t == "DIELECTRIC_SPECULAR":  # the Principled BSDF's specular layer (issue 11)
                entry["ior"] = _number(lobe, "ior", lp, 1.5, lo=0, lo_open=True, hi=100)
                entry["tint"] = _vector(lobe, "tint", lp, 3, default=[1, 1, 1], lo=0.0).tolist()
                entry["multiscatter"] = _bool(lobe, "multiscatter", lp, True) if "multiscatter" in lobe else True
            if t == "METALLIC":  # the Principled BSDF's metal (issue 11): colour = weight × base
                entry["tint"] = _vector(lobe, "tint", lp, 3, default=[1, 1, 1], lo=0.0).tolist()
                entry["multiscatter"] = _bool(lobe, "multiscatter", lp, True) if "multiscatter" in lobe else True
                entry["weight"] = _number(lobe, "weight", lp, 1.0, lo=0, lo_open=True)
            if "layer" in lobe:  # the index of the layer lobe (specular, coat, sheen) this one lies under
                entry["layer"] = _number(lobe, "layer", lp, integer=True, lo=0, hi=len(lobes) - 1)
            if "layer_weight" in lobe:  # a coat / sheen layer's weight relative to what lies under it
                entry["layer_weight"] = _number(lobe, "layer_weight", lp, 1.0, lo=0)
            if "frame" in lobe:  # COAT: shaded about the coat normal; SHEEN: about its mix with the normal
                entry["frame"] = _enum(lobe, "frame", lp, ("COAT", "SHEEN"))
                if (entry["frame"], t) not in (("COAT", "DIELECTRIC_SPECULAR"), ("SHEEN", "SHEEN")):
                    raise SceneError(lp + ".frame", f"{entry['frame']} is only allowed on a "
                                     f"{'DIELECTRIC_SPECULAR' if entry['frame'] == 'COAT' else 'SHEEN'} lobe")
            if "coat_tint" in lobe:  # a coat's tint: absorption of the lobes under it
                entry["coat_tint"] = _vector(lobe, "coat_tint", lp, 3, default=[1, 1, 1], lo=0.0).tolist()
            if t in ("GLASS", "REFRACTION"):
                entry["ior"] = _number(lobe, "ior", lp, 1.45, lo=0, lo_open=True, hi=100)
            if t == "GLASS" and "reflection_weight" in lobe:  # a Principled transmission (issue 11)
                entry["reflection_weight"] = _number(lobe, "reflection_weight", lp, 1.0, lo=0)
            if t in ("GLASS", "GLOSSY") and "multiscatter_tint" in lobe:  # Multiscatter GGX: Fss (issue 11)
                entry["multiscatter_tint"] = _vector(lobe, "multiscatter_tint", lp, 3, lo=0.0).tolist()
            if t == "SUBSURFACE":
                if version < 2:
                    raise SceneError(lp + ".type", "SUBSURFACE lobes need scene version >= 2")
                entry["radius"] = _vector(lobe, "radius", lp, 3, lo=0.0).tolist()
                entry["method"] = _enum(lobe, "method", lp, SSS_METHODS) if "method" in lobe else "RANDOM_WALK"
                entry["ior"] = _number(lobe, "ior", lp, 1.4, lo=0, lo_open=True, hi=100)
                entry["roughness"] = _number(lobe, "roughness", lp, 1.0, lo=0, hi=1)
                entry["anisotropy"] = _number(lobe, "anisotropy", lp, 0.0, lo=-1, hi=1)
                entry["weight"] = _number(lobe, "weight", lp, 1.0, lo=0, lo_open=True)
            for key in ("color_reg", "roughness_reg", "weight_reg", "layer_weight_reg", "coat_tint_reg",
                        "ior_reg", "ior_level_reg", "tint_reg"):
                if key in lobe:
                    entry[key] = _number(lobe, key, lp, integer=True, lo=0)
            clean.append(entry)
        mat = {
            "name": str(_get(m, "name", p, f"material{i}")),
            "lobes": clean,
            "emission": _vector(m, "emission", p, 3, default=[0, 0, 0], lo=0.0).tolist(),
        }
        if "cryptomatte" in m:  # the name Cryptomatte's material layer hashes (default: "name")
            cname = _get(m, "cryptomatte", p)
            if not isinstance(cname, str) or not cname:
                raise SceneError(f"{p}.cryptomatte", f"must be a non-empty name, got {cname!r}")
            mat["cryptomatte"] = cname
        if "pass_index" in m:  # Material > Settings > Pass Index (the Material Index pass)
            mat["pass_index"] = _number(m, "pass_index", p, integer=True, lo=0, hi=2**31 - 1)
        if "emission_layer" in m:  # the coat / sheen lobe over a Principled's emission (issue 11)
            mat["emission_layer"] = _number(m, "emission_layer", p, integer=True, lo=0, hi=max(len(lobes) - 1, 0))
        volume = _medium(m, p)
        if volume is not None:
            mat["volume"] = volume
        if "surface" in m:
            mat["surface"] = _bool(m, "surface", p)
        if "light" in m:  # false: emission found by BSDF rays only (Cycles's Emission Sampling None)
            mat["light"] = _bool(m, "light", p)
        if m.get("program") is not None:
            try:
                mat["program"] = validate_program(m["program"], n_images, f"{p}.program", n_attributes)
            except ValueError as e:  # "materials[i].program.field: problem"
                where, _, problem = str(e).partition(": ")
                raise SceneError(where, problem) from None
            if "emission_reg" in m:
                mat["emission_reg"] = _number(m, "emission_reg", p, integer=True, lo=0)
            if "normal_reg" in m:
                mat["normal_reg"] = _number(m, "normal_reg", p, integer=True, lo=0)
            if "coat_normal_reg" in m:  # a Principled Coat Normal driven apart from Normal
                mat["coat_normal_reg"] = _number(m, "coat_normal_reg", p, integer=True, lo=0)
            elif "coat_normal" in m:  # "SMOOTH": an unlinked Coat Normal (the unmapped normal)
                mat["coat_normal"] = _enum(m, "coat_normal", p, ("SMOOTH",))
        for key in ("density_reg", "color_reg"):
            if volume is not None and key in volume:
                prog = mat.get("program")
                if prog is None or not volume[key] < prog["registers"]:
                    raise SceneError(f"{p}.volume.{key}", "must be a register of the material's program")
        out.append(mat)
    return out


def _medium(d: dict, path: str) -> dict | None:
    """The optional ``volume`` of a material or the world (drt.volumes.media), validated."""
    if d.get("volume") is None:
        return None
    from .volumes.media import validate_medium

    try:
        return validate_medium(d["volume"], f"{path}.volume")
    except ValueError as e:  # "path.volume.field: problem"
        where, _, problem = str(e).partition(": ")
        raise SceneError(where, problem) from None


#: largest world importance-map side (the map is W × H float64 pairs: 8192 × 4096 → 0.5 GB)
MAX_WORLD_MAP_RESOLUTION = 8192


def _world_program(world: dict, n_images: int) -> dict | None:
    """The world's validated ``program`` with its ``radiance_reg`` and ``map_size``
    (docs/scene-format.md), or None for a constant world."""
    from .materials.program_format import validate_program

    if not isinstance(world, dict):
        raise SceneError("world", "must be an object")
    if world.get("program") is None:
        return None
    try:
        prog = validate_program(world["program"], n_images, "world.program")
    except ValueError as e:
        where, _, problem = str(e).partition(": ")
        raise SceneError(where, problem) from None
    prog["radiance_reg"] = _number(world, "radiance_reg", "world", integer=True, lo=0,
                                   hi=prog["registers"] - 1)
    size = _get(world, "map_size", "world", [1024, 512])
    if not isinstance(size, (list, tuple)) or len(size) != 2:
        raise SceneError("world.map_size", f"must be [width, height], got {size!r}")
    w, h = (_number({"map_size": v}, "map_size", "world", integer=True, lo=0, hi=MAX_WORLD_MAP_RESOLUTION)
            for v in size)
    if (w == 0) != (h == 0):
        raise SceneError("world.map_size", f"must be [0, 0] (no importance sampling) or both > 0, got {size!r}")
    prog["map_size"] = (w, h)
    return prog


def _images(h: dict, arrays: dict) -> list:
    """The header's ``images`` with their pixel arrays ((H, W, 4) uint8 or float16)."""
    out = []
    for i, img in enumerate(_list(h, "images", "") if "images" in h else []):
        p = f"images[{i}]"
        if not isinstance(img, dict):
            raise SceneError(p, "must be an object")
        name = str(_get(img, "array", p))
        a = arrays.get(name)
        if not isinstance(a, np.ndarray) or a.dtype not in (np.uint8, np.float16, np.float32) \
                or a.ndim != 3 or a.shape[2] != 4:
            raise SceneError(name, "must be an (H, W, 4) uint8 or float16 array")
        w = _number(img, "width", p, integer=True, lo=1)
        hgt = _number(img, "height", p, integer=True, lo=1)
        if a.shape[:2] != (hgt, w):
            raise SceneError(name, f"has shape {a.shape}, expected ({hgt}, {w}, 4)")
        if a.dtype != np.uint8 and not np.all(np.isfinite(a)):
            raise SceneError(name, "contains NaN or infinite values")
        info = {"name": str(img.get("name", name)), "width": w, "height": hgt,
                "srgb": _bool(img, "srgb", p, False)}
        out.append((info, a))
    return out


#: largest light radius / size in metres (10¹⁵ m, ~7000 au): beyond any scene, and small enough
#: that squares and areas stay finite in float64
MAX_LIGHT_SIZE = 1e15


def _lights(h: dict) -> list[dict]:
    lights = _list(h, "lights", "")
    out = []
    for i, li in enumerate(lights):
        p = f"lights[{i}]"
        t = _enum(li, "type", p, LIGHT_TYPES)
        e = {
            "name": str(_get(li, "name", p, f"light{i}")),
            "type": t,
            "matrix_world": _matrix(li, "matrix_world", p).tolist(),
            "color": _vector(li, "color", p, 3, default=[1, 1, 1], lo=0.0).tolist(),
            # Blender 5.0 lights are invisible to camera rays by default (object.visible_camera)
            "visible_camera": _bool(li, "visible_camera", p, _bool(li, "visible_to_camera", p, False)),
        }
        if t == "SUN":
            e["strength"] = _number(li, "strength", p, 1.0, lo=0)
            e["angle"] = _number(li, "angle", p, 0.00918043, lo=0, hi=math.pi)
        else:
            e["power"] = _number(li, "power", p, 10.0, lo=0)
        if t in ("POINT", "SPOT"):
            e["radius"] = _number(li, "radius", p, 0.1, lo=0, hi=MAX_LIGHT_SIZE)
            e["soft_falloff"] = _bool(li, "soft_falloff", p, True)
        if t == "SPOT":
            e["spot_size"] = _number(li, "spot_size", p, math.radians(45), lo=0, hi=math.pi)
            e["spot_blend"] = _number(li, "spot_blend", p, 0.15, lo=0, hi=1)
        if t == "AREA":
            e["shape"] = _enum(li, "shape", p, AREA_SHAPES, "SQUARE")
            e["size"] = _number(li, "size", p, 1.0, lo=0, hi=MAX_LIGHT_SIZE)
            e["size_y"] = _number(li, "size_y", p, e["size"], lo=0, hi=MAX_LIGHT_SIZE)
            e["spread"] = _number(li, "spread", p, math.pi, lo=0, hi=math.pi)
        out.append(e)
    return out


def _array(arrays: dict, name: str, kinds: str, ndim: int, shape_tail=()) -> np.ndarray:
    if name not in arrays:
        raise SceneError(name, "array is missing")
    a = arrays[name]
    if not isinstance(a, np.ndarray):
        raise SceneError(name, "must be a numpy array")
    if a.dtype.kind not in kinds:
        raise SceneError(name, f"has dtype {a.dtype}, expected {'an integer' if kinds == 'iu' else 'a float'} dtype")
    if a.ndim != ndim or tuple(a.shape[1:]) != tuple(shape_tail):
        want = "(N, " + ", ".join(str(s) for s in shape_tail) + ")" if shape_tail else "(N,)"
        raise SceneError(name, f"has shape {a.shape}, expected {want}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise SceneError(name, "contains NaN or infinite values")
    return a


def _meshes(h: dict, arrays: dict, n_materials: int, n_attributes: int = 0) -> list[MeshData]:
    meshes = _list(h, "meshes", "")
    out = []
    for k, m in enumerate(meshes):
        p = f"meshes[{k}]"
        if not isinstance(m, dict):
            raise SceneError(p, "must be an object")
        pre = f"mesh{k}."
        pos = _array(arrays, pre + "positions", "f", 2, (3,)).astype(np.float64)
        tri = _array(arrays, pre + "triangles", "iu", 2, (3,)).astype(np.int64)
        if tri.size and (tri.min() < 0 or tri.max() >= len(pos)):
            raise SceneError(pre + "triangles", f"indices must lie in [0, {len(pos) - 1}], found {int(tri.min())}..{int(tri.max())}")
        if pre + "material_index" in arrays:
            mi = _array(arrays, pre + "material_index", "iu", 1).astype(np.int64)
            if len(mi) != len(tri):
                raise SceneError(pre + "material_index", f"has {len(mi)} entries for {len(tri)} triangles")
        else:
            mi = np.zeros(len(tri), np.int64)
        if mi.size and (mi.min() < 0 or mi.max() >= max(n_materials, 1)):
            raise SceneError(pre + "material_index", f"indices must lie in [0, {max(n_materials, 1) - 1}]")
        normals = uvs = close = None
        if pre + "normals" in arrays:
            normals = _array(arrays, pre + "normals", "f", 3, (3, 3))
            if len(normals) != len(tri):
                raise SceneError(pre + "normals", f"has {len(normals)} triangles, expected {len(tri)}")
        if pre + "uvs" in arrays:
            uvs = _array(arrays, pre + "uvs", "f", 3, (3, 2))
            if len(uvs) != len(tri):
                raise SceneError(pre + "uvs", f"has {len(uvs)} triangles, expected {len(tri)}")
        if _bool(m, "deforming", p, False):
            close = _array(arrays, pre + "positions_close", "f", 2, (3,)).astype(np.float64)
            if close.shape != pos.shape:
                raise SceneError(pre + "positions_close", f"has shape {close.shape}, expected {pos.shape}")
        attrs = {}
        for attr in ("generated", "object_coords") + tuple(f"attr{i}" for i in range(n_attributes)):
            if pre + attr in arrays:
                attrs[attr] = _array(arrays, pre + attr, "f", 3, (3, 3))
                if len(attrs[attr]) != len(tri):
                    raise SceneError(pre + attr, f"has {len(attrs[attr])} triangles, expected {len(tri)}")
        out.append(MeshData(str(m.get("name", f"mesh{k}")), pos, tri, mi, normals, uvs, close, attrs))
    return out


def _visibility(o: dict, p: str) -> int:
    """An object's ``"visibility"`` ({ray kind: bool}, kinds of RAY_VISIBILITY, absent: true)
    as VIS_* bits."""
    vis = _get(o, "visibility", p, None)
    if vis is None:
        return VIS_ALL
    vp = f"{p}.visibility"
    if not isinstance(vis, dict):
        raise SceneError(vp, f"must be an object of {', '.join(RAY_VISIBILITY)} flags")
    unknown = sorted(set(vis) - set(RAY_VISIBILITY))
    if unknown:
        raise SceneError(f"{vp}.{unknown[0]}", f"is not a ray kind (one of {', '.join(RAY_VISIBILITY)})")
    return sum(1 << k for k, kind in enumerate(RAY_VISIBILITY) if _bool(vis, kind, vp, True))


def _crypto_names(o: dict, p: str, name: str) -> tuple[str, str]:
    """An object's ``"cryptomatte": {"object": name, "asset": name}`` (each default ``name``)."""
    c = _get(o, "cryptomatte", p, None)
    if c is None:
        return name, name
    if not isinstance(c, dict):
        raise SceneError(f"{p}.cryptomatte", "must be an object with object / asset names")
    names = []
    for key in ("object", "asset"):
        v = c.get(key, name)
        if not isinstance(v, str) or not v:
            raise SceneError(f"{p}.cryptomatte.{key}", f"must be a non-empty name, got {v!r}")
        names.append(v)
    return names[0], names[1]


def _objects(h: dict, n_meshes: int) -> list[ObjectSpec]:
    objs = _list(h, "objects", "")
    out = []
    for i, o in enumerate(objs):
        p = f"objects[{i}]"
        mesh = _number(o, "mesh", p, integer=True, lo=0)
        if mesh >= n_meshes:
            raise SceneError(f"{p}.mesh", f"refers to mesh {mesh} but the scene has {n_meshes} meshes")
        info = None
        if o.get("info") is not None:
            inf = _get(o, "info", p, {})
            info = np.concatenate([_vector(inf, "color", f"{p}.info", 3, default=[1, 1, 1]),
                                   [_number(inf, "alpha", f"{p}.info", default=1.0),
                                    _number(inf, "pass_index", f"{p}.info", default=0.0),
                                    _number(inf, "random", f"{p}.info", default=0.0, lo=0.0)]])
        term = _get(o, "shadow_terminator", p, {}) if o.get("shadow_terminator") is not None else {}
        if not isinstance(term, dict):
            raise SceneError(f"{p}.shadow_terminator", "must be an object with geometry_offset / shading_offset")
        tp = f"{p}.shadow_terminator"
        out.append(ObjectSpec(str(o.get("name", f"object{i}")), mesh, _matrix(o, "matrix_world", p),
                              _motion(o, "motion", p), info,
                              _number(term, "geometry_offset", tp, default=0.0, lo=0.0, hi=1.0),
                              _number(term, "shading_offset", tp, default=0.0, lo=0.0, hi=1.0),
                              _visibility(o, p), _bool(o, "holdout", p, False),
                              _number(o, "pass_index", p, 0, lo=0, hi=2**31 - 1, integer=True),
                              *_crypto_names(o, p, str(o.get("name", f"object{i}")))))
    return out


def scene_from_dict(header: dict, arrays: dict | None = None) -> Scene:
    """Validate an exported scene (header dict + arrays) and build a ``Scene``.

    Raises ``SceneError`` naming the first bad field. Arrays are not copied unless converted.
    """
    arrays = arrays or {}
    if not isinstance(header, dict):
        raise SceneError("header", "must be a JSON object")
    fmt = header.get("format")
    if fmt != FORMAT_NAME:
        raise SceneError("format", f"must be '{FORMAT_NAME}', got {fmt!r}")
    version = header.get("version")
    if isinstance(version, bool) or version not in SUPPORTED_VERSIONS:
        raise SceneError("version", f"{version!r} is not supported (this DRT reads versions {', '.join(map(str, SUPPORTED_VERSIONS))})")
    render = _render_settings(header)
    camera = _camera(header)
    world = _get(header, "world", "", {"color": [0, 0, 0]})
    world_color = _vector(world, "color", "world", 3, default=[0, 0, 0], lo=0.0)
    world_volume = _medium(world, "world")
    images = _images(header, arrays)
    attributes = _list(header, "attributes", "") if "attributes" in header else []
    if not all(isinstance(a, str) for a in attributes):
        raise SceneError("attributes", "must be a list of names")
    world_program = _world_program(world, len(images))
    materials = _materials(header, len(images), len(attributes), version)
    lights = _lights(header)
    meshes = _meshes(header, arrays, len(materials), len(attributes))
    objects = _objects(header, len(meshes))
    if not materials and any(len(m.triangles) for m in meshes):
        # Geometry without materials renders as a neutral grey diffuse (Blender's default look).
        materials = [{"name": "default", "lobes": [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}], "emission": [0, 0, 0]}]
    return Scene(render, camera, world_color, materials, lights, meshes, objects, header, arrays, images,
                 list(attributes), world_volume, world_program)
