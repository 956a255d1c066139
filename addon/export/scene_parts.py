"""Render settings, camera, lights and world → header dicts (docs/scene-format.md).

Blender's units and Cycles's meaning; conversions as measured in
../shared/docs/blender-conventions.md.
"""

import math

import numpy as np

from .. import compat
from .light_nodes import light_node_factor


class ExportError(Exception):
    """A scene DRT cannot render at all (no camera, panoramic camera, ...)."""


def matrix_list(m) -> list:
    """A mathutils 4×4 Matrix as a row-major nested list of floats."""
    return [[float(x) for x in row] for row in m]


def shadow_terminator(obj) -> dict:
    """The object's Cycles shadow terminator offsets (Object properties in Blender ≥ 3.0;
    geometry offset default 0.1, shading offset default 0), clamped to the format's [0, 1]."""
    def get(name):
        return min(max(float(getattr(obj, name, 0.0)), 0.0), 1.0)
    return {"geometry_offset": get("shadow_terminator_geometry_offset"),
            "shading_offset": get("shadow_terminator_shading_offset")}


def render_resolution(render) -> tuple[int, int]:
    """Final pixel count after the resolution percentage, as Blender computes it."""
    pct = render.resolution_percentage
    return (max(1, render.resolution_x * pct // 100), max(1, render.resolution_y * pct // 100))


def shutter_interval(render) -> list | None:
    """[open, close] in frames relative to the current frame, or None without motion blur.

    START / CENTER / END move the centre by +shutter/2, 0, −shutter/2.
    """
    if not render.use_motion_blur:
        return None
    s = float(render.motion_blur_shutter)
    if s <= 0:
        return None
    delta = {"START": 0.5 * s, "CENTER": 0.0, "END": -0.5 * s}.get(
        getattr(render, "motion_blur_position", "CENTER"), 0.0)
    return [delta - 0.5 * s, delta + 0.5 * s]


def pixel_filter(scene) -> dict:
    """The pixel filter Cycles renders the scene with: the Cycles add-on's Film > Pixel Filter
    (``scene.cycles.pixel_filter_type``, ``.filter_width``), not Blender's ``render.filter_size``
    (EEVEE's: Cycles ignores it). Cycles's box filter is one pixel wide whatever the width says
    (its UI hides the width then). Without the Cycles add-on: DRT's own type and Blender's Filter
    Size. The width is rounded to 6 decimals: Blender's float32 0.01 (the minimum) is
    0.00999999977, below the scene validator's 0.01."""
    cycles = getattr(scene, "cycles", None)
    if cycles is not None and hasattr(cycles, "pixel_filter_type"):
        kind, width = cycles.pixel_filter_type, cycles.filter_width
    else:
        kind, width = scene.drt.filter_type, scene.render.filter_size
    if kind == "BOX":
        width = 1.0
    return {"type": kind, "width": round(float(width), 6)}


def render_settings(scene, preview: bool = False) -> dict:
    r = scene.render
    d = scene.drt
    border = None
    if r.use_border:
        border = [float(r.border_min_x), float(r.border_min_y),
                  float(r.border_max_x), float(r.border_max_y)]
        if border == [0.0, 0.0, 1.0, 1.0]:
            border = None
    return {
        "resolution": list(render_resolution(r)),
        "pixel_aspect": [float(r.pixel_aspect_x), float(r.pixel_aspect_y)],
        "border": border,
        "film_transparent": bool(r.film_transparent),
        "filter": pixel_filter(scene),
        "spp": int(d.preview_samples if preview else d.samples),
        "seed": int(d.seed),
        "sampler": d.sampler,
        "max_bounces": int(d.max_bounces), "diffuse_bounces": int(d.diffuse_bounces),
        "glossy_bounces": int(d.glossy_bounces),
        "transmission_bounces": int(d.transmission_bounces),
        "clamp_direct": float(d.clamp_direct), "clamp_indirect": float(d.clamp_indirect),
        "shutter": shutter_interval(r),
    } | ({"volume_bounces": int(d.volume_bounces)} if getattr(d, "volume_bounces", 0) else {}) \
      | ({"transparent_bounces": int(d.transparent_bounces)}
         if getattr(d, "transparent_bounces", 8) != 8 else {}) \
      | ({"exposure": exposure} if (exposure := film_exposure(scene)) != 1.0 else {}) \
      | ({"film_transparent_roughness": glass} if (glass := transparent_glass(scene)) is not None else {}) \
      | ({"filter_glossy": blur} if (blur := filter_glossy(scene)) > 0.0 else {}) \
      | {f"caustics_{kind}": False for kind, on in caustics_switches(scene).items() if not on}


def _cycles_setting(scene, name: str, default):
    """Cycles's scene setting ``name``: from the Cycles add-on's properties, or, without the
    add-on, the value the file stored in its ID properties (``default`` if it never had one)."""
    cy = getattr(scene, "cycles", None)
    if cy is not None and hasattr(cy, name):
        return getattr(cy, name)
    stored = scene.get("cycles")
    return stored.get(name, default) if hasattr(stored, "get") else default


def mist_settings(world) -> dict:
    """The world's Mist Pass settings (World > Mist Pass: start, depth in scene units, falloff),
    which Cycles's Mist pass reads; Blender's defaults (5, 25, quadratic) without a world."""
    ms = getattr(world, "mist_settings", None)
    if ms is None:
        return {"start": 5.0, "depth": 25.0, "falloff": "QUADRATIC"}
    return {"start": float(ms.start), "depth": float(ms.depth), "falloff": str(ms.falloff)}


#: the view layer's data passes DRT renders: Blender's property → the scene format's name
DATA_PASS_PROPERTIES = (("use_pass_object_index", "object_index"), ("use_pass_material_index", "material_index"),
                        ("use_pass_position", "position"), ("use_pass_uv", "uv"))


#: the view layer's light passes DRT renders (Passes > Light > Other)
LIGHT_PASS_PROPERTIES = (("use_pass_emit", "emission"), ("use_pass_environment", "environment"),
                         ("use_pass_diffuse_color", "diffuse_color"), ("use_pass_ambient_occlusion", "ao"))


def data_pass_settings(view_layer) -> dict:
    """``render.data_passes`` (the data passes the view layer enables) and, with any, its Alpha
    Threshold (View Layer > Passes > Data: a surface more transparent than it is seen through);
    ``render.light_passes`` (the Emission, Environment and Diffuse Color passes it enables); {}
    without any."""
    out = {}
    names = [name for prop, name in DATA_PASS_PROPERTIES if getattr(view_layer, prop, False)]
    if names:
        out["data_passes"] = names
        out["pass_alpha_threshold"] = float(min(max(getattr(view_layer, "pass_alpha_threshold", 0.5), 0.0), 1.0))
    light = [name for prop, name in LIGHT_PASS_PROPERTIES if getattr(view_layer, prop, False)]
    if light:
        out["light_passes"] = light
    if "ao" in light:  # (World > Ambient Occlusion > Distance; a scene without a world: 10 m)
        world = getattr(getattr(view_layer, "id_data", None), "world", None)
        distance = getattr(getattr(world, "light_settings", None), "distance", 10.0)
        out["ao_distance"] = float(distance) if distance > 0.0 else 1e-6
    crypto = [layer for layer in ("object", "material", "asset")
              if getattr(view_layer, f"use_pass_cryptomatte_{layer}", False)]
    if crypto:  # (View Layer > Passes > Cryptomatte: its layers and Levels)
        out["cryptomatte"] = crypto
        out["cryptomatte_levels"] = int(min(max(getattr(view_layer, "pass_cryptomatte_depth", 6), 2), 16))
    return out


def cryptomatte_names(inst) -> dict:
    """An object instance's Cryptomatte names, as Cycles's object sync: ``object`` the object's
    own name (an instance: the instanced object's), ``asset`` its topmost parent's (itself
    without a parent)."""
    obj = inst.object
    top = obj  # (an instance's too: measured, Cycles names a collection instance's asset by it)
    seen = 0
    while top.parent is not None and seen < 1000:  # (a parent loop cannot happen; bounded anyway)
        top = top.parent
        seen += 1
    return {"object": obj.name, "asset": top.name}


def caustics_switches(scene) -> dict[str, bool]:
    """Cycles's Light Paths > Caustics > Reflective / Refractive (``scene.cycles.caustics_*``,
    on in a new file): off, a hit right after a diffuse bounce is shaded without the glossy
    reflection / refraction closures (drt.materials.caustics)."""
    return {kind: bool(_cycles_setting(scene, f"caustics_{kind}", True)) for kind in ("reflective", "refractive")}


def filter_glossy(scene) -> float:
    """Cycles's Light Paths > Caustics > Filter Glossy (``scene.cycles.blur_glossy``), which
    widens glossy lobes after unlikely bounces (drt.path_stages.glossy_blur): the file's own
    value, so a .blend gives Cycles's picture. Without the Cycles add-on the value the file
    stored is read from its ID properties; a file that never had one gets Cycles's default 1."""
    return min(max(float(_cycles_setting(scene, "blur_glossy", 1.0)), 0.0), 10.0)


def transparent_glass(scene) -> float | None:
    """Cycles's Film > Transparent Glass roughness threshold when it is on with a transparent
    film (``scene.cycles``), else None (not exported)."""
    cy = getattr(scene, "cycles", None)
    if not (scene.render.film_transparent and getattr(cy, "film_transparent_glass", False)):
        return None
    return float(getattr(cy, "film_transparent_roughness", 0.1))


def film_exposure(scene) -> float:
    """Cycles's Film > Exposure (a scale of the written radiance, ``scene.cycles.film_exposure``);
    1 without the Cycles add-on. Exported only when not 1, as the other optional settings."""
    return float(getattr(getattr(scene, "cycles", None), "film_exposure", 1.0))


def camera_dict(cam_obj, matrix) -> dict:
    """Camera header from an evaluated camera object and its (camera → world) matrix."""
    cam = cam_obj.data
    if cam.type not in ("PERSP", "ORTHO", "PANO"):
        raise ExportError(f"camera '{cam_obj.name}': type {cam.type} is not supported")
    panorama = panorama_dict(cam_obj) if cam.type == "PANO" else None
    dof = cam.dof
    focus = float(dof.focus_distance)
    if dof.focus_object is not None:
        # Distance along the view axis (a focus plane), like Cycles.
        fpos = np.array(dof.focus_object.matrix_world.translation[:])
        cpos = np.array(matrix.translation[:])
        z_axis = np.array(matrix.col[2][:3])
        z_axis /= max(np.linalg.norm(z_axis), 1e-12)
        focus = float(abs(np.dot(z_axis, cpos - fpos)))
    return {
        "type": cam.type,
        "matrix_world": matrix_list(matrix.normalized()),
        "lens": float(cam.lens),
        "sensor_width": float(cam.sensor_width), "sensor_height": float(cam.sensor_height),
        "sensor_fit": cam.sensor_fit,
        "shift_x": float(cam.shift_x), "shift_y": float(cam.shift_y),
        "clip_start": float(cam.clip_start), "clip_end": float(cam.clip_end),
        "ortho_scale": float(cam.ortho_scale),
        "dof": {"use": bool(dof.use_dof), "focus_distance": max(focus, 1e-6),
                "fstop": float(dof.aperture_fstop), "blades": int(dof.aperture_blades),
                "rotation": float(dof.aperture_rotation), "ratio": float(dof.aperture_ratio)},
        "motion": None,
    } | ({"panorama": panorama} if panorama is not None else {})


#: Blender's panorama types DRT renders (drt.panorama.PANORAMA_TYPES)
_PANORAMA_TYPES = ("EQUIRECTANGULAR", "EQUIANGULAR_CUBEMAP_FACE", "MIRRORBALL", "FISHEYE_EQUIDISTANT",
                   "FISHEYE_EQUISOLID", "FISHEYE_LENS_POLYNOMIAL")


def panorama_dict(cam_obj) -> dict:
    """A panoramic camera's ``"panorama"`` (scene format): its projection and parameters, from
    the camera data (Blender 4+) or, before that, Cycles's camera settings."""
    cam = cam_obj.data
    src = cam if hasattr(cam, "panorama_type") else getattr(cam, "cycles", cam)
    kind = getattr(src, "panorama_type", "FISHEYE_EQUISOLID")
    if kind not in _PANORAMA_TYPES:
        raise ExportError(f"camera '{cam_obj.name}': panorama type {kind} is not supported "
                          f"({', '.join(t.replace('_', ' ').title() for t in _PANORAMA_TYPES)} are)")
    out = {"type": kind}
    for name in ("fisheye_fov", "fisheye_lens", "latitude_min", "latitude_max", "longitude_min", "longitude_max"):
        if hasattr(src, name):
            out[name] = float(getattr(src, name))
    if hasattr(src, "fisheye_polynomial_k0"):
        out["polynomial"] = [float(getattr(src, f"fisheye_polynomial_k{k}")) for k in range(5)]
    return out


def light_dict(obj, matrix, warnings: list) -> dict | None:
    """Light header from an evaluated light object and its world matrix (None: skipped)."""
    light = obj.data
    if light.type == "AREA" and getattr(getattr(getattr(obj.original, "data", None), "cycles", None), "is_portal", False):
        # a portal emits nothing: in Cycles it only guides the world's sampling through a
        # window, so leaving it out changes the noise, not the image
        return None
    # a light's node tree (Use Nodes) scales its colour × power, folded to a constant
    color = (np.array(compat.light_color(light)) * light_node_factor(light, warnings, obj.name)).tolist()
    scale = compat.light_power_scale(light)
    d = {"name": obj.name, "type": light.type, "matrix_world": matrix_list(matrix),
         "color": color, "visible_to_camera": bool(getattr(obj, "visible_camera", True))}
    if light.type in ("POINT", "SPOT"):
        d.update(power=float(light.energy) * scale, radius=float(light.shadow_soft_size),
                 soft_falloff=compat.light_soft_falloff(light))
        if light.type == "SPOT":
            d.update(spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
            if getattr(light, "use_square", False):
                warnings.append(f"Light '{obj.name}': square spot rendered as round")
    elif light.type == "SUN":
        d.update(strength=float(light.energy) * scale, angle=float(light.angle))
    elif light.type == "AREA":
        power = float(light.energy) * scale
        size, size_y = float(light.size), float(light.size_y)
        if light.shape in ("SQUARE", "DISK"):
            size_y = size
        if not compat.light_normalized(light):
            # Unnormalised: radiance P/π regardless of area, i.e. power scales with the area.
            sx = np.linalg.norm(np.array(matrix.col[0][:3]))
            sy = np.linalg.norm(np.array(matrix.col[1][:3]))
            area = size * size_y * sx * sy
            if light.shape in ("DISK", "ELLIPSE"):
                area *= math.pi / 4
            power *= area
        d.update(power=power, shape=light.shape, size=size, size_y=size_y,
                 spread=min(float(getattr(light, "spread", math.pi)), math.pi))
    else:
        warnings.append(f"Light '{obj.name}': type {light.type} not supported, skipped")
        return None
    return d


def world_dict(world, warnings: list, images=None) -> dict:
    """The world: a constant background radiance (Background color × strength) or, when
    textures drive it, a world program (``world_program.world_surface``) whose images join
    ``images`` (the export's ``ImageTable``; the viewport passes a table of its own); without
    ``images`` a textured world is its constant stand-in colour (+ the world's medium)."""
    return _with_volume(world, warnings, _world_surface(world, warnings, images))


def _world_surface(world, warnings: list, images=None) -> dict:
    """The world's surface: a constant colour or a program (``world_program``)."""
    if world is None:
        return {"color": [0.0, 0.0, 0.0]}
    tree = compat.world_node_tree(world)
    if tree is None:
        return {"color": [float(x) for x in world.color[:3]]}
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    out = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
    if out is None or not out.inputs["Surface"].is_linked:
        return {"color": [0.0, 0.0, 0.0]}
    from .world_program import world_surface
    d = world_surface(world, out.inputs["Surface"], images, warnings)
    if images is None:
        d = {"color": d["color"]}
    return d


def _with_volume(world, warnings: list, d: dict) -> dict:
    """``d`` plus the world's medium (its Volume output, addon/export/volumes.py), if any."""
    from .volumes import world_volume

    medium = world_volume(world, warnings)
    if medium is not None:
        d["volume"] = medium
    return d
