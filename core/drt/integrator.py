"""The wavefront distribution ray tracer: every camera sample integrates, by Monte Carlo, over
pixel area (filter), lens area (depth of field), shutter time (motion blur), light area (soft
shadows: next-event estimation) and the BSDF (glossy, transmission, diffuse interreflection),
each from its own well-stratified sample dimension (Cook 1984; estimators from Veach 1997).

A batch of paths is a set of arrays (``drt.path_stages.Paths``). This module only drives it:
per bounce, Embree finds the closest hits of all live rays (``Tracer.intersect``), the compiled
``shade`` stage does the rest for every path (emission with MIS, next-event estimation, BSDF
sampling, bounce counting, Russian roulette, compaction), and Embree answers the shadow rays it
queued. The estimators themselves are documented in ``drt/path_stages.py``.

How direct light is estimated at each vertex is selectable for study (MIS_POWER is best):
LIGHT: next-event estimation only; BSDF: only BSDF-sampled rays that hit emitters; MIS_*: both,
combined by the balance or power heuristic. The path continues by importance-sampling the BSDF
(best), or cosine-weighted / uniform over the hemisphere on wo's side (materials with
refraction or mirrors always use their BSDF).
"""

from __future__ import annotations

import collections
import functools
import threading
from types import SimpleNamespace

import numpy as np

from . import path_stages as stages
from . import scene as scene_module
from .camera import Camera
from .cryptomatte import CRYPTO_COLUMNS, CRYPTO_SURFACES
from .film import LIGHT_AO, SampleBatch
from .geometry import SceneGeometry
from .lights import LightSet
from .lights.world_map import point_rows
from .materials import MaterialTable
from .materials.table import BLURRED_LOBES
from .path_stages import (D_BOUNCE0, D_LENS, D_PIXEL, D_TIME, DIMS_PER_BOUNCE,  # noqa: F401 (re-exported)
                          MAX_SAMPLE_RADIANCE, RR_START_BOUNCE, SHADOW_EPSILON)
from .sampling.pixel_filter import PixelFilter
from .sampling.sequences import Sampler
from .scene import VIS_ALL, VIS_HOLDOUT, VIS_SHADOW, RenderSettings
from .scratch import Scratch
from .terminator import shading_multipliers, terminator_arrays
from .trace import Tracer
from .kernels import kernel_variant
from .volumes.media import STACK_SIZE, MediumData, build_medium_data
from .volumes.stack import camera_stack
from .materials.transparency import transparent_materials
from .volumes.stage import add_transmitted, shadow_step

DIRECT_STRATEGIES = scene_module.DIRECT_STRATEGIES
INDIRECT_STRATEGIES = scene_module.INDIRECT_STRATEGIES

_NO_XFORM = np.zeros((0, 3, 3))
_NO_MOVING = np.zeros(0, dtype=bool)


def _paths(n: int, sss: bool = False, blur: bool = False) -> stages.Paths:
    m = n if sss else 0  # subsurface state only in scenes with SSS
    b = n if blur else 0  # Filter Glossy's path state only when a render filters
    return stages.Paths(
        o=np.empty((n, 3)), d=np.empty((n, 3)), tmax=np.empty(n), tau=np.empty(n),
        throughput=np.empty((n, 3)), prev_pdf=np.empty(n), prev_delta=np.empty(n, dtype=bool),
        prev_p=np.empty((n, 3)), prev_n=np.empty((n, 3)), prev_wo=np.empty((n, 3)),
        prev_mat=np.empty(n, dtype=np.int64), counts=np.empty((n, 4), dtype=np.int32),
        terminate=np.empty(n, dtype=bool), slot=np.empty(n, dtype=np.int64),
        pixel=np.empty(n, dtype=np.int64), index=np.empty(n, dtype=np.int64),
        prev_flags=np.empty(n, dtype=np.int32),
        vstack=np.empty((n, STACK_SIZE), dtype=np.int64), vcount=np.empty(n, dtype=np.int32),
        vseg=np.empty(n, dtype=np.int32),
        sss=np.zeros(m, dtype=np.int8), sss_coef=np.empty((m, 10)), sss_n=np.empty((m, 3)),
        sss_p=np.empty((m, 3)), sss_prim=np.empty(m, dtype=np.int64), sss_b=np.empty((m, 2)),
        sss_count=np.zeros(m, dtype=np.int32), tcount=np.zeros(n, dtype=np.int32), min_pdf=np.empty(b))


