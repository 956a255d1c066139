"""The Rendered viewport: Blender's depsgraph and 3D view → the core's interactive session.

``ViewportSync`` runs on Blender's main thread (``view_update`` / ``view_draw``). It exports the
scene once, then reads ``depsgraph.updates`` and sends the core's ``ProgressiveSession`` only
what changed, as edits of its ``LiveScene`` (``drt/interactive.py``):

* an object transform → a new matrix (no mesh export; no BVH rebuild for large objects);
* ``is_updated_geometry`` on a mesh object → that object's mesh is exported again;
* a material (or its node tree) → that material converted again; the material list replaced;
* a light, the world, render settings → re-read and sent only if they differ;
* objects added, removed, hidden or instanced → found by comparing the object instances with
  what the session holds (a transform-only update reads only matrices).

``view_camera`` turns the 3D view (camera view, free perspective, orthographic) into a core
camera; ``draw_frame`` is the thin GPU layer (not testable without a display).

The session thread never touches bpy: everything it needs is copied here first.
"""

from __future__ import annotations

import numpy as np

from . import compat, denoising
from .export import (_instance_key, _instance_name, _is_rendered, instance_visibility,
                     objects_presented_as_meshes, visibility_bits)
from .export.materials import MaterialExporter
from .export.node_programs import ImageTable
from .export.mesh import MESH_LIKE_TYPES, evaluated_mesh_arrays
from .export.scene_parts import camera_dict, light_dict, matrix_list, render_settings, world_dict

_IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


def _validated(scene, materials: list, lights: list, world: dict, extra=None, arrays=None):
    """Render settings, materials, lights and world validated by the core like a scene file's
    (the camera is a placeholder: the view supplies the real one); ``extra`` header entries
    (images, attributes) with their ``arrays``."""
    scene_mod = compat.core_module("scene")
    header = {"format": "drt-scene", "version": 2, "render": render_settings(scene, preview=True),
              "camera": {"type": "PERSP", "matrix_world": _IDENTITY}, "world": world,
              "materials": materials, "lights": lights, "meshes": [], "objects": [], **(extra or {})}
    return scene_mod.scene_from_dict(header, dict(arrays or {}))


