"""Interactive rendering: a scene that takes edits, and a restartable progressive session.

This is the core side of the Blender viewport (``addon/viewport.py``); nothing here knows
Blender. Two pieces:

``LiveScene`` holds the scene as *objects* (a local-space ``MeshData`` and a 4×4 matrix each),
materials, lights, world and render settings, and turns them into a ``RenderContext`` for any
camera, rebuilding only what an edit touched:

* Large objects (``INSTANCE_MIN_TRIANGLES`` and up) and objects that are being moved while the
  rest of the static set is large get their own Embree scene in local space, traced through a
  transform (the tracer's rigid-motion path, ``drt.trace``, with the same matrix at shutter open
  and close). Moving such an object changes one matrix and one culling box: no BVH is rebuilt.
  Two or more of them, with the static set, are one Embree scene of instances (one query per
  ray, rebuilt at each edit), so up to ``MAX_SHARED_INSTANCES`` are kept apart (without
  Embree's C handles each costs a pass over the rays: ``MAX_INSTANCES``).
* Every other object is flattened into one world-space static set (the tracer's fast path);
  moving, adding or removing one of them rebuilds that set, which is small by construction.
* Emissive objects stay static: only static emissive triangles are sampled as lights.
* A material edit rebuilds the material table (and the light set when emission changed); a
  light or world edit rebuilds the light set; a camera change builds a new ``Camera``. None of
  these touches a BVH.

The world is translated by a fixed ``origin_shift`` (the first view's position, as the final
render shifts by the camera's position, for float32 precision): it does not follow the view,
so looking around never rebuilds geometry.

``ProgressiveSession`` renders a ``LiveScene`` on one background thread (which drives the
render loop's own worker threads). Edits are queued as functions of the ``LiveScene`` and
applied *by the session thread* between renders, so the caller (Blender's main thread) never
waits and no structure is changed while a render reads it. Every edit or view change cancels
the render in flight (the render loop polls ``cancel`` between batches) and restarts
accumulation: first a coarse image (the resolution divided by a power of two so that it has at
most ``COARSE_PIXELS`` pixels), then each finer divider for one sample, then full resolution
accumulating up to the sample count in chunks of about ``CHUNK_SECONDS``.
"""

from __future__ import annotations

import os
import threading
import time
import traceback
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from . import embree_direct
from .camera import Camera
from .embree_mesh import new_device
from .geometry import MovingMesh, SceneGeometry, _points_to_world, _transform_normals
from .volumes.media import lights_reaching, media_for_scene, world_blocks_infinity
from .integrator import Integrator
from .lights import LightSet
from .materials import MaterialTable
from .motion import RigidMotion
from .render import RenderContext, _emissive_triangles, render, settle_abandoned_batches, textured_emission_in
from .sampling.pixel_filter import PixelFilter
from .sampling.sequences import Sampler
from .scene import MAX_TRANSFORM_ENTRY, VIS_ALL, CameraSpec, MeshData, RenderSettings, Scene, SceneError
# The tracer's per-object pieces: a moving object's Embree scene + transform, and its culling
# box. LiveScene keeps them across edits (a moved object is one new transform), so it builds
# the Tracer from parts instead of from a SceneGeometry.
from .trace import Tracer, _instances, _MovingObject

#: objects with at least this many triangles get their own BVH (moving them costs a matrix)
INSTANCE_MIN_TRIANGLES = 1 << 15
#: at most this many objects are traced through transforms when each costs a pass over the
#: rays (without Embree's C handles: the per-object path)
MAX_INSTANCES = 16
#: ... and when they are one Embree scene of instances (``Tracer.instanced``), whose cost per
#: ray does not grow with their number; it is rebuilt and checked at each edit: 5.7 ms with 16
#: objects, 22 ms with 64 (a floor and objects of 32 768 triangles, 128² at 8 spp: 0.176 s
#: against 0.444 s per object), where an edit of an object in the static set rebuilds the BVH of
#: all of them
MAX_SHARED_INSTANCES = 64
#: the first image after an edit has at most this many pixels (640 × 360 starts at 80 × 45)
COARSE_PIXELS = 1 << 13
#: camera paths per batch in the viewport: small batches make cancel (and so edits) prompt
VIEWPORT_BATCH_PATHS = 1 << 13
#: full-resolution samples are rendered in chunks of about this many seconds (a redraw each)
CHUNK_SECONDS = 0.5


@dataclass
class LiveObject:
    """One object: ``mesh`` in its local space, ``matrix`` (4, 4) float64 local → Blender world;
    ``instance``: traced through its transform (own BVH) rather than flattened."""

    name: str
    mesh: MeshData
    matrix: np.ndarray
    instance: bool = False
    #: VIS_* bits of the rays that see it (drt.scene.RAY_VISIBILITY), plus VIS_HOLDOUT if it
    #: is a holdout (ObjectSpec.holdout)
    visibility: int = VIS_ALL


@dataclass
class BuildCounters:
    """What LiveScene rebuilt so far (tests and benchmarks read these)."""

    static_builds: int = 0  # world-space static set: triangles transformed + Embree BVH
    static_triangles: int = 0  # triangles put through those builds, in total
    instance_builds: int = 0  # per-object BVHs (local space)
    instance_triangles: int = 0
    matrix_updates: int = 0  # instances moved without any BVH work
    material_builds: int = 0
    light_builds: int = 0


def _matrix(m) -> np.ndarray:
    """A 4×4 transform validated like a scene file's (finite, entries within ±1e15)."""
    a = np.array(m, dtype=np.float64).reshape(4, 4)
    if not np.all(np.isfinite(a)):
        raise SceneError("matrix", "contains NaN or infinite values")
    if np.any(np.abs(a) > MAX_TRANSFORM_ENTRY):
        raise SceneError("matrix", f"entries must be within ±{MAX_TRANSFORM_ENTRY:g}")
    return a


