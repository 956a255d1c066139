"""The DRT RenderEngine: export the depsgraph, render with the core, stream the film back.

Failure semantics (../shared/docs/blender-addon-notes.md): an exception escaping ``render()``
makes ``blender -b`` save an empty image and exit 0, so ``render()`` catches everything and
reports it with ``self.report({'ERROR'}, ...)``, which aborts the render with exit code 1 (and
makes ``bpy.ops.render.render`` raise RuntimeError).
"""

import time
import traceback

import bpy
import numpy as np

from . import cluster, compat, denoising, viewport
from .export import ExportError, export_depsgraph

# Film arrays are top row first; Blender's render result wants bottom row first.
PASSES = (  # (Blender pass name before 4.2: compat.pass_name, channels, chan_id, type, film attribute,
    #         view-layer flag)
    ("Depth", 1, "Z", "VALUE", "depth", "depth"),
    ("Normal", 3, "XYZ", "VECTOR", "normal", "normal"),
    ("DiffCol", 3, "RGB", "COLOR", "diffuse_color", "albedo"),
    ("Mist", 1, "Z", "VALUE", "mist", "mist"),
    ("Position", 3, "XYZ", "VECTOR", "position", "position"),
    ("UV", 3, "UVA", "VECTOR", "uv", "uv"),
    ("IndexOB", 1, "X", "VALUE", "object_index", "object_index"),
    ("IndexMA", 1, "X", "VALUE", "material_index", "material_index"),
    ("Emit", 3, "RGB", "COLOR", "emission", "emission"),
    ("Env", 3, "RGB", "COLOR", "environment", "environment"),
    ("AO", 3, "RGB", "COLOR", "ao", "ao"),
)


def _format_seconds(s: float) -> str:
    s = max(0.0, s)
    m, sec = divmod(int(round(s)), 60)
    h, m = divmod(m, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m:02d}:{sec:02d}"


def sample_range(scene) -> tuple[int, int, int | None]:
    """(spp, sample_offset, sample_count or None) from the scene's DRT settings."""
    d = scene.drt
    spp = int(d.samples)
    if not d.use_sample_subset:
        return spp, 0, None
    offset = min(int(d.sample_offset), spp - 1)
    count = int(d.sample_count) or spp - offset
    return spp, offset, min(count, spp - offset)


