"""A render never wakes OpenBLAS's threads (docs/decisions.md, "No BLAS or LAPACK on a
render's path").

OpenBLAS runs a large product, and LAPACK's ``dgesv`` (``np.linalg.inv``) even on a 4×4
matrix, on its own threads, which then spin for ~0.1 s before they sleep. Inside Blender, whose
numpy keeps every core's BLAS thread, one ``np.linalg.inv`` while setting up a render took
~0.1 s of a core from every F12's render threads (a two-thread F12 of a 0.4 s render was 1.5×
faster than one thread instead of 1.8×). The CLI limits BLAS to one thread; the library and the
add-on cannot, so their code must not call it.

The viewport's scene (``drt.interactive.LiveScene``) builds a context on every view change; it
is checked too. The check runs in a child process with numpy's default BLAS threads: it finds them by a
product that wakes them, waits until they sleep, renders, and reads how long they ran (Linux's
per-thread CPU clocks). Skipped where numpy's BLAS has no threads of its own (one core, a
BLAS limited by the environment, another BLAS library).
"""

import json
import os
import subprocess
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)

PROBE = r"""
import json, os, sys, threading, time
import numpy as np

def cpu_ns():
    # nanoseconds each thread of this process has run
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/schedstat") as f:
                out[tid] = int(f.read().split()[0])
        except (OSError, ValueError, IndexError):
            pass
    return out

def blas_ns(tids):
    now = cpu_ns()
    return sum(now.get(t, 0) for t in tids)

main = str(threading.get_native_id())
before = cpu_ns()
x = np.random.default_rng(0).random((700, 700))
for _ in range(3):
    x @ x  # large enough for OpenBLAS's threads
time.sleep(0.5)  # they spin, then sleep
after = cpu_ns()
blas = [t for t in after if t != main and after[t] - before.get(t, 0) > 1_000_000]
if not blas:
    print(json.dumps({"skip": "numpy's BLAS has no threads of its own here"}))
    sys.exit(0)
idle = blas_ns(blas)
time.sleep(0.2)
if blas_ns(blas) - idle > 1_000_000:
    print(json.dumps({"skip": "numpy's BLAS threads do not sleep"}))
    sys.exit(0)
"""

