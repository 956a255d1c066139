"""Denoising with Intel Open Image Denoise (OIDN): one array-in / array-out function.

``denoise(color, albedo, normal)`` runs OIDN's ``RT`` filter on a scene-linear HDR image with
the albedo and normal passes as guides, the way Cycles runs it after a final render:

* **prefilter** (Cycles's ``denoising_prefilter``, default ``ACCURATE``):
  ``ACCURATE`` first denoises the albedo and the normal image on their own (two extra RT
  filters with only that auxiliary input), then denoises the colour with OIDN's ``cleanAux``
  flag set, i.e. it tells OIDN the guides are now noise-free; ``FAST`` hands the noisy guides
  to OIDN with ``cleanAux`` off (OIDN then trusts them less, a blurrier result, no extra
  passes); ``NONE`` sets ``cleanAux`` on the raw guides (right only when they are already
  noise-free, e.g. at high sample counts or without depth of field / motion blur).
* **quality** (Cycles's ``denoising_quality``): ``HIGH`` | ``BALANCED`` | ``FAST``.

Inputs are (H, W, 3) arrays, any float dtype, rows in any order (the same for all three; DRT's
film and EXRs are top row first). ``color`` is scene-linear radiance (HDR, OIDN's ``hdr``
mode); ``albedo`` in [0, 1]; ``normal`` in [-1, 1]. OIDN accepts normals in world or camera
space and needs no unit length; DRT's film holds the **world-space** shading normal of the first
hit (mean over the pixel's samples, renormalised; 0 where nothing was hit) and passes it as is
(Cycles's "Denoising Normal" pass is camera space; OIDN's result does not depend on the choice
beyond noise).

**Sanitising.** OIDN must never see NaN, Inf or negative radiance (its HDR mode requires
finite values >= 0; a NaN spreads over the whole receptive field of its network, hundreds of
pixels). Before anything reaches OIDN (``sanitize``): a colour pixel with any non-finite
channel is replaced by the mean of the finite pixels among its 3 × 3 neighbours (0 if there are
none), as a missing sample; negative channels become 0; non-finite albedo and normal values
become 0 and are clamped to [0, 1] and [-1, 1]. The count of replaced colour pixels is
returned by ``sanitize`` and by ``denoise(..., return_info=True)``.

**Backends.** The OIDN library comes either from the ``pyoidn`` wheel (``pip install
'drt-renderer[denoise]'``; the CLI's backend) or from an OIDN shared library given by path and
driven through ``ctypes`` (inside Blender: Blender's own ``libOpenImageDenoise``, the one its
compositor and Cycles use, so the add-on bundles nothing; see docs/decisions.md). Both are
imported lazily: importing this module never loads OIDN. Without either, ``require_backend``
raises ``DenoiserUnavailable`` naming what to install, so callers can fail before rendering.

This module holds no renderer state: the CLI, ``drt merge``, the Blender add-on and (later)
the interactive viewport all call ``denoise`` on plain arrays.
"""

from __future__ import annotations

import ctypes
import os
import threading
import time
from dataclasses import dataclass

import numpy as np

PREFILTERS = ("ACCURATE", "FAST", "NONE")
QUALITIES = ("HIGH", "BALANCED", "FAST")
DEFAULT_PREFILTER = "ACCURATE"
DEFAULT_QUALITY = "HIGH"
# OIDN_QUALITY_* values of the C API (oidn.h)
_OIDN_QUALITY = {"HIGH": 6, "BALANCED": 5, "FAST": 4}
_OIDN_FORMAT_FLOAT3 = 3
_OIDN_DEVICE_TYPE_CPU = 1

INSTALL_HINT = "pip install 'drt-renderer[denoise]' (the pyoidn package)"


class DenoiserUnavailable(ImportError):
    """No OIDN library could be loaded; the message says what to install."""