class DRTRenderEngine(bpy.types.RenderEngine):
    bl_idname = "DRT"
    bl_label = "DRT"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)

    def __del__(self):
        viewport.engine_free(self)

    # --- Rendered viewport (addon/viewport.py) --------------------------------------------

    def view_update(self, context, depsgraph):
        viewport.engine_view_update(self, context, depsgraph)

    def view_draw(self, context, depsgraph):
        viewport.engine_view_draw(self, context, depsgraph)

    # --- passes -----------------------------------------------------------------------------

    def update_render_passes(self, scene=None, renderlayer=None):
        if scene is None or renderlayer is None:
            return
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        flags = compat.view_layer_pass_flags(renderlayer)
        for name, channels, chan_id, kind, _attr, flag in PASSES:
            if flags[flag]:
                self.register_pass(scene, renderlayer, compat.pass_name(name), channels, chan_id, kind)
        for name, channels, chan_id, kind in denoising.extra_passes(scene, renderlayer):
            self.register_pass(scene, renderlayer, name, channels, chan_id, kind)
        for name, _layer, _index in cryptomatte_passes(renderlayer):
            self.register_pass(scene, renderlayer, name, 4, "rgba", "COLOR")  # (Cycles's: the spec's)

    # --- final render -----------------------------------------------------------------------

    def cancel_requested(self) -> bool:
        """Esc in Blender. A Python method (test_break itself is an RNA function, which a
        subclass attribute cannot override), so tests can simulate a user's cancel."""
        return bool(self.test_break())

    def warn(self, msg: str) -> None:
        """A warning in Blender's report (``report`` is an RNA function: tests replace this)."""
        self.report({"WARNING"}, f"DRT: {msg}")

    def render(self, depsgraph):
        try:
            self._render(depsgraph)
        except Exception as exc:  # noqa: BLE001 -- must not escape: see the module docstring
            traceback.print_exc()
            msg = str(exc) or exc.__class__.__name__
            if not isinstance(exc, ExportError) and \
                    exc.__class__.__name__ not in ("SceneError", "DenoiserUnavailable", "FarmError"):
                msg = f"{exc.__class__.__name__}: {msg}"
            self.report({"ERROR"}, f"DRT: {msg}")

    def _render(self, depsgraph):
        scene = depsgraph.scene
        t_start = time.perf_counter()
        dn_passes = denoising.extra_passes(scene, depsgraph.view_layer)
        dn_lib, denoise_mod = None, None
        if denoising.enabled(scene, depsgraph.view_layer):
            if scene.drt.use_sample_subset:  # a range is an intermediate: merge, then denoise once
                self.report({"WARNING"}, "DRT: denoising skipped for a sample subset; denoise the "
                                         "merged image (drt merge --denoise)")
            else:  # fail before any work when no denoiser is available
                denoise_mod = compat.core_module("denoise")
                dn_lib = denoising.backend_library(denoise_mod)
        self.update_stats("", "DRT | Exporting scene")
        exported = export_depsgraph(depsgraph, frame_set=self.frame_set)
        for w in exported.warnings:
            self.report({"WARNING"}, f"DRT: {w}")
        if missing := compat.unrendered_passes(depsgraph.view_layer):
            self.warn("passes not rendered (left out of the result): " + ", ".join(missing))
        if self.cancel_requested():
            return

        scene_mod = compat.core_module("scene")
        render_mod = compat.core_module("render")
        drt_scene = scene_mod.scene_from_dict(exported.header, exported.arrays)
        spp, offset, count = sample_range(scene)
        width, height = drt_scene.render.width, drt_scene.render.height
        layer_name = depsgraph.view_layer.name
        flags = compat.view_layer_pass_flags(depsgraph.view_layer)
        wanted = [p for p in PASSES if flags[p[5]]]
        if cluster.cluster_address(scene):  # render on a Dask cluster (docs/farm.md)
            client = cluster.connect(self, scene)  # before begin_result: a failure leaves no image
            crop = border_crop(scene, width, height)
            rh, rw = crop[0].stop - crop[0].start, crop[1].stop - crop[1].start
            result = self.begin_result(0, 0, rw, rh, layer=layer_name)
            try:
                film = cluster.render_on_cluster(self, client, scene, exported, drt_scene, spp, offset, count,
                                                 result, crop, wanted, t_start)
                if film is not None:
                    self._finish_film(film, result, scene, crop, wanted, dn_passes, denoise_mod, dn_lib,
                                      drt_scene)
            finally:
                self.end_result(result)
                cluster.close(client, scene)
            return

        kernels = compat.core_module("kernels")
        variant = kernels.scene_kernel_variant(drt_scene)
        if not kernels.kernels_compiled(variant):  # the first render of an install compiles
            self.report({"INFO"}, f"DRT: {kernels.COMPILING_NOTICE}")
        self.update_stats("", "DRT | Building acceleration structures")
        context = render_mod.prepare(drt_scene, threads=render_threads(scene))
        for w in getattr(context, "warnings", []):
            self.report({"WARNING"}, f"DRT: {w}")
        if not kernels.kernels_compiled(variant):
            self.update_stats("", "DRT | Compiling render kernels (first render of this kind of scene: up to a minute)")
        t_render = time.perf_counter()
        last_draw = [0.0]
        crop = border_crop(scene, width, height)
        rh, rw = crop[0].stop - crop[0].start, crop[1].stop - crop[1].start
        result = self.begin_result(0, 0, rw, rh, layer=layer_name)

        def progress(film, done, total):
            frac = done / max(total, 1)
            elapsed = time.perf_counter() - t_render
            remaining = elapsed / frac - elapsed if frac > 0 else 0.0
            self.update_progress(frac)
            self.update_stats("", f"DRT | Sample {done}/{total} | Elapsed "
                                  f"{_format_seconds(time.perf_counter() - t_start)} | Remaining "
                                  f"{_format_seconds(remaining)}")
            now = time.perf_counter()
            if now - last_draw[0] > 0.25 and done < total:
                last_draw[0] = now
                fill_layer(result.layers[0], film, crop, wanted, cryptomatte=False)
                self.update_result(result)

        try:
            film = render_mod.render(drt_scene, spp=spp, sample_offset=offset,
                                     sample_count=count, progress=progress,
                                     cancel=self.cancel_requested, context=context,
                                     threads=render_threads(scene))
            self._finish_film(film, result, scene, crop, wanted, dn_passes, denoise_mod, dn_lib, drt_scene)
        finally:
            self.end_result(result)
        stats = getattr(film, "stats", None)
        done = getattr(stats, "samples_done", count or spp)
        self.update_stats("", f"DRT | {done} samples in "
                              f"{_format_seconds(time.perf_counter() - t_start)}")


    def _finish_film(self, film, result, scene, crop, wanted, dn_passes, denoise_mod, dn_lib, drt_scene):
        """The finished film into the result's passes, denoised when asked (not when cancelled)."""
        fill_layer(result.layers[0], film, crop, wanted)
        stamp_cryptomatte(self.get_result(), result.layers[0].name, film)
        cancelled = getattr(getattr(film, "stats", None), "cancelled", False)
        denoised = None
        if denoise_mod is not None and not cancelled:
            self.update_stats("", "DRT | Denoising")
            denoised, info = denoising.denoise(film, scene, denoise_mod, dn_lib, render_threads(scene))
            if info.replaced_pixels:
                self.report({"WARNING"}, f"DRT: {info.replaced_pixels} non-finite pixels filled before denoising")
        denoising.fill_passes(result.layers[0], _set_pass, film, crop, dn_passes, denoised,
                              drt_scene.camera.matrix)