CHILD = PROBE + r"""
sys.path.insert(0, sys.argv[1])
from drt.render import prepare, render
from drt.scene import scene_from_dict
from drt.scene_file import load_scene
from scene_builders import add_material, add_mesh, base_header, translation, uv_sphere

def big_scene():
    # a deforming moving mesh and an emissive mesh of 80 000 vertices each: large enough for
    # OpenBLAS to thread a product over their rows
    h, a = base_header(24, 24, 1), {}
    h["render"]["shutter"] = [0.0, 1.0]
    grey = add_material(h, "grey", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
    glow = add_material(h, "glow", [], emission=(2.0, 1.5, 1.0))
    pos, tri, nrm = uv_sphere(0.6, rings=200, segments=400)
    add_mesh(h, a, "mover", pos, tri, material=grey, normals=nrm,
             motion={"matrix_open": translation(-0.8, 0, 0), "matrix_close": translation(-0.6, 0, 0.1)},
             positions_close=pos * 1.05)
    add_mesh(h, a, "lamp", pos, tri, material=glow, normals=nrm, matrix=translation(0.8, 0.5, 0.3))
    return scene_from_dict(h, a)

def viewport(scene):
    # the Rendered viewport's scene (drt.interactive): a new context for each of three views
    from dataclasses import replace
    from drt.interactive import LiveScene
    from drt.scene import MeshData
    live = LiveScene(scene.render, scene.materials, [], scene.world_color)
    for k, o in enumerate(scene.objects):
        m = scene.meshes[o.mesh]
        live.set_object(k, m.name, MeshData(m.name, m.positions, m.triangles, m.material_index), o.matrix)
    for x in (0.0, 0.3, 0.6):
        matrix = np.array(scene.camera.matrix, np.float64)
        matrix[0, 3] += x
        s, ctx = live.context(replace(scene.camera, matrix=matrix), 24, 24, spp=1)
        film = render(s, spp=1, threads=2, context=ctx)
    return film

report = {}
for name in sys.argv[2:]:
    scene = big_scene() if name in ("big", "viewport") else load_scene(name)
    start = blas_ns(blas)
    if name == "viewport":
        viewport(scene)
        time.sleep(0.15)
        report[name] = (blas_ns(blas) - start) / 1e6
        continue
    film = render(scene, spp=1, threads=2, context=prepare(scene, threads=2))
    time.sleep(0.15)  # a woken thread would be spinning now
    report[os.path.basename(name)] = (blas_ns(blas) - start) / 1e6
    assert np.isfinite(film.combined).all()
print(json.dumps({"blas_ms": report}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads Linux's per-thread CPU clocks")
def test_a_render_leaves_openblas_threads_asleep():
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "GOTO_NUM_THREADS")}
    scenes = ["big", "viewport", os.path.join(REPO, "blend_scenes", "hdri.npz"),
              os.path.join(REPO, "blend_scenes", "textured.npz")]
    out = subprocess.run([sys.executable, "-c", CHILD, HERE] + scenes, capture_output=True, text=True,
                         env=env, timeout=600)
    _check(out)


def _check(out):
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if "skip" in result:
        pytest.skip(result["skip"])
    # a woken BLAS thread spins ~100 ms; asleep they run nothing
    assert all(ms < 5.0 for ms in result["blas_ms"].values()), result


# Blender's F12 through the add-on: its export too (a texture mapped in another object's space
# inverts that object's matrix)
CHILD_BLENDER = PROBE + r"""
import bpy
sys.path.insert(0, sys.argv[1])
import addon
addon.register()
report = {}
for path in sys.argv[2:]:
    bpy.ops.wm.open_mainfile(filepath=path)
    sc = bpy.context.scene
    sc.render.engine = "DRT"
    sc.render.resolution_percentage = 25
    sc.drt.samples = 1
    sc.render.threads_mode = "FIXED"
    sc.render.threads = 2
    mat = bpy.data.materials.new("mapped")
    mat.use_nodes = True
    nt = mat.node_tree
    checker, coords = nt.nodes.new("ShaderNodeTexChecker"), nt.nodes.new("ShaderNodeTexCoord")
    coords.object = sc.camera
    nt.links.new(coords.outputs["Object"], checker.inputs["Vector"])
    nt.links.new(checker.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    mesh = next(o for o in sc.objects if o.type == "MESH")
    mesh.data.materials.clear()
    mesh.data.materials.append(mat)
    start = blas_ns(blas)
    bpy.ops.render.render()
    time.sleep(0.15)
    report[os.path.basename(path)] = (blas_ns(blas) - start) / 1e6
print(json.dumps({"blas_ms": report}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads Linux's per-thread CPU clocks")
def test_a_blender_f12_leaves_openblas_threads_asleep():
    pytest.importorskip("bpy")
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "GOTO_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", CHILD_BLENDER, REPO,
                          os.path.join(REPO, "blend_scenes", "dof.blend")],
                         capture_output=True, text=True, env=env, timeout=600)
    _check(out)


def test_the_code_in_place_of_lapack_gives_lapacks_answers():
    """`invert_affine`, the mirror test and the normal matrix against ``np.linalg`` on random
    affine matrices (rotations, shears, scales, mirrors); luminance against the BLAS product."""
    import numpy as np

    from drt.geometry import _mirrors, _normal_matrix
    from drt.lights.common import LUMINANCE, luminance
    from drt.motion import invert_affine

    rng = np.random.default_rng(7)
    for _ in range(200):
        m = np.eye(4)
        m[:3, :3] = rng.normal(size=(3, 3)) * rng.choice([1e-3, 1.0, 1e3])
        m[:3, 3] = rng.normal(size=3) * 100.0
        np.testing.assert_allclose(invert_affine(m), np.linalg.inv(m), rtol=1e-9, atol=1e-12 * np.abs(np.linalg.inv(m)).max())
        assert _mirrors(m) == (np.linalg.det(m[:3, :3]) < 0)
        np.testing.assert_allclose(_normal_matrix(m), np.linalg.inv(m[:3, :3]).T, rtol=1e-9,
                                   atol=1e-12 * np.abs(np.linalg.inv(m[:3, :3])).max())
    flat = np.diag([1.0, 0.0, 1.0, 1.0])  # an object scaled to zero along y
    assert invert_affine(flat) is None
    np.testing.assert_array_equal(_normal_matrix(flat), np.eye(3))
    projective = np.eye(4)
    projective[3, 2] = 0.5
    assert invert_affine(projective) is None
    rgb = rng.random((1000, 3)) * 10.0
    np.testing.assert_allclose(luminance(rgb), rgb @ LUMINANCE, rtol=1e-15)
    assert np.isclose(float(luminance([1.0, 1.0, 1.0])), LUMINANCE.sum(), rtol=1e-15)