def _program_key(prog) -> tuple | None:
    """A program's operations, constants and tables as bytes (a comparable key)."""
    if not prog:
        return None
    return (prog.get("registers"),) + tuple(np.asarray(prog.get(k, []), np.float64).tobytes()
                                            for k in ("constants", "ops", "data"))


def _is_rigid(m: np.ndarray) -> bool:
    """Can the tracer's rigid transform (translation · rotation · scale, no shear) represent m?"""
    rm = RigidMotion(m, m)
    linear, translation = rm.at(np.zeros(1))
    scale = max(float(np.abs(m[:3, :3]).max()), 1e-30)
    return bool(np.allclose(linear[0], m[:3, :3], rtol=0, atol=1e-6 * scale)
                and np.allclose(translation[0], m[:3, 3], rtol=0, atol=1e-6 * (1 + np.abs(m[:3, 3]).max())))


class _LiveTracer(Tracer):
    """A ``Tracer`` assembled from parts LiveScene keeps between edits. With two or more
    objects kept apart from the static set, and every Embree scene on LiveScene's one device,
    all of them are one Embree scene of instances (``Tracer.instanced``): a ray's cost then
    does not grow with their number."""

    def __init__(self, geom: SceneGeometry, static_scene, static_ng, moving: list, device=None):
        # deliberately not Tracer.__init__: that would rebuild every BVH
        self.geom = geom
        self.static = static_scene
        self._static_ng = static_ng
        self.moving = moving
        self.embree_seconds = 0.0
        self.rays_traced = 0
        self.instanced = _instances(self, device)