def render_threads(scene) -> int | None:
    """Blender's Performance > Threads setting: a fixed count, or None (auto: every core)."""
    r = scene.render
    if getattr(r, "threads_mode", "AUTO") == "FIXED":
        return max(1, int(r.threads))
    return None


def border_crop(scene, width, height) -> tuple[slice, slice]:
    """Rows (top first) and columns of the film the render result shows.

    Same pixel rounding as the core's border region; the full frame without a border.
    """
    r = scene.render
    if not r.use_border or (r.border_min_x, r.border_min_y, r.border_max_x, r.border_max_y) \
            == (0.0, 0.0, 1.0, 1.0):
        return slice(0, height), slice(0, width)
    x0 = int(np.floor(r.border_min_x * width))
    x1 = max(int(np.ceil(r.border_max_x * width)), x0 + 1)
    r0 = int(np.floor((1 - r.border_max_y) * height))
    r1 = max(int(np.ceil((1 - r.border_min_y) * height)), r0 + 1)
    return slice(r0, r1), slice(x0, x1)


def _set_pass(layer, name, img):
    """Write an (h, w, c) top-row-first image into a render pass (bottom row first)."""
    rp = layer.passes.find_by_name(name, "")
    if rp is None:
        return
    compat.set_pass_pixels(rp, np.ascontiguousarray(img[::-1], dtype=np.float32))


def fill_layer(layer, film, crop, wanted, cryptomatte=True) -> None:
    """Copy the film's passes into a render layer (``cryptomatte`` False: not its layers, whose
    sort per pixel a progressive redraw of a large frame need not pay)."""
    rows, cols = crop
    # (in place: `combined` is a new array on every access; 8 against 17 ms at 1080p)
    _set_pass(layer, "Combined", np.nan_to_num(film.combined[rows, cols], nan=0.0, copy=False))
    for name, channels, _cid, _kind, attr, _flag in wanted:
        img = getattr(film, attr)
        if img is None:  # (a film without the pass: film.mist of a render that did not ask for it)
            continue
        img = np.asarray(img)[rows, cols]  # film.depth: background already 1e10
        _set_pass(layer, compat.pass_name(name), img.reshape(img.shape[0], img.shape[1], channels))
    for crypto_layer in getattr(film, "crypto_layers", ()) if cryptomatte else ():  # two (id, coverage) a pass
        slots = film.cryptomatte(crypto_layer)[rows, cols]
        h, w = slots.shape[:2]
        for j in range(slots.shape[2] // 2):
            pair = slots[:, :, 2 * j:2 * j + 2].reshape(h, w, 4)
            _set_pass(layer, f"{CRYPTO_PASS_PREFIX[crypto_layer]}{j:02d}", pair)


#: Cycles's pass name prefix of each Cryptomatte layer: drt.cryptomatte.PASS_PREFIX, copied
#: because registering passes (any UI change) must not import the core's kernels (numba);
#: tests/test_cryptomatte.py keeps the two equal
CRYPTO_PASS_PREFIX = {"object": "CryptoObject", "material": "CryptoMaterial", "asset": "CryptoAsset"}


def cryptomatte_passes(view_layer) -> list[tuple[str, str, int]]:
    """(pass name, layer, index) of the Cryptomatte passes the view layer enables, as Cycles
    registers them: Levels (rounded up to even) / 2 RGBA passes per layer, CryptoObject00, …"""
    n = (int(getattr(view_layer, "pass_cryptomatte_depth", 6)) + 1) // 2
    return [(f"{CRYPTO_PASS_PREFIX[layer]}{j:02d}", layer, j) for layer in CRYPTO_PASS_PREFIX
            if getattr(view_layer, f"use_pass_cryptomatte_{layer}", False) for j in range(n)]


def stamp_cryptomatte(full_result, view_layer: str, film) -> None:
    """The Cryptomatte manifest into the render's metadata (Blender's compositor and the
    multilayer EXR read it), under the layer names ``<view layer>.CryptoObject`` …, as Cycles:
    on the engine's whole result (``RenderEngine.get_result``; a result from ``begin_result``
    does not pass its stamps on)."""
    layers = getattr(film, "crypto_layers", ())
    if not layers or full_result is None or not hasattr(full_result, "stamp_data_add_field"):
        return
    crypto = compat.core_module("cryptomatte")
    for layer in layers:
        entries = crypto.metadata(f"{view_layer}.{CRYPTO_PASS_PREFIX[layer]}", film.crypto_names.get(layer, ()))
        for key, value in entries.items():
            full_result.stamp_data_add_field(key, value)
