"""The scene's participating media as arrays, their validation, and Blender's volume nodes as
coefficients (Cycles's svm_node_principled_volume / svm_node_closure_volume, Blender 5.0).

A medium is homogeneous and given per material (scene file: ``materials[i].volume``) and for
the world (``world.volume``), in Cycles's units, per metre of scene length::

    {"scatter": [r, g, b],      # σs (1/m)
     "absorption": [r, g, b],   # σa (1/m); extinction σt = σs + σa
     "emission": [r, g, b],     # emitted radiance per metre, W/(m³·sr) (added as σe·dt)
     "anisotropy": g}           # Henyey-Greenstein g in [-1, 1]

A material whose node tree has a Volume output but nothing on its Surface output has
``"surface": false``: its triangles only bound the medium and rays pass through them (Cycles).

``MediumData`` rows: one per material (zero coefficients for materials without a volume), then
the world's row (index M). Kernels read the coefficients of a *stack key*
``object * stride + row`` (``drt.volumes.stack``) through ``key % stride``.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

#: Stefan-Boltzmann σ / π in Cycles's blackbody scale (W/(m²·sr·K⁴) × 1e-6: Cycles's constant)
_BLACKBODY_SIGMA = 5.670373e-8 * 1e-6 / math.pi

MediumData = namedtuple("MediumData", [
    "enabled",        # bool: the scene has a medium (else kernels skip everything)
    "sigma_s",        # (K, 3) f64 scattering coefficient 1/m (K = materials + 1, last: world)
    "sigma_t",        # (K, 3) f64 extinction σs + σa, 1/m
    "emission",       # (K, 3) f64 radiance per metre
    "g",              # (K,) f64 HG anisotropy
    "is_medium",      # (K,) bool: the row has any coefficient
    "pass_through",   # (M,) bool: material without surface (rays cross its triangles)
    "stride",         # int: rows per object in a stack key (K)
    "world_key",      # int: stack key of the world medium, −1: none
    "tri_object",     # (T,) int32 object index of each global triangle ((0,) when disabled)
    "camera_stack",   # (VS,) int64: the stack of rays leaving the camera (−1: empty slot)
    # heterogeneous media (drt.volumes.hetero; all rows −1 / zero-size when there are none):
    "hetero",         # bool: some row's density comes from its material's program
    "density_reg",    # (K,) int64 register of the row's density (x channel), −1: constant 1
    "color_reg",      # (K,) int64 register of the row's colour (σs = S·c, σa = A·(1 − c)), −1: none
    "density_prog",   # (K,) int64 the row's material program, −1: a homogeneous row
    "majorant",       # (K,) f64 bound on the row's σt / its largest constant σt (1: homogeneous)
    "coord_map",      # (O, 6, 4) f64 per object: shifted world → Generated (rows 0–2), → Object (3–5)
])


def _fail(where: str, msg: str) -> ValueError:
    return ValueError(f"{where}: {msg}")


def validate_medium(v, where: str) -> dict:
    """A scene-file ``volume`` dict checked and normalised (raises ValueError naming the field)."""
    if not isinstance(v, dict):
        raise _fail(where, f"must be an object, got {type(v).__name__}")
    unknown = set(v) - {"scatter", "absorption", "emission", "anisotropy", "density_reg", "color_reg"}
    if unknown:
        raise _fail(f"{where}.{sorted(unknown)[0]}", "unknown field")
    out = {}
    for key in ("scatter", "absorption", "emission"):
        val = v.get(key, [0.0, 0.0, 0.0])
        try:
            a = np.asarray(val, dtype=np.float64)
        except (TypeError, ValueError):
            raise _fail(f"{where}.{key}", "must be a list of 3 numbers") from None
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a < 0) or np.any(a > 1e30):
            raise _fail(f"{where}.{key}", f"must be 3 finite numbers in [0, 1e30], got {val!r}")
        out[key] = [float(x) for x in a]
    g = v.get("anisotropy", 0.0)
    if isinstance(g, bool) or not isinstance(g, (int, float)) or not -1.0 <= g <= 1.0:
        raise _fail(f"{where}.anisotropy", f"must be a number in [-1, 1], got {g!r}")
    out["anisotropy"] = float(g)
    for key in ("density_reg", "color_reg"):
        if key in v:
            r = v[key]
            if isinstance(r, bool) or not isinstance(r, int) or r < 0:
                raise _fail(f"{where}.{key}", f"must be a register index >= 0, got {r!r}")
            if max(out["emission"]) > 0.0:
                raise _fail(f"{where}.emission", f"must be 0 in a heterogeneous medium ({key})")
            out[key] = r
    return out


def has_any(medium: dict | None) -> bool:
    return bool(medium) and any(max(medium[k]) > 0.0 for k in ("scatter", "absorption", "emission"))


# --------------------------------------------------------------------- Blender's volume nodes

# Cycles's fit of the blackbody colour in Rec.709 (kernel/tables.h, svm_math_blackbody_color_rec709):
# R, G = a/T + b·T + c, B = ((a·T + b)·T + c)·T + d, piecewise over 800–12000 K
_BB_EDGES = (965.0, 1167.0, 1449.0, 1902.0, 3315.0, 6365.0)
_BB_R = ((1.61919106e+03, -2.05010916e-03, 5.02995757e+00), (2.48845471e+03, -1.11330907e-03, 3.22621544e+00),
         (3.34143193e+03, -4.86551192e-04, 1.76486769e+00), (4.09461742e+03, -1.27446582e-04, 7.25731635e-01),
         (4.67028036e+03, 2.91258199e-05, 1.26703442e-01), (4.59509185e+03, 2.87495649e-05, 1.50345020e-01),
         (3.78717450e+03, 9.35907826e-06, 3.99075871e-01))
_BB_G = ((-4.88999748e+02, 6.04330754e-04, -7.55807526e-02), (-7.55994277e+02, 3.16730098e-04, 4.78306139e-01),
         (-1.02363977e+03, 1.20223470e-04, 9.36662319e-01), (-1.26571316e+03, 4.87340896e-06, 1.27054498e+00),
         (-1.42529332e+03, -4.01150431e-05, 1.43972784e+00), (-1.17554822e+03, -2.16378048e-05, 1.30408023e+00),
         (-5.00799571e+02, -4.59832026e-06, 1.09098763e+00))
_BB_B = ((5.96945309e-11, -4.85742887e-08, -9.70622247e-05, -4.07936148e-03),
         (2.40430366e-11, 5.55021075e-08, -1.98503712e-04, 2.89312858e-02),
         (-1.40949732e-11, 1.89878968e-07, -3.56632824e-04, 9.10767778e-02),
         (-3.61460868e-11, 2.84822009e-07, -4.93211319e-04, 1.56723440e-01),
         (-1.97075738e-11, 1.75359352e-07, -2.50542825e-04, -2.22783266e-02),
         (-1.61997957e-13, -1.64216008e-08, 3.86216271e-04, -7.38077418e-01),
         (6.72650283e-13, -2.73078809e-08, 4.24098264e-04, -7.52335691e-01))


def blackbody_rgb_of(t: float) -> np.ndarray:
    """Rec.709 colour of a blackbody at t kelvin, Cycles's fit (may be negative: wide gamut;
    Blender's default scene-linear space is Rec.709, so no further conversion)."""
    if t >= 12000.0:
        return np.array([0.8262954810464208, 0.9945080501520986, 1.566307710274283])
    if t < 800.0:
        return np.array([5.413294490189271, -0.20319390035873933, -0.0822535242887164])
    i = sum(t >= e for e in _BB_EDGES)
    r, g, b = _BB_R[i], _BB_G[i], _BB_B[i]
    return np.array([r[0] / t + r[1] * t + r[2], g[0] / t + g[1] * t + g[2],
                     ((b[0] * t + b[1]) * t + b[2]) * t + b[3]])


