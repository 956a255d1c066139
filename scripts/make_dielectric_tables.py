"""Generate core/drt/materials/dielectric_specular_tables.npz: the GGX albedo tables the
Principled BSDF's dielectric specular layer needs (docs/materials.md, "Dielectric specular").

Definitions (Cycles 5.0's, app/cycles_precompute.cpp; our own Monte Carlo, numpy):
  E(r, mu)      32×32: directional albedo of a white single-scatter GGX reflection lobe,
                alpha = r², cos θo = mu; E[G2/G1] over visible normals (0 below the horizon).
  E_avg(r)      32: 2 ∫ mu E(r, mu) dmu.
  s(r, mu, z)   16×16×16: mean over visible normals of the remap
                saturate((F(h·wo, eta) − F0(eta)) / (1 − F0(eta))) where the reflected direction
                stays above the horizon (0 otherwise), eta = ior_from_F0(z⁴).
Grid nodes: r = clamp(i/(n−1), 1e-4, 1), mu = clamp(j/(n−1), 1e-4, 1), z = clamp(k/(n−1), 1e-4,
0.99); tables are read with (tri)linear interpolation. Run: python scripts/make_dielectric_tables.py
"""
import os
import sys

import numpy as np


def vndf(wo, alpha, u0, u1):
    """Heitz 2018 visible normals, wo (3,) upper hemisphere, u arrays → h (n, 3)."""
    v = np.array([wo[0] * alpha, wo[1] * alpha, wo[2]])
    v /= np.linalg.norm(v)
    lensq = v[0] ** 2 + v[1] ** 2
    t1 = np.array([-v[1], v[0], 0.0]) / np.sqrt(lensq) if lensq > 1e-14 else np.array([1.0, 0, 0])
    t2 = np.cross(v, t1)
    r = np.sqrt(u0)
    phi = 2 * np.pi * u1
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = 0.5 * (1 + v[2])
    p2 = (1 - s) * np.sqrt(np.maximum(0, 1 - p1 * p1)) + s * p2
    p3 = np.sqrt(np.maximum(0, 1 - p1 * p1 - p2 * p2))
    h = p1[:, None] * t1 + p2[:, None] * t2 + p3[:, None] * v
    h = h * np.array([alpha, alpha, 1.0])
    h[:, 2] = np.maximum(h[:, 2], 0)
    return h / np.linalg.norm(h, axis=1, keepdims=True)


def lam(c, alpha):
    c2 = np.maximum(c * c, 1e-300)
    return 0.5 * (np.sqrt(1 + alpha * alpha * np.maximum(1 / c2 - 1, 0)) - 1)


def fresnel(c, eta):
    c = np.abs(c)
    g2 = eta * eta - 1 + c * c
    g = np.sqrt(np.maximum(g2, 0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1) / (c * (g - c) + 1)
    return np.where(g2 > 0, 0.5 * a * a * (1 + b * b), 1.0)


def ior_from_f0(f0):
    s = np.sqrt(np.clip(f0, 0, 0.99))
    return (1 + s) / (1 - s)


def main(n_side=96):
    g = (np.arange(n_side) + 0.5) / n_side
    rng = np.random.default_rng(1)
    u0, u1 = np.meshgrid(g, g)
    u0 = (u0.ravel() + (rng.random(u0.size) - 0.5) / n_side)
    u1 = (u1.ravel() + (rng.random(u1.size) - 0.5) / n_side)

    def cell(r, mu, etas):
        alpha = max(r * r, 1e-7)
        wo = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
        h = vndf(wo, alpha, u0, u1)
        c = h @ wo
        wi = 2 * c[:, None] * h - wo
        up = wi[:, 2] > 0
        w = np.where(up, (1 + lam(mu, alpha)) / (1 + lam(mu, alpha) + lam(wi[:, 2], alpha)), 0.0)
        s = []
        for eta in etas:
            f0 = ((eta - 1) / (eta + 1)) ** 2
            sh = np.clip((fresnel(c, eta) - f0) / (1 - f0), 0, 1)
            s.append(np.where(up, sh, 0.0).mean())
        return w.mean(), s

    def node(i, n, hi=1.0):
        return min(max(i / (n - 1), 1e-4), hi)

    E = np.zeros((32, 32))
    for j in range(32):
        for i in range(32):
            E[j, i] = cell(node(i, 32), node(j, 32), [])[0]
    # E_avg by integrating the fine mu grid: 2 ∫ mu E dmu (midpoint rule on 64 points)
    mus = (np.arange(64) + 0.5) / 64
    Eavg = np.array([2 * np.mean([m * cell(node(i, 32), m, [])[0] for m in mus]) for i in range(32)])
    etas = [ior_from_f0(node(k, 16, 0.99) ** 4) for k in range(16)]
    S = np.zeros((16, 16, 16))
    for j in range(16):
        for i in range(16):
            S[:, j, i] = cell(node(i, 16), node(j, 16), etas)[1]
    out = os.path.join(os.path.dirname(__file__), "..", "core", "drt", "materials",
                       "dielectric_specular_tables.npz")
    np.savez_compressed(out, ggx_E=np.clip(E, 0, 1).astype(np.float32),
                        ggx_Eavg=np.clip(Eavg, 0, 1).astype(np.float32),
                        gen_schlick_ior_s=np.clip(S, 0, 1).astype(np.float32))
    print("wrote", os.path.abspath(out), E[0, 0], E[31, 31], Eavg[31], S[8, 8, 8], file=sys.stderr)


if __name__ == "__main__":
    main()