def _shadow_rays(n: int) -> stages.ShadowRays:
    return stages.ShadowRays(o=np.empty((n, 3)), d=np.empty((n, 3)), tmax=np.empty(n), tau=np.empty(n),
                             contrib=np.empty((n, 3)), slot=np.empty(n, dtype=np.int64),
                             vstack=np.empty((n, STACK_SIZE), dtype=np.int64))


def program_data_for(materials: MaterialTable, geom: SceneGeometry, camera: Camera, world=None):
    """The ``ProgramData`` of the scene's material programs, and of the validated ``world``
    program if given (appended last; ``drt.materials.program_format.world_program_index``)."""
    return materials.program_data(geom.uvs, getattr(geom, "corner_attrs", None),
                                  getattr(geom, "origin_shift", None),
                                  getattr(geom, "object_of", None), getattr(geom, "object_info", None),
                                  getattr(geom, "static_positions", None),
                                  getattr(geom, "static_triangles", None),
                                  camera.pixel_footprint(), camera.texture_space(), world=world)


def uv_pass_corners(geom) -> np.ndarray:
    """(T, 3, 3) float32 per corner (u, v, 1) of the render UV map for the UV pass, (0, 0, 0)
    on meshes without one, as Cycles's primitive_uv; (0, 3, 3) when no mesh has one."""
    uvs = getattr(geom, "uvs", None)
    if uvs is None:
        return np.zeros((0, 3, 3), np.float32)
    out = np.zeros((len(uvs), 3, 3), np.float32)
    out[..., :2] = uvs
    has = getattr(geom, "has_uvs", None)
    out[..., 2] = 1.0 if has is None else np.asarray(has, np.float32)[:, None]
    out[..., :2] *= out[..., 2:]
    return out