@dataclass
class DenoiseInfo:
    """What a ``denoise`` call did: the backend ("pyoidn 2.5.1" / "ctypes:<library path>"),
    settings, seconds spent in OIDN (all filters) and colour pixels replaced by ``sanitize``."""

    backend: str
    prefilter: str
    quality: str
    seconds: float
    replaced_pixels: int


# ------------------------------------------------------------------------------ sanitising


def _fill_nonfinite(color: np.ndarray) -> tuple[np.ndarray, int]:
    """Replace every pixel with a non-finite channel by the mean of its finite 3 × 3 neighbours."""
    bad = ~np.isfinite(color).all(axis=-1)
    n_bad = int(bad.sum())
    if n_bad == 0:
        return color, 0
    good = ~bad
    clean = np.where(good[..., None], color, 0.0)
    # 3×3 box sums of the finite pixels and of their count (edges padded with zeros)
    pad_c = np.pad(clean, ((1, 1), (1, 1), (0, 0)))
    pad_n = np.pad(good.astype(np.float64), 1)
    h, w = bad.shape
    s = np.zeros_like(clean)
    n = np.zeros((h, w))
    for dy in range(3):
        for dx in range(3):
            s += pad_c[dy:dy + h, dx:dx + w]
            n += pad_n[dy:dy + h, dx:dx + w]
    fill = np.where(n[..., None] > 0, s / np.maximum(n, 1)[..., None], 0.0)
    # a finite but huge neighbour could still overflow float32 in the sum: bound the fill
    fill = np.nan_to_num(fill, nan=0.0, posinf=0.0, neginf=0.0)
    clean[bad] = fill[bad]
    return clean, n_bad


def sanitize(color, albedo=None, normal=None):
    """(color, albedo, normal, replaced) as C-contiguous float32 (H, W, 3) arrays OIDN accepts.

    color: non-finite pixels filled from finite neighbours (see the module docstring), then
    clamped to [0, float32 max]; albedo: non-finite → 0, clamped to [0, 1]; normal: non-finite → 0,
    clamped to [-1, 1]. ``replaced`` counts the filled colour pixels. Inputs are not modified.
    """
    c = np.asarray(color, dtype=np.float64)
    if c.ndim != 3 or c.shape[2] < 3 or c.shape[0] == 0 or c.shape[1] == 0:
        raise ValueError(f"color must be an (H, W, 3) image, got shape {c.shape}")
    c, replaced = _fill_nonfinite(c[..., :3])
    c = np.clip(c, 0.0, float(np.finfo(np.float32).max))
    out = [np.ascontiguousarray(c, dtype=np.float32)]
    for img, lo in ((albedo, 0.0), (normal, -1.0)):
        if img is None:
            out.append(None)
            continue
        a = np.asarray(img, dtype=np.float64)
        if a.shape[:2] != c.shape[:2] or a.ndim != 3 or a.shape[2] < 3:
            raise ValueError(f"guide image of shape {a.shape} does not match the color's {c.shape}")
        a = np.clip(np.nan_to_num(a[..., :3], nan=0.0, posinf=0.0, neginf=0.0), lo, 1.0)
        out.append(np.ascontiguousarray(a, dtype=np.float32))
    return out[0], out[1], out[2], replaced


# ------------------------------------------------------------------------------ backends


class _PyOIDN:
    """OIDN through the ``pyoidn`` wheel's Device/Filter wrappers (one CPU device per process)."""

    def __init__(self, threads: int | None):
        import pyoidn  # noqa: F401 -- the lazy import; ImportError is handled by the caller

        self.pyoidn = pyoidn
        self.name = f"pyoidn (OIDN {getattr(pyoidn.version, 'oidn_version', '?')})"
        self.device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
        if threads:
            self.device.set_int("numThreads", int(threads))
        self.device.commit()
        self._check("device creation")

    def _check(self, what: str):
        err = self.device.get_error()
        if err:
            raise RuntimeError(f"Open Image Denoise {what} failed: {err}")

    def run(self, images: dict, bools: dict, quality: int) -> None:
        p = self.pyoidn
        flt = p.Filter(self.device, p.OIDN_FILTER_TYPE_RT)
        try:
            for name, img in images.items():
                flt.set_image(name, img, p.OIDN_FORMAT_FLOAT3)
            for k, v in bools.items():
                flt.set_bool(k, v)
            flt.set_int("quality", quality)
            flt.commit()
            self._check("filter setup")
            flt.execute()
            self._check("filter execution")
        finally:
            flt.release()


