"""EXR output and input through OpenEXR (scene-linear float32, top row first).

Channels written: R, G, B, A (combined); Z (depth along the view axis; 1e10 where nothing was
hit, Cycles's convention); Normal.X/Y/Z (world-space shading normal); Albedo.R/G/B; Mist.Y (Cycles's
Mist pass, when the scene asks for it: ``render.mist``); IndexOB.X, IndexMA.X, Position.X/Y/Z,
UV.U/V/A (Cycles's data passes, when the scene asks for any: ``render.data_passes``; all four
then); Emit.RGB, Env.RGB, DiffCol.RGB, AO.RGB (Cycles's Emission, Environment, Diffuse Color
and Ambient Occlusion passes: ``render.light_passes``; all four then); CryptoObject00.RGBA, CryptoObject01.RGBA, … (and
CryptoMaterial / CryptoAsset: the Cryptomatte layers of ``render.cryptomatte``, two (id,
coverage) pairs per pass, with the specification's ``cryptomatte/<key>/…`` manifest headers);
SampleCount.Y (samples taken by
each pixel); Variance.Y (variance of the pixel mean's luminance). The header carries
``drt:sample_offset``, ``drt:sample_count``, ``drt:seed`` and ``drt:version`` so that renders of
disjoint sample ranges can be merged exactly (``python -m drt merge``).

A denoised render (``--denoise``) stores the denoised image in R, G, B (A stays the film's
coverage) and the film's own mean in the layer ``Noisy.R/G/B/A``, bit-identical to the same
render without denoising; the header then also has ``drt:denoised`` (backend and settings).
``film_from_exr`` rebuilds the film from ``Noisy`` when it is there, so merging or re-denoising
a denoised file works on the Monte Carlo estimate, never on a denoised image.
"""

from __future__ import annotations

import json
import os

import numpy as np
import OpenEXR

from . import cryptomatte
from .film import DATA_MATERIAL, DATA_OBJECT, DATA_POSITION, DATA_UV, DATA_WIDTH, LIGHT_WIDTH, Film, luminance


def film_channels(film: Film, denoised: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """EXR channels of ``film``; with ``denoised`` ((H, W, 3) RGB, top row first) the combined
    pass is the denoised image and the film's mean goes to the ``Noisy`` layer."""
    rgba = film.combined
    ch = {"R": rgba[..., 0], "G": rgba[..., 1], "B": rgba[..., 2], "A": rgba[..., 3], "Z": film.depth}
    if denoised is not None:
        if denoised.shape[:2] != rgba.shape[:2]:
            raise ValueError(f"denoised image {denoised.shape[:2]} does not match the film {rgba.shape[:2]}")
        for i, c in enumerate("RGBA"):
            ch[f"Noisy.{c}"] = rgba[..., i]
        for i, c in enumerate("RGB"):
            ch[c] = denoised[..., i]
    # (each pass is a property computed from the sums on every access: read each one once)
    normal, albedo = film.normal, film.albedo
    for i, axis in enumerate("XYZ"):
        ch[f"Normal.{axis}"] = normal[..., i]
    for i, c in enumerate("RGB"):
        ch[f"Albedo.{c}"] = albedo[..., i]
    mist = film.mist
    if mist is not None:
        ch["Mist.Y"] = mist
    if film.sum_light is not None:
        light = (("Emit", film.emission), ("Env", film.environment), ("DiffCol", film.diffuse_color),
                 ("AO", film.ao))
        for i, c in enumerate("RGB"):
            for name, image in light:
                ch[f"{name}.{c}"] = image[..., i]
    if film.sum_data is not None:
        ch["IndexOB.X"] = film.object_index
        ch["IndexMA.X"] = film.material_index
        position, uv = film.position, film.uv
        for i, axis in enumerate("XYZ"):
            ch[f"Position.{axis}"] = position[..., i]
        for i, c in enumerate("UVA"):
            ch[f"UV.{c}"] = uv[..., i]
    for layer in film.crypto_layers:  # Cryptomatte: CryptoObject00.RGBA = id, coverage, id, coverage
        for j, img in enumerate(cryptomatte.pass_images(film.cryptomatte(layer).reshape(-1, film.crypto_slots, 2),
                                                        film.height, film.width)):
            for i, c in enumerate("RGBA"):
                ch[f"{cryptomatte.PASS_PREFIX[layer]}{j:02d}.{c}"] = img[..., i]
    ch["SampleCount.Y"] = film.sample_count
    ch["Variance.Y"] = film.variance
    return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in ch.items()}


def use_threads(threads: int | None = None) -> None:
    """Let OpenEXR compress and decompress on ``threads`` threads (default: every core).

    The Python binding starts with none (``global_thread_count()`` is 0): a 1920 × 1080 file of
    DRT's 13 channels then took ~0.9 s to ZIP on one core, ~0.5 s on two (2 vCPUs; Blender's
    own EXR writer uses every core too). The setting is process-wide; only a different count
    changes it."""
    n = max(1, int(threads or os.cpu_count() or 1))
    if OpenEXR.global_thread_count() != n:
        OpenEXR.set_global_thread_count(n)


