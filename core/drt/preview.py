"""An sRGB PNG preview of a linear image (Blender's "Standard" view transform, no AgX).

The PNG is encoded here with the standard library (``zlib`` + ``struct``): an 8-bit RGB PNG is
a signature, three chunks and a deflated stream of filtered rows, which is less code than an
optional dependency would cost users to install.
"""

from __future__ import annotations

import os
import struct
import zlib

import numpy as np


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB transfer function on linear values clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def to_srgb8(rgba: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """(H, W, 3) uint8 sRGB of a top-row-first (H, W, 3|4) scene-linear image; NaN shows black."""
    rgb = np.nan_to_num(rgba[..., :3].astype(np.float64), nan=0.0, posinf=1.0, neginf=0.0) * (2.0**exposure)
    return (linear_to_srgb(rgb) * 255 + 0.5).astype(np.uint8)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def encode_png(rgb8: np.ndarray) -> bytes:
    """PNG bytes of an (H, W, 3) uint8 image, top row first (filter type 0 on every row)."""
    h, w, c = rgb8.shape
    if c != 3 or rgb8.dtype != np.uint8:
        raise ValueError(f"expected an (H, W, 3) uint8 image, got {rgb8.shape} {rgb8.dtype}")
    rows = np.concatenate([np.zeros((h, 1), np.uint8), np.ascontiguousarray(rgb8).reshape(h, w * 3)], axis=1)
    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)  # 8-bit, colour type 2 (RGB)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header)
            + _chunk(b"IDAT", zlib.compress(rows.tobytes(), 6)) + _chunk(b"IEND", b""))


def write_png(path: str, rgba: np.ndarray, exposure: float = 0.0) -> None:
    """Write the top-row-first (H, W, 3|4) linear image as an 8-bit sRGB PNG (atomically: a
    failed write leaves no partial file)."""
    data = encode_png(to_srgb8(rgba, exposure))
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