class LiveScene:
    """A scene kept for interactive edits (see the module docstring).

    Objects are keyed by any hashable key (the add-on uses Blender's instance key). Materials
    are a list indexed by ``MeshData.material_index``; lights are header dicts as in
    ``docs/scene-format.md`` (validated here like a scene file's); ``world_color`` is the
    background radiance (3,). Not thread-safe: one thread edits and builds (the session's).
    """

    def __init__(self, settings: RenderSettings | None = None, materials: list | None = None,
                 lights: list | None = None, world_color=(0.0, 0.0, 0.0),
                 origin_shift=None):
        self.settings = settings or RenderSettings(width=64, height=64)
        self.objects: dict = {}
        self.materials = list(materials or [])
        self.images: list = []       # (info dict, pixels) the material programs read
        self.attributes: list = []   # names of the named per-corner attributes they read
        self.lights: list = []
        self.world_color = np.zeros(3)
        self.world_volume = None  # the world medium (drt.volumes), set by set_world
        self.world_program = None   # a textured world's validated program (scene.world_program)
        self.world_images: list = []  # the images it reads (its image indices count from 0)
        self._world_map = None      # (program index, radiance register, map) while unchanged
        self.origin_shift = None if origin_shift is None else np.asarray(origin_shift, np.float64).reshape(3).copy()
        self.counters = BuildCounters()
        self.warnings: list[str] = []
        self._device = None  # the Embree device of every BVH below (_embree_device)
        self._static = None  # (positions, triangles, tables, embree scene, face normals)
        self._static_dirty = True
        self._instances: dict = {}  # key -> (_MovingObject, MovingMesh) of instance objects
        self._tables = None  # per-triangle tables of static set + instances, global ids
        self._attr_tables: dict = {}  # per-corner program attributes, global ids
        self._tables_dirty = True
        self._tables_layout = None
        self._material_table = None
        self._light_set = None
        self._lights_dirty = True
        self._filter = None
        self.set_lights(lights or [])
        self.set_world(world_color)

    # ------------------------------------------------------------------ edits
    def set_object(self, key, name: str, mesh: MeshData, matrix, visibility: int = VIS_ALL) -> None:
        """Add or replace an object (new geometry: its BVH is rebuilt)."""
        m = _matrix(matrix)
        old = self.objects.get(key)
        if old is not None:
            self.remove_object(key)
        obj = LiveObject(str(name), mesh, m, visibility=int(visibility))
        obj.instance = self._wants_instance(obj, moving=False)
        self.objects[key] = obj
        if obj.instance:
            self._tables_dirty = True
        else:
            self._static_dirty = True

    def set_matrix(self, key, matrix) -> None:
        """Move an object: an instance costs a matrix; a static one rebuilds the static set,
        unless it is promoted to an instance (the static set is large and it is being moved)."""
        obj = self.objects[key]
        m = _matrix(matrix)
        if np.array_equal(m, obj.matrix):
            return
        obj.matrix = m
        if obj.instance:
            if not _is_rigid(m):  # a sheared transform: the tracer's rigid path cannot hold it
                obj.instance = False
                self._drop_instance(key)
                self._static_dirty = True
            elif key in self._instances:  # (not built yet: it is built with this matrix)
                # the light set keeps its scene radius (it only weighs the sun's selection
                # probability against other lights): no rebuild for a move
                mo, mm = self._instances[key]
                mm.motion = RigidMotion(self._shifted(m), self._shifted(m))
                self._instances[key] = (self._moved(mo, mm), mm)
                self.counters.matrix_updates += 1
            return
        if self._wants_instance(obj, moving=True):
            obj.instance = True
            self._tables_dirty = True
        self._static_dirty = True

    def set_visibility(self, key, visibility: int) -> None:
        """Change which rays see an object and whether it is a holdout (VIS_* bits as
        LiveObject.visibility; no BVH rebuild: the next render's per-triangle visibility is
        gathered from the objects)."""
        self.objects[key].visibility = int(visibility)

    def remove_object(self, key) -> None:
        obj = self.objects.pop(key, None)
        if obj is None:
            return
        if obj.instance:
            self._drop_instance(key)
        else:
            self._static_dirty = True
            if self._has_emission(obj):
                self._lights_dirty = True

    def set_materials(self, materials: list, images=None, attributes=None) -> None:
        """Replace the material list (same indices; appended ones are new), with the images and
        attribute names their programs read (``scene.images`` / ``scene.attributes`` of a
        validated scene; meshes carry the attributes as ``MeshData.corner_attrs``)."""
        emission_before = self._light_signature()
        self.materials = list(materials)
        if images is not None:
            self.images = list(images)
        if attributes is not None:
            if list(attributes) != self.attributes:
                self._static_dirty = self._tables_dirty = True  # tangents are mapped per name
            self.attributes = list(attributes)
        self._material_table = None
        if self._light_signature() != emission_before:
            self._lights_dirty = True
            # an object that became emissive must be static (only static triangles are lights)
            for key, obj in self.objects.items():
                if obj.instance and self._has_emission(obj):
                    obj.instance = False
                    self._drop_instance(key)
                    self._static_dirty = True

    def set_lights(self, lights: list) -> None:
        """Lights as header dicts (validated like a scene file's ``lights``)."""
        from .scene import _lights
        self.lights = _lights({"lights": list(lights)})
        self._lights_dirty = True

    def set_world(self, color, volume: dict | None = None, program: dict | None = None, images=()) -> None:
        """The world: constant radiance ``color`` (3,), its (validated, ``Scene.world_volume``)
        medium if any, and for a textured world its validated ``program``
        (``Scene.world_program``) with the ``images`` it reads (a scene's ``images`` entries;
        the program's image indices count in this list)."""
        c = np.asarray(color, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(c)) or np.any(c < 0):
            raise SceneError("world.color", f"must be finite and >= 0, got {c.tolist()}")
        if volume != self.world_volume:  # a medium can hide the sun (lights_reaching)
            self._lights_dirty = True
        self.world_volume = volume  # read when the next context is built (media are per context)
        if not np.array_equal(c, self.world_color):
            self.world_color = c.copy()
            self._lights_dirty = True
        if program is not None or self.world_program is not None:
            if len(self.world_images) or len(images):
                self._material_table = None  # its image list carries the world's images
            self.world_program = program
            self.world_images = list(images)
            self._world_map = None
            self._lights_dirty = True

    def _world_program_in_table(self) -> dict:
        """The world program with its image indices moved past the materials' images (the
        material table holds both lists, materials' first)."""
        from .materials.program_format import OP_ENVIRONMENT, OP_IMAGE

        wp = dict(self.world_program)
        ops = wp["ops"].copy()
        ops[np.isin(ops[:, 0], (OP_IMAGE, OP_ENVIRONMENT)), 10] += len(self.images)
        wp["ops"] = ops
        return wp

    def set_settings(self, settings: RenderSettings) -> None:
        if settings != self.settings:
            if (settings.filter_type, settings.filter_width) != (self.settings.filter_type,
                                                                 self.settings.filter_width):
                self._filter = None
            if (settings.caustics_reflective, settings.caustics_refractive) != (
                    self.settings.caustics_reflective, self.settings.caustics_refractive):
                self._material_table = None  # (the switches' twin rows: drt.materials.caustics)
            self.settings = settings

    # ------------------------------------------------------------------ build
    def context(self, camera: CameraSpec, width: int, height: int,
                spp: int | None = None) -> tuple[Scene, RenderContext]:
        """A scene and render context for ``camera`` at width × height pixels, building what
        edits made stale. The scene carries only render settings and camera: the geometry is
        in the context."""
        if self.origin_shift is None:
            self.origin_shift = np.asarray(camera.matrix, dtype=np.float64)[:3, 3].copy()
        settings = replace(self.settings, width=int(width), height=int(height), border=None,
                           shutter=None, spp=int(spp or self.settings.spp),
                           adaptive_threshold=0.0)
        geom, tracer = self._geometry()
        if self._material_table is None:
            try:
                self._material_table = MaterialTable.from_scene(
                    self._materials_or_default(), self.images + self.world_images, self.attributes,
                    (self.settings.caustics_reflective, self.settings.caustics_refractive))
            except ValueError as e:
                raise SceneError("materials", str(e)) from None
            self.counters.material_builds += 1
        cam = Camera(camera, settings, geom.origin_shift)
        programs, world_regs = None, 0
        if self.world_program is not None:  # a textured world: its program joins the materials'
            from .integrator import program_data_for
            from .render import world_setup

            programs = program_data_for(self._material_table, geom, cam, world=self._world_program_in_table())
            world_regs = self.world_program["registers"]
            if self._world_map is None:
                self._world_map = world_setup(self.world_program, programs)
                self._lights_dirty = True
        media = media_for_scene(self.materials, getattr(self, "world_volume", None), geom)
        mats = self._materials_or_default()
        # textured emitters are lights as in the final render (render.prepare); none with media
        textured = textured_emission_in(mats) and not media.enabled
        if textured and programs is None:
            from .integrator import program_data_for

            programs = program_data_for(self._material_table, geom, cam)
        if self._lights_dirty or self._light_set is None:
            emissive = _emissive_triangles(None, geom, self._material_table, programs if textured else None,
                                           material_dicts=mats)
            wprog, wmap = self._world_map if self.world_program is not None else (None, None)
            try:
                blocked = world_blocks_infinity(media)  # as render.prepare
                self._light_set = LightSet(lights_reaching(self.lights, media), self.world_color, emissive,
                                           origin_shift=geom.origin_shift,
                                           scene_radius=geom.scene_radius,
                                           world_nee=wmap is not None and not blocked,
                                           world_program=wprog, world_map=wmap)
            except ValueError as e:
                raise SceneError("lights", str(e)) from None
            self._lights_dirty = False
            self.counters.light_builds += 1
        if self._filter is None:
            self._filter = PixelFilter(settings.filter_type, settings.filter_width)
        integ = Integrator(settings, geom, tracer, self._material_table, self._light_set, cam,
                           Sampler(settings.sampler, settings.seed, settings.spp), self._filter,
                           direct=settings.direct, indirect=settings.indirect,
                           media=media,
                           programs=programs, world_registers=world_regs)
        scene = Scene(settings, camera, self.world_color, self.materials, self.lights, [], [],
                      world_program=self.world_program)
        return scene, RenderContext(scene, integ, tracer)

    @property
    def triangle_count(self) -> int:
        return int(sum(len(o.mesh.triangles) for o in self.objects.values()))

    @property
    def instance_count(self) -> int:
        return sum(1 for o in self.objects.values() if o.instance)

    # ------------------------------------------------------------------ internals
    def _materials_or_default(self) -> list:
        if self.materials:
            return self.materials
        return [{"name": "default", "lobes": [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}],
                 "emission": [0, 0, 0]}]

    def _light_signature(self) -> tuple:
        """What the light set takes from the materials: each one's emission (the textured
        emitters' estimates come from their programs), program emission and ``light`` flag."""
        return tuple((tuple(np.asarray(m.get("emission", (0, 0, 0)), np.float64).ravel().tolist()),
                      m.get("emission_reg") is not None, m.get("light", True),
                      _program_key(m.get("program")) if m.get("emission_reg") is not None else None)
                     for m in self.materials)

    def _emission_signature(self) -> tuple:
        return tuple(bool(np.any(np.asarray(m.get("emission", (0, 0, 0))) > 0)) for m in self.materials)

    def _has_emission(self, obj: LiveObject) -> bool:
        emissive = np.array(self._emission_signature() or (False,), dtype=bool)
        mi = obj.mesh.material_index
        if len(mi) == 0:
            return False
        return bool(np.any(emissive[np.clip(mi, 0, len(emissive) - 1)]))

    def _wants_instance(self, obj: LiveObject, moving: bool) -> bool:
        n = len(obj.mesh.triangles)
        if n == 0 or obj.mesh.positions_close is not None or self._has_emission(obj):
            return False
        limit = MAX_SHARED_INSTANCES if embree_direct.intersect1_address() else MAX_INSTANCES
        if self.instance_count >= limit or not _is_rigid(obj.matrix):
            return False
        if n >= INSTANCE_MIN_TRIANGLES:
            return True
        if moving:  # dragging it would rebuild a large static set at every step
            static = sum(len(o.mesh.triangles) for o in self.objects.values() if not o.instance)
            return static - n >= INSTANCE_MIN_TRIANGLES
        return False

    def _drop_instance(self, key) -> None:
        if self._instances.pop(key, None) is not None:
            self._tables_dirty = True

    def _embree_device(self):
        """The one Embree device of this scene's BVHs (a scene of instances can only instance
        scenes of its own device), or None without Embree's checked C handles."""
        if self._device is None and embree_direct.intersect1_address():
            self._device = new_device()
        return self._device

    def _shifted(self, m: np.ndarray) -> np.ndarray:
        out = np.array(m, dtype=np.float64)
        out[:3, 3] -= self.origin_shift
        return out

    def _moved(self, old: _MovingObject, mm: MovingMesh) -> _MovingObject:
        """A copy of ``old`` with mm's new transform and culling box, sharing its Embree scene
        (the old object stays as it was for whoever still holds it)."""
        mo = _MovingObject.__new__(_MovingObject)
        mo.__dict__.update(old.__dict__)
        mo.mesh = mm
        mo.motion = mm.motion.data
        mo.box_lo, mo.box_hi = _culling_box(old.local_radius, mm.motion)
        return mo

    def _geometry(self) -> tuple[SceneGeometry, Tracer]:
        from .embree_mesh import triangle_scene
        from .trace import _unit_face_normals

        static_changed = False
        if self._static_dirty or self._static is None:
            pos, tri, tables, attrs = self._flatten_static()
            scene = ng = None
            if len(tri):
                # Embree's fast build, as Cycles's viewport (Dynamic BVH): an edit waits for it
                scene = triangle_scene(pos, tri, fast_build=True, device=self._embree_device())
                ng = _unit_face_normals(pos, tri)
            self._static = (pos, tri, tables, scene, ng, attrs)
            self._static_dirty = False
            static_changed = True
            self.counters.static_builds += 1
            self.counters.static_triangles += len(tri)
            self._lights_dirty = True  # emissive triangles come from the static set
        pos, tri, static_tables, static_scene, static_ng, static_attrs = self._static

        # instances: build new ones, drop gone ones; ids follow the static set
        for key, obj in self.objects.items():
            if obj.instance and key not in self._instances:
                mm = MovingMesh(obj.name, 0, np.ascontiguousarray(obj.mesh.positions, np.float64), None,
                                np.ascontiguousarray(obj.mesh.triangles, np.int64),
                                RigidMotion(self._shifted(obj.matrix), self._shifted(obj.matrix)))
                mo = _MovingObject(mm, fast_build=True, device=self._embree_device())
                # the local bounding radius, kept so that a move need not visit the vertices
                mo.local_radius = float(np.sqrt((mm.positions ** 2).sum(axis=1).max()))
                self._instances[key] = (mo, mm)
                self.counters.instance_builds += 1
                self.counters.instance_triangles += len(obj.mesh.triangles)
                self._tables_dirty = True
        for key in [k for k in self._instances if k not in self.objects or not self.objects[k].instance]:
            self._drop_instance(key)
        keys = [k for k in self.objects if k in self._instances]
        offset = len(tri)
        moving_objects, moving_meshes = [], []
        for key in keys:
            mo, mm = self._instances[key]
            if mo.prim_offset != offset:
                mm.prim_offset = offset
                mo = self._moved(mo, mm)
                mo.prim_offset = offset
                self._instances[key] = (mo, mm)
            moving_objects.append(mo)
            moving_meshes.append(mm)
            offset += len(mm.triangles)

        layout = (len(tri), tuple((k, len(self._instances[k][1].triangles)) for k in keys))
        if (self._tables_dirty or self._tables is None or layout != self._tables_layout
                or set(self._attr_tables) != set(self._attr_names())):
            parts = [static_tables] + [self._mesh_tables(self.objects[k].mesh, None) for k in keys]
            self._tables = tuple(np.concatenate([p[i] for p in parts]) for i in range(4))
            self._attr_tables = self._corner_attr_tables(static_attrs, len(tri),
                                                         [(self.objects[k].mesh, self.objects[k].matrix)
                                                          for k in keys])
            self._tables_dirty = False
            self._tables_layout = layout
        elif static_changed:
            # same layout: overwrite the static rows only, instead of copying every instance's
            # tables again (no render runs now: the session thread builds between renders)
            for table, rows in zip(self._tables, static_tables):
                table[: len(tri)] = rows
            for name, rows in static_attrs.items():
                self._attr_tables[name][: len(tri)] = rows
        material, normals, has_normals, uvs = self._tables

        geom = SceneGeometry(origin_shift=self.origin_shift, static_positions=pos, static_triangles=tri,
                             moving=moving_meshes, material=material,
                             normals=normals if has_normals.any() else None,
                             has_normals=has_normals, uvs=uvs, triangle_count=offset,
                             corner_attrs=self._attr_tables)
        if any(o.visibility != VIS_ALL for o in self.objects.values()):
            # in the triangle order of the static set (_flatten_static) and the instances
            parts = [np.full(len(o.mesh.triangles), o.visibility, np.uint8) for o in self.objects.values()
                     if not o.instance and len(o.mesh.triangles)]
            parts += [np.full(len(self._instances[k][1].triangles), self.objects[k].visibility, np.uint8)
                      for k in keys]
            geom.visibility = np.concatenate(parts)
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        if len(pos):
            lo, hi = pos.min(axis=0).astype(np.float64), pos.max(axis=0).astype(np.float64)
        for mo in moving_objects:
            lo, hi = np.minimum(lo, mo.box_lo), np.maximum(hi, mo.box_hi)
        if np.all(np.isfinite(lo)):
            geom.scene_radius = float(max(np.linalg.norm(hi - 0.5 * (lo + hi)), 1e-3))
        return geom, _LiveTracer(geom, static_scene, static_ng, moving_objects, self._device)

    @staticmethod
    def _mesh_tables(mesh: MeshData, normals_world, swapped: bool = False) -> tuple:
        """Per-triangle (material, normals, has_normals, uvs) of one mesh (corners 1 and 2
        swapped when its triangles are)."""
        from .geometry import _corners

        t = len(mesh.triangles)
        nrm = normals_world if normals_world is not None else (
            mesh.normals if mesh.normals is not None else np.zeros((t, 3, 3), np.float32))
        uv = mesh.uvs if mesh.uvs is not None else np.zeros((t, 3, 2), np.float32)
        nrm, uv = _corners(np.asarray(nrm), swapped), _corners(np.asarray(uv), swapped)
        return (np.asarray(mesh.material_index, dtype=np.int32), np.asarray(nrm, dtype=np.float32),
                np.full(t, mesh.normals is not None), np.asarray(uv, dtype=np.float32))

    def _attr_names(self) -> list:
        """The per-corner attributes the programs read ("generated", "object_coords",
        "attr<I>"), those some mesh has."""
        return sorted({k for o in self.objects.values() for k in o.mesh.corner_attrs})

    def _corner_attr_tables(self, static_attrs: dict, n_static: int, instance_meshes: list) -> dict:
        """Global per-triangle corner attributes: the static rows, then each instance's (local:
        instance tangents are mapped at the hit like their normals)."""
        from .geometry import _mirrors, corner_attribute, corner_attribute_kinds

        kinds = corner_attribute_kinds(self.attributes)
        out = {}
        for name in self._attr_names():
            parts = [static_attrs.get(name, np.zeros((n_static, 3, 3), np.float32))]
            parts += [corner_attribute(np.asarray(m.corner_attrs.get(name, np.zeros((len(m.triangles), 3, 3))),
                                                  np.float32), kinds.get(name), None, False, _mirrors(matrix))
                      for m, matrix in instance_meshes]
            out[name] = np.concatenate(parts)
        return out

    def _flatten_static(self):
        """World-space (shifted) positions and triangles of the static objects, their
        per-triangle tables and corner attributes (tangents mapped to world space)."""
        from .geometry import _corners, _mirrors, corner_attribute, corner_attribute_kinds

        kinds = corner_attribute_kinds(self.attributes)
        names = self._attr_names()
        attr_parts: dict = {n: [] for n in names}
        pos_parts, tri_parts, tables = [], [], []
        v_offset = 0
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for obj in self.objects.values():
            mesh = obj.mesh
            if obj.instance or len(mesh.triangles) == 0:
                continue
            m = self._shifted(obj.matrix)
            world = np.empty((len(mesh.positions), 3), dtype=np.float32)
            _points_to_world(np.ascontiguousarray(mesh.positions, dtype=np.float64),
                             np.ascontiguousarray(m), world, lo, hi)
            pos_parts.append(world)
            flip = _mirrors(m)  # a mirroring matrix: corners swapped (geometry.build_geometry)
            tri_parts.append((_corners(np.asarray(mesh.triangles), flip) + v_offset).astype(np.int32))
            v_offset += len(world)
            nw = _transform_normals(mesh.normals, m) if mesh.normals is not None else None
            tables.append(self._mesh_tables(mesh, nw, flip))
            for n in names:
                a = mesh.corner_attrs.get(n)
                a = np.zeros((len(mesh.triangles), 3, 3), np.float32) if a is None else np.asarray(a, np.float32)
                attr_parts[n].append(corner_attribute(a, kinds.get(n), m, flip, flip))
        pos = np.concatenate(pos_parts) if pos_parts else np.zeros((0, 3), np.float32)
        tri = np.concatenate(tri_parts) if tri_parts else np.zeros((0, 3), np.int32)
        empty = (np.zeros(0, np.int32), np.zeros((0, 3, 3), np.float32), np.zeros(0, bool),
                 np.zeros((0, 3, 2), np.float32))
        static_tables = tuple(np.concatenate([t[i] for t in tables]) if tables else empty[i]
                              for i in range(4))
        attrs = {n: np.concatenate(p) if p else np.zeros((0, 3, 3), np.float32) for n, p in attr_parts.items()}
        return pos, tri, static_tables, attrs