def principled_volume(color, density, anisotropy=0.0, absorption_color=(0.0, 0.0, 0.0),
                      emission_strength=0.0, emission_color=(1.0, 1.0, 1.0),
                      blackbody_intensity=0.0, blackbody_tint=(1.0, 1.0, 1.0),
                      temperature=1000.0, blackbody_rgb=None, weight=1.0) -> dict:
    """Principled Volume → medium (Cycles 5.0 svm_node_principled_volume): σs = density·color,
    σa = density·max(1 − color, 0)·max(1 − √absorption_color, 0), emission = strength·colour
    (not scaled by density) + blackbody σ_SB/π·mix(1, T⁴, intensity)·tint·rgb(T).
    ``blackbody_rgb``: the Rec.709 colour of temperature T (None: ``blackbody_rgb(T)``,
    Cycles's table by default); ``weight``: a Mix/Add shader factor."""
    c = np.maximum(np.asarray(color, dtype=np.float64), 0.0)
    dens = max(float(density), 0.0) * weight
    ac = np.sqrt(np.maximum(np.asarray(absorption_color, dtype=np.float64), 0.0))
    sigma_s = dens * c
    sigma_a = dens * np.maximum(1.0 - c, 0.0) * np.maximum(1.0 - ac, 0.0)
    emission = max(float(emission_strength), 0.0) * np.asarray(emission_color, dtype=np.float64) * weight
    if blackbody_intensity > 0.0:
        t = max(float(temperature), 0.0)
        if blackbody_rgb is None:
            blackbody_rgb = blackbody_rgb_of(t)
        intensity = _BLACKBODY_SIGMA * (1.0 + (t ** 4 - 1.0) * blackbody_intensity)
        emission = emission + intensity * np.asarray(blackbody_tint, float) * np.asarray(blackbody_rgb, float) * weight
    return {"scatter": sigma_s.tolist(), "absorption": sigma_a.tolist(),
            "emission": np.maximum(emission, 0.0).tolist(), "anisotropy": float(anisotropy)}