class ViewportSync:
    """Keeps a ``ProgressiveSession`` in step with a Blender depsgraph (main thread only).

    ``exports`` counts what was exported from Blender and sent to the session: "meshes" (one
    per mesh export), "materials" (one per material converted), "lights", "world", "settings"
    (one per changed list / value sent); tests use it to check that an edit re-exports only
    what it touched.
    """

    def __init__(self, threads: int | None = None, on_frame=None):
        interactive = compat.core_module("interactive")
        self.session = interactive.ProgressiveSession(threads=threads, on_frame=on_frame)
        self.exports = {"meshes": 0, "materials": 0, "lights": 0, "world": 0, "settings": 0}
        self.warnings: list[str] = []
        self._materials = MaterialExporter()
        self._objects: dict = {}  # instance key -> (matrix (4,4) array, mesh key)
        self._mesh_keys: set = set()
        self._mesh_reads: dict = {}  # mesh key -> geometry inputs its export carries
        self._lights: list = []
        self._world: dict | None = None
        # what the session was sent, for the kernel variant it needs (kernel_variant)
        self._sent_materials: list = []
        self._sent_world = (None, None)  # (world volume, world program)
        self._settings = None
        self._denoise_config = (False,)  # off until the scene says otherwise
        self._view = None
        self.synced = False
        self.texture = None  # FrameTexture: the latest frame on the GPU (main thread only)

    # ------------------------------------------------------------------ depsgraph
    def sync(self, depsgraph) -> None:
        """The first full export, or the incremental one from ``depsgraph.updates``."""
        if not self.synced:
            self._full(depsgraph)
            self.synced = True
            return
        geometry, materials, lights, world, settings, objects = set(), [], False, False, False, False
        updates = list(depsgraph.updates)
        shading_edit = any(type(u.id).__name__ in ("Material", "ShaderNodeTree") for u in updates)
        # original data-block pointer → that data-block's own geometry flag in this batch
        data_geometry = {u.id.original.as_pointer(): u.is_updated_geometry
                         for u in updates if type(u.id).__name__ != "Object"}
        for u in updates:
            idt = u.id
            kind = type(idt).__name__
            if kind == "Object":
                if idt.type == "LIGHT":
                    lights = True
                elif u.is_updated_geometry and not (
                        shading_edit and self._only_its_material_changed(idt, data_geometry)):
                    geometry.add(idt.original.name)
                    objects = True
                elif u.is_updated_transform or u.is_updated_shading:
                    objects = True  # (shading: object settings such as its ray visibility)
                if idt.instance_type != "NONE" or idt.type == "EMPTY":
                    objects = True  # an instancer or a parent: its instances may move
            elif kind == "Material":
                materials.append(idt.original)
            elif kind == "ShaderNodeTree":
                materials += [m for m in self._materials_using(idt)]
                world = world or self._is_world_tree(depsgraph, idt)
            elif kind in ("World",):
                world = True
            elif kind == "Scene":
                settings = True
                objects = True  # visibility, frame, view-layer changes
            elif kind == "Collection":
                objects = True
            elif kind in ("PointLight", "SpotLight", "SunLight", "AreaLight", "Light"):
                lights = True
        if materials:
            self._update_materials(depsgraph.scene, materials)
            # a program that now reads geometry inputs its meshes lack: export those again
            geometry |= {key[0] for _, key, _ in self._objects.values()
                         if not set(self._materials.reads(key[1])) <= self._mesh_reads.get(key, set())}
        if objects or geometry:
            self._reconcile(depsgraph, geometry)
        if lights or objects:
            self._sync_lights(depsgraph)
        if world or settings:
            self._sync_world_and_settings(depsgraph.scene)

    @staticmethod
    def _only_its_material_changed(obj, data_geometry: dict) -> bool:
        """Whether an object's geometry flag only echoes an edit of one of its materials.

        Blender 5.1+ flags ``is_updated_geometry`` on every object that uses an edited material
        (5.0 did not); its mesh comes in the same batch with its own geometry flag off. A real
        edit of the mesh flags the mesh too, and a geometry-nodes edit does not list the mesh, but
        any modifier could read anything: an object with modifiers is exported again anyway.
        DRT's material programs never move geometry (displacement is bump), so the mesh export
        and the hierarchy rebuild would change nothing."""
        orig = obj.original
        data = orig.data
        return data is not None and data_geometry.get(data.as_pointer()) is False and not orig.modifiers

    def _full(self, depsgraph) -> None:
        self._reconcile(depsgraph, set())
        self._sync_lights(depsgraph, force=True)
        self._sync_world_and_settings(depsgraph.scene, force=True)

    def _materials_using(self, tree):
        for idx_key, idx in list(self._materials._index.items()):
            mat = self._find_material(idx_key)
            if mat is not None and mat.node_tree is not None and \
                    mat.node_tree.as_pointer() in (tree.as_pointer(), tree.original.as_pointer()):
                yield mat

    @staticmethod
    def _is_world_tree(depsgraph, tree) -> bool:
        w = depsgraph.scene.world
        return w is not None and w.node_tree is not None and \
            w.node_tree.as_pointer() in (tree.as_pointer(), tree.original.as_pointer())

    @staticmethod
    def _find_material(pointer):
        import bpy
        if pointer is None:
            return None
        for m in bpy.data.materials:
            if m.as_pointer() == pointer:
                return m
        return None

    def _update_materials(self, scene, materials) -> None:
        """Convert edited materials again and send the list."""
        seen = set()
        for mat in materials:
            key = mat.original.as_pointer()
            if key in seen:
                continue
            seen.add(key)
            idx = self._materials._index.get(key)
            if idx is None:
                continue  # not used by any exported object yet: exported when it is
            self._materials.materials[idx] = self._materials.convert(mat)
            self.exports["materials"] += 1
        self._send_materials(scene)

    def kernel_variant(self) -> str:
        """The variant of the render kernels the scene sent so far renders with
        (``drt.kernels.scene_kernel_variant``). Any thread."""
        from types import SimpleNamespace
        volume, program = self._sent_world
        sent = SimpleNamespace(materials=self._sent_materials, world_volume=volume, world_program=program)
        return compat.core_module("kernels").scene_kernel_variant(sent)

    def _send_materials(self, scene) -> None:
        """The material list with its programs, the images and attribute names they read."""
        mats = self._materials
        extra = {"attributes": list(mats.attributes)} if mats.attributes else {}
        if mats.images.images:
            extra["images"] = mats.images.images
        sc = _validated(scene, mats.materials, [], {"color": [0, 0, 0]}, extra, mats.images.arrays)
        self._sent_materials = sc.materials
        self.session.edit(lambda live, m=sc.materials, i=sc.images, a=sc.attributes:
                          live.set_materials(m, i, a))

    def _reconcile(self, depsgraph, geometry: set) -> None:
        """Compare the object instances with what the session holds; send the differences.
        ``geometry``: original names of objects whose geometry changed (exported again)."""
        seen = set()
        exported: dict = {}  # mesh key -> MeshData, shared by instances of one object
        n_materials = len(self._materials.materials)
        edits = []
        presented = objects_presented_as_meshes(depsgraph)
        for inst in depsgraph.object_instances:
            obj = inst.object
            if obj.type not in MESH_LIKE_TYPES or not _is_rendered(inst, presented):
                continue
            key = _instance_key(inst)
            matrix = np.array(matrix_list(inst.matrix_world), dtype=np.float64)
            visibility = visibility_bits(*instance_visibility(inst, depsgraph.view_layer))
            slots = [s.material for s in obj.material_slots] or [None]
            slot_mats = tuple(self._materials.index_of(m) for m in slots)
            mesh_key = (obj.original.name, slot_mats)
            old = self._objects.get(key)
            seen.add(key)
            if old is not None and old[1] == mesh_key and obj.original.name not in geometry:
                if not np.array_equal(old[0], matrix):
                    edits.append(lambda live, k=key, m=matrix: live.set_matrix(k, m))
                if old[2] != visibility:
                    edits.append(lambda live, k=key, v=visibility: live.set_visibility(k, v))
                self._objects[key] = (matrix, mesh_key, visibility)
                continue
            mesh = exported.get(mesh_key)
            if mesh is None:
                reads = self._materials.reads(slot_mats)
                data = evaluated_mesh_arrays(obj, np.array(slot_mats, dtype=np.int32), reads)
                self._mesh_reads[mesh_key] = set(reads)
                self.exports["meshes"] += 1
                mesh = interactive_mesh(obj.name, data)
                exported[mesh_key] = mesh
            if mesh is False:
                if old is not None:
                    edits.append(lambda live, k=key: live.remove_object(k))
                    del self._objects[key]
                continue
            self._objects[key] = (matrix, mesh_key, visibility)
            edits.append(lambda live, k=key, n=_instance_name(inst, key), me=mesh, m=matrix, v=visibility:
                         live.set_object(k, n, me, m, v))
        for key in [k for k in self._objects if k not in seen]:
            del self._objects[key]
            edits.append(lambda live, k=key: live.remove_object(k))
        if len(self._materials.materials) != n_materials or not self.synced:
            self._send_materials(depsgraph.scene)  # before the objects: their meshes index them
        if edits:
            self.session.edit(lambda live, es=edits: [e(live) for e in es])

    def _sync_lights(self, depsgraph, force: bool = False) -> None:
        lights = []
        for inst in depsgraph.object_instances:
            if inst.object.type == "LIGHT" and _is_rendered(inst):
                ld = light_dict(inst.object, inst.matrix_world.copy(), [])
                if ld is not None:
                    lights.append(ld)
        if force or lights != self._lights:
            self.exports["lights"] += 1
            self._lights = lights
            valid = _validated(depsgraph.scene, [], lights, {"color": [0, 0, 0]}).lights
            self.session.edit(lambda live, li=valid: live.set_lights(li))

    def _sync_denoiser(self, scene, force: bool = False) -> None:
        """Viewport denoising on/off and its settings (read here, on the main thread: the
        session thread never touches bpy)."""
        d = scene.drt
        config = (bool(d.use_preview_denoising), int(d.preview_denoising_start_sample),
                  d.preview_denoising_prefilter, d.preview_denoising_quality, d.preview_denoising_input_passes)
        if not force and config == self._denoise_config:
            return
        self._denoise_config = config
        self.exports["settings"] += 1
        self.session.set_denoiser(viewport_denoiser(*config[2:]) if config[0] else None, config[1])

    def _sync_world_and_settings(self, scene, force: bool = False) -> None:
        self._sync_denoiser(scene, force)
        images = ImageTable()  # the world's own images (LiveScene appends them to the materials')
        world = world_dict(scene.world, [], images)
        extra = {"images": images.images} if images.images else None
        checked = _validated(scene, [], [], world, extra, images.arrays)
        if force or world != self._world:
            self.exports["world"] += 1
            self._world = world
            self._sent_world = (checked.world_volume, checked.world_program)
            self.session.edit(lambda live, c=checked.world_color, v=checked.world_volume,
                              p=checked.world_program, im=checked.images: live.set_world(c, v, p, im))
        if force or checked.render != self._settings:
            self.exports["settings"] += 1
            self._settings = checked.render
            self.session.edit(lambda live, s=checked.render: live.set_settings(s))

    # ------------------------------------------------------------------ view
    def set_view(self, camera, width: int, height: int, spp: int) -> bool:
        """Render ``camera`` (a core CameraSpec) at width × height; True when that restarts."""
        return self.session.set_view(camera, width, height, spp)

    def stop(self, timeout: float = 5.0) -> bool:
        self.session.on_frame = None
        return self.session.stop(timeout)