def _culling_box(radius: float, motion: RigidMotion) -> tuple[np.ndarray, np.ndarray]:
    """World box (tracer space) of an object whose local points lie within ``radius`` of its
    origin, under a static ``motion``: the tracer's swept box (``trace._swept_box``) for
    open = close, from a cached radius instead of the vertices."""
    rho = radius * float(np.abs(motion.open.scale).max())
    t = motion.open.translation
    lo, hi = t - rho, t + rho
    pad = 1e-6 * (np.abs(lo) + np.abs(hi) + rho) + 1e-9
    return (np.ascontiguousarray(lo - pad, dtype=np.float64).copy(),
            np.ascontiguousarray(hi + pad, dtype=np.float64).copy())


# ---------------------------------------------------------------------------- session


@dataclass
class Frame:
    """The latest image of a session: ``rgba`` (height, width, 4) float32 scene-linear,
    **bottom row first** (what a GPU texture and Blender want); ``samples`` per pixel;
    ``divider``: 1 at full resolution, k when rendered at 1/k of it (drawn scaled up);
    ``generation``: which edit/view state it shows; ``seconds``: from that state's request;
    ``denoised``: the RGB went through the session's ``denoiser``."""

    rgba: np.ndarray
    width: int
    height: int
    samples: int
    divider: int
    generation: int
    seconds: float
    denoised: bool = False