def volume_absorption(color, density, weight=1.0) -> dict:
    """Volume Absorption → σa = density·(1 − color) (Cycles: the closure weight is 1 − color)."""
    dens = max(float(density), 0.0) * weight
    sigma_a = dens * np.maximum(1.0 - np.asarray(color, dtype=np.float64), 0.0)
    return {"scatter": [0.0] * 3, "absorption": sigma_a.tolist(), "emission": [0.0] * 3, "anisotropy": 0.0}


def volume_scatter(color, density, anisotropy=0.0, weight=1.0) -> dict:
    """Volume Scatter (Henyey-Greenstein) → σs = density·color, no absorption."""
    dens = max(float(density), 0.0) * weight
    sigma_s = dens * np.maximum(np.asarray(color, dtype=np.float64), 0.0)
    return {"scatter": sigma_s.tolist(), "absorption": [0.0] * 3, "emission": [0.0] * 3,
            "anisotropy": float(anisotropy)}


def add_media(a: dict | None, b: dict | None) -> dict | None:
    """Add Shader of two media: coefficients add; g is the σs-weighted mean (one HG lobe: DRT
    keeps one lobe per medium, exact when both g agree)."""
    if not a:
        return b
    if not b:
        return a
    wa, wb = float(np.mean(a["scatter"])), float(np.mean(b["scatter"]))
    g = (wa * a["anisotropy"] + wb * b["anisotropy"]) / (wa + wb) if wa + wb > 0 else 0.0
    return {k: (np.asarray(a[k]) + np.asarray(b[k])).tolist() for k in ("scatter", "absorption", "emission")} | \
        {"anisotropy": float(g)}


def scale_medium(m: dict | None, w: float) -> dict | None:
    """A medium times a Mix Shader factor w (all coefficients are linear in the closure weight)."""
    if not m:
        return m
    return {k: (np.asarray(m[k]) * w).tolist() for k in ("scatter", "absorption", "emission")} | \
        {"anisotropy": m["anisotropy"]}


# --------------------------------------------------------------------- the arrays