class _CtypesOIDN:
    """OIDN through its C API (oidn.h) in a shared library, e.g. the one Blender ships.

    Works with OIDN 1.x (``oidnSetFilter1b``/``1i``, no quality setting) and 2.x."""

    def __init__(self, path: str, threads: int | None):
        lib = ctypes.CDLL(path)
        self.name = f"ctypes:{os.path.basename(path)}"
        vp, cp, sz = ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t
        lib.oidnNewDevice.restype = vp
        lib.oidnNewDevice.argtypes = [ctypes.c_int]
        lib.oidnCommitDevice.argtypes = [vp]
        lib.oidnReleaseDevice.argtypes = [vp]
        lib.oidnGetDeviceError.restype = ctypes.c_int
        lib.oidnGetDeviceError.argtypes = [vp, ctypes.POINTER(cp)]
        lib.oidnNewFilter.restype = vp
        lib.oidnNewFilter.argtypes = [vp, cp]
        lib.oidnSetSharedFilterImage.argtypes = [vp, cp, vp, ctypes.c_int, sz, sz, sz, sz, sz]
        for fn in ("oidnCommitFilter", "oidnExecuteFilter", "oidnReleaseFilter"):
            getattr(lib, fn).argtypes = [vp]
        v2 = hasattr(lib, "oidnSetFilterBool")
        self.set_bool = lib.oidnSetFilterBool if v2 else lib.oidnSetFilter1b
        self.set_bool.argtypes = [vp, cp, ctypes.c_bool]
        self.set_int = lib.oidnSetFilterInt if v2 else lib.oidnSetFilter1i
        self.set_int.argtypes = [vp, cp, ctypes.c_int]
        set_dev_int = lib.oidnSetDeviceInt if v2 else lib.oidnSetDevice1i
        set_dev_int.argtypes = [vp, cp, ctypes.c_int]
        self.has_quality = v2
        self.lib = lib
        self.device = lib.oidnNewDevice(_OIDN_DEVICE_TYPE_CPU)
        if not self.device:
            raise RuntimeError(f"Open Image Denoise ({path}) could not create a CPU device")
        if threads:
            set_dev_int(self.device, b"numThreads", int(threads))
        lib.oidnCommitDevice(self.device)
        self._check("device creation")

    def _check(self, what: str):
        msg = ctypes.c_char_p()
        if self.lib.oidnGetDeviceError(self.device, ctypes.byref(msg)):
            text = msg.value.decode("utf-8", "replace") if msg.value else "no message"
            raise RuntimeError(f"Open Image Denoise {what} failed: {text}")

    def run(self, images: dict, bools: dict, quality: int) -> None:
        lib = self.lib
        flt = lib.oidnNewFilter(self.device, b"RT")
        try:
            for name, img in images.items():
                h, w = img.shape[:2]
                lib.oidnSetSharedFilterImage(flt, name.encode(), img.ctypes.data, _OIDN_FORMAT_FLOAT3,
                                             w, h, 0, 0, 0)
            for k, v in bools.items():
                self.set_bool(flt, k.encode(), bool(v))
            if self.has_quality:
                self.set_int(flt, b"quality", quality)
            lib.oidnCommitFilter(flt)
            self._check("filter setup")
            lib.oidnExecuteFilter(flt)
            self._check("filter execution")
        finally:
            lib.oidnReleaseFilter(flt)


_backends: dict = {}
_lock = threading.Lock()  # OIDN devices are thread-safe, our cache and filters are not


