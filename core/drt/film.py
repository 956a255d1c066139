"""Per-pixel accumulation of samples and the passes written out.

The pixel filter is importance-sampled (``sampling.pixel_filter``), so every camera sample has
weight 1 and belongs to exactly one pixel: a pixel's value is the plain mean of its samples, the
estimator Cycles uses. Sums are kept in float64 and added in a fixed order, so the result is
bit-identical for a given seed whatever the thread timing.

Arrays are stored **top row first** (row 0 is the top of the image, as in EXR).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import cryptomatte
from .kernels import kernel


LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)


#: the Z-pass value of pixels that see only the background: Cycles writes 1e10 (measured with
#: bpy 5.0, docs/conventions.md), and compositing setups (Z Combine, Defocus) expect it
BACKGROUND_DEPTH = 1e10


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec.709 / linear sRGB luminance of (..., 3) radiance (no BLAS call: BLAS threads would
    spin beside the render's own)."""
    r, g, b = LUMINANCE_WEIGHTS
    return r * rgb[..., 0] + g * rgb[..., 1] + b * rgb[..., 2]


@kernel
def _accumulate(pixel, radiance, alpha, depth, normal, albedo,
                sum_rgba, sum_lum2, sum_normal, sum_albedo, min_depth, count):
    """Add one batch's samples to the film sums, in batch order (deterministic)."""
    wr, wg, wb = LUMINANCE_WEIGHTS
    for i in range(pixel.shape[0]):
        k = pixel[i]
        for c in range(3):
            sum_rgba[k, c] += radiance[i, c]
            sum_normal[k, c] += normal[i, c]
            sum_albedo[k, c] += albedo[i, c]
        sum_rgba[k, 3] += alpha[i]
        lum = wr * radiance[i, 0] + wg * radiance[i, 1] + wb * radiance[i, 2]
        sum_lum2[k] += lum * lum
        if depth[i] < min_depth[k]:
            min_depth[k] = depth[i]
        count[k] += 1


@kernel
def _accumulate_mist(pixel, mist, sum_mist):
    for i in range(pixel.shape[0]):
        sum_mist[pixel[i]] += mist[i]


@kernel
def _accumulate_data(pixel, data, sum_data):
    for i in range(pixel.shape[0]):
        k = pixel[i]
        for c in range(data.shape[1]):
            sum_data[k, c] += data[i, c]


#: columns of ``Film.sum_data`` (drt.path_stages.DATA_* up to DATA_DONE): the Object Index, the
#: Material Index, the Position (3, Blender world space), whether sample 0 hit a surface — each
#: from the pixel's sample 0 only, so their sum is that sample's value — and Σ UV (3: u, v, 1)
DATA_OBJECT, DATA_MATERIAL, DATA_POSITION, DATA_HIT, DATA_UV = 0, 1, 2, 5, 6
DATA_WIDTH = 9
#: columns of ``Film.sum_light``: Σ Emission, Σ Environment (exposed, as the combined pass),
#: Σ Diffuse Color (an albedo: not exposed, as Cycles's colour passes), Σ Ambient Occlusion (a
#: visibility: not exposed), rgb each
LIGHT_EMISSION, LIGHT_ENVIRONMENT, LIGHT_DIFFUSE_COLOR, LIGHT_AO = 0, 3, 6, 9
LIGHT_WIDTH = 12


@kernel
def _mean_image(sums, count, out, clamp_last):
    """out[i, c] = sums[i, c] / max(count[i], 1) as float32: a pass's per-pixel mean (the
    combined pass clamps its last column, alpha, to [0, 1]). The same float64 division and
    rounding to float32 as NumPy's ``(sums / c).astype(np.float32)``, in one pass over the
    film instead of three (the combined pass at 1920 × 1080: 9.5 ms against 23-50 ms)."""
    last = sums.shape[1] - 1
    for i in range(sums.shape[0]):
        c = float(max(count[i], 1))
        for k in range(sums.shape[1]):
            v = sums[i, k] / c
            if clamp_last and k == last:
                v = min(max(v, 0.0), 1.0)
            out[i, k] = v


@kernel
def _unit_mean_image(sums, count, out):
    """The mean of (n, 3) vector sums scaled to unit length, as float32 (0 where it is 0): the
    Normal pass. Same operations, in the same order, as ``mean / np.linalg.norm(mean)``."""
    for i in range(sums.shape[0]):
        c = float(max(count[i], 1))
        x, y, z = sums[i, 0] / c, sums[i, 1] / c, sums[i, 2] / c
        length = math.sqrt(x * x + y * y + z * z)
        if length > 0.0:
            out[i, 0], out[i, 1], out[i, 2] = x / length, y / length, z / length
        else:
            out[i, 0], out[i, 1], out[i, 2] = 0.0, 0.0, 0.0