STACK_SIZE = 8  # volume stack slots per path (Cycles's default volume_stack_size is 4 + world)


def build_medium_data(materials: list[dict], world_volume: dict | None, tri_material=None,
                      tri_object=None, camera_stack=None) -> MediumData:
    """The kernels' ``MediumData`` (disabled with zero-size arrays when nothing has a medium)."""
    m = len(materials)
    k = m + 1
    sigma_s = np.zeros((k, 3))
    sigma_a = np.zeros((k, 3))
    emission = np.zeros((k, 3))
    g = np.zeros(k)
    density_reg = np.full(k, -1, np.int64)
    color_reg = np.full(k, -1, np.int64)
    rows = list(enumerate(mat.get("volume") for mat in materials)) + [(m, world_volume)]
    for i, v in rows:
        if has_any(v):
            sigma_s[i], sigma_a[i], emission[i] = v["scatter"], v["absorption"], v["emission"]
            g[i] = v["anisotropy"]
            if i < m and materials[i].get("program") is not None:
                density_reg[i] = v.get("density_reg", -1)
                color_reg[i] = v.get("color_reg", -1)
    is_medium = np.any((sigma_s + sigma_a + emission) > 0.0, axis=1)
    pass_through = np.array([mat.get("surface", True) is False for mat in materials], dtype=bool)
    enabled = bool(is_medium.any() or pass_through.any())
    world_key = m if is_medium[m] else -1
    if camera_stack is None:
        camera_stack = np.full(STACK_SIZE, -1, np.int64)
        if world_key >= 0:
            camera_stack[0] = world_key
    return MediumData(
        enabled=enabled, sigma_s=sigma_s, sigma_t=sigma_s + sigma_a, emission=emission, g=g,
        is_medium=is_medium, pass_through=pass_through if m else np.zeros(1, bool), stride=k,
        world_key=world_key,
        tri_object=np.ascontiguousarray(tri_object if enabled and tri_object is not None
                                        else np.zeros(0), dtype=np.int32),
        camera_stack=np.ascontiguousarray(camera_stack, dtype=np.int64),
        hetero=bool(enabled and ((density_reg >= 0) | (color_reg >= 0)).any()), density_reg=density_reg,
        color_reg=color_reg,
        density_prog=np.full(k, -1, np.int64), majorant=np.ones(k), coord_map=np.zeros((1, 6, 4)))


def media_for_scene(materials: list[dict], world_volume: dict | None, geom) -> MediumData:
    """``MediumData`` of a scene's (validated) material dicts, world medium and geometry
    (``drt.geometry.SceneGeometry``); the camera's stack is filled by the ``Integrator``."""
    obj = getattr(geom, "object_id", None)
    if obj is None or len(obj) != len(geom.material):
        obj = np.zeros(len(geom.material), np.int32)
    md = build_medium_data(materials, world_volume, tri_object=obj)
    if md.enabled:
        # the camera stack is computed by the Integrator (it needs the tracer): mark it unknown
        md = md._replace(camera_stack=np.full(STACK_SIZE, -1, np.int64))
    return md


def world_blocks_infinity(md: MediumData) -> bool:
    """Does the world medium attenuate every channel (σt > 0)? Then nothing at infinity — the
    sun, the world background — reaches any point: a ray toward it crosses an infinite length of
    that medium, transmittance 0 (Cycles renders the same, black). Light selection then leaves
    those lights out instead of spending next-event samples on a contribution that is always 0
    (volume_world: DRT's relMSE was ~2× Cycles's with the sun in the selection, 1.16× without)."""
    if not md.enabled or md.world_key < 0:
        return False
    return bool((md.sigma_t[md.world_key % md.stride] > 0.0).all())


def lights_reaching(lights: list[dict], md: MediumData) -> list[dict]:
    """The light dicts that can deliver anything under ``md``: all of them, but no suns when the
    world medium blocks infinity (``world_blocks_infinity``)."""
    if not world_blocks_infinity(md):
        return lights
    return [light for light in lights if str(light.get("type", "")).upper() != "SUN"]