def write_exr(path: str | os.PathLike, film: Film, metadata: dict | None = None,
              denoised: np.ndarray | None = None, threads: int | None = None) -> None:
    """Write ``film`` to ``path`` (ZIP-compressed scanline EXR). Metadata values become strings.
    ``denoised``: see ``film_channels``. ``threads``: OpenEXR's compression threads (`use_threads`)."""
    use_threads(threads)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for k, v in {**film.meta, **(metadata or {})}.items():
        header[f"drt:{k}"] = str(v)
    for layer in film.crypto_layers:  # the Cryptomatte specification's manifest
        header.update(cryptomatte.metadata(cryptomatte.PASS_PREFIX[layer], film.crypto_names.get(layer, ())))
    tmp = f"{os.fspath(path)}.tmp.exr"
    with OpenEXR.File(header, film_channels(film, denoised)) as f:
        f.write(tmp)
    os.replace(tmp, path)  # a reader never sees half a file


def read_exr(path: str | os.PathLike, with_header: bool = False):
    """Channels by name (each (H, W) float32) and the header's ``drt:`` metadata (strings);
    ``with_header``: also the whole header."""
    use_threads()
    with OpenEXR.File(os.fspath(path), separate_channels=True) as f:
        channels = {k: np.array(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
        header = dict(f.header())
        meta = {k[4:]: v for k, v in header.items() if isinstance(k, str) and k.startswith("drt:")}
    return (channels, meta, header) if with_header else (channels, meta)


def _crypto_from_exr(film: Film, ch: dict, header: dict, count: np.ndarray) -> None:
    """Cryptomatte slots back from the passes (coverage × N) and names from the manifests."""
    layers = tuple(t for t in cryptomatte.CRYPTO_LAYERS if f"{cryptomatte.PASS_PREFIX[t]}00.R" in ch)
    if not layers:
        return
    first = cryptomatte.PASS_PREFIX[layers[0]]
    n_slots = 2 * sum(1 for k in ch if k.startswith(first) and k.endswith(".R") and k[len(first):-2].isdigit())
    parts = []
    for layer in layers:
        prefix = cryptomatte.PASS_PREFIX[layer]
        rgba = [np.stack([ch[f"{prefix}{j:02d}.{c}"] for c in "RGBA"], -1).reshape(-1, 2, 2)
                for j in range(n_slots // 2)]
        parts.append(np.concatenate(rgba, axis=1).astype(np.float32))
    slots = np.concatenate(parts, axis=1)
    slots[:, :, 1] *= count[:, None].astype(np.float32)
    film.sum_crypto, film.crypto_layers, film.crypto_slots = slots, layers, n_slots
    for layer in layers:
        key = cryptomatte.layer_key(cryptomatte.PASS_PREFIX[layer])
        try:
            film.crypto_names[layer] = tuple(sorted(json.loads(header.get(key + "manifest", "{}"))))
        except (TypeError, ValueError):
            film.crypto_names[layer] = ()


def film_from_exr(path: str | os.PathLike) -> Film:
    """Rebuild a ``Film`` (its sums) from a DRT EXR, for merging sample ranges. A denoised
    file's sums come from its ``Noisy`` layer (the Monte Carlo mean); ``denoised`` is dropped
    from the metadata."""
    ch, meta, header = read_exr(path, with_header=True)
    h, w = ch["R"].shape
    count = ch["SampleCount.Y"].astype(np.float64).reshape(-1)
    film = Film(w, h)
    layer = "Noisy." if "Noisy.R" in ch else ""
    rgba = np.stack([ch[layer + c] for c in "RGBA"], axis=-1).reshape(-1, 4).astype(np.float64)
    film.sum_rgba = rgba * count[:, None]
    film.sum_normal = np.stack([ch[f"Normal.{a}"] for a in "XYZ"], -1).reshape(-1, 3) * count[:, None]
    film.sum_albedo = np.stack([ch[f"Albedo.{c}"] for c in "RGB"], -1).reshape(-1, 3) * count[:, None]
    film.min_depth = ch["Z"].astype(np.float64).reshape(-1)
    if "Mist.Y" in ch:  # (the pass is 1 − the mean of the samples' sums)
        film.sum_mist = (1.0 - ch["Mist.Y"].astype(np.float64).reshape(-1)) * count
    if "Emit.R" in ch:  # the light passes: their means × N
        layers = ("Emit", "Env", "DiffCol", "AO")  # (a file from before the AO pass has no AO: 0)
        film.sum_light = np.stack([ch.get(f"{layer}.{c}", np.zeros_like(ch["R"])) for layer in layers for c in "RGB"],
                                  -1).reshape(-1, LIGHT_WIDTH).astype(np.float64) * count[:, None]
    if "IndexOB.X" in ch:  # the data passes: sample 0's values as they are, the UV's mean × N
        film.sum_data = np.zeros((h * w, DATA_WIDTH))
        film.sum_data[:, DATA_OBJECT] = ch["IndexOB.X"].reshape(-1)
        film.sum_data[:, DATA_MATERIAL] = ch["IndexMA.X"].reshape(-1)
        for i, axis in enumerate("XYZ"):
            film.sum_data[:, DATA_POSITION + i] = ch[f"Position.{axis}"].reshape(-1)
        for i, c in enumerate("UVA"):
            film.sum_data[:, DATA_UV + i] = ch[f"UV.{c}"].astype(np.float64).reshape(-1) * count
    _crypto_from_exr(film, ch, header, count)
    film.count = np.rint(count).astype(np.int64)
    # recover Σ L² from the stored variance of the mean: var·(N−1) + mean² = E[L²]
    lum = luminance(rgba[:, :3])  # (not a BLAS product: docs/decisions.md)
    var = ch["Variance.Y"].astype(np.float64).reshape(-1)
    film.sum_lum2 = (var * np.maximum(count - 1, 0) + lum**2) * count
    film.meta = {k: v for k, v in meta.items() if k != "denoised"}
    return film