def coarse_dividers(width: int, height: int, coarse_pixels: int = COARSE_PIXELS) -> list[int]:
    """Resolution dividers after an edit, coarsest first, ending with 1: the first is the
    smallest power of two that brings width·height down to ``coarse_pixels``."""
    div = 1
    while (width // div) * (height // div) > coarse_pixels and div < 64:
        div *= 2
    out = []
    while div >= 1:
        out.append(div)
        div //= 2
    return out


class ProgressiveSession:
    """Progressive rendering of a ``LiveScene`` on a background thread, restarted by edits.

    ``edit(fn)`` queues ``fn(live_scene)``; ``set_view(camera, width, height, spp)`` sets what
    to render (spp: samples per pixel to accumulate; 0 = keep going). Either restarts the
    accumulation. ``latest()`` is the newest ``Frame`` (or None); ``on_frame()`` is called
    from the session thread after each new frame (Blender: ``tag_redraw``). ``stop()`` ends the
    thread (and with it every render thread) and returns within about one batch (< 0.5 s).
    ``error`` holds the message of the first failed edit (skipped; the rest renders) or failed
    build/render (the session then waits for the next edit) of the current state.
    """

    def __init__(self, live: LiveScene | None = None, *, threads: int | None = None,
                 on_frame: Callable[[], None] | None = None,
                 coarse_pixels: int = COARSE_PIXELS):
        self.live = live or LiveScene()
        self.threads = max(1, int(threads or os.cpu_count() or 1))
        self.on_frame = on_frame
        self.coarse_pixels = coarse_pixels
        self.error: str | None = None
        self.restarts = 0
        #: where the time to the first frame of the latest generation went (seconds): "wait"
        #: (the render in flight draining), "edits" (applying them), "build" (BVHs, tables,
        #: camera), "render" (the coarse pass); for benchmarks
        self.timings: dict = {}
        #: gate() -> bool: while it returns False the session waits before rendering (polled
        #: every 0.1 s, from the session thread; the add-on waits for a kernel compilation)
        self.gate: Callable[[], bool] | None = None
        #: denoiser(film) -> (H, W, 3) RGB, top row first (``drt.denoise`` with the viewport's
        #: settings), applied to full-resolution frames from ``denoise_start_sample`` samples on,
        #: as Cycles's viewport denoising; None: off. Runs on the session thread, so a slow
        #: denoiser slows refinement, never Blender's UI. A failure is reported in ``error``
        #: and turns it off until it is set again.
        self.denoiser: Callable | None = None
        self.denoise_start_sample = 1
        self._cond = threading.Condition()
        self._edits: list = []
        self._view = None  # (CameraSpec, width, height, spp)
        self._generation = 0
        self._requested_at = time.perf_counter()
        self._pending = False
        self._busy = False
        self._stopped = False
        self._frame: Frame | None = None
        self._timing: dict | None = None
        self._done = False  # the current generation reached its sample count
        self._thread = threading.Thread(target=self._run, name="drt-viewport", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ caller side
    def edit(self, fn: Callable[[LiveScene], None]) -> None:
        with self._cond:
            self._edits.append(fn)
            self._restart()

    def set_view(self, camera: CameraSpec, width: int, height: int, spp: int = 0) -> bool:
        """Set the view; returns True when it differs from the current one (a restart)."""
        view = (camera, int(width), int(height), int(spp))
        with self._cond:
            if self._view is not None and _same_view(self._view, view):
                return False
            self._view = view
            self._restart()
            return True

    def set_denoiser(self, denoiser: Callable | None, start_sample: int = 1) -> None:
        """Turn viewport denoising on (``denoiser(film) -> RGB``) or off (None); restarts the
        accumulation so the next frames show the change."""
        with self._cond:
            self.denoiser, self.denoise_start_sample = denoiser, max(1, int(start_sample))
            self._restart()

    def latest(self) -> Frame | None:
        return self._frame

    @property
    def generation(self) -> int:
        return self._generation

    @property
    def converged(self) -> bool:
        """The current view has all its samples (the thread idles until the next edit)."""
        return self._done

    def wait(self, predicate: Callable[[Frame], bool], timeout: float = 10.0) -> Frame | None:
        """Block until ``latest()`` satisfies ``predicate`` (or an error / timeout); for
        tests and benchmarks."""
        end = time.perf_counter() + timeout
        while time.perf_counter() < end:
            f = self._frame
            if f is not None and f.generation == self._generation and predicate(f):
                return f
            if self.error is not None and not self._pending and not self._busy \
                    and (f is None or f.generation != self._generation):
                return None
            time.sleep(0.002)
        return None

    def stop(self, timeout: float = 5.0) -> bool:
        """Stop rendering and end the session thread; True when it ended within ``timeout``."""
        with self._cond:
            self._stopped = True
            self._generation += 1  # cancels the render in flight
            self._cond.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)
        return not self._thread.is_alive()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _restart(self) -> None:
        """(lock held) Cancel the render in flight and schedule a new one."""
        self._generation += 1
        self._requested_at = time.perf_counter()
        self._pending = True
        self._done = False
        self.restarts += 1
        self._cond.notify_all()

    # ------------------------------------------------------------------ session thread
    def _run(self) -> None:
        while True:
            with self._cond:
                while not (self._pending and self._view is not None) and not self._stopped:
                    self._cond.wait()
                if self._stopped:
                    return
            gate = self.gate
            if gate is not None and not gate():
                with self._cond:  # not yet (e.g. kernels compiling elsewhere): stoppable wait
                    self._cond.wait(0.1)
                continue
            # a cancelled render may have left a batch running (compiling the kernels); the
            # edits below change scene data it reads
            if not settle_abandoned_batches(lambda: self._stopped):
                return
            with self._cond:
                if self._stopped:
                    return
                edits, self._edits = self._edits, []
                view, gen, t0 = self._view, self._generation, self._requested_at
                self._pending = False
                self._busy = True
            try:
                t1 = time.perf_counter()
                self.error = None
                for fn in edits:
                    try:
                        fn(self.live)
                    except Exception as exc:  # noqa: BLE001 -- a bad edit is reported and skipped
                        self._fail(exc)
                self._timing = {"wait": t1 - t0, "edits": time.perf_counter() - t1}
                self._render(view, gen, t0)
            except Exception as exc:  # noqa: BLE001 -- reported to the caller, never fatal
                self._fail(exc)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def _fail(self, exc: Exception) -> None:
        if not isinstance(exc, SceneError):
            traceback.print_exc()
        msg = str(exc) if isinstance(exc, SceneError) else f"{exc.__class__.__name__}: {exc}"
        self.error = self.error or msg  # the first problem of this state

    def _render(self, view, gen: int, t0: float) -> None:
        camera, width, height, spp = view

        def cancelled() -> bool:
            return self._generation != gen

        for div in coarse_dividers(width, height, self.coarse_pixels)[:-1]:
            if cancelled():
                return
            w, h = max(1, width // div), max(1, height // div)
            t1 = time.perf_counter()
            scene, ctx = self.live.context(camera, w, h, spp=1)
            t2 = time.perf_counter()
            film = render(scene, spp=1, context=ctx, cancel=cancelled, threads=self.threads,
                          max_batch_paths=VIEWPORT_BATCH_PATHS)
            if film.stats.samples_done and not cancelled():
                if self._timing is not None:
                    self._timing.update(build=t2 - t1, render=time.perf_counter() - t2)
                    self.timings, self._timing = self._timing, None
                self._publish(film, 1, div, gen, t0)
        if cancelled():
            return
        total = spp if spp > 0 else 1 << 20
        t1 = time.perf_counter()
        scene, ctx = self.live.context(camera, width, height, spp=total)
        t_build = time.perf_counter() - t1
        # Full resolution in chunks of samples sized to take about CHUNK_SECONDS each, so the
        # image refreshes at a steady rate (the render loop's own passes double up to 64 spp,
        # minutes apart on a large view). Sample numbers continue from chunk to chunk, so the
        # sum equals one render of `total` samples.
        film, done, chunk = None, 0, 1
        while done < total and not cancelled():
            k = min(chunk, total - done)
            t_chunk = time.perf_counter()
            part = render(scene, spp=total, sample_offset=done, sample_count=k, context=ctx,
                          cancel=cancelled, threads=self.threads,
                          max_batch_paths=VIEWPORT_BATCH_PATHS)
            if cancelled() or part.stats.cancelled:
                return
            if film is None:
                film = part
            else:
                film.merge(part)
            done += k
            if self._timing is not None:  # no coarse pass (a small view)
                self._timing.update(build=t_build, render=time.perf_counter() - t_chunk)
                self.timings, self._timing = self._timing, None
            self._publish(film, done, 1, gen, t0)
            rate = k / max(time.perf_counter() - t_chunk, 1e-3)  # samples per second
            chunk = int(min(max(1, rate * CHUNK_SECONDS), 2 * k, 64))
        if not cancelled():
            self._done = True

    def _publish(self, film, samples: int, divider: int, gen: int, t0: float) -> None:
        combined = np.nan_to_num(film.combined, nan=0.0, posinf=0.0, copy=False)  # (a new array)
        denoiser, denoised = self.denoiser, False
        if denoiser is not None and divider == 1 and samples >= max(1, self.denoise_start_sample):
            try:
                rgb = np.asarray(denoiser(film), dtype=np.float32)
                combined = np.concatenate([rgb, combined[..., 3:]], axis=-1)
                denoised = True
            except Exception as exc:  # noqa: BLE001 -- show the noisy image and say why
                self.denoiser = None
                self.error = self.error or f"viewport denoising failed: {exc}"
        rgba = np.ascontiguousarray(combined[::-1], dtype=np.float32)
        self._frame = Frame(rgba, film.width, film.height, int(samples), divider, gen,
                            time.perf_counter() - t0, denoised)
        if self.on_frame is not None:
            try:
                self.on_frame()
            except Exception:  # noqa: BLE001 -- e.g. the Blender engine is gone: just stop drawing
                self.on_frame = None


def _same_view(a, b) -> bool:
    ca, cb = a[0], b[0]
    if a[1:] != b[1:]:
        return False
    for f in ca.__dataclass_fields__:
        x, y = getattr(ca, f), getattr(cb, f)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if x is None or y is None or not np.array_equal(np.asarray(x), np.asarray(y)):
                return False
        elif x != y:
            return False
    return True


# ---------------------------------------------------------------------------- view → camera


def camera_from_projection(view_to_world, projection, *, lens: float, clip_start: float,
                           clip_end: float, dof: dict | None = None) -> CameraSpec:
    """A ``CameraSpec`` that renders exactly what an OpenGL-style projection shows.

    view_to_world: (4, 4) camera → world (the inverse of a viewport's view matrix; looks along
    −Z, +Y up). projection: (4, 4) the viewport's window matrix (perspective or orthographic,
    possibly off-centre: camera-view zoom and offset, lens shift). The image-plane extent and
    centre are read from it: perspective, at distance 1: width 2/P[0,0], centre P[0,2]/P[0,0];
    orthographic, in scene units: width 2/P[0,0], centre −P[0,3]/P[0,0] (y alike). The result
    uses a horizontal sensor fit with ``sensor_width = lens · width`` (so the aperture radius,
    lens/(2·fstop), uses the real ``lens`` in mm) and shift in units of the width. Clip
    distances are taken as given (the float32 matrix loses the far plane's precision).
    dof: {"use", "focus_distance", "fstop", "blades", "rotation", "ratio"} or None (pinhole).
    """
    p = np.asarray(projection, dtype=np.float64).reshape(4, 4)
    m = np.asarray(view_to_world, dtype=np.float64).reshape(4, 4)
    ortho = abs(p[3, 3] - 1.0) < 1e-6 and abs(p[3, 2]) < 1e-6
    if not (p[0, 0] > 0 and p[1, 1] > 0):
        raise SceneError("view", "the projection matrix is degenerate")
    plane_w = 2.0 / p[0, 0]
    if ortho:
        cx, cy = -p[0, 3] / p[0, 0], -p[1, 3] / p[1, 1]
    else:
        cx, cy = p[0, 2] / p[0, 0], p[1, 2] / p[1, 1]
    lens = float(lens) if lens > 0 else 50.0
    d = dof or {}
    return CameraSpec(
        type="ORTHO" if ortho else "PERSP", matrix=m,
        lens=lens, sensor_width=plane_w * lens, sensor_height=plane_w * lens,
        sensor_fit="HORIZONTAL", shift_x=cx / plane_w, shift_y=cy / plane_w,
        clip_start=float(clip_start), clip_end=float(max(clip_end, clip_start + 1e-6)),
        ortho_scale=plane_w,
        dof_use=bool(d.get("use", False)), focus_distance=float(d.get("focus_distance", 10.0)),
        fstop=float(d.get("fstop", 2.8)), blades=int(d.get("blades", 0)),
        rotation=float(d.get("rotation", 0.0)), ratio=float(d.get("ratio", 1.0)))


def projection_plane(spec: CameraSpec, width: int, height: int) -> tuple[float, float, float, float]:
    """(plane width, plane height, centre x, centre y) of ``spec`` at width × height pixels:
    at distance 1 (perspective) or in scene units (orthographic), as ``Camera`` computes them.
    The inverse of ``camera_from_projection``, for tests."""
    cam = Camera(spec, RenderSettings(width=int(width), height=int(height)), np.zeros(3))
    return float(cam.plane_w), float(cam.plane_h), float(cam.shift[0]), float(cam.shift[1])


__all__ = ["LiveScene", "LiveObject", "BuildCounters", "ProgressiveSession", "Frame",
           "coarse_dividers", "camera_from_projection", "projection_plane",
           "INSTANCE_MIN_TRIANGLES", "MAX_INSTANCES", "MAX_SHARED_INSTANCES", "COARSE_PIXELS"]