class Integrator:
    """Renders batches of camera samples. Thread-safe: holds only read-only scene data; every
    batch owns its arrays."""

    def __init__(
        self,
        settings: RenderSettings,
        geom: SceneGeometry,
        tracer: Tracer,
        materials: MaterialTable,
        lights: LightSet,
        camera: Camera,
        sampler: Sampler,
        pixel_filter: PixelFilter,
        direct: str = "MIS_POWER",
        indirect: str = "BSDF",
        media: MediumData | None = None,
        programs=None,
        world_registers: int = 0,
    ):
        if direct not in DIRECT_STRATEGIES:
            raise ValueError(f"unknown direct-light strategy {direct!r} (choose from {', '.join(DIRECT_STRATEGIES)})")
        if indirect not in INDIRECT_STRATEGIES:
            raise ValueError(f"unknown indirect strategy {indirect!r} (choose from {', '.join(INDIRECT_STRATEGIES)})")
        self.direct = direct
        self.indirect = indirect
        self.s = settings
        self.geom = geom
        self.tracer = tracer
        self.materials = materials
        self.lights = lights
        self.camera = camera
        self.sampler = sampler
        self.filter = pixel_filter
        self.motion = bool(geom.moving) or camera.motion is not None
        self.max_depth = settings.max_bounces + 1
        # subsurface scattering: walks between shade calls; an SSS exit takes a loop pass of its
        # own without counting a bounce, so a path needs at most twice the passes
        self.sss = None
        if getattr(materials, "has_subsurface", False):
            from .subsurface import SubsurfaceWalker

            self.sss = SubsurfaceWalker(geom, tracer, materials)
        mist = getattr(settings, "mist", None) or (0.0, 0.0, 1.0)
        self.stage_settings = stages.StageSettings(
            width=int(settings.width), height=int(settings.height),
            max_bounces=int(settings.max_bounces), diffuse_bounces=int(settings.diffuse_bounces),
            glossy_bounces=int(settings.glossy_bounces),
            transmission_bounces=int(settings.transmission_bounces),
            clamp_direct=float(settings.clamp_direct), clamp_indirect=float(settings.clamp_indirect),
            direct=DIRECT_STRATEGIES.index(direct), indirect=INDIRECT_STRATEGIES.index(indirect),
            film_transparent=bool(settings.film_transparent), motion=self.motion,
            volume_bounces=int(getattr(settings, "volume_bounces", 0)),
            transparent_bounces=int(getattr(settings, "transparent_bounces", 8)),
            transparent_glass=(float(settings.film_transparent_roughness) ** 2  # (as alpha = roughness²)
                               if settings.film_transparent and settings.film_transparent_roughness is not None
                               else -1.0),
            filter_glossy=float(getattr(settings, "filter_glossy", 0.0)),
            mist_start=float(mist[0]), mist_inv_depth=1.0 / mist[1] if mist[1] > 0.0 else 0.0,
            mist_falloff=float(mist[2]), mist_ortho=getattr(getattr(camera, "spec", None), "type", "") == "ORTHO",
            pass_alpha=float(getattr(settings, "pass_alpha_threshold", 0.5)),
            ao_distance=(float(getattr(settings, "ao_distance", 10.0))
                         if "ao" in getattr(settings, "light_passes", ()) else 0.0))
        #: the Mist pass is kept only for a render that asks for it (``RenderSettings.mist``)
        self.mist_pass = getattr(settings, "mist", None) is not None
        #: likewise the data passes (``RenderSettings.data_passes``; path_stages.write_data_passes)
        self.data_passes = tuple(getattr(settings, "data_passes", ()))
        #: and the Emission / Environment passes (``RenderSettings.light_passes``)
        self.light_passes = bool(getattr(settings, "light_passes", ()))
        #: and Cryptomatte (``RenderSettings.cryptomatte``; path_stages.write_cryptomatte)
        self.cryptomatte = bool(getattr(settings, "cryptomatte", ())) and getattr(geom, "crypto_ids", None) is not None
        # Filter Glossy keeps a pdf per path only where it can widen a lobe: a render with it on,
        # of a scene with a microfacet lobe (drt.materials.table.filtered_alpha)
        self.filters_glossy = self.stage_settings.filter_glossy > 0.0 and bool(
            np.isin(materials.data.lobe_type, BLURRED_LOBES).any())
        # a batch's working arrays (path state, scratch, ...) are a workspace it holds while it
        # runs (``_held``: the one of the batch this thread runs) and gives back to
        # ``_idle_workspaces`` after; the next batch, on any thread and in any later render with
        # this integrator, takes it up again (``_enter_workspace``)
        self._held = threading.local()
        self._idle_workspaces = collections.deque()
        self._returned_outputs = collections.deque()  # per-batch output buffers (``_outputs``)
        # material programs (textures): a thread rewrites its own copy of the material data
        # (``programs``: built by the caller when it also holds the world's program, see
        # render.prepare; ``world_registers``: that program's register count)
        self.programs = programs if programs is not None else program_data_for(materials, geom, camera)
        src = getattr(materials, "program_source", None)
        self.material_programs = src is not None
        self.n_registers = max(int(max((m["program"]["registers"] for m in src[0] if m.get("program")),
                                       default=0)) if src is not None else 0, int(world_registers))
        normals = geom.normals if geom.normals is not None else np.zeros((0, 3, 3), np.float32)
        term_cut, term_pos, term_tri = terminator_arrays(geom)  # shadow terminator offset (drt.terminator)
        self.surfaces = stages.Surfaces(
            material=np.ascontiguousarray(geom.material, dtype=np.int32),
            normals=np.ascontiguousarray(normals, dtype=np.float32),
            has_normals=np.ascontiguousarray(geom.has_normals, dtype=bool),
            terminator=term_cut, positions=term_pos, triangles=term_tri, shading_mult=shading_multipliers(geom),
            visibility=(np.ascontiguousarray(geom.visibility, dtype=np.uint8) if geom.visibility is not None
                        else np.zeros(0, np.uint8)),
            pass_ids=(np.ascontiguousarray(geom.pass_ids, dtype=np.float32)
                      if getattr(geom, "pass_ids", None) is not None else np.zeros((0, 2), np.float32)),
            uvs=uv_pass_corners(geom) if "uv" in self.data_passes else np.zeros((0, 3, 3), np.float32),
            crypto_ids=(np.ascontiguousarray(geom.crypto_ids, dtype=np.float32) if self.cryptomatte
                        else np.zeros((0, 3), np.float32)))
        # objects some rays do not see (Cycles's ray visibility): path rays pass them before
        # shade (_skip_unseen), shadow rays in _shadows_through's rounds of closest hits
        vis, path_bits = self.surfaces.visibility, VIS_ALL & ~VIS_SHADOW
        self.unseen_by_paths = bool(np.any((vis & path_bits) != path_bits))
        self.unseen_by_shadows = bool(np.any((vis & VIS_SHADOW) == 0))
        # holdout objects: shade's variant with their test (None: a variant without it)
        self.holdouts_arg = vis if np.any(vis & VIS_HOLDOUT) else None
        # participating media (drt.volumes): a disabled MediumData costs the kernels one flag test
        if media is None:
            media = build_medium_data([], None)
        if media.hetero:  # density programs: coordinate maps and majorants (drt.volumes.hetero)
            from .volumes.hetero import prepare

            media = prepare(media, self.programs, geom, self.n_registers, len(point_rows()))
        if media.enabled and media.camera_stack[0] < 0:
            media = media._replace(camera_stack=camera_stack(media, tracer))
        self.media = media
        # what the kernels get: None without media, so they run (and compile) a variant with
        # no media code at all (path_stages.shade)
        self.media_arg = media if media.enabled else None
        # likewise None for the programs when there is none: no interpreter in that variant (a
        # heterogeneous medium's density is a program, so only homogeneous media go without)
        no_programs = len(self.programs.op_start) <= 1
        self.programs_arg = None if no_programs and not media.hetero else self.programs
        #: which variant of the kernels this scene runs (drt.kernels.scene_kernel_variant)
        self.kernel_variant = kernel_variant(media.enabled, self.programs_arg is not None,
                                             self.programs.procedural is not None)
        self.loop_limit = self.max_depth + 1 + (stages.VOLUME_BOUNDS_MAX if media.enabled else 0)
        if self.sss is not None:  # an SSS exit takes a loop pass of its own, no bounce
            self.loop_limit += self.max_depth + 1
        # transparent surfaces (alpha, Transparent BSDF): passes of their own, and shadow rays
        # that pass them (the closest-hit loop of _shadows_through) instead of Embree's occlusion
        self.transparent = transparent_materials(materials.data)
        if not self.transparent.any():
            self.transparent = np.zeros(0, dtype=bool)
        else:
            self.loop_limit += int(settings.transparent_bounces)

    def _hit_arrays(self, hits) -> stages.HitArrays:
        if hits.normal_xform is not None:
            # normals transform by the inverse transpose of the local→world map (the tracer's
            # surface kernel computes it for the hit points' normals anyway)
            xform, moving = hits.normal_xform, hits.moving
        else:
            xform, moving = _NO_XFORM, _NO_MOVING
        return stages.HitArrays(prim=hits.prim, t=hits.t, b1=hits.b1, b2=hits.b2, p=hits.p,
                                ng=hits.ng, normal_xform=xform, moving=moving)

    def _ws(self) -> SimpleNamespace:
        """The workspace of the batch this thread runs (outside a batch, e.g. a test's call:
        one of this thread's own)."""
        ws = getattr(self._held, "ws", None)
        if ws is None:
            ws = self._held.ws = SimpleNamespace()
        return ws

    def _enter_workspace(self) -> None:
        """A batch starts on this thread: it takes an idle workspace (arrays a batch of an
        earlier render or on another thread filled: no fresh pages) or a new one. Nested entries
        (``render_pixels`` → ``render_batch``) keep the outer one."""
        held = self._held
        if getattr(held, "depth", 0):
            held.depth += 1
            return
        try:
            held.ws = self._idle_workspaces.pop()  # (deque: atomic append and pop)
        except IndexError:
            held.ws = SimpleNamespace()
        held.depth = 1

    def _leave_workspace(self) -> None:
        held = self._held
        held.depth -= 1
        if held.depth == 0:
            self._idle_workspaces.append(held.ws)
            held.ws = None

    def _material_workspace(self):
        """The batch's (material data, register file, shading-point rows): the shared read-only table when no
        material has a program, else a private copy that ``shade`` rewrites per textured hit."""
        ws = getattr(self._ws(), "materials", None)
        if ws is None:
            md = self.materials.data
            if self.material_programs:
                md = type(md)(*(np.array(a, copy=True) for a in md))
            ws = self._ws().materials = (md, np.zeros((max(self.n_registers, 1), 3)), point_rows())
        return ws

    def _outputs(self, n: int) -> tuple[tuple, stages.Outputs, np.ndarray]:
        """(buffers, views of their first n rows, the first n of their (n,) int64 pixel ids) for
        a batch's per-path outputs and the pixels they go to: buffers a
        consumer gave back (``SampleBatch.release``) when one is large enough, else new arrays.
        Like the path state (``_workspace``), and for the same reason: fresh arrays cost a page
        fault and a zeroed page per 4 KB every batch — measured, a camera stage writing into
        fresh outputs took ~120 ns a sample against ~62 into reused ones. The buffers travel with
        their batch (the film adds it on another thread, later), so they come back through the
        consumer instead of staying with this thread."""
        while True:
            try:
                buffers = self._returned_outputs.pop()  # (deque: atomic append and pop)
            except IndexError:
                buffers = (stages.Outputs(radiance=np.empty((n, 3)), alpha=np.empty(n), depth=np.empty(n),
                                          normal=np.empty((n, 3)), albedo=np.empty((n, 3)),
                                          eye=np.empty((n, 3)), forward=np.empty((n, 3)),
                                          mist=np.empty(n if self.mist_pass else 0),
                                          data=np.empty((n if self.data_passes else 0, stages.DATA_COLUMNS)),
                                          light=np.empty((n if self.light_passes else 0, stages.LIGHT_COLUMNS)),
                                          crypto=np.empty((n if self.cryptomatte else 0, CRYPTO_SURFACES,
                                                           CRYPTO_COLUMNS))),
                           np.empty(n, dtype=np.int64))
                break
            if buffers[1].shape[0] >= n:
                break  # (a smaller one is dropped; a new set of this batch's size replaces it)
        return buffers, stages.Outputs(*(a[:n] for a in buffers[0])), buffers[1][:n]

    def _workspace(self, n: int) -> tuple[stages.Paths, stages.ShadowRays]:
        """The batch's path and shadow-ray arrays, at least n rows (views of the first n).
        Reused from batch to batch (and render to render, ``_enter_workspace``): fresh arrays
        would cost a page fault per 4 KB every batch."""
        ws = getattr(self._ws(), "arrays", None)
        # a path in a medium may queue two shadow rays per bounce (volume + surface NEE)
        n_shadow = 2 * n if self.media.enabled else n
        if ws is None or len(ws[0].slot) < n or len(ws[1].slot) < n_shadow:
            ws = self._ws().arrays = (_paths(n, self.sss is not None, self.filters_glossy),
                                      _shadow_rays(n_shadow))
        paths, shadow = ws
        return (stages.Paths(*(a[:n] for a in paths)), stages.ShadowRays(*(a[:n_shadow] for a in shadow)))

    def _scratch(self) -> Scratch:
        """The batch's arrays for the tracer's queries (``drt.scratch``): the render loop's
        hits and shadow tests are views into them, dead by the batch's next query."""
        sc = getattr(self._ws(), "scratch", None)
        if sc is None:
            sc = self._ws().scratch = Scratch()
        return sc

    def _camera_samples(self, n: int) -> np.ndarray:
        """The batch's (n, 5) scratch rows for the camera stage's samples (pixel filter, lens,
        shutter time), reused from batch to batch as ``_workspace``."""
        u = getattr(self._ws(), "camera_u", None)
        if u is None or len(u) < n:
            u = self._ws().camera_u = np.empty((n, 5))
        return u[:n]

    def _ao_workspace(self, n: int) -> stages.ShadowRays:
        """The batch's queue of Ambient Occlusion pass rays: n rows (one per path and bounce;
        ``path_stages.queue_ao_ray``), or zero rows for a render without the pass."""
        if self.stage_settings.ao_distance <= 0.0:
            n = 0
        q = getattr(self._ws(), "ao_rays", None)
        if q is None or len(q.slot) < n:
            q = self._ws().ao_rays = _shadow_rays(n)
        return stages.ShadowRays(*(a[:n] for a in q))

    def _trace_ao(self, ao_rays, n_ao, out, md, regs, point) -> None:
        """Trace the queued AO rays as shadow rays (through transparent surfaces and media, as
        Cycles's PATH_RAY_SHADOW_FOR_AO) and add the unoccluded ones' weight to the AO columns
        of ``out.light``: seen as (n·LIGHT_WIDTH/3, 3) rows, a path's AO is row slot·4 + 3."""
        groups = stages.LIGHT_COLUMNS // 3
        slot = ao_rays.slot[:n_ao]
        slot *= groups
        slot += LIGHT_AO // 3
        target = out.light.reshape(-1, 3)
        if self.media.enabled or self.transparent.shape[0] or self.unseen_by_shadows:
            self._shadows_through(ao_rays, n_ao, target, md, regs, point)
        else:
            blocked = self.tracer.occluded(ao_rays.o[:n_ao], ao_rays.d[:n_ao], ao_rays.tmax[:n_ao], ao_rays.tau[:n_ao],
                                           scratch=self._scratch())
            stages.add_unoccluded(ao_rays, n_ao, blocked, target)

    def _skip_unseen(self, paths, live, hits) -> None:
        """Rows whose hit is on an object their kind of ray does not see (Cycles's ray
        visibility) are traced on from just past it, as if it were not there (``hits``
        patched in place, ``t`` still measured from the ray's origin), up to VOLUME_BOUNDS_MAX
        objects deep: then the row misses. Before ``shade``, so that it has no code for this."""
        rows = np.empty(live, np.int64)
        o_next, tmax_next, t_done = np.empty((live, 3)), np.empty(live), np.empty(live)
        sss_on = self.sss is not None
        for round_ in range(stages.VOLUME_BOUNDS_MAX + 1):
            n = stages.unseen_hits(self.surfaces.visibility, paths, live, sss_on, hits.prim, hits.p, hits.ng,
                                   rows, o_next, tmax_next, t_done)
            if n == 0:
                return
            r = rows[:n].copy()
            if round_ == stages.VOLUME_BOUNDS_MAX:
                hits.prim[r] = -1  # still crossing: give up, as a volume boundary
                hits.t[r] = np.inf
                return
            new = self._hit_arrays(self.tracer.intersect(o_next[:n], paths.d[r], paths.tau[r], tmax_next[:n]))
            hits.prim[r] = new.prim
            hits.t[r] = t_done[:n] + new.t
            hits.b1[r], hits.b2[r] = new.b1, new.b2
            hits.p[r], hits.ng[r] = new.p, new.ng
            if hits.moving.shape[0]:
                hits.moving[r] = new.moving
                hits.normal_xform[r] = new.normal_xform

    def _shadows_through(self, shadow, count, radiance, md, regs, point):
        """Shadow rays in a scene with media or transparent surfaces: closest hits, repeatedly,
        so that rays attenuate by exp(−∫σt) and by the transparent colour of the surfaces they
        pass (Cycles's transparent shadows; a textured one runs its program at the hit), and
        pass volume-only boundaries (updating their stacks), until they reach their light, an
        opaque surface, or the crossing limit (VOLUME_BOUNDS_MAX with media, else the transparent
        bounce limit + 1: then blocked, as Cycles)."""
        trans = np.ones((count, 3))
        blocked = np.zeros(count, dtype=bool)
        active = np.arange(count, dtype=np.int64)
        n_active = count
        o, d, tmax = shadow.o[:count], shadow.d[:count], shadow.tmax[:count]
        rounds = stages.VOLUME_BOUNDS_MAX if self.media.enabled else int(self.s.transparent_bounces) + 1
        scratch = self._scratch()  # (each round's hits are spent before the next round's query)
        if self.unseen_by_shadows:
            rounds += stages.VOLUME_BOUNDS_MAX
        for _ in range(rounds):
            if n_active == 0:
                break
            rows = active[:n_active]
            hits = self.tracer.intersect(o[rows], d[rows], shadow.tau[:count][rows], tmax[rows], scratch=scratch)
            n_active = shadow_step(self.media_arg, self.surfaces.material, self.surfaces.visibility, active,
                                   n_active, hits.prim, hits.t,
                                   hits.ng, o, d, tmax, shadow.vstack, trans, blocked,
                                   self.transparent, md, self.programs_arg, regs, point, hits.b1, hits.b2)
        blocked[active[:n_active]] = True  # still crossing boundaries: give up (as Cycles)
        add_transmitted(shadow, count, blocked, trans, radiance)

    def render_pixels(self, x: np.ndarray, row: np.ndarray, first: int, k: int) -> SampleBatch:
        """`render_batch` of samples first … first + k − 1 of each pixel (x, row) (m,), the k
        samples of a pixel in consecutive entries. The (m·k,) columns are written into the
        batch's scratch, not allocated by the caller: the render loop hands a batch over as a
        slice of its pixel list."""
        m = len(x)
        self._enter_workspace()
        try:
            scratch = self._scratch()
            xs, rows = scratch.take("batch_x", m * k, (), np.int64), scratch.take("batch_row", m * k, (), np.int64)
            index = scratch.take("batch_index", m * k, (), np.int64)
            xs.reshape(m, k)[:] = np.asarray(x, dtype=np.int64)[:, None]
            rows.reshape(m, k)[:] = np.asarray(row, dtype=np.int64)[:, None]
            index.reshape(m, k)[:] = np.arange(first, first + k, dtype=np.int64)
            return self.render_batch(xs, rows, index)
        finally:
            self._leave_workspace()

    def render_batch(self, x: np.ndarray, row: np.ndarray, index: np.ndarray) -> SampleBatch:
        """Trace one camera path per entry. x: (n,) pixel column from the left; row: (n,) pixel
        row from the TOP; index: (n,) sample number within the pixel. Returns per-path results."""
        self._enter_workspace()
        try:
            return self._trace_batch(x, row, index)
        finally:
            self._leave_workspace()

    def _trace_batch(self, x, row, index) -> SampleBatch:
        n = len(x)
        paths, shadow = self._workspace(n)
        ao_rays = self._ao_workspace(n)
        buffers, out, pixel = self._outputs(n)
        sd, ld = self.sampler.data, self.lights.data
        md, regs, point = self._material_workspace()
        scratch = self._scratch()
        live = stages.camera_stage(sd, self.filter.data, self.camera.data, self.stage_settings,
                                   np.ascontiguousarray(x, dtype=np.int64), np.ascontiguousarray(row, dtype=np.int64),
                                   np.ascontiguousarray(index, dtype=np.int64), self._camera_samples(n), paths, out)
        vd = self.media
        if vd.enabled:
            paths.vstack[:] = vd.camera_stack
            paths.vcount[:] = 0
            paths.vseg[:] = 0
        if self.sss is not None:
            paths.sss[:] = 0
            paths.sss_count[:] = 0
        for depth_i in range(self.loop_limit):
            if live == 0:
                break
            # (this bounce's hits are spent by `shade`; the shadow and AO queries after it reuse
            # the scratch)
            hits = self.tracer.intersect(paths.o[:live], paths.d[:live], paths.tau[:live], paths.tmax[:live],
                                         scratch=scratch)
            hit_arrays = self._hit_arrays(hits)
            if self.unseen_by_paths:
                self._skip_unseen(paths, live, hit_arrays)
            if self.sss is not None:
                self.sss.patch_hits(paths, live, hit_arrays)
            live, n_shadow, n_ao = stages.shade(sd, md, self.programs_arg, regs, point, ld, self.surfaces,
                                                self.stage_settings, depth_i, live, paths, hit_arrays, out, shadow,
                                                ao_rays, self.media_arg, self.holdouts_arg)
            if n_ao:
                self._trace_ao(ao_rays, n_ao, out, md, regs, point)
            if n_shadow and (vd.enabled or self.transparent.shape[0] or self.unseen_by_shadows):
                self._shadows_through(shadow, n_shadow, out.radiance, md, regs, point)
            elif n_shadow:
                blocked = self.tracer.occluded(shadow.o[:n_shadow], shadow.d[:n_shadow],
                                               shadow.tmax[:n_shadow], shadow.tau[:n_shadow], scratch=scratch)
                stages.add_unoccluded(shadow, n_shadow, blocked, out.radiance)
            if self.sss is not None and live:
                self.sss.run(paths, live, depth_i, sd)

        # a NaN/Inf sample is counted, dropped (it does not enter its pixel's mean) and reported;
        # so is one beyond MAX_SAMPLE_RADIANCE, which would overflow the float32 passes
        radiance = out.radiance
        good = scratch.take("good", n, dtype=bool)
        n_good = stages.good_samples(radiance, good)
        np.multiply(row, self.s.width, out=pixel)
        pixel += x
        alpha, depth, normal, albedo = out.alpha, out.depth, out.normal, out.albedo
        mist = out.mist if self.mist_pass else None
        light = out.light if self.light_passes else None
        crypto = out.crypto if self.cryptomatte else None
        data, data_pixel = self._data_pass_rows(out, pixel, good)
        nan_count = n - n_good
        if nan_count:
            pixel, radiance, alpha, depth = pixel[good], radiance[good], alpha[good], depth[good]
            normal, albedo = normal[good], albedo[good]
            mist = mist[good] if mist is not None else None
            light = light[good] if light is not None else None
            crypto = crypto[good] if crypto is not None else None
        return SampleBatch(pixel, radiance, alpha, depth, normal, albedo, nan_count, mist=mist,
                           data=data, data_pixel=data_pixel, light=light, crypto=crypto,
                           release=functools.partial(self._returned_outputs.append, buffers))

    def _data_pass_rows(self, out, pixel, good):
        """The batch's data-pass columns for the film (``SampleBatch.data``) and their pixels, or
        (None, None) without data passes. Every sample keeps its sample-0 columns (a sample whose
        radiance was dropped as non-finite still hit what it hit); only the UV, which the film
        averages over the counted samples, is dropped with it. The Position goes back to
        Blender's world space where sample 0 hit a surface."""
        if not self.data_passes:
            return None, None
        data = out.data[:, :stages.DATA_DONE].copy()
        shift = getattr(self.geom, "origin_shift", None)
        if shift is not None:
            hit = data[:, stages.DATA_HIT] > 0.0
            data[hit, stages.DATA_POSITION:stages.DATA_POSITION + 3] += np.asarray(shift, np.float64)
        data[~good, stages.DATA_UV:stages.DATA_UV + 3] = 0.0
        return data, pixel
