"""Depsgraph → DRT scene (header dict + arrays), in memory; see docs/scene-format.md.

``export_depsgraph`` is the one entry point: the render engine calls it with its own
``frame_set`` (so motion sampling re-evaluates the render depsgraph), the command line and the
tests call it with ``scene.frame_set``. Nothing here touches the core renderer.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from .libraries import missing_link_warnings
from .materials import MaterialExporter
from .mesh import MESH_LIKE_TYPES, evaluated_mesh_arrays, evaluated_positions
from .object_info import object_info
from .scene_parts import (ExportError, camera_dict, cryptomatte_names, data_pass_settings, shadow_terminator,
                          light_dict, matrix_list, mist_settings, render_settings, world_dict)

__all__ = ["ExportError", "ExportResult", "export_depsgraph"]


@dataclass
class ExportResult:
    header: dict
    arrays: dict
    warnings: list = field(default_factory=list)


def _instance_key(inst) -> tuple:
    """Stable identity of an object instance across frames (copied immediately)."""
    obj = inst.object
    parent = inst.parent.original.name if inst.parent is not None else ""
    pid = tuple(inst.persistent_id) if inst.is_instance else ()
    return (obj.original.name, parent, pid)


def _instance_name(inst, key) -> str:
    """Readable object name: instances are 'Object@Instancer.i.j' (persistent id path)."""
    if not inst.is_instance:
        return inst.object.name
    ids = [str(i) for i in key[2] if i != 0x7FFFFFFF]
    parent = inst.parent.name if inst.parent is not None else ""
    return f"{inst.object.name}@{parent}." + ".".join(ids)


#: object types whose evaluated geometry Blender can hand render engines as a mesh instance of
#: the object itself (curves and text since 3.0; NURBS surfaces and metaballs by 5.0)
MESH_PRESENTED_TYPES = frozenset({"CURVE", "SURFACE", "FONT", "META"})


def _presents_a_mesh(inst) -> bool:
    """Whether ``inst`` is the mesh a curve-like object's evaluated geometry presents as an
    instance of that object (its ``parent``, whose original it shares)."""
    if not inst.is_instance or inst.object.type != "MESH":
        return False
    parent = inst.parent
    return parent is not None and parent.type in MESH_PRESENTED_TYPES and inst.object.original == parent.original


def objects_presented_as_meshes(depsgraph) -> frozenset:
    """Original pointers of the curve-like objects whose geometry ``depsgraph`` also presents as
    a mesh instance. Cycles renders only that instance (its object data is a Mesh; the object's
    own is a Curve or MetaBall): exporting the object as well rendered every curve, text,
    surface and metaball twice, on top of each other. Older Blenders that present metaballs
    and surfaces only as the object itself keep them. Walks the instances only when such an
    object exists."""
    if not any(o.type in MESH_PRESENTED_TYPES for o in depsgraph.objects):
        return frozenset()
    return frozenset(inst.parent.original.as_pointer() for inst in depsgraph.object_instances
                     if _presents_a_mesh(inst))


def _is_rendered(inst, presented: frozenset = frozenset()) -> bool:
    """Whether an instance is rendered; ``presented`` (`objects_presented_as_meshes`): the
    curve-like objects rendered through their mesh instance instead of themselves."""
    obj = inst.object
    if not inst.is_instance:
        if not inst.show_self:
            return False
        if obj.type in MESH_PRESENTED_TYPES and obj.original.as_pointer() in presented:
            return False
        orig = obj.original
        if orig.hide_render:
            return False
    return True  # (holdouts too: they occlude, cast shadows and are seen in bounces)


#: Cycles's per-object ray visibility (Object > Visibility > Ray Visibility): Blender's
#: property of each ray kind of the scene format's object "visibility" (drt.scene.RAY_VISIBILITY)
_RAY_VISIBILITY = (("camera", "visible_camera"), ("diffuse", "visible_diffuse"),
                   ("glossy", "visible_glossy"), ("transmission", "visible_transmission"),
                   ("volume_scatter", "visible_volume_scatter"), ("shadow", "visible_shadow"))


def instance_visibility(inst, view_layer) -> tuple[dict | None, bool]:
    """An object instance's ray visibility — the scene format's ``{ray kind: bool}``, or None
    when every kind of ray sees it (Cycles's default: nothing exported) — and whether it is a
    holdout, as Cycles's sync_object decides them: for an instance (of a particle system, a collection
    instance, geometry nodes) the instancer's settings count — its ray visibility is ANDed in,
    and its holdout / indirect-only (the object's Mask > Holdout flag, or its collection's in
    ``view_layer``) are the instance's. An indirect-only object (not a holdout) is one camera
    rays do not see."""
    instanced = inst.is_instance and inst.parent is not None
    parent = inst.parent if instanced else inst.object
    sources = (inst.object, parent) if instanced else (parent,)
    vis = {kind: all(bool(getattr(o, attr, True)) for o in sources) for kind, attr in _RAY_VISIBILITY}
    orig = parent.original  # (an evaluated object answers False: the flags live on the original)
    try:
        holdout = bool(orig.holdout_get(view_layer=view_layer))
        indirect_only = bool(orig.indirect_only_get(view_layer=view_layer))
    except (TypeError, RuntimeError, ValueError):  # not in that view layer (or an old bpy)
        holdout, indirect_only = bool(getattr(orig, "is_holdout", False)), False
    if indirect_only and not holdout:
        vis["camera"] = False
    return (None if all(vis.values()) else vis), holdout


def visibility_bits(visibility: dict | None, holdout: bool = False) -> int:
    """``instance_visibility``'s answer as the core's VIS_* bits, VIS_HOLDOUT included (the
    viewport's live objects)."""
    from .. import compat

    core_scene = compat.core_module("scene")
    bits = core_scene.VIS_ALL if visibility is None else sum(
        1 << k for k, kind in enumerate(core_scene.RAY_VISIBILITY) if visibility[kind])
    return bits | (core_scene.VIS_HOLDOUT if holdout else 0)


def ignored_ray_visibility(obj) -> list[str]:
    """The object settings Cycles renders and DRT does not yet: their names, [] when none is
    set — the shadow catcher, light and shadow linking (an emitter's receiver / blocker
    collections), Cycles's shadow caustics flags; on a light, its ray visibility other than to
    the camera and its cast-shadow switch."""
    # (a light object reports is_shadow_catcher True in 5.0; the setting is a geometry one)
    names = ["shadow catcher"] if obj.type != "LIGHT" and getattr(obj, "is_shadow_catcher", False) else []
    linking = getattr(obj, "light_linking", None)
    if linking is not None and getattr(linking, "receiver_collection", None) is not None:
        names.append("light linking")
    if linking is not None and getattr(linking, "blocker_collection", None) is not None:
        names.append("shadow linking")
    # (the original's: reading the Cycles add-on's properties on an evaluated copy leaks the
    # property group Blender creates for it)
    cyc = getattr(obj.original, "cycles", None)
    if getattr(cyc, "is_caustics_caster", False) or getattr(cyc, "is_caustics_receiver", False):
        names.append("shadow caustics")
    if obj.type == "LIGHT":
        hidden = [kind for kind in ("diffuse", "glossy", "transmission", "volume_scatter")
                  if not getattr(obj, f"visible_{kind}", True)]
        if hidden:
            names.append("invisible to " + ", ".join(k.replace("_", " ") for k in hidden) + " rays")
        if not getattr(obj, "visible_shadow", True):
            names.append("casts no shadow")
        if getattr(getattr(obj.original.data, "cycles", None), "is_caustics_light", False):
            names.append("shadow caustics")
    return names


#: object types Cycles renders and DRT does not (no primitive for them), by the name the export
#: warning gives them
UNRENDERED_GEOMETRY_TYPES = {"CURVES": "hair curves", "POINTCLOUD": "point cloud", "VOLUME": "volume"}


def _has_elements(obj) -> bool:
    """Whether an evaluated hair-curves, point-cloud or volume object holds anything to render
    (an empty one renders nothing in Cycles either)."""
    data = obj.data
    for attr in ("curves", "points", "grids"):
        items = getattr(data, attr, None)
        if items is not None:
            try:
                return len(items) > 0
            except (TypeError, RuntimeError):
                return True
    return True


def hair_systems(obj) -> list:
    """The particle systems of ``obj`` that Cycles renders as hair curves (Hair type rendered as
    Path); other render types instance objects, which the export receives as instances."""
    return [ps for ps in getattr(obj, "particle_systems", ())
            if ps.settings.type == "HAIR" and ps.settings.render_type == "PATH"]


def _deform_candidate(inst, scene) -> bool:
    """Objects whose shape may change over the shutter (compared later, vertex by vertex)."""
    if inst.is_instance:  # the mesh of an animated curve-like object is its own geometry
        return _presents_a_mesh(inst) and inst.parent.original.animation_data is not None
    orig = inst.object.original
    if orig.type != "MESH":
        return orig.type in MESH_LIKE_TYPES and orig.animation_data is not None
    try:
        if orig.is_deform_modified(scene, "RENDER"):
            return True
    except (TypeError, RuntimeError):
        pass
    data = orig.data
    if getattr(data, "shape_keys", None) is not None:
        return True
    return any(m.type == "NODES" for m in orig.modifiers)


def _frame_time(t: float) -> tuple[int, float]:
    f = math.floor(t)
    return int(f), float(t - f)


def _matrices_equal(a: list, b: list) -> bool:
    return np.allclose(np.array(a), np.array(b), rtol=0.0, atol=1e-7)


def export_depsgraph(depsgraph, *, frame_set=None, preview: bool = False) -> ExportResult:
    """Export the evaluated scene of ``depsgraph`` at its current frame.

    frame_set(frame: int, subframe: float) moves time (and re-evaluates ``depsgraph``); needed
    only when motion blur is on. Time is restored before returning.
    """
    scene = depsgraph.scene
    warnings: list[str] = []
    mats = MaterialExporter()
    render = render_settings(scene, preview)
    if not preview and getattr(depsgraph.view_layer, "use_pass_mist", False):
        render["mist"] = mist_settings(scene.world)  # (the view layer asks for the Mist pass)
    if not preview:  # the data passes the view layer asks for (Cycles's film_write_data_passes)
        render.update(data_pass_settings(depsgraph.view_layer))

    if scene.camera is None:
        raise ExportError("the scene has no active camera")
    warnings += missing_link_warnings(depsgraph)

    meshes: list[dict] = []
    arrays: dict[str, np.ndarray] = {}
    mesh_of_key: dict = {}  # (data pointer, material tuple) -> mesh index
    objects: list[dict] = []
    object_index: dict = {}  # instance key -> index into objects
    deform_keys: dict = {}  # instance key -> mesh index (candidates for deformation)
    lights: list[dict] = []
    infos: list[dict] = []  # Object Info per object, attached if a material reads it
    unsupported_visibility: dict[str, list[str]] = {}  # object name -> visibility settings DRT ignores
    unrendered: set[str] = set()  # geometry DRT has no primitive for (hair, points, OpenVDB)
    checked_settings: set[str] = set()  # objects whose unrendered settings were looked at

    presented = objects_presented_as_meshes(depsgraph)
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type == "LIGHT":
            if _is_rendered(inst):
                ld = light_dict(obj, inst.matrix_world.copy(), warnings)
                if ld is not None:
                    lights.append(ld)
                    if ignored := ignored_ray_visibility(obj):
                        unsupported_visibility.setdefault(obj.name, ignored)
            continue
        if obj.type not in MESH_LIKE_TYPES or not _is_rendered(inst, presented):
            if obj.type in UNRENDERED_GEOMETRY_TYPES and _is_rendered(inst) and _has_elements(obj):
                unrendered.add(f"{UNRENDERED_GEOMETRY_TYPES[obj.type]} '{obj.original.name}'")
            continue
        if not inst.is_instance and inst.show_particles and hair_systems(obj):
            unrendered.add(f"hair on '{obj.original.name}'")
        key = _instance_key(inst)
        visibility, holdout = instance_visibility(inst, depsgraph.view_layer)
        if obj.name not in checked_settings:  # once per object: instances repeat it by the million
            checked_settings.add(obj.name)
            if ignored := ignored_ray_visibility(obj):
                unsupported_visibility.setdefault(obj.name, ignored)
        matrix = matrix_list(inst.matrix_world.copy())
        slots = [s.material for s in obj.material_slots] or [None]
        slot_mats = np.array([mats.index_of(m) for m in slots], dtype=np.int32)
        deforming = _deform_candidate(inst, scene)
        mkey = (obj.data.as_pointer() if obj.data is not None else obj.as_pointer(),
                tuple(slot_mats.tolist()))
        if deforming:
            mkey = ("deform",) + key  # never shared
        k = mesh_of_key.get(mkey)
        if k is None:
            data = evaluated_mesh_arrays(obj, slot_mats, mats.reads(slot_mats))
            if data is None:
                mesh_of_key[mkey] = -1
                continue
            k = len(meshes)
            meshes.append({"name": obj.name, "deforming": False})
            for name, arr in data.items():
                arrays[f"mesh{k}.{name}"] = arr
            mesh_of_key[mkey] = k
        if k < 0:
            continue
        if deforming:
            deform_keys[key] = k
        object_index[key] = len(objects)
        objects.append({"name": _instance_name(inst, key),
                        "mesh": k, "matrix_world": matrix, "motion": None})
        if visibility is not None:
            objects[-1]["visibility"] = visibility
        if holdout:
            objects[-1]["holdout"] = True
        if getattr(obj, "pass_index", 0):  # (the Object Index pass; an instance: its object's, as Cycles)
            objects[-1]["pass_index"] = int(obj.pass_index)
        if "cryptomatte" in render:
            objects[-1]["cryptomatte"] = cryptomatte_names(inst)
        term = shadow_terminator(obj)
        # the geometry offset acts on smooth shading only, the shading offset on any (drt.terminator)
        if term["shading_offset"] > 0.0 or (f"mesh{k}.normals" in arrays and term["geometry_offset"] > 0.0):
            objects[-1]["shadow_terminator"] = term
        infos.append(object_info(inst))

    cam_obj = scene.camera.evaluated_get(depsgraph)
    camera = camera_dict(cam_obj, cam_obj.matrix_world.copy())

    if render["shutter"] is not None:
        if frame_set is None:
            warnings.append("motion blur needs frame_set; exported without motion")
        else:
            _export_motion(depsgraph, scene, frame_set, render["shutter"], camera, objects,
                           object_index, deform_keys, meshes, arrays, warnings)

    if unrendered:
        names = sorted(unrendered)
        warnings.append("not rendered (DRT has no curve, point or OpenVDB primitive yet): "
                        + ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else ""))
    if unsupported_visibility:
        named = "; ".join(f"'{n}' ({', '.join(v)})" for n, v in sorted(unsupported_visibility.items())[:8])
        more = len(unsupported_visibility) - 8
        warnings.append("not rendered yet (the objects render as plain ones): "
                        + named + (f" and {more} more" if more > 0 else ""))
    warnings += mats.warnings
    if mats.reads_object_info():
        for o, info in zip(objects, infos):
            o["info"] = info
    # version 2 only when needed (SUBSURFACE lobes), so that other scenes stay readable by v1 readers
    version = 2 if any(lb["type"] == "SUBSURFACE" for m in mats.materials for lb in m["lobes"]) else 1
    header = {"format": "drt-scene", "version": version, "render": render, "camera": camera,
              "world": world_dict(scene.world, warnings, mats.images), "materials": mats.materials,
              "lights": lights, "meshes": meshes, "objects": objects}
    if mats.attributes:  # named per-corner attributes programs read (arrays mesh<K>.attr<I>)
        header["attributes"] = list(mats.attributes)
    if mats.images.images:  # pixels of the images material programs read (docs/materials.md)
        header["images"] = mats.images.images
        arrays.update(mats.images.arrays)
    return ExportResult(header, arrays, warnings)


