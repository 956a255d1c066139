"""Cryptomatte: per-pixel coverage of named objects, materials and assets, as Cycles writes it.

A Cryptomatte layer ("object", "material" or "asset") gives every pixel a short list of
(id, coverage) pairs: the ids of the names seen in it, each with the share of the pixel's
samples (weighted by how much of the sample each surface took) that saw it. Compositors pick a
name and get a soft-edged matte. The conventions are the Cryptomatte specification's (Psyop,
2015) as Blender and Cycles use them:

- **id** of a name: MurmurHash3 (x86, 32 bit, seed 0) of its UTF-8 bytes, stored as the float32
  with those bits, its exponent clamped to 1..254 so that it is never 0, inf or NaN
  (``name_id``; Cycles's util_hash_to_float). An id of 0 marks an empty slot.
- **what a sample adds** (Cycles's film_write_data_passes): at every surface a camera ray hits —
  still one after transparent surfaces (DRT's see-through hits) — average(throughput) ×
  (1 − average transparency), to the object's id, the material's and the asset's (the object's
  topmost parent). The world adds nothing.
- **slots**: a pixel keeps ``levels`` (rounded up to even) slots per layer; a new id takes the
  first empty slot, an id already there adds its weight, an id that finds no room is dropped
  (Cycles's film_write_cryptomatte_slots). Reading the film sorts a pixel's slots by weight,
  heaviest first, and divides the weights by its sample count (Cycles's cryptomatte post-pass
  and film_get_pass_pixel_cryptomatte). Ids are not scaled.
- **passes**: layer L's slots go to passes named ``Crypto<Object|Material|Asset>NN``, NN = 00,
  01, …, two (id, weight) pairs per RGBA pass.
- **metadata** (the images' header, Blender's render-result stamp): per layer, under
  ``cryptomatte/<first 7 hex digits of the layer name's hash>/``: ``name`` (the layer name, e.g.
  ``ViewLayer.CryptoObject``), ``hash`` ``MurmurHash3_32``, ``conversion``
  ``uint32_to_float32`` and ``manifest``, a JSON object of name → 8-digit hex hash.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from .kernels import kernel

#: the layers a scene may ask for (``render.cryptomatte``), in their order in the film
CRYPTO_LAYERS = ("object", "material", "asset")
#: each layer's pass prefix in Blender's render result (Cycles's names)
PASS_PREFIX = {"object": "CryptoObject", "material": "CryptoMaterial", "asset": "CryptoAsset"}
#: Blender's Levels range (View Layer > Passes > Cryptomatte > Levels)
MIN_LEVELS, MAX_LEVELS = 2, 16
#: surfaces one sample records (``Outputs.crypto``): a camera ray seeing through more
#: transparent surfaces than this drops the rest (their weight is what the first ones left)
CRYPTO_SURFACES = 4
#: columns of one recorded surface: its weight, then the object, material and asset ids
CRYPTO_WEIGHT, CRYPTO_IDS = 0, 1
CRYPTO_COLUMNS = 4


def murmur3_32(data: bytes, seed: int = 0) -> int:
    """MurmurHash3 x86 32-bit of ``data`` (Austin Appleby's public-domain algorithm)."""
    c1, c2 = 0xCC9E2D51, 0x1B873593
    h = seed & 0xFFFFFFFF
    n = len(data)
    for i in range(0, n - n % 4, 4):
        k = int.from_bytes(data[i:i + 4], "little")
        k = (k * c1) & 0xFFFFFFFF
        k = ((k << 15) | (k >> 17)) & 0xFFFFFFFF
        k = (k * c2) & 0xFFFFFFFF
        h ^= k
        h = ((h << 13) | (h >> 19)) & 0xFFFFFFFF
        h = (h * 5 + 0xE6546B64) & 0xFFFFFFFF
    tail = data[n - n % 4:]
    k = 0
    for j in reversed(range(len(tail))):
        k = (k << 8) | tail[j]
    if tail:
        k = (k * c1) & 0xFFFFFFFF
        k = ((k << 15) | (k >> 17)) & 0xFFFFFFFF
        k = (k * c2) & 0xFFFFFFFF
        h ^= k
    h ^= n
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & 0xFFFFFFFF
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & 0xFFFFFFFF
    h ^= h >> 16
    return h


def name_hash(name: str) -> int:
    return murmur3_32(name.encode("utf-8"))


def hash_to_float(h: int) -> float:
    """The float32 Cryptomatte stores for hash ``h`` (exponent clamped to 1..254)."""
    exponent = min(max((h >> 23) & 0xFF, 1), 254)
    bits = (h & 0x80000000) | (exponent << 23) | (h & 0x7FFFFF)
    return struct.unpack("<f", struct.pack("<I", bits))[0]


def name_id(name: str) -> float:
    """The id of ``name`` in a Cryptomatte pass (a float32 value, returned as a Python float)."""
    return hash_to_float(name_hash(name))


def slot_count(levels: int) -> int:
    """Slots per layer for Blender's Levels: two per RGBA pass, so rounded up to even."""
    return 2 * ((int(levels) + 1) // 2)


def layer_key(layer_name: str) -> str:
    """The metadata key prefix of a layer (``cryptomatte/<7 hex digits>/``)."""
    return f"cryptomatte/{name_hash(layer_name):08x}"[:19] + "/"


def metadata(layer_name: str, names) -> dict:
    """A layer's metadata entries (key → string) for the names it may hold."""
    manifest = {n: f"{name_hash(n):08x}" for n in sorted(set(names))}
    key = layer_key(layer_name)
    return {key + "name": layer_name, key + "hash": "MurmurHash3_32",
            key + "conversion": "uint32_to_float32",
            key + "manifest": json.dumps(manifest, separators=(",", ":"))}


def scene_names(scene, layers) -> dict:
    """layer → the sorted names a scene's triangles carry in it (the manifest's entries)."""
    names = {}
    for layer in layers:
        if layer == "object":
            ns = {o.crypto_object or o.name for o in scene.objects}
        elif layer == "asset":
            ns = {o.crypto_asset or o.name for o in scene.objects}
        else:
            ns = {str(m.get("cryptomatte", m.get("name", f"material{i}")))
                  for i, m in enumerate(scene.materials) if isinstance(m, dict)}
        names[layer] = tuple(sorted(ns))
    return names


@kernel
def add_to_slots(slots, k, base, n_slots, ident, weight):
    """Add ``weight`` to id ``ident`` among pixel k's slots ``base .. base + n_slots`` of the
    (pixels, slots, 2) array ``slots`` ([id, weight]); first come, first slot; no room: dropped."""
    if weight <= 0.0 or ident == 0.0:
        return
    for s in range(base, base + n_slots):
        if slots[k, s, 0] == ident:
            slots[k, s, 1] += weight
            return
        if slots[k, s, 0] == 0.0:
            slots[k, s, 0] = ident
            slots[k, s, 1] = weight
            return


@kernel
def accumulate(pixel, crypto, layers, n_slots, slots):
    """Add a batch's recorded surfaces (``crypto`` (n, CRYPTO_SURFACES, CRYPTO_COLUMNS)) of the
    samples of pixels ``pixel`` (n,) to the film's ``slots`` (pixels, len(layers)·n_slots, 2);
    ``layers`` (int64) holds the id column offset (0 object, 1 material, 2 asset) of each of the
    film's layers. In sample order, so the result does not depend on threads."""
    for i in range(pixel.shape[0]):
        k = pixel[i]
        for e in range(crypto.shape[1]):
            w = crypto[i, e, CRYPTO_WEIGHT]
            if w <= 0.0:
                break
            for t in range(layers.shape[0]):
                add_to_slots(slots, k, t * n_slots, n_slots, crypto[i, e, CRYPTO_IDS + layers[t]], w)


@kernel
def merge_slots(into, other, n_layers, n_slots):
    """Add film ``other``'s slots to ``into``'s (same shape), pixel by pixel."""
    for k in range(other.shape[0]):
        for t in range(n_layers):
            for s in range(t * n_slots, (t + 1) * n_slots):
                if other[k, s, 0] == 0.0:
                    break
                add_to_slots(into, k, t * n_slots, n_slots, other[k, s, 0], other[k, s, 1])


def read_layer(slots: np.ndarray, layer: int, n_slots: int, count: np.ndarray) -> np.ndarray:
    """(pixels, n_slots, 2) float32 [id, coverage] of one layer: each pixel's slots sorted by
    weight, heaviest first (empty slots last; equal weights by id, so that films merged in any
    order read alike), the weights divided by its sample count."""
    part = slots[:, layer * n_slots:(layer + 1) * n_slots, :]
    order = np.lexsort((part[:, :, 0], -part[:, :, 1]), axis=-1)
    out = np.take_along_axis(part, order[:, :, None], axis=1).copy()
    out[:, :, 1] /= np.maximum(count, 1)[:, None]
    return out.astype(np.float32)


def pass_images(layer_slots: np.ndarray, height: int, width: int) -> list[np.ndarray]:
    """A layer's (pixels, n_slots, 2) slots as its RGBA passes (each (H, W, 4): id, weight, id,
    weight), in order 00, 01, …"""
    n_slots = layer_slots.shape[1]
    return [layer_slots[:, 2 * j:2 * j + 2, :].reshape(height, width, 4) for j in range(n_slots // 2)]
