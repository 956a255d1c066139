"""Frame ranges and per-frame output names, as Blender numbers animation frames.

``parse_frames("1-250")`` gives the frame numbers; ``frame_path("out/OUT_####.exr", 7)`` gives
``out/OUT_0007.exr``: the last run of ``#`` in the file name becomes the zero-padded frame number
(as many digits as ``#``); a name without ``#`` gets the frame number, padded to four digits,
before its extension (``OUT.exr`` -> ``OUT0007.exr``).
"""

from __future__ import annotations

import os
import re

MAX_FRAMES = 1_048_574  # Blender's MAXFRAME


def parse_frames(text: str) -> list[int]:
    """Frame numbers from ``"A-B"``, ``"A"`` or a comma list of both (``"1-10,20,30-32"``).

    Raises ValueError with a one-line message on anything else, on a range that runs
    backwards, or on frame numbers outside [0, MAX_FRAMES]. Order is kept; repeats are dropped.
    """
    frames: list[int] = []
    for part in text.replace(" ", "").split(","):
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not m:
            raise ValueError(f"expected frames like 1-250 or 1,5,10-20, got {text!r}")
        a = int(m.group(1))
        b = int(m.group(2)) if m.group(2) is not None else a
        if b < a:
            raise ValueError(f"frame range {part} runs backwards")
        if b > MAX_FRAMES:
            raise ValueError(f"frame {b} is beyond Blender's last frame {MAX_FRAMES}")
        frames.extend(range(a, b + 1))
    seen: set[int] = set()
    return [f for f in frames if not (f in seen or seen.add(f))]


def frame_path(pattern: str, frame: int) -> str:
    """The output path of ``frame`` for an output pattern (see the module docstring)."""
    head, name = os.path.split(pattern)
    runs = list(re.finditer(r"#+", name))
    if runs:
        r = runs[-1]
        name = f"{name[:r.start()]}{frame:0{len(r.group())}d}{name[r.end():]}"
    else:
        stem, ext = os.path.splitext(name)
        name = f"{stem}{frame:04d}{ext}"
    return os.path.join(head, name)
