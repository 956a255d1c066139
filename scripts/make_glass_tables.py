"""Generate core/drt/materials/glass_ms_tables.npz: the albedo tables of the white GGX glass
lobe that Cycles's Multiscatter GGX glass compensation reads (docs/materials.md,
"Multiscatter GGX glass").

Definitions (Cycles 5.0's ``ggx_glass_E`` / ``_Eavg`` / ``_inv_E`` / ``_inv_Eavg``, see
app/cycles_precompute.cpp; our own Monte Carlo with DRT's glass sampling kernel):
  E(r, mu, z)    16×16×16 [z, mu, r]: directional albedo of a white single-scatter GGX glass
                 (reflection + refraction, exact dielectric Fresnel choice), alpha = r²,
                 cos θo = mu, eta = ior_from_F0(z⁴) > 1: E[G2/G1] over visible normals, 0 for
                 samples leaving on the wrong side.
  E_avg(r, z)    16×16 [z, r]: 2 ∫ mu E dmu.
  inv_E, inv_E_avg: the same seen from inside (eta → 1/eta).
At z = 0 (|eta − 1| < 1e-4) Cycles's glass is a straight delta: E = E_avg = 1.
Checked against the tables Cycles ships (scene/shader.tables): E agrees to 1.5e-3, E_avg to
5e-3, inv E_avg to 1e-2; inv E agrees to 0.03 for cos θo ≥ 0.3 but is lower than Cycles's at
grazing angles inside (up to 0.21 at cos θo = 1/15, rough ≥ 0.5): ours is the albedo of DRT's
own glass lobe (whose sampling and eval agree and match Cycles's renders).
Grid nodes: r = clamp(i/15, 1e-4, 1), mu = clamp(j/15, 1e-4, 1), z = clamp(k/15, 1e-4, 0.99);
read with (tri)linear interpolation. Run: PYTHONPATH=core python scripts/make_glass_tables.py
"""
import os
import sys

import numpy as np
from numba import njit

from drt.materials.dielectric import glass_sample
from drt.materials.ggx import ggx_smith_lambda


@njit(cache=False)
def _albedo(r, mu, eta_ior, inside, u):
    """Mean weight of white glass samples (wo at cos θ = mu, on the inside if ``inside``)."""
    alpha = max(r * r, 1e-8)
    s = np.sqrt(max(1.0 - mu * mu, 0.0))
    wo = (s, 0.0, -mu if inside else mu)
    lam_o = ggx_smith_lambda(mu, alpha)
    total = 0.0
    for k in range(u.shape[0]):
        wi, refracted = glass_sample(wo, alpha, eta_ior, u[k, 0], u[k, 1], u[k, 2])
        side = wo[2] * wi[2]
        if (side < 0.0) if refracted else (side > 0.0):
            total += (1.0 + lam_o) / (1.0 + lam_o + ggx_smith_lambda(abs(wi[2]), alpha))
    return total / u.shape[0]


def main(n=1 << 16):
    rng = np.random.default_rng(1)
    side = int(round(n ** 0.5))
    g = (np.arange(side) + 0.5) / side
    u1, u2 = np.meshgrid(g, g)
    u = np.stack([rng.random(side * side), u1.ravel() + (rng.random(side * side) - 0.5) / side,
                  u2.ravel() + (rng.random(side * side) - 0.5) / side], 1)
    u = np.clip(u, 0.0, np.nextafter(1.0, 0.0))

    def node(i, hi=1.0):
        return min(max(i / 15, 1e-4), hi)

    out = {}
    mus = (np.arange(64) + 0.5) / 64
    for name, inside in (("ggx_glass", False), ("ggx_glass_inv", True)):
        E = np.zeros((16, 16, 16))
        Eavg = np.zeros((16, 16))
        for k in range(16):
            z = node(k, 0.99)
            f0 = z ** 4
            ior = (1 + np.sqrt(f0)) / (1 - np.sqrt(f0))
            if abs(ior - 1.0) < 1e-4:  # Cycles refracts straight (a delta, weight 1) there
                E[k], Eavg[k] = 1.0, 1.0
                continue
            for i in range(16):
                r = node(i)
                for j in range(16):
                    E[k, j, i] = _albedo(r, node(j), ior, inside, u)
                Eavg[k, i] = 2 * np.mean([m * _albedo(r, m, ior, inside, u[::4]) for m in mus])
            print(name, k, E[k, 8, 8], Eavg[k, 8], file=sys.stderr)
        out[f"{name}_E"] = np.clip(E, 0, 1).astype(np.float32)
        out[f"{name}_Eavg"] = np.clip(Eavg, 0, 1).astype(np.float32)
    path = os.path.join(os.path.dirname(__file__), "..", "core", "drt", "materials", "glass_ms_tables.npz")
    np.savez_compressed(path, **out)
    print("wrote", os.path.abspath(path), file=sys.stderr)


if __name__ == "__main__":
    main()