def viewport_denoiser(prefilter: str, quality: str, input_passes: str):
    """``denoiser(film) -> RGB`` for ``ProgressiveSession`` with the viewport's settings: Open
    Image Denoise from Blender (or pyoidn), the film's albedo/normal as guides per
    ``input_passes``. Without a denoiser it raises on first use, which the session reports in
    the viewport header and then shows the noisy image."""
    denoise_mod = compat.core_module("denoise")
    try:
        library = denoising.backend_library(denoise_mod)
    except denoise_mod.DenoiserUnavailable as exc:
        message = str(exc)

        def unavailable(film):
            raise denoise_mod.DenoiserUnavailable(message)

        return unavailable

    def run(film):
        return denoising.denoise_with(film, input_passes, prefilter, quality, denoise_mod, library)

    return run


def interactive_mesh(name: str, data: dict | None):
    """Exported mesh arrays → a core ``MeshData`` (False when the object has no triangles)."""
    if data is None:
        return False
    scene_mod = compat.core_module("scene")
    attrs = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in data.items()
             if k in ("generated", "object_coords") or k.startswith("attr")}
    return scene_mod.MeshData(
        name, np.ascontiguousarray(data["positions"], dtype=np.float64),
        np.ascontiguousarray(data["triangles"], dtype=np.int64),
        np.ascontiguousarray(data["material_index"], dtype=np.int64),
        data.get("normals"), data.get("uvs"), None, attrs)


