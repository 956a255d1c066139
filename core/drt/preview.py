"""An sRGB PNG preview of a linear image (Blender's "Standard" view transform, no AgX).

Pillow does the PNG encoding; it is optional (a bench/preview extra), so the import is local.
"""

from __future__ import annotations

import numpy as np


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB transfer function on linear values clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def write_png(path: str, rgba: np.ndarray, exposure: float = 0.0) -> None:
    """Write the top-row-first (H, W, 3|4) linear image as an 8-bit sRGB PNG."""
    try:
        from PIL import Image
    except ImportError:
        raise OSError("writing a PNG preview needs Pillow (pip install pillow)") from None
    rgb = np.nan_to_num(rgba[..., :3].astype(np.float64)) * (2.0**exposure)
    img = (linear_to_srgb(rgb) * 255 + 0.5).astype(np.uint8)
    Image.fromarray(img, "RGB").save(path)
