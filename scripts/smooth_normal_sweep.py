"""DRT vs Cycles on low-poly smooth meshes under a sun from many directions (issue 11, the
back-lit / grazing gap of docs/lights.md): an unsubdivided Suzanne and a 16×8 torus, white
Diffuse, Glossy (GGX 0.3) and a Principled BSDF, direct light only (no world, no bounces).

    python scripts/smooth_normal_sweep.py OUTDIR [--label NAME] [--spp N] [--res N]

Prints DRT/Cycles image-mean ratios per view and writes, per view, the Cycles render
(cached as OUTDIR/cyc_*.npy, reused on later runs) and a PNG of DRT − Cycles
(red: DRT darker, green: DRT brighter) next to both images.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for p in (REPO, os.path.join(REPO, "blend_scenes"), os.path.join(REPO, "scripts"), os.path.join(REPO, "tests")):
    if p not in sys.path:
        sys.path.insert(0, p)

SUNS = {  # sun rotation (x, z) degrees; the camera looks along +y from −y
    "front-side": (60.0, -50.0),
    "top": (0.0, 0.0),
    "side-graze": (90.0, 90.0),
    "back-high": (-45.0, 0.0),
    "back": (-70.0, 20.0),
    "back-graze": (-95.0, 30.0),
    "back-low": (-130.0, 0.0),
}


def build(shape, material, sun):
    import bpy
    import _common as C
    from test_addon import ensure_registered
    import test_terminator as T

    T.SUN = sun
    scene = T.sphere_scene(0.1, shape=shape)
    ball = bpy.data.objects["Ball"]
    if material != "diffuse":
        if material == "glossy":
            mat = C.glossy("G", (0.8, 0.8, 0.8), 0.3)
        else:
            mat, nodes, out = C._new_material("P")
            n = nodes.new("ShaderNodeBsdfPrincipled")
            n.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
            n.inputs["Roughness"].default_value = 0.4
            mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
        ball.data.materials.clear()
        ball.data.materials.append(mat)
    ensure_registered()
    return scene


def cycles(scene, spp, path):
    import _common as C
    from compare_cycles import render as bpy_render

    orig = C.reference_settings

    def direct_only(sc, samples=1024):
        orig(sc, samples)
        sc.cycles.max_bounces = sc.cycles.diffuse_bounces = sc.cycles.glossy_bounces = 0

    C.reference_settings = direct_only
    try:
        return bpy_render(scene, "CYCLES", spp, path)
    finally:
        C.reference_settings = orig


def png(path, drt, cyc):
    from PIL import Image

    def tone(x):
        return (np.clip(x, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)

    d = (drt - cyc).mean(-1)
    s = max(np.abs(d).max(), 1e-6)
    diff = np.zeros(d.shape + (3,), np.uint8)
    diff[..., 0] = (np.clip(-d / s, 0, 1) * 255).astype(np.uint8)
    diff[..., 1] = (np.clip(d / s, 0, 1) * 255).astype(np.uint8)
    img = np.concatenate([tone(drt), tone(cyc), diff], axis=1)
    Image.fromarray(img).resize((img.shape[1] * 3, img.shape[0] * 3), Image.NEAREST).save(path)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--label", default="drt")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--shapes", default="SUZANNE,TORUS")
    ap.add_argument("--materials", default="diffuse,glossy,principled")
    ap.add_argument("--suns", default=",".join(SUNS))
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    import test_terminator as T
    T.RES = a.res
    for shape in a.shapes.split(","):
        for material in a.materials.split(","):
            for sun_name in a.suns.split(","):
                key = f"{shape.lower()}_{material}_{sun_name}"
                cpath = os.path.join(a.out, f"cyc_{key}_{a.res}_{a.spp}.npy")
                if os.path.exists(cpath):
                    cyc = np.load(cpath)
                else:
                    cyc = cycles(build(shape, material, SUNS[sun_name]), a.spp, os.path.join(a.out, "c.exr"))
                    np.save(cpath, cyc)
                build(shape, material, SUNS[sun_name])
                drt, _ = T.drt_render(a.spp)
                np.save(os.path.join(a.out, f"{a.label}_{key}.npy"), drt)
                png(os.path.join(a.out, f"{a.label}_{key}.png"), drt, cyc)
                print(f"{key:36s} drt/cycles {drt.mean() / max(cyc.mean(), 1e-12):.4f}  "
                      f"(cycles mean {cyc.mean():.4f})", flush=True)


if __name__ == "__main__":
    main()