def _backend(library: str | None, threads: int | None):
    key = (library, threads)
    if key not in _backends:
        if library:
            try:
                _backends[key] = _CtypesOIDN(library, threads)
            except (OSError, AttributeError) as e:
                raise DenoiserUnavailable(f"cannot use Open Image Denoise library {library}: {e}") from None
        else:
            try:
                _backends[key] = _PyOIDN(threads)
            except ImportError:
                raise DenoiserUnavailable(f"denoising needs Open Image Denoise: {INSTALL_HINT}") from None
            except OSError as e:  # the wheel is there but its shared library does not load
                raise DenoiserUnavailable(f"Open Image Denoise (pyoidn) does not load: {e}") from None
    return _backends[key]


def require_backend(library: str | None = None) -> str:
    """Load the OIDN backend now (pyoidn, or the shared library at ``library``) and return its
    name; raises ``DenoiserUnavailable`` with a one-line message when it cannot be loaded.
    Call this before rendering so a missing denoiser fails fast."""
    with _lock:
        return _backend(library, None).name


def denoise(color, albedo=None, normal=None, *, prefilter: str = DEFAULT_PREFILTER,
            quality: str = DEFAULT_QUALITY, library: str | None = None, threads: int | None = None,
            return_info: bool = False):
    """Denoise a linear HDR RGB image with OIDN; returns a new (H, W, 3) float32 array
    (and a ``DenoiseInfo`` if ``return_info``).

    color: (H, W, 3[+]) scene-linear radiance (extra channels such as alpha are ignored);
    albedo, normal: optional guides of the same size (the normal is used only with an albedo,
    as OIDN requires); prefilter: ACCURATE | FAST | NONE; quality: HIGH | BALANCED | FAST (see
    the module docstring); library: path of an OIDN shared library to use instead of pyoidn;
    threads: OIDN worker threads (None: all cores). Inputs are sanitised first (``sanitize``)
    and never modified. Raises ``DenoiserUnavailable`` without a backend, ValueError on bad
    settings or shapes, RuntimeError if OIDN reports an error.
    """
    prefilter, quality = str(prefilter).upper(), str(quality).upper()
    if prefilter not in PREFILTERS:
        raise ValueError(f"denoise prefilter must be one of {', '.join(PREFILTERS)}, got {prefilter}")
    if quality not in QUALITIES:
        raise ValueError(f"denoise quality must be one of {', '.join(QUALITIES)}, got {quality}")
    if albedo is None:
        normal = None  # OIDN's RT filter takes a normal only together with an albedo
    c, a, n, replaced = sanitize(color, albedo, normal)
    q = _OIDN_QUALITY[quality]
    out = np.empty_like(c)
    with _lock:
        be = _backend(library, threads)
        t0 = time.perf_counter()
        if a is not None and prefilter == "ACCURATE":
            # Cycles's ACCURATE: denoise each guide on its own, then treat them as clean
            a_f, n_f = np.empty_like(a), None
            be.run({"albedo": a, "output": a_f}, {}, q)
            a = a_f
            if n is not None:
                n_f = np.empty_like(n)
                be.run({"normal": n, "output": n_f}, {}, q)
                n = n_f
        images = {"color": c, "output": out}
        if a is not None:
            images["albedo"] = a
            if n is not None:
                images["normal"] = n
        be.run(images, {"hdr": True, "cleanAux": a is not None and prefilter != "FAST"}, q)
        seconds = time.perf_counter() - t0
    if return_info:
        return out, DenoiseInfo(be.name, prefilter, quality, seconds, replaced)
    return out


def denoise_film(film, **kwargs):
    """``denoise`` a ``drt.film.Film``'s combined pass with its albedo and normal passes.
    Returns ((H, W, 3) float32 denoised RGB, top row first, DenoiseInfo)."""
    return denoise(film.combined, film.albedo, film.normal, return_info=True, **kwargs)
