"""Build every scene: saves <name>.blend and exports <name>.npz into blend_scenes/ (or --out).

    python blend_scenes/make_all.py [--out DIR] [--no-large]

Each scene is built in a fresh Blender state; large_mesh is generated but git-ignored.
"""

import argparse
import importlib
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

SCENES = ["cornell_box", "dof", "motion_blur", "glossy_glass", "all_lights", "showcase", "textured", "procedural",
          "volume_fog", "volume_liquid", "volume_world", "volume_noise", "hdri", "sss_head", "cutout", "coat_sheen",
          "large_mesh"]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--out", default=HERE)
    p.add_argument("--no-large", action="store_true")
    p.add_argument("--only", nargs="*")
    opts, _ = p.parse_known_args(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else None)
    import _common as C
    names = opts.only or [s for s in SCENES if not (opts.no_large and s == "large_mesh")]
    for name in names:
        mod = importlib.import_module(name)
        scene = mod.build()
        C.finish(scene, name, out=opts.out, **mod.FINISH)
    return 0


if __name__ == "__main__":
    sys.exit(main())
