"""Render .blend files with DRT and with Cycles and compare the linear images.

    python scripts/compare_cycles.py blend_scenes/cornell_box.blend [...] [--spp 1024]
        [--cycles-spp N] [--scale 100] [--out DIR]

Cycles runs with the reference settings of ../shared/docs/blender-conventions.md (no denoising,
no clamping, blur_glossy 0, no adaptive sampling, filter width 1.5, fixed threads, 32-bit EXR);
both renders use the file's resolution (× --scale %). Prints per scene: the DRT/Cycles mean ratio
per channel (target within 1 %) and the fraction of 16×16 blocks whose mean is within 3 % (target
≥ 95 %; blocks darker than 1 % of the image mean compare absolutely against that floor).
"""

import argparse
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
sys.path.insert(0, os.path.join(REPO, "blend_scenes"))


def render(scene, engine, spp, path):
    import bpy
    scene.render.engine = engine
    if engine == "CYCLES":
        import _common
        _common.reference_settings(scene, samples=spp)
        scene.cycles.device = "CPU"
    else:
        scene.drt.samples = spp
    fmt = scene.render.image_settings
    if hasattr(fmt, "media_type"):
        fmt.media_type = "IMAGE"
    fmt.file_format, fmt.color_depth = "OPEN_EXR", "32"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    import OpenEXR
    with OpenEXR.File(path) as f:
        return np.array(f.parts[0].channels["RGBA"].pixels)[..., :3].astype(np.float64)


def compare(drt_img, cyc_img, block=16, tol=0.03):
    ratio = drt_img.mean((0, 1)) / np.maximum(cyc_img.mean((0, 1)), 1e-12)
    h, w = (s // block * block for s in cyc_img.shape[:2])

    def blocks(img):
        return img[:h, :w].reshape(h // block, block, w // block, block, 3).mean((1, 3))

    a, b = blocks(drt_img), blocks(cyc_img)
    floor = 0.01 * cyc_img.mean()
    ok = np.abs(a - b) <= tol * np.maximum(b, floor)
    return ratio, float(ok.all(axis=-1).mean())


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("blends", nargs="+")
    p.add_argument("--spp", type=int, default=1024)
    p.add_argument("--cycles-spp", type=int)
    p.add_argument("--scale", type=int, default=100)
    p.add_argument("--out", default=os.path.join(REPO, "out", "compare"))
    opts = p.parse_args(argv)
    import bpy
    import addon
    addon.register()
    os.makedirs(opts.out, exist_ok=True)
    worst = 0
    for blend in opts.blends:
        name = os.path.splitext(os.path.basename(blend))[0]
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(blend))
        scene = bpy.context.scene
        scene.render.resolution_percentage = opts.scale
        cyc = render(scene, "CYCLES", opts.cycles_spp or opts.spp,
                     os.path.join(opts.out, f"{name}_cycles.exr"))
        drt = render(scene, "DRT", opts.spp, os.path.join(opts.out, f"{name}_drt.exr"))
        ratio, frac = compare(drt, cyc)
        good = bool(np.all(np.abs(ratio - 1) <= 0.01) and frac >= 0.95)
        worst |= not good
        print(f"{name}: mean ratio R {ratio[0]:.4f} G {ratio[1]:.4f} B {ratio[2]:.4f}; "
              f"blocks within 3%: {100 * frac:.1f}% -> {'OK' if good else 'DIFFERS'}", flush=True)
    return int(worst)


if __name__ == "__main__":
    sys.exit(main())