# ---------------------------------------------------------------------------- view → camera


def view_camera(depsgraph, space, region_data, width: int, height: int):
    """The core camera (CameraSpec) that shows what the 3D view shows, at width × height.

    Camera view: the scene's (or the view's local) camera with its lens, clipping and depth of
    field; the framing (zoom, pan, lens shift, sensor fit) comes from the view's projection,
    so the render lines up with the camera frame Blender draws. Free perspective: the view's
    lens and clip range, no depth of field (as Cycles). Orthographic: clip range
    [−clip_end/2, clip_end/2] around the view centre, as Blender's own ortho view uses.
    """
    interactive = compat.core_module("interactive")
    view_to_world = np.array(matrix_list(region_data.view_matrix.inverted()), dtype=np.float64)
    projection = np.array(matrix_list(region_data.window_matrix), dtype=np.float64)
    kind = region_data.view_perspective
    if kind == "CAMERA":
        cam_obj = space.camera if getattr(space, "use_local_camera", False) and space.camera \
            else depsgraph.scene.camera
        if cam_obj is not None and cam_obj.type == "CAMERA":
            cam_eval = cam_obj.evaluated_get(depsgraph)
            d = camera_dict(cam_eval, cam_eval.matrix_world.copy())
            return interactive.camera_from_projection(
                np.array(d["matrix_world"], dtype=np.float64), projection, lens=d["lens"],
                clip_start=d["clip_start"], clip_end=d["clip_end"], dof=d["dof"])
    if kind == "ORTHO" or not region_data.is_perspective:
        half = float(space.clip_end) * 0.5
        return interactive.camera_from_projection(view_to_world, projection, lens=float(space.lens),
                                                  clip_start=-half, clip_end=half)
    return interactive.camera_from_projection(view_to_world, projection, lens=float(space.lens),
                                              clip_start=float(space.clip_start),
                                              clip_end=float(space.clip_end))