@kernel
def _variance_image(sum_rgba, sum_lum2, count, out):
    """Variance of each pixel's mean luminance, (E[L²] − E[L]²)/(N − 1), as float32 (`Film.variance`)."""
    wr, wg, wb = LUMINANCE_WEIGHTS
    for i in range(sum_rgba.shape[0]):
        n = float(count[i])
        c = max(n, 1.0)
        mean = wr * (sum_rgba[i, 0] / c) + wg * (sum_rgba[i, 1] / c) + wb * (sum_rgba[i, 2] / c)
        m2 = sum_lum2[i] / c
        out[i] = max(m2 - mean * mean, 0.0) * n / max(n - 1.0, 1.0) / c


def zeroed(shape, dtype=np.float64) -> np.ndarray:
    """``np.zeros`` whose pages are written now. A large ``np.zeros`` is fresh memory that the
    kernel maps page by page on first touch; a film's sums are first touched when the main
    thread adds the first pass's batches, while the render threads run on every core, and
    there each fault cost ~6 µs of CPU taken from them against ~1.4 µs here, before the
    threads start (2 vCPUs, 256² film: ~17 ms against 2 ms; docs/kernels.md)."""
    out = np.empty(shape, dtype)
    out.fill(0)
    return out


def _f64_rows(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _rows3(a) -> np.ndarray:
    return _f64_rows(a).reshape(-1, 3)


@dataclass
class SampleBatch:
    """What one batch of camera paths produced. pixel: (n,) flat pixel id (row-major from the
    TOP row); radiance (n,3); alpha (n,); depth (n,) (inf: nothing hit); normal (n,3) world;
    albedo (n,3); mist (n,) or None (the Mist pass, when asked for). release: None, or a
    callable that gives the arrays' memory back to the integrator that made them, to be reused
    for a later batch: whoever consumes the batch (the render loop, once the film has added
    it) may call it once, and must not read the arrays after that."""

    pixel: np.ndarray
    radiance: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    albedo: np.ndarray
    nan_count: int = 0
    release: object = field(default=None, repr=False, compare=False)
    #: (n,) each sample's Mist sum (drt.path_stages.mist_weight), or None: no Mist pass
    mist: np.ndarray | None = None
    #: (m, DATA_WIDTH) the data passes' columns of m samples (``Film.sum_data``), with their own
    #: flat pixel ids ``data_pixel`` (m,): also samples whose radiance was dropped; None: none
    data: np.ndarray | None = None
    data_pixel: np.ndarray | None = None
    #: (n, LIGHT_WIDTH) each sample's Emission, Environment and Diffuse Color (rgb each), or
    #: None: none
    light: np.ndarray | None = None
    #: (n, CRYPTO_SURFACES, CRYPTO_COLUMNS) each sample's see-through hits for Cryptomatte
    #: (drt.cryptomatte), or None: none
    crypto: np.ndarray | None = None


@dataclass
class Film:
    """Accumulated passes for a width × height image.

    ``combined`` (H, W, 4): mean RGBA (scene-linear radiance); ``depth`` (H, W): distance along
    the camera's view axis to the first hit (inf: none); ``normal`` (H, W, 3): mean world-space
    shading normal of first hits; ``albedo`` (H, W, 3); ``sample_count`` (H, W); ``variance``
    (H, W): estimated variance of the pixel mean's luminance (σ²/N); ``mist`` (H, W) Cycles's
    Mist pass, or None for a film whose samples carried none (``sum_mist`` None); the data
    passes ``object_index``, ``material_index`` (H, W), ``position`` (H, W, 3) Blender world
    space (0 where nothing was hit) — from each pixel's sample 0, as Cycles — and ``uv``
    (H, W, 3) (mean u, v and coverage), or None without them (``sum_data`` None); the light
    passes ``emission`` and ``environment`` (H, W, 3) mean radiance and ``diffuse_color``
    (H, W, 3), or None (``sum_light`` None).
    """

    width: int
    height: int
    sum_rgba: np.ndarray = None
    sum_lum2: np.ndarray = None
    sum_normal: np.ndarray = None
    sum_albedo: np.ndarray = None
    min_depth: np.ndarray = None
    count: np.ndarray = None
    nan_samples: int = 0
    #: Σ of the samples' Mist sums per pixel (created by the first batch that carries one)
    sum_mist: np.ndarray = None
    #: (n, DATA_WIDTH) the data passes' sums (created by the first batch that carries them)
    sum_data: np.ndarray = None
    #: (n, LIGHT_WIDTH) the Emission, Environment and Diffuse Color passes' sums
    sum_light: np.ndarray = None
    #: Cryptomatte: (n, len(crypto_layers) · crypto_slots, 2) float32 [id, Σ weight] slots per
    #: pixel, unsorted (drt.cryptomatte; float32 as Cycles's: ids are float32 values, and a 4K
    #: frame's three layers of 6 slots take 1.2 GB so); None without Cryptomatte. ``crypto_layers``: the layers
    #: ("object", "material", "asset") in slot order; ``crypto_slots``: slots per layer
    sum_crypto: np.ndarray = None
    crypto_layers: tuple = ()
    crypto_slots: int = 0
    #: the names each Cryptomatte layer may hold (layer → tuple of names), for the manifest
    crypto_names: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    #: radiance scale applied as samples are added (Cycles's Film > Exposure); films merged
    #: from exposed parts keep 1
    exposure: float = 1.0

    def __post_init__(self):
        n = self.width * self.height
        if self.sum_rgba is None:
            # one allocation for the six sums: the allocator then hands the next render's film
            # the memory this one frees, where six arrays came back as fresh pages (at 256²,
            # 7-20 ms of page faults in the first batches the main thread adds; docs/kernels.md),
            # and its pages written now, before the render threads start (`zeroed`)
            block = zeroed(13 * n)
            self.sum_rgba = block[:4 * n].reshape(n, 4)
            self.sum_lum2 = block[4 * n:5 * n]
            self.sum_normal = block[5 * n:8 * n].reshape(n, 3)
            self.sum_albedo = block[8 * n:11 * n].reshape(n, 3)
            self.min_depth = block[11 * n:12 * n]
            self.min_depth[:] = np.inf
            self.count = block[12 * n:].view(np.int64)

    def reserve(self, mist: bool = False, light: bool = False, data: bool = False, crypto: bool = False) -> None:
        """Create now the sums of the passes a render's batches will carry (Mist, the light
        passes, the data passes, Cryptomatte), which `add` would otherwise create at the first
        batch that carries them: a render calls this before its threads start (`zeroed`)."""
        n = self.width * self.height
        if mist and self.sum_mist is None:
            self.sum_mist = zeroed(n)
        if light and self.sum_light is None:
            self.sum_light = zeroed((n, LIGHT_WIDTH))
        if data and self.sum_data is None:
            self.sum_data = zeroed((n, DATA_WIDTH))
        if crypto and self.crypto_layers and self.sum_crypto is None:
            self.sum_crypto = zeroed((n, len(self.crypto_layers) * self.crypto_slots, 2), np.float32)

    def add(self, b: SampleBatch) -> None:
        radiance = b.radiance if self.exposure == 1.0 else np.asarray(b.radiance) * self.exposure
        _accumulate(np.ascontiguousarray(b.pixel, dtype=np.int64), _rows3(radiance),
                    np.ascontiguousarray(b.alpha, dtype=np.float64),
                    np.ascontiguousarray(b.depth, dtype=np.float64), _rows3(b.normal), _rows3(b.albedo),
                    self.sum_rgba, self.sum_lum2, self.sum_normal, self.sum_albedo, self.min_depth,
                    self.count)
        self.nan_samples += b.nan_count
        if b.mist is not None:
            if self.sum_mist is None:
                self.sum_mist = zeroed(self.width * self.height)
            _accumulate_mist(np.ascontiguousarray(b.pixel, dtype=np.int64),
                             np.ascontiguousarray(b.mist, dtype=np.float64), self.sum_mist)
        if b.light is not None:
            if self.sum_light is None:
                self.sum_light = zeroed((self.width * self.height, LIGHT_WIDTH))
            light = b.light
            if self.exposure != 1.0:
                light = np.array(light, dtype=np.float64)
                light[:, :LIGHT_DIFFUSE_COLOR] *= self.exposure
            _accumulate_data(np.ascontiguousarray(b.pixel, dtype=np.int64),
                             np.ascontiguousarray(light, dtype=np.float64), self.sum_light)
        if b.crypto is not None and self.crypto_layers:
            if self.sum_crypto is None:
                self.sum_crypto = zeroed((self.width * self.height, len(self.crypto_layers) * self.crypto_slots, 2),
                                         np.float32)
            cryptomatte.accumulate(np.ascontiguousarray(b.pixel, dtype=np.int64),
                                   np.ascontiguousarray(b.crypto, dtype=np.float64), self._crypto_columns(),
                                   self.crypto_slots, self.sum_crypto)
        if b.data is not None:
            if self.sum_data is None:
                self.sum_data = zeroed((self.width * self.height, DATA_WIDTH))
            _accumulate_data(np.ascontiguousarray(b.data_pixel, dtype=np.int64),
                             np.ascontiguousarray(b.data, dtype=np.float64), self.sum_data)

    def merge(self, other: "Film") -> None:
        """Add another film of the same size (e.g. a disjoint sample range)."""
        self.sum_rgba += other.sum_rgba
        self.sum_lum2 += other.sum_lum2
        self.sum_normal += other.sum_normal
        self.sum_albedo += other.sum_albedo
        self.min_depth = np.minimum(self.min_depth, other.min_depth)
        self.count += other.count
        self.nan_samples += other.nan_samples
        if other.sum_mist is not None:
            self.sum_mist = other.sum_mist.copy() if self.sum_mist is None else self.sum_mist + other.sum_mist
        if other.sum_light is not None:
            self.sum_light = other.sum_light.copy() if self.sum_light is None else self.sum_light + other.sum_light
        if other.sum_crypto is not None:
            self.merge_crypto(other.sum_crypto, other.crypto_layers, other.crypto_slots, other.crypto_names)
        if other.sum_data is not None:  # (only one part holds a pixel's sample 0)
            self.sum_data = other.sum_data.copy() if self.sum_data is None else self.sum_data + other.sum_data

    def _crypto_columns(self) -> np.ndarray:
        return np.array([cryptomatte.CRYPTO_LAYERS.index(t) for t in self.crypto_layers], np.int64)

    def merge_crypto(self, slots: np.ndarray, layers: tuple, n_slots: int, names: dict | None = None) -> None:
        """Add another film's Cryptomatte slots (same pixels) and manifest names to this one's."""
        for layer, ns in (names or {}).items():
            self.crypto_names[layer] = tuple(sorted(set(self.crypto_names.get(layer, ())) | set(ns)))
        if self.sum_crypto is None:
            self.crypto_layers, self.crypto_slots = tuple(layers), int(n_slots)
            self.sum_crypto = np.zeros((self.width * self.height, len(layers) * n_slots, 2), np.float32)
        if tuple(layers) != self.crypto_layers or int(n_slots) != self.crypto_slots:
            raise ValueError(f"Cryptomatte layers {tuple(layers)} x {n_slots} slots do not match "
                             f"{self.crypto_layers} x {self.crypto_slots}")
        cryptomatte.merge_slots(self.sum_crypto, np.ascontiguousarray(slots, dtype=np.float32),
                                len(self.crypto_layers), self.crypto_slots)

    def cryptomatte(self, layer: str) -> np.ndarray | None:
        """(H, W, slots, 2) float32 [id, coverage] of a Cryptomatte layer ("object", "material",
        "asset"): each pixel's ids by coverage, heaviest first (empty slots: id 0, coverage 0);
        None when the film has no such layer."""
        if self.sum_crypto is None or layer not in self.crypto_layers:
            return None
        slots = cryptomatte.read_layer(self.sum_crypto, self.crypto_layers.index(layer), self.crypto_slots,
                                       self.count)
        return slots.reshape(self.height, self.width, self.crypto_slots, 2)

    def _mean(self, s: np.ndarray) -> np.ndarray:
        c = np.maximum(self.count, 1).reshape((-1,) + (1,) * (s.ndim - 1))
        return s / c

    def _counts(self) -> np.ndarray:
        return np.ascontiguousarray(self.count, dtype=np.int64)

    def _mean_image(self, sums: np.ndarray, clamp_last: bool = False) -> np.ndarray:
        """(H, W, c) float32 per-pixel means of (n, c) sums (`_mean_image`)."""
        sums = _f64_rows(sums)
        out = np.empty(sums.shape, np.float32)
        _mean_image(sums, self._counts(), out, clamp_last)
        return out.reshape(self.height, self.width, sums.shape[1])

    def _image(self, flat: np.ndarray) -> np.ndarray:
        return flat.reshape((self.height, self.width) + flat.shape[1:]).astype(np.float32)

    @property
    def combined(self) -> np.ndarray:
        """(H, W, 4) float32: mean radiance and alpha. A sample's alpha is 1 less what the world
        and holdouts took (more than 1 where a transparent lobe's sampled weight exceeds 1);
        the pixel's mean is clamped to [0, 1], as Cycles's film_transparency_to_alpha."""
        return self._mean_image(self.sum_rgba, clamp_last=True)

    @property
    def depth(self) -> np.ndarray:
        """(H, W) nearest hit distance along the view axis (Blender's Z pass); pixels where no
        sample hit anything hold BACKGROUND_DEPTH (1e10), as in Cycles's Z pass, not inf."""
        d = self.min_depth
        return self._image(np.where(np.isfinite(d), d, BACKGROUND_DEPTH))

    @property
    def normal(self) -> np.ndarray:
        """(H, W, 3) float32: the mean world-space shading normal of first hits, unit length (0
        where no sample hit anything)."""
        out = np.empty((self.width * self.height, 3), np.float32)
        _unit_mean_image(_f64_rows(self.sum_normal), self._counts(), out)
        return out.reshape(self.height, self.width, 3)

    @property
    def albedo(self) -> np.ndarray:
        return self._mean_image(self.sum_albedo)

    @property
    def mist(self) -> np.ndarray | None:
        """(H, W) Cycles's Mist pass: 1 − the mean of the samples' Mist sums, in [0, 1] (1 where
        only the world is seen, 0 at opaque surfaces nearer than the mist's start); None
        without one."""
        if self.sum_mist is None:
            return None
        return self._image(np.clip(1.0 - self._mean(self.sum_mist), 0.0, 1.0))

    @property
    def object_index(self) -> np.ndarray | None:
        """(H, W) Cycles's Object Index pass: the pass index of the object sample 0 saw (0: none)."""
        return None if self.sum_data is None else self._image(self.sum_data[:, DATA_OBJECT])

    @property
    def material_index(self) -> np.ndarray | None:
        """(H, W) Cycles's Material Index pass (sample 0's material's pass index)."""
        return None if self.sum_data is None else self._image(self.sum_data[:, DATA_MATERIAL])

    @property
    def position(self) -> np.ndarray | None:
        """(H, W, 3) Cycles's Position pass: sample 0's surface point, Blender world space."""
        return None if self.sum_data is None else self._image(self.sum_data[:, DATA_POSITION:DATA_POSITION + 3])

    @property
    def uv(self) -> np.ndarray | None:
        """(H, W, 3) Cycles's UV pass: the mean over samples of (u, v, 1) at the first surface
        each one saw (0 for samples that saw none, or a mesh without a UV map)."""
        return None if self.sum_data is None else self._image(self._mean(self.sum_data[:, DATA_UV:DATA_UV + 3]))

    @property
    def emission(self) -> np.ndarray | None:
        """(H, W, 3) Cycles's Emission pass: the mean light a camera ray (also past transparency)
        brings from emitters before its first scattering; None without it."""
        return None if self.sum_light is None else self._light(LIGHT_EMISSION)

    @property
    def environment(self) -> np.ndarray | None:
        """(H, W, 3) Cycles's Environment pass: the world (and suns) camera rays see, also with a
        transparent film; None without it."""
        return None if self.sum_light is None else self._light(LIGHT_ENVIRONMENT)

    @property
    def diffuse_color(self) -> np.ndarray | None:
        """(H, W, 3) Cycles's Diffuse Color pass: the mean over samples of the diffuse-class
        lobes' colours × throughput, summed over the surfaces a camera ray meets while the world
        still shows through (drt.path_stages.diffuse_color); None without it."""
        return None if self.sum_light is None else self._light(LIGHT_DIFFUSE_COLOR)

    @property
    def ao(self) -> np.ndarray | None:
        """(H, W, 3) Cycles's Ambient Occlusion pass: the mean over samples of throughput ×
        alpha at each surface a camera ray meets (through transparent ones), where a
        cosine-distributed ray about its normal is unoccluded within the AO distance
        (drt.path_stages.queue_ao_ray); 0 for the world; None without it."""
        return None if self.sum_light is None else self._light(LIGHT_AO)

    def _light(self, first: int) -> np.ndarray:
        return self._image(self._mean(self.sum_light[:, first:first + 3]))

    @property
    def sample_count(self) -> np.ndarray:
        return self._image(self.count.astype(np.float64))

    @property
    def variance(self) -> np.ndarray:
        """Variance of each pixel's mean luminance: (E[L²] − E[L]²)/(N − 1)."""
        out = np.empty(self.width * self.height, np.float32)
        _variance_image(_f64_rows(self.sum_rgba), np.ascontiguousarray(self.sum_lum2, dtype=np.float64),
                        self._counts(), out)
        return out.reshape(self.height, self.width)
