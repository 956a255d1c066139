"""Denoising in Blender: which settings apply, the Denoising Data passes, and which OIDN runs.

Settings (as Cycles): the scene's ``drt.use_denoising`` / ``denoising_prefilter`` /
``denoising_quality`` / ``denoising_input_passes``, and the view layer's own Cycles settings
where the Cycles add-on provides them (``view_layer.cycles.use_denoising``: denoise this layer;
``view_layer.cycles.denoising_store_passes``: the "Denoising Data" passes). Without the Cycles
add-on every layer is denoised and no Denoising Data passes are stored.

Passes, with Cycles's names so compositor setups carry over: "Noisy Image" (RGBA, the image
before denoising) when the layer is denoised; "Denoising Normal" (camera space, as Cycles's),
"Denoising Albedo" and "Denoising Depth" with Denoising Data.

The denoiser is Blender's own Open Image Denoise library (the one its compositor Denoise node
and Cycles use), loaded through ``ctypes`` by ``drt.denoise``; pyoidn is the fallback when the
library cannot be found (docs/decisions.md, "Denoising inside Blender").
"""

import glob
import os
import sys

import bpy
import numpy as np

NOISY_PASS = ("Noisy Image", 4, "RGBA", "COLOR")
DATA_PASSES = (  # (name, channels, chan_id, type)
    ("Denoising Normal", 3, "XYZ", "VECTOR"),
    ("Denoising Albedo", 3, "RGB", "COLOR"),
    ("Denoising Depth", 1, "Z", "VALUE"),
)


def layer_settings(view_layer) -> tuple[bool, bool]:
    """(denoise this layer, store the Denoising Data passes) from the view layer's Cycles
    settings; (True, False) when the Cycles add-on is not enabled."""
    cl = getattr(view_layer, "cycles", None)
    return bool(getattr(cl, "use_denoising", True)), bool(getattr(cl, "denoising_store_passes", False))


def enabled(scene, view_layer) -> bool:
    """Will F12 / ``blender -b`` denoise this layer?"""
    return bool(scene.drt.use_denoising) and layer_settings(view_layer)[0]


def extra_passes(scene, view_layer) -> list:
    """The denoising passes to register for a view layer: [(name, channels, chan_id, type)]."""
    out = [NOISY_PASS] if enabled(scene, view_layer) else []
    if layer_settings(view_layer)[1]:
        out += list(DATA_PASSES)
    return out


def _loaded_libraries() -> list:
    """Paths of loaded shared objects named like OIDN's main library (Linux: /proc/self/maps)."""
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "OpenImageDenoise" in line}
    except OSError:
        return []
    return sorted(p for p in paths if os.path.basename(p).startswith("libOpenImageDenoise.so"))


def blender_oidn_library() -> str | None:
    """Path of the OIDN library Blender ships (None if not found): the one already loaded in the
    process, else a search next to Blender's binary / the bpy module."""
    found = _loaded_libraries()
    if found:
        return found[0]
    roots = [os.path.dirname(bpy.app.binary_path or "")]
    roots.append(os.path.dirname(getattr(bpy, "__file__", "") or ""))
    if sys.platform == "darwin":  # Blender.app/Contents/MacOS/Blender → Contents/Resources/lib
        roots.append(os.path.join(roots[0], "..", "Resources"))
    names = {"win32": "OpenImageDenoise.dll", "darwin": "libOpenImageDenoise*.dylib"}.get(
        sys.platform, "libOpenImageDenoise.so*")
    for root in filter(None, roots):
        for sub in ("", "lib", "blender.shared"):
            hits = sorted(glob.glob(os.path.join(root, sub, names)))
            hits = [h for h in hits if "_core" not in h and "_device" not in h]
            if hits:
                return hits[0]
    return None


def backend_library(denoise_mod) -> str | None:
    """The library argument for ``drt.denoise``: Blender's OIDN if it loads, else None (pyoidn).
    Raises ``DenoiserUnavailable`` (its message says what to do) when neither is available."""
    lib = blender_oidn_library()
    if lib:
        try:
            denoise_mod.require_backend(lib)
            return lib
        except denoise_mod.DenoiserUnavailable:
            pass
    try:
        denoise_mod.require_backend(None)
    except denoise_mod.DenoiserUnavailable:
        raise denoise_mod.DenoiserUnavailable(
            "denoising needs Open Image Denoise, which this Blender does not ship: "
            "install pyoidn into Blender's Python, or turn DRT denoising off") from None
    return None


def camera_space(normal: np.ndarray, camera_matrix) -> np.ndarray:
    """World-space normals (H, W, 3) → camera space (+Y up, looking along −Z), as Cycles's
    Denoising Normal pass. Zero vectors (no hit) stay zero."""
    m = np.asarray(camera_matrix, dtype=np.float64)[:3, :3]
    rot = m / np.maximum(np.linalg.norm(m, axis=0, keepdims=True), 1e-30)  # drop the camera's scale
    return np.einsum("hwi,ij->hwj", normal.astype(np.float64), rot).astype(np.float32)


def denoise_with(film, input_passes, prefilter, quality, denoise_mod, library, threads=None,
                 return_info=False):
    """Denoise a film's combined pass with Cycles-style settings: ``input_passes`` (RGB,
    RGB_ALBEDO, RGB_ALBEDO_NORMAL) picks the film's guides. Returns the denoised RGB (H, W, 3),
    top row first (and the DenoiseInfo with ``return_info``)."""
    albedo = film.albedo if input_passes in ("RGB_ALBEDO", "RGB_ALBEDO_NORMAL") else None
    normal = film.normal if input_passes == "RGB_ALBEDO_NORMAL" else None
    return denoise_mod.denoise(film.combined, albedo, normal, prefilter=prefilter, quality=quality,
                               library=library, threads=threads, return_info=return_info)


def denoise(film, scene, denoise_mod, library, threads=None):
    """(denoised RGB (H, W, 3) top row first, DenoiseInfo) with the scene's final-render settings."""
    d = scene.drt
    return denoise_with(film, d.denoising_input_passes, d.denoising_prefilter, d.denoising_quality,
                        denoise_mod, library, threads=threads, return_info=True)


def fill_passes(layer, set_pass, film, crop, passes, denoised, camera_matrix) -> None:
    """Write the denoised Combined (RGB denoised, alpha the film's) and the denoising passes
    in ``passes`` into a render layer. ``set_pass(layer, name, (h, w, c) top-row-first image)``."""
    rows, cols = crop
    names = {p[0] for p in passes}
    if denoised is not None or NOISY_PASS[0] in names:  # (not read again by every plain F12)
        noisy = np.nan_to_num(film.combined[rows, cols], nan=0.0, copy=False)  # (a new array)
        if denoised is not None:
            set_pass(layer, "Combined", np.concatenate([denoised[rows, cols], noisy[..., 3:]], axis=-1))
        if NOISY_PASS[0] in names:
            set_pass(layer, NOISY_PASS[0], noisy)
    if "Denoising Normal" in names:
        set_pass(layer, "Denoising Normal", camera_space(film.normal[rows, cols], camera_matrix))
    if "Denoising Albedo" in names:
        set_pass(layer, "Denoising Albedo", film.albedo[rows, cols])
    if "Denoising Depth" in names:
        set_pass(layer, "Denoising Depth", film.depth[rows, cols][..., None])  # background 1e10