def render_size(region_width: int, region_height: int, pixel_size: int) -> tuple[int, int]:
    """Render resolution for a region: Blender's viewport pixel size divides it (retina/UI
    scale or the scene's Viewport > Pixel Size setting)."""
    p = max(1, int(pixel_size))
    return max(1, region_width // p), max(1, region_height // p)


# ---------------------------------------------------------------------------- drawing


class FrameTexture:
    """A GPU texture of the session's latest frame, remade only when a new frame arrives."""

    def __init__(self):
        self.key = None
        self.texture = None

    def update(self, frame) -> None:
        import gpu
        key = (frame.generation, frame.samples, frame.divider, frame.width, frame.height)
        if key == self.key:
            return
        n = frame.width * frame.height * 4
        buf = gpu.types.Buffer("FLOAT", n, frame.rgba.reshape(-1))
        self.texture = gpu.types.GPUTexture((frame.width, frame.height), format="RGBA16F", data=buf)
        self.key = key


def draw_frame(engine, scene, tex: FrameTexture, frame, region_width: int, region_height: int) -> None:
    """Draw the frame over the whole region through the scene's display transform."""
    import gpu
    from gpu_extras.presets import draw_texture_2d

    tex.update(frame)
    gpu.state.blend_set("ALPHA_PREMULT")
    engine.bind_display_space_shader(scene)
    draw_texture_2d(tex.texture, (0, 0), region_width, region_height)
    engine.unbind_display_space_shader()
    gpu.state.blend_set("NONE")


def status_text(frame, target: int, error: str | None, variant: str = "") -> str:
    """The viewport header; ``variant``: the kernel variant the scene needs (before its first
    frame, the header says when those kernels are still compiling)."""
    if error:
        return f"DRT | Error: {error}"
    if frame is None:
        if not compat.core_module("kernels").kernels_compiled(variant):
            return "DRT | Compiling render kernels (first render of this kind of scene: up to a minute)"
        return "DRT | Preparing"
    if frame.divider > 1:
        return f"DRT | Preview 1/{frame.divider}"
    if frame.denoised:
        done = " | Done" if target and frame.samples >= target else ""
        return f"DRT | Sample {frame.samples}/{target} | Denoised{done}" if target else \
            f"DRT | Sample {frame.samples} | Denoised"
    if target and frame.samples >= target:
        return f"DRT | Sample {frame.samples}/{target} | Done"
    return f"DRT | Sample {frame.samples}/{target}" if target else f"DRT | Sample {frame.samples}"



# ---------------------------------------------------------------------------- kernel warm-up

# Compiling the kernels (first use of an install) inside Blender's UI process while the viewport
# runs crashed Debian's Blender 3.4.1 (segfaults in the compiling thread, twice in two tries;
# F12, which blocks the UI meanwhile, compiled fine). So in an interactive Blender the first
# viewport compiles them in a background Blender process (``blender -b``) into the shared kernel
# cache and renders once that has finished; if that process fails, the session compiles them
# itself as before.
WARMUP_SCRIPT = """
import sys
sys.path[:0] = {paths!r}
import importlib
import numpy as np
compat = importlib.import_module({package!r} + ".compat")
interactive = compat.core_module("interactive")
scene_mod = compat.core_module("scene")
render = compat.core_module("render")
n = 128  # a grid of 2·128² triangles: large enough to get its own BVH (the instance path)
u = np.linspace(-1.0, 1.0, n + 1)
x, y = np.meshgrid(u, u)
pos = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
i = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
tri = np.concatenate([np.stack([i, i + 1, i + n + 2], 1), np.stack([i, i + n + 2, i + n + 1], 1)])
normals = np.tile(np.array([0.0, 0.0, 1.0], np.float32), (len(tri), 3, 1))
mesh = scene_mod.MeshData("grid", pos, tri.astype(np.int64), np.zeros(len(tri), np.int64), normals)
small = scene_mod.MeshData("tri", pos[:3], np.array([[0, 1, 2]]), np.zeros(1, np.int64), normals[:1])
small.material_index[:] = 1  # emissive: the mesh-light path
mats = [{{"name": "m", "lobes": [{{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}},
                              {{"type": "GLOSSY", "color": [0.2, 0.2, 0.2], "roughness": 0.3}}],
         "emission": [0, 0, 0]}},
        {{"name": "e", "lobes": [{{"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": 1.45}}],
         "emission": [2, 2, 2]}}]
eye = np.eye(4).tolist()
lights = [{{"name": t, "type": t, "matrix_world": eye}} for t in ("SUN", "POINT", "SPOT", "AREA")]
m = np.eye(4)
m[:3, 3] = (0.0, 0.0, 5.0)
# every variant of the stage kernels (drt.kernels.KERNEL_VARIANTS), so that adding a texture or
# a volume in the viewport later never compiles inside Blender: plain, a material program, one
# with a procedural texture, a medium, and a medium with each kind of program
fmt = compat.core_module("materials.program_format")
program = fmt.validate_program({{"registers": 2, "constants": [[0, 0.5, 0.4, 0.3]], "data": [],
                                "ops": [[fmt.OP_COMBINE, 0, 1, -1, 0, 0, 0, -1, -1, -1, 0]]}}, 0, "warm-up")
white_noise = fmt.validate_program({{"registers": 2, "constants": [[0, 0.5, 0.4, 0.3]], "data": [],
                                    "ops": [[fmt.OP_WHITE_NOISE, 3, 1, -1, 0, 0, -1, -1, -1, -1, 0]]}}, 0,
                                   "warm-up")
textured = dict(mats[0], program=program, lobes=[dict(mats[0]["lobes"][0], color_reg=1), mats[0]["lobes"][1]])
fog = dict(mats[0], volume=compat.core_module("volumes.media").validate_medium({{"absorption": [0.1, 0.1, 0.1]}},
                                                                               "warm-up"))
noisy = dict(textured, program=white_noise)
for first in (mats[0], textured, noisy, fog, dict(textured, volume=fog["volume"]), dict(noisy, volume=fog["volume"])):
    live = interactive.LiveScene(scene_mod.RenderSettings(width=8, height=8), [first, mats[1]], lights,
                                 (0.1, 0.1, 0.1))
    live.set_object("grid", "grid", mesh, np.eye(4))
    live.set_object("tri", "tri", small, np.eye(4))
    scene, ctx = live.context(scene_mod.CameraSpec(type="PERSP", matrix=m), 8, 8, spp=1)
    render.render(scene, spp=1, context=ctx, threads=1)
"""

_warmup = None  # the warm-up process (one per Blender session)


def kernels_cached() -> bool:
    """Are all the render kernels of *this copy* of the core compiled: every variant of the stage
    kernels marked compiled (``drt.kernels.KERNEL_VARIANTS``: plain, textures, procedural
    textures, volumes, volumes with either kind of texture) in this copy's cache folder, and numba's index of
    ``shade`` there? (The folder is keyed by the sources and their import name, so a development
    checkout and an installed add-on each have their own marks.)"""
    import os
    kernels = compat.core_module("kernels")
    try:
        stages = compat.core_module("path_stages")
        indexed = all(os.path.exists(k._cache._cache_file._index_path)  # numba internals
                      for k in (stages.shade, stages.camera_stage))
    except Exception:  # noqa: BLE001 -- another numba: the marks alone
        indexed = True
    return indexed and all(kernels.kernels_compiled(v) for v in kernels.KERNEL_VARIANTS)


def start_kernel_warmup(variant=None):
    """In an interactive Blender whose kernels are not all compiled yet, start compiling them in
    a background Blender; returns a gate for ``ProgressiveSession.gate`` (None: nothing to wait
    for): open when that process has ended, or as soon as the variant of the kernels the scene
    needs (``variant()``, e.g. ``ViewportSync.kernel_variant``) is marked compiled — the warm-up
    compiles the plain variant first. Main thread only; the gate itself only polls the process
    and the marks (safe from any thread)."""
    import subprocess
    import sys

    import bpy

    global _warmup
    if bpy.app.background or kernels_cached():
        return None
    if _warmup is None:
        package = __name__.rsplit(".", 1)[0]
        code = WARMUP_SCRIPT.format(paths=list(sys.path), package=package)
        try:
            _warmup = subprocess.Popen([bpy.app.binary_path, "-b", "--python-expr", code],
                                       stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                       stderr=subprocess.DEVNULL)
        except OSError:
            return None
    proc = _warmup
    kernels = compat.core_module("kernels")
    if variant is None:
        return lambda: proc.poll() is not None
    return lambda: proc.poll() is not None or kernels.kernels_compiled(variant())


# ---------------------------------------------------------------------------- engine hooks
# RenderEngine.view_update / view_draw / __del__ delegate here (engine.py stays thin).

# Viewport sessions by id() of their engine: __del__ may run after Blender removed the engine's
# RNA struct, when even reading an attribute of it raises ReferenceError; id() still works.
_sessions: dict = {}


def engine_view_update(engine, context, depsgraph) -> None:
    """Start the session on the first call; then send what the depsgraph says changed."""
    vp = _sessions.get(id(engine))
    try:
        if vp is None:
            from .engine import render_threads
            vp = ViewportSync(threads=render_threads(depsgraph.scene), on_frame=engine.tag_redraw)
            vp.session.gate = start_kernel_warmup(vp.kernel_variant)
            _sessions[id(engine)] = vp
        vp.sync(depsgraph)
    except Exception as exc:  # noqa: BLE001 -- never a traceback dialog in the viewport
        import traceback
        traceback.print_exc()
        if vp is not None:
            vp.session.error = str(exc) or exc.__class__.__name__
        engine.update_stats("", f"DRT | Error: {exc}")


def engine_view_draw(engine, context, depsgraph) -> None:
    """Follow the view (a new view restarts the session) and draw the latest frame."""
    vp = _sessions.get(id(engine))
    if vp is None:
        return
    scene = depsgraph.scene
    region = context.region
    try:
        width, height = render_size(region.width, region.height,
                                    compat.preview_pixel_size(engine, scene))
        camera = view_camera(depsgraph, context.space_data, context.region_data, width, height)
        vp.set_view(camera, width, height, int(scene.drt.preview_samples))
        vp._sync_denoiser(scene)  # also caught here: a setting changed without a depsgraph update
    except Exception as exc:  # noqa: BLE001 -- e.g. a panoramic camera: say so, draw nothing new
        vp.session.error = str(exc) or exc.__class__.__name__
    frame = vp.session.latest()
    engine.update_stats("", status_text(frame, int(scene.drt.preview_samples), vp.session.error,
                                        vp.kernel_variant() if frame is None else ""))
    if frame is None:
        return
    if vp.texture is None:
        vp.texture = FrameTexture()
    try:
        draw_frame(engine, scene, vp.texture, frame, region.width, region.height)
    except Exception as exc:  # noqa: BLE001 -- a drawing failure is shown once, not every redraw
        if vp.session.error is None:
            import traceback
            traceback.print_exc()
            vp.session.error = f"drawing failed: {exc}"


def engine_free(engine) -> None:
    """Stop the viewport session (the engine is being freed: Solid mode, closed view)."""
    vp = _sessions.pop(id(engine), None)
    if vp is not None:
        vp.stop(timeout=5.0)
