"""Side-by-side PNG of back-lit rims on smooth low-poly meshes, DRT (left) and Cycles (right).

    python scripts/backlit_rims.py [--spp 256] [--out docs/img/backlit_rims_drt_vs_cycles.png]

Rows: a diffuse torus and Suzanne, then the same with a Principled sheen over a grey base, each
lit by a sun from behind (direct light only), the scenes of tests/test_terminator.py. Prints
the image-mean ratio DRT/Cycles per row. docs/lights.md ("silhouettes of smooth meshes")."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [os.path.join(REPO, "tests"), REPO]

CASES = [("TORUS", (-80.0, 0.0), False), ("SUZANNE", (-60.0, 20.0), False),
         ("TORUS", (-80.0, 0.0), True), ("SUZANNE", (-60.0, 20.0), True)]


class _Patch:
    """The one monkeypatch method the test helpers use."""

    def setattr(self, obj, name, value):
        setattr(obj, name, value)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--out", default=os.path.join(REPO, "docs", "img", "backlit_rims_drt_vs_cycles.png"))
    opts = ap.parse_args(argv)
    import bpy
    import test_terminator as T
    from drt.preview import write_png

    rows = []
    tmp = tempfile.mkdtemp()
    for shape, sun, sheen in CASES:
        T.SUN = sun
        scene = T.sphere_scene(0.1, shape=shape)
        if sheen:
            ball = bpy.data.objects["Ball"]
            ball.data.materials.clear()
            ball.data.materials.append(T._principled_sheen())
        drt, _ = T.drt_render(opts.spp)
        cyc = T.cycles_render(scene, opts.spp, os.path.join(tmp, "cycles.exr"), _Patch())
        print(f"{shape:8s} sun {sun} {'sheen  ' if sheen else 'diffuse'} DRT/Cycles image mean "
              f"{drt.mean() / cyc.mean():.3f}")
        gap = np.ones((drt.shape[0], 2, 3))
        rows.append(np.concatenate([drt, gap, cyc], axis=1))
        rows.append(np.ones((2, rows[-1].shape[1], 3)))
    img = np.concatenate(rows[:-1], axis=0)
    img = img / max(np.percentile(img[img < 1.0], 99.5), 1e-6)  # the rims, not the white gaps
    img = np.repeat(np.repeat(img, 4, axis=0), 4, axis=1)
    write_png(opts.out, np.clip(img, 0.0, 1.0))
    print("wrote", opts.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