def _export_motion(depsgraph, scene, frame_set, shutter, camera, objects, object_index,
                   deform_keys, meshes, arrays, warnings):
    """Sample transforms (and candidate deformations) at shutter open and close."""
    frame = scene.frame_current
    subframe = float(scene.frame_subframe)
    samples = []  # per end: (camera matrix, {key: matrix}, {key: positions})
    try:
        for offset in shutter:
            frame_set(*_frame_time(frame + subframe + offset))
            cam_obj = scene.camera.evaluated_get(depsgraph)
            cam_m = matrix_list(cam_obj.matrix_world.normalized())
            mats, pos = {}, {}
            for inst in depsgraph.object_instances:
                if inst.object.type not in MESH_LIKE_TYPES:
                    continue
                key = _instance_key(inst)
                if key in object_index:
                    mats[key] = matrix_list(inst.matrix_world.copy())
                    if key in deform_keys:
                        pos[key] = evaluated_positions(inst.object)
            samples.append((cam_m, mats, pos))
    finally:
        frame_set(frame, subframe)

    (cam_open, m_open, p_open), (cam_close, m_close, p_close) = samples
    if not (_matrices_equal(cam_open, cam_close) and _matrices_equal(cam_open, camera["matrix_world"])):
        camera["motion"] = {"matrix_open": cam_open, "matrix_close": cam_close}
    for key, i in object_index.items():
        a, b = m_open.get(key), m_close.get(key)
        if a is None or b is None:
            continue
        if not (_matrices_equal(a, b) and _matrices_equal(a, objects[i]["matrix_world"])):
            objects[i]["motion"] = {"matrix_open": a, "matrix_close": b}
    for key, k in deform_keys.items():
        a, b = p_open.get(key), p_close.get(key)
        base = arrays[f"mesh{k}.positions"]
        if a is None or b is None:
            continue
        if a.shape != base.shape or b.shape != base.shape:
            warnings.append(f"Mesh '{meshes[k]['name']}': topology changes during the shutter, "
                            "deformation blur skipped")
            continue
        if np.array_equal(a, b) and np.array_equal(a, base):
            continue
        meshes[k]["deforming"] = True
        arrays[f"mesh{k}.positions"] = a
        arrays[f"mesh{k}.positions_close"] = b
