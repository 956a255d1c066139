"""The Rendered viewport: incremental updates, restarts, stopping, and view → camera.

Core parts (``drt.interactive``) are tested with numpy scenes; the add-on side
(``addon/viewport.py``) with the bpy module, edits made with bpy and handed to the sync by a
``depsgraph_update_post`` handler, which receives the same ``depsgraph.updates`` as
``RenderEngine.view_update``. Drawing (``gpu``) needs a display and is not tested here.
"""

import os
import sys
import threading
import types

import numpy as np
import pytest

from drt.interactive import (INSTANCE_MIN_TRIANGLES, LiveScene, ProgressiveSession,
                             camera_from_projection, coarse_dividers, projection_plane)
from drt.render import render
from drt.scene import CameraSpec, MeshData, RenderSettings

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DIFFUSE = {"name": "grey", "lobes": [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}],
           "emission": [0, 0, 0]}
DARK = {"name": "dark", "lobes": [{"type": "DIFFUSE", "color": [0.05, 0.05, 0.05]}],
        "emission": [0, 0, 0]}
SUN = {"name": "sun", "type": "SUN", "matrix_world": np.eye(4).tolist(), "strength": 3.0,
       "angle": 0.1, "color": [1, 1, 1]}


def grid_mesh(n: int, size: float = 1.0) -> MeshData:
    """A flat n×n-cell square in the local XY plane, facing +Z: 2n² triangles."""
    u = np.linspace(-size / 2, size / 2, n + 1)
    x, y = np.meshgrid(u, u)
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n + 2, i.ravel() + n + 1
    tri = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    return MeshData("grid", pos, tri, np.zeros(len(tri), np.int64))


def translate(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def top_camera(height=3.0) -> CameraSpec:
    """Looking straight down (−Z) from above the origin."""
    return CameraSpec(type="PERSP", matrix=translate(0, 0, height), lens=50.0)


def live_scene() -> LiveScene:
    live = LiveScene(RenderSettings(width=32, height=32, spp=4), [DIFFUSE], [SUN], (0.1, 0.1, 0.1))
    live.set_object("floor", "floor", grid_mesh(4, 4.0), translate(z=-1.0))
    return live


def render_live(live, camera, w=32, h=32, spp=2):
    scene, ctx = live.context(camera, w, h, spp=spp)
    return render(scene, spp=spp, context=ctx, threads=1).combined


# ---------------------------------------------------------------------------- LiveScene


def test_large_object_moves_by_its_matrix_only():
    big = grid_mesh(int(np.ceil(np.sqrt(INSTANCE_MIN_TRIANGLES / 2))), 1.0)
    assert len(big.triangles) >= INSTANCE_MIN_TRIANGLES
    live = live_scene()
    big.material_index[:] = 1  # dark, over the light floor
    live.set_materials([DIFFUSE, DARK])
    live.set_object("big", "big", big, translate(0.5, 0, 0))
    cam = top_camera()
    render_live(live, cam)
    assert live.objects["big"].instance and live.instance_count == 1
    before = live.counters.static_builds, live.counters.instance_builds, live.counters.static_triangles
    live.set_matrix("big", translate(-0.5, 0.2, 0))
    moved = render_live(live, cam)
    c = live.counters
    assert (c.static_builds, c.instance_builds, c.static_triangles) == before
    assert c.matrix_updates == 1
    # the same picture as a scene built from scratch with the object already there
    fresh = live_scene()
    fresh.set_materials([DIFFUSE, DARK])
    fresh.set_object("big", "big", big, translate(-0.5, 0.2, 0))
    np.testing.assert_allclose(moved, render_live(fresh, cam), rtol=1e-5, atol=1e-6)
    # and the dark square is where it was moved: the left of the image, not the right
    lum = moved[..., :3].mean(axis=2)
    assert lum[7:19, 3:14].mean() < 0.3 * lum[7:19, 19:].mean()  # x ∈ [−1, 0], y ∈ [−0.3, 0.7]


def test_objects_apart_from_the_static_set_are_one_scene_of_instances():
    """Two large objects are kept apart from the static set (moving one costs a matrix): the
    viewport's tracer queries them and the floor as one Embree scene of instances, with the
    picture the per-object path gives, also after one of them moved."""
    from drt import embree_direct

    if not embree_direct.intersect1_address():
        pytest.skip("Embree's C handles not confirmed here")
    big = grid_mesh(int(np.ceil(np.sqrt(INSTANCE_MIN_TRIANGLES / 2))), 1.0)
    big.material_index[:] = 1
    live = live_scene()
    live.set_materials([DIFFUSE, DARK])
    live.set_object("a", "a", big, translate(0.6, 0, 0))
    live.set_object("b", "b", big, translate(-0.6, 0.3, -0.5))
    cam = top_camera()
    for step in range(2):
        if step:
            live.set_matrix("a", translate(0.4, -0.5, 0.2))
        scene, ctx = live.context(cam, 32, 32, spp=4)
        assert live.instance_count == 2 and ctx.tracer.instanced is not None
        instanced = render(scene, spp=4, context=ctx, threads=1).combined
        ctx.tracer.instanced = None
        per_object = render(scene, spp=4, context=ctx, threads=1).combined
        np.testing.assert_allclose(instanced, per_object, rtol=1e-4, atol=1e-5)


def test_more_large_objects_stay_apart_when_they_share_a_scene_of_instances(monkeypatch):
    """Objects kept apart cost a pass over the rays each on the per-object path, so at most
    MAX_INSTANCES are; as one scene of instances they cost one query, and up to
    MAX_SHARED_INSTANCES are (an edit of one then moves a matrix instead of rebuilding the
    static set)."""
    import drt.interactive as interactive
    from drt import embree_direct

    if not embree_direct.intersect1_address():
        pytest.skip("Embree's C handles not confirmed here")
    monkeypatch.setattr(interactive, "MAX_INSTANCES", 2)
    monkeypatch.setattr(interactive, "MAX_SHARED_INSTANCES", 4)
    monkeypatch.setattr(interactive, "INSTANCE_MIN_TRIANGLES", 8)
    live = live_scene()
    for k in range(6):
        live.set_object(f"o{k}", f"o{k}", grid_mesh(2, 0.3), translate(-1 + 0.4 * k, 0, 0))
    scene, ctx = live.context(top_camera(), 16, 16, spp=1)
    assert live.instance_count == 4 and ctx.tracer.instanced is not None
    monkeypatch.setattr(embree_direct, "intersect1_address", lambda: 0)
    fewer = live_scene()
    for k in range(6):
        fewer.set_object(f"o{k}", f"o{k}", grid_mesh(2, 0.3), translate(-1 + 0.4 * k, 0, 0))
    fewer.context(top_camera(), 16, 16, spp=1)
    assert fewer.instance_count == 2


def test_small_object_rebuilds_only_the_static_set():
    live = live_scene()
    live.set_object("box", "box", grid_mesh(2, 0.5), translate(0, 0, 0))
    cam = top_camera()
    render_live(live, cam)
    c0 = live.counters.static_builds, live.counters.material_builds
    live.set_matrix("box", translate(0.3, 0, 0))
    render_live(live, cam)
    assert live.counters.static_builds == c0[0] + 1
    assert live.counters.material_builds == c0[1]  # materials untouched
    assert not live.objects["box"].instance


def test_moved_object_is_promoted_when_the_static_set_is_large():
    live = live_scene()
    n = int(np.ceil(np.sqrt(INSTANCE_MIN_TRIANGLES / 2)))
    live.set_object("a", "a", grid_mesh(n // 2 + 1, 1.0), translate(-2, 0, 0))
    live.set_object("b", "b", grid_mesh(n // 2 + 1, 1.0), translate(2, 0, 0))
    live.set_object("c", "c", grid_mesh(n // 2 + 1, 1.0), translate(0, 2, 0))
    live.set_object("d", "d", grid_mesh(n // 2 + 1, 1.0), translate(0, -2, 0))
    live.set_object("small", "small", grid_mesh(2, 0.3), translate(0, 0, 0))
    render_live(live, top_camera())
    assert live.instance_count == 0
    live.set_matrix("small", translate(0.1, 0, 0))  # first move: promoted (one static rebuild)
    render_live(live, top_camera())
    builds = live.counters.static_builds
    assert live.objects["small"].instance
    live.set_matrix("small", translate(0.2, 0, 0))  # later moves: a matrix each
    render_live(live, top_camera())
    assert live.counters.static_builds == builds


def test_material_edit_rebuilds_no_geometry():
    live = live_scene()
    cam = top_camera()
    a = render_live(live, cam)
    builds = live.counters.static_builds
    red = dict(DIFFUSE, lobes=[{"type": "DIFFUSE", "color": [0.8, 0.1, 0.1]}])
    live.set_materials([red])
    b = render_live(live, cam)
    assert live.counters.static_builds == builds
    assert live.counters.material_builds == 2
    assert b[..., 1].mean() < 0.5 * a[..., 1].mean()  # green dropped from 0.8 to 0.1


def test_sheared_object_stays_static():
    big = grid_mesh(int(np.ceil(np.sqrt(INSTANCE_MIN_TRIANGLES / 2))), 1.0)
    shear = np.eye(4)
    shear[0, 1] = 0.5  # x += 0.5·y: not translation · rotation · scale
    live = live_scene()
    live.set_object("big", "big", big, shear)
    assert not live.objects["big"].instance
    live.set_object("big2", "big2", big, translate(1, 0, 0))
    assert live.objects["big2"].instance
    live.set_matrix("big2", shear @ translate(1, 0, 0))
    render_live(live, top_camera())
    assert not live.objects["big2"].instance and live.instance_count == 0


def test_emissive_object_stays_static():
    big = grid_mesh(int(np.ceil(np.sqrt(INSTANCE_MIN_TRIANGLES / 2))), 1.0)
    big.material_index[:] = 1
    live = live_scene()
    live.set_materials([DIFFUSE, dict(DIFFUSE, emission=[5.0, 5.0, 5.0])])
    live.set_object("lamp", "lamp", big, translate(0, 0, 0))
    assert not live.objects["lamp"].instance  # only static triangles are sampled as lights


def test_coarse_dividers():
    assert coarse_dividers(640, 360) == [8, 4, 2, 1]
    assert coarse_dividers(64, 36) == [1]
    assert coarse_dividers(1920, 1080)[0] == 16


# ---------------------------------------------------------------------------- session


def test_session_accumulates_to_the_same_image_as_one_render():
    live = live_scene()
    s = ProgressiveSession(live, threads=2, coarse_pixels=64)
    try:
        s.set_view(top_camera(), 32, 32, spp=6)
        f = s.wait(lambda f: f.divider == 1 and f.samples == 6, 60)
        assert f is not None and s.converged, s.error
        scene, ctx = live.context(top_camera(), 32, 32, spp=6)
        ref = render(scene, spp=6, context=ctx, threads=1).combined[::-1]
        np.testing.assert_allclose(f.rgba, ref, rtol=1e-6, atol=1e-7)
    finally:
        assert s.stop()


class FrameLog:
    """Every frame a session publishes, as (generation, samples, divider)."""

    def __init__(self):
        self.session = None
        self.frames = []

    def __call__(self):
        f = self.session.latest()
        self.frames.append((f.generation, f.samples, f.divider))

    def of(self, gen):
        return [f[1:] for f in self.frames if f[0] == gen]


def test_edit_restarts_accumulation():
    live = live_scene()
    log = FrameLog()
    s = log.session = ProgressiveSession(live, threads=1, coarse_pixels=256, on_frame=log)
    try:
        s.set_view(top_camera(), 32, 32, spp=64)
        f = s.wait(lambda f: f.divider == 1 and f.samples >= 2, 60)
        assert f is not None, s.error
        gen = s.generation
        s.edit(lambda lv: lv.set_world((0.5, 0.5, 0.5)))
        assert s.generation == gen + 1
        assert s.wait(lambda f: f.divider == 1 and f.samples >= 3, 30) is not None
        # a coarse sample at half resolution, then full resolution from sample 1 again
        assert log.of(gen + 1)[:3] == [(1, 2), (1, 1), (3, 1)]
        assert s.set_view(top_camera(), 32, 32, spp=64) is False  # same view: no restart
        assert s.set_view(top_camera(2.5), 32, 32, spp=64) is True
        assert s.generation == gen + 2
    finally:
        assert s.stop()


def test_gate_holds_rendering_until_open():
    live = live_scene()
    s = ProgressiveSession(live, threads=1, coarse_pixels=256)
    is_open = threading.Event()
    s.gate = is_open.is_set
    try:
        s.set_view(top_camera(), 16, 16, spp=1)
        assert s.wait(lambda f: True, 0.5) is None  # held: no frame
        is_open.set()
        assert s.wait(lambda f: True, 30) is not None
    finally:
        assert s.stop()


def test_stop_ends_every_thread():
    before = {t.ident for t in threading.enumerate()}
    live = live_scene()
    s = ProgressiveSession(live, threads=2, coarse_pixels=256)
    s.set_view(top_camera(), 48, 48, spp=1 << 12)
    assert s.wait(lambda f: f.divider == 1, 60) is not None, s.error
    assert s.stop(timeout=5.0) and not s.alive
    left = [t.name for t in threading.enumerate() if t.ident not in before]
    assert left == []


def test_session_reports_a_bad_edit_and_renders_the_rest():
    live = live_scene()
    s = ProgressiveSession(live, threads=1, coarse_pixels=256)
    try:
        s.set_view(top_camera(), 16, 16, spp=1)
        s.edit(lambda lv: lv.set_object("bad", "bad", grid_mesh(1), np.full((4, 4), np.nan)))
        s.edit(lambda lv: lv.set_world((0.2, 0.2, 0.2)))
        assert s.wait(lambda f: True, 30) is not None
        assert "NaN" in s.error and "bad" not in live.objects
        np.testing.assert_array_equal(live.world_color, [0.2, 0.2, 0.2])
        s.edit(lambda lv: lv.set_matrix("floor", np.diag([1e300, 1.0, 1.0, 1.0])))
        assert s.wait(lambda f: True, 30) is not None and "±1e+15" in s.error
        s.edit(lambda lv: lv.set_world((0.3, 0.3, 0.3)))
        assert s.wait(lambda f: True, 30) is not None and s.error is None
    finally:
        assert s.stop()


# ---------------------------------------------------------------------------- view → camera

# Projections Blender 3.4.1 drew in a 1057×667 3D view (captured with xvfb; lens 50 mm,
# clip 0.01–1000, view distance 6): Blender's viewport uses a 36 mm sensor and a zoom of 2,
# so the view plane at distance 1 is 2·36/50 = 1.44 wide, and the orthographic view is
# 2·6·36/50 = 8.64 wide; the ortho clip range is ±clip_end/2.
PERSP_1057x667 = [[1.38888884, 0, 0, 0], [0, 2.20098281, 0, 0],
                  [0, 0, -1.00002003, -0.0200002], [0, 0, -1, 0]]
ORTHO_1057x667 = [[0.23148148, 0, 0, 0], [0, 0.36683047, 0, 0], [0, 0, -0.002, 0], [0, 0, 0, 1]]


def test_free_perspective_view_camera():
    spec = camera_from_projection(np.eye(4), PERSP_1057x667, lens=50.0, clip_start=0.01,
                                  clip_end=1000.0)
    w, h, cx, cy = projection_plane(spec, 1057, 667)
    assert w == pytest.approx(1.44, rel=1e-6)
    assert h == pytest.approx(1.44 * 667 / 1057, rel=1e-6)
    assert (cx, cy) == (0.0, 0.0) and spec.type == "PERSP" and not spec.dof_use


def test_orthographic_view_camera():
    spec = camera_from_projection(np.eye(4), ORTHO_1057x667, lens=50.0, clip_start=-500.0,
                                  clip_end=500.0)
    w, h, _, _ = projection_plane(spec, 1057, 667)
    assert spec.type == "ORTHO"
    assert w == pytest.approx(8.64, rel=1e-6) and spec.ortho_scale == pytest.approx(8.64, rel=1e-6)


def test_off_centre_projection_gives_shift():
    # a frustum from x ∈ [−0.2, 0.6], y ∈ [−0.3, 0.1] at distance 1 (camera-view pan / lens shift)
    l, r, b, t, n, f = -0.2, 0.6, -0.3, 0.1, 1.0, 100.0
    p = [[2 * n / (r - l), 0, (r + l) / (r - l), 0], [0, 2 * n / (t - b), (t + b) / (t - b), 0],
         [0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)], [0, 0, -1, 0]]
    spec = camera_from_projection(np.eye(4), p, lens=35.0, clip_start=n, clip_end=f)
    w, h, cx, cy = projection_plane(spec, 200, 100)
    assert (w, h) == pytest.approx((0.8, 0.4))
    assert (cx, cy) == pytest.approx((0.2, -0.1))


# ---------------------------------------------------------------------------- Blender side

try:
    import bpy
except ImportError:  # the core tests above still run
    bpy = None


def blender_only(fn):
    """Marks a test that needs the bpy module."""
    return pytest.mark.blender(pytest.mark.skipif(bpy is None, reason="needs the bpy module")(fn))


@pytest.fixture
def blender_viewport():
    """cornell_box open, a ViewportSync fed by the depsgraph handler, a 64×36 camera view."""
    if REPO not in sys.path:
        sys.path.insert(0, REPO)
    import addon
    from addon import viewport
    if not hasattr(bpy.types.Scene, "drt"):
        addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(REPO, "blend_scenes", "cornell_box.blend"))
    vp = viewport.ViewportSync(threads=2)

    def handler(scene, depsgraph):
        vp.sync(depsgraph)

    dg = bpy.context.evaluated_depsgraph_get()
    vp.sync(dg)
    bpy.app.handlers.depsgraph_update_post.append(handler)
    vp.set_view(camera_view_spec(viewport, dg, 64, 36), 64, 36, 64)
    assert vp.session.wait(lambda f: f.divider == 1, 120) is not None, vp.session.error
    try:
        yield vp
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
        assert vp.stop()


def camera_view_spec(viewport, depsgraph, w, h, cam=None):
    cam = cam or bpy.context.scene.camera
    proj = np.array(cam.calc_matrix_camera(depsgraph, x=w, y=h), dtype=np.float64)
    d = viewport.camera_dict(cam, cam.matrix_world.copy())
    return camera_from_projection(np.array(d["matrix_world"]), proj, lens=d["lens"],
                                  clip_start=d["clip_start"], clip_end=d["clip_end"], dof=d["dof"])


def evaluate():
    bpy.context.evaluated_depsgraph_get()  # runs the handler with depsgraph.updates


@blender_only
def test_blender_transform_edit_sends_a_matrix_only(blender_viewport):
    vp = blender_viewport
    exports = dict(vp.exports)
    gen = vp.session.generation
    ob = bpy.data.objects["TallBox"]
    ob.location.x += 0.1
    evaluate()
    assert vp.exports == exports  # no mesh, material, light or world export
    assert vp.session.generation > gen
    f = vp.session.wait(lambda f: True, 30)
    assert f is not None and f.generation == vp.session.generation
    key = next(k for k in vp.session.live.objects if k[0] == "TallBox")
    np.testing.assert_allclose(vp.session.live.objects[key].matrix[:3, 3],
                               np.array(ob.matrix_world.translation), atol=1e-6)


@blender_only
def test_blender_material_edit_reexports_only_that_material(blender_viewport):
    vp = blender_viewport
    assert vp.kernel_variant() == ""  # plain materials, no world program or volume
    exports = dict(vp.exports)
    live = vp.session.live
    builds = live.counters.static_builds
    mat = bpy.data.materials["Green"]
    node = next(n for n in mat.node_tree.nodes if "Base Color" in n.inputs or "Color" in n.inputs)
    (node.inputs.get("Base Color") or node.inputs.get("Color")).default_value = (0.9, 0.1, 0.1, 1)
    evaluate()
    assert vp.session.wait(lambda f: True, 30) is not None, vp.session.error
    assert vp.exports == dict(exports, materials=exports["materials"] + 1)
    assert live.counters.static_builds == builds
    green = next(m for m in live.materials if m["name"] == "Green")
    assert green["lobes"][0]["color"][0] > green["lobes"][0]["color"][1]


@blender_only
def test_blender_5_1_material_edit_flags_do_not_reexport_meshes(blender_viewport):
    """Blender 5.1+ flags the geometry of every object using an edited material, and lists its
    mesh with the mesh's own geometry flag off: DRT converts the material again and leaves the
    mesh (and its hierarchy) alone. The same batch with the mesh itself flagged (a real edit in
    the same update) does export it again. The batch is 5.3's, replayed on the real data-blocks."""
    vp = blender_viewport
    live = vp.session.live
    dg = bpy.context.evaluated_depsgraph_get()

    class Batch:
        def __init__(self, updates):
            self.updates = updates

        def __getattr__(self, name):  # scene, object_instances: the real depsgraph's
            return getattr(dg, name)

    def update(idt, geometry, shading=True):
        return types.SimpleNamespace(id=idt, is_updated_geometry=geometry, is_updated_transform=False,
                                     is_updated_shading=shading)

    room, mat = bpy.data.objects["Room"], bpy.data.materials["Green"]
    assert not room.modifiers and mat.name in [s.material.name for s in room.material_slots]

    def batch(mesh_flag):
        return Batch([update(room, True), update(room.data, mesh_flag), update(mat, False),
                      update(mat.node_tree, False, shading=False)])

    exports, builds = dict(vp.exports), live.counters.static_builds
    vp.sync(batch(mesh_flag=False))
    assert vp.exports == dict(exports, materials=exports["materials"] + 1)
    assert live.counters.static_builds == builds
    vp.sync(batch(mesh_flag=True))
    assert vp.exports["meshes"] == exports["meshes"] + 1


@blender_only
def test_blender_ray_visibility_edit_reaches_the_viewport(blender_viewport):
    """Object > Visibility > Camera off: the live object's visibility changes, without a mesh
    export or a hierarchy rebuild, and the next frame no longer shows the box; Mask > Holdout
    on: the same, and the box cuts the frame's alpha."""
    from drt.scene import VIS_ALL, VIS_CAMERA, VIS_HOLDOUT

    vp = blender_viewport
    live = vp.session.live
    exports, builds = dict(vp.exports), live.counters.static_builds
    before = vp.session.wait(lambda f: f.divider == 1, 60)
    ob = bpy.data.objects["TallBox"]
    ob.visible_camera = False
    evaluate()
    gen = vp.session.generation
    after = vp.session.wait(lambda f: f.generation == gen and f.divider == 1, 60)
    assert after is not None, vp.session.error
    key = next(k for k in live.objects if k[0] == "TallBox")
    assert live.objects[key].visibility == VIS_ALL & ~VIS_CAMERA
    assert vp.exports["meshes"] == exports["meshes"] and live.counters.static_builds == builds
    assert np.abs(after.rgba - before.rgba).max() > 0.05  # the box is gone from the picture
    ob.visible_camera = True
    evaluate()
    assert live.objects[key].visibility == VIS_ALL or vp.session.wait(
        lambda f: live.objects[key].visibility == VIS_ALL, 30) is not None
    # Mask > Holdout: the same edit path; the box becomes a hole in the frame's alpha
    ob.is_holdout = True
    evaluate()
    held = vp.session.wait(lambda f: live.objects[key].visibility == VIS_ALL | VIS_HOLDOUT
                           and f.divider == 1, 60)
    assert held is not None, vp.session.error
    assert held.rgba[..., 3].min() < 0.05 < before.rgba[..., 3].min()
    assert vp.exports["meshes"] == exports["meshes"] and live.counters.static_builds == builds
    ob.is_holdout = False
    evaluate()


@blender_only
def test_blender_geometry_edit_reexports_that_object(blender_viewport):
    vp = blender_viewport
    exports = dict(vp.exports)
    ob = bpy.data.objects["ShortBox"]
    ob.data.vertices[0].co.z += 0.05
    ob.data.update()
    evaluate()
    assert vp.session.wait(lambda f: True, 30) is not None, vp.session.error
    assert vp.exports == dict(exports, meshes=exports["meshes"] + 1)


@blender_only
def test_blender_light_edit_resends_lights_only(blender_viewport):
    vp = blender_viewport
    exports = dict(vp.exports)
    light = next(o for o in bpy.data.objects if o.type == "LIGHT")
    light.data.energy *= 2
    evaluate()
    assert vp.session.wait(lambda f: True, 30) is not None, vp.session.error
    assert vp.exports == dict(exports, lights=exports["lights"] + 1)
    assert vp.session.live.lights[0]["power"] == pytest.approx(light.data.energy)


@blender_only
def test_blender_hdri_world_reaches_the_viewport(blender_viewport, tmp_path):
    """An Environment Texture world is sent with its program and image; the session renders
    it (the program runs in the viewport like in the final render)."""
    vp = blender_viewport
    exports = dict(vp.exports)
    img = bpy.data.images.new("sky", 8, 4, alpha=False, float_buffer=True)
    img.pixels.foreach_set(np.tile([2.0, 1.0, 0.5, 1.0], 32).astype(np.float32))
    nt = bpy.context.scene.world.node_tree
    bg = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBackground")
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    evaluate()
    f = vp.session.wait(lambda f: f.divider == 1, 60)
    assert f is not None, vp.session.error
    assert vp.exports == dict(exports, world=exports["world"] + 1)
    live = vp.session.live
    assert live.world_program is not None and len(live.world_images) == 1
    assert np.isfinite(f.rgba).all()


@blender_only
def test_blender_added_and_hidden_objects(blender_viewport):
    vp = blender_viewport
    n = len(vp.session.live.objects)
    bpy.ops.mesh.primitive_cube_add(size=0.2, location=(0, 0, 1))
    evaluate()
    assert vp.session.wait(lambda f: True, 30) is not None, vp.session.error
    assert len(vp.session.live.objects) == n + 1
    bpy.data.objects["TallBox"].hide_viewport = True
    evaluate()
    assert vp.session.wait(lambda f: True, 30) is not None, vp.session.error
    assert not any(k[0] == "TallBox" for k in vp.session.live.objects)


@blender_only
def test_blender_accumulation_restarts_after_an_edit(blender_viewport):
    vp = blender_viewport
    log = FrameLog()
    log.session = vp.session
    vp.session.on_frame = log
    assert vp.session.wait(lambda f: f.divider == 1 and f.samples >= 2, 60) is not None
    bpy.data.objects["TallBox"].rotation_euler.z += 0.2
    evaluate()
    gen = vp.session.generation
    assert vp.session.wait(lambda f: f.divider == 1 and f.samples >= 3, 60) is not None
    assert log.of(gen)[0] == (1, 1) and (1, 1) in log.of(gen)  # coarse first, full from 1


@blender_only
def test_blender_engine_free_stops_the_threads(blender_viewport):
    from addon import viewport
    vp = blender_viewport
    engine = types.SimpleNamespace()
    viewport._sessions[id(engine)] = vp
    viewport.engine_free(engine)
    assert id(engine) not in viewport._sessions and not vp.session.alive
    assert not [t for t in threading.enumerate() if t.name == "drt-viewport"]


@blender_only
@pytest.mark.parametrize("kind", ["PERSP_SHIFT_VERTICAL", "ORTHO"])
def test_blender_camera_view_matches_the_render_camera(kind):
    """Camera view: the projection Blender computes for the camera (calc_matrix_camera)
    turned into a core camera gives the same rays as the F12 export of that camera."""
    if REPO not in sys.path:
        sys.path.insert(0, REPO)
    import addon
    from addon import viewport
    from drt.camera import Camera
    from drt.scene import scene_from_dict
    if not hasattr(bpy.types.Scene, "drt"):
        addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(REPO, "blend_scenes", "cornell_box.blend"))
    cam = bpy.context.scene.camera
    if kind == "ORTHO":
        cam.data.type, cam.data.ortho_scale = "ORTHO", 3.0
    else:
        cam.data.sensor_fit, cam.data.shift_x, cam.data.shift_y = "VERTICAL", 0.1, -0.05
    w, h = 80, 50
    dg = bpy.context.evaluated_depsgraph_get()
    spec = camera_view_spec(viewport, dg, w, h)
    d = viewport.camera_dict(cam, cam.matrix_world.copy())
    header = {"format": "drt-scene", "version": 1, "camera": d, "materials": [], "lights": [],
              "meshes": [], "objects": [], "render": {"resolution": [w, h]}}
    ref = scene_from_dict(header)
    px = np.array([0.0, w / 2, w, 13.5])
    py = np.array([0.0, h / 2, h, 41.0])
    a = Camera(spec, ref.render, np.zeros(3)).generate(px, py, None, None)
    b = Camera(ref.camera, ref.render, np.zeros(3)).generate(px, py, None, None)
    np.testing.assert_allclose(a.d, b.d, atol=1e-5)
    np.testing.assert_allclose(a.o, b.o, atol=1e-5)


@blender_only
def test_blender_view_camera_reads_the_3d_view():
    """view_camera with a stand-in 3D view: lens and clipping from the view, ±clip_end/2 in
    orthographic views, the camera's depth of field only in camera view."""
    import mathutils
    if REPO not in sys.path:
        sys.path.insert(0, REPO)
    from addon import viewport
    space = types.SimpleNamespace(lens=50.0, clip_start=0.01, clip_end=1000.0, camera=None,
                                  use_local_camera=False)
    rv3d = types.SimpleNamespace(view_matrix=mathutils.Matrix.Translation((0, 0, -6)),
                                 window_matrix=mathutils.Matrix(PERSP_1057x667),
                                 view_perspective="PERSP", is_perspective=True)
    dg = types.SimpleNamespace(scene=None)
    spec = viewport.view_camera(dg, space, rv3d, 1057, 667)
    assert (spec.type, spec.lens, spec.clip_start, spec.clip_end) == ("PERSP", 50.0, 0.01, 1000.0)
    np.testing.assert_allclose(spec.matrix[:3, 3], [0, 0, 6], atol=1e-6)
    rv3d.view_perspective, rv3d.is_perspective = "ORTHO", False
    rv3d.window_matrix = mathutils.Matrix(ORTHO_1057x667)
    spec = viewport.view_camera(dg, space, rv3d, 1057, 667)
    assert (spec.type, spec.clip_start, spec.clip_end) == ("ORTHO", -500.0, 500.0)
    assert spec.ortho_scale == pytest.approx(8.64, rel=1e-6) and not spec.dof_use
    # camera view: the camera's lens, clipping and depth of field, not the view's
    import addon
    if not hasattr(bpy.types.Scene, "drt"):
        addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(REPO, "blend_scenes", "dof.blend"))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = bpy.context.scene.camera
    assert cam.data.dof.use_dof
    rv3d.view_perspective, rv3d.is_perspective = "CAMERA", True
    rv3d.view_matrix = cam.matrix_world.inverted()
    rv3d.window_matrix = cam.calc_matrix_camera(depsgraph, x=160, y=90)
    spec = viewport.view_camera(depsgraph, space, rv3d, 160, 90)
    assert spec.dof_use and spec.lens == pytest.approx(cam.data.lens)
    assert spec.fstop == pytest.approx(cam.data.dof.aperture_fstop)
    assert (spec.clip_start, spec.clip_end) == pytest.approx((cam.data.clip_start, cam.data.clip_end))


# ---------------------------------------------------------------------------- viewport denoising


def test_session_denoises_full_resolution_frames_from_the_start_sample():
    """Cycles's viewport denoising: full-resolution frames from the start sample on go through
    the denoiser (alpha kept); coarse previews and earlier samples stay noisy."""
    live = live_scene()
    calls = []

    def halve(film):
        calls.append(film.width)
        return film.combined[..., :3] * 0.5

    log = FrameLog()
    s = log.session = ProgressiveSession(live, threads=1, coarse_pixels=256, on_frame=log)
    try:
        s.set_denoiser(halve, start_sample=3)
        s.set_view(top_camera(), 32, 32, spp=4)
        f = s.wait(lambda f: f.divider == 1 and f.samples == 4, 60)
        assert f is not None and f.denoised, s.error
        scene, ctx = live.context(top_camera(), 32, 32, spp=4)
        ref = render(scene, spp=4, context=ctx, threads=1).combined[::-1]
        np.testing.assert_allclose(f.rgba[..., :3], 0.5 * ref[..., :3], rtol=1e-6, atol=1e-7)
        np.testing.assert_array_equal(f.rgba[..., 3], ref[..., 3].astype(np.float32))
        assert set(calls) == {32}  # never the coarse 16x16 preview
        s.set_denoiser(None)
        f = s.wait(lambda f: f.divider == 1 and f.samples == 4 and f.generation == s.generation, 60)
        assert f is not None and not f.denoised
    finally:
        assert s.stop()


def test_a_failing_denoiser_is_reported_and_the_noisy_image_shown():
    live = live_scene()
    s = ProgressiveSession(live, threads=1, coarse_pixels=256)

    def broken(film):
        raise RuntimeError("no OIDN here")

    try:
        s.set_denoiser(broken)
        s.set_view(top_camera(), 16, 16, spp=2)
        f = s.wait(lambda f: f.divider == 1 and f.samples == 2, 60)
        assert f is not None and not f.denoised
        assert s.error == "viewport denoising failed: no OIDN here" and s.denoiser is None
    finally:
        assert s.stop()


@blender_only
def test_blender_viewport_denoise_setting_reaches_the_session(blender_viewport):
    """Render properties > Sampling > Viewport Denoise: the session gets a denoiser that runs
    Open Image Denoise (Blender's own) and the frames say so; turning it off removes it."""
    vp = blender_viewport
    d = bpy.context.scene.drt
    assert vp.session.denoiser is None
    d.preview_denoising_start_sample = 2
    d.use_preview_denoising = True
    evaluate()
    assert vp.session.denoiser is not None and vp.session.denoise_start_sample == 2
    f = vp.session.wait(lambda f: f.divider == 1 and f.samples >= 4 and f.generation == vp.session.generation, 120)
    assert f is not None and f.denoised, vp.session.error
    d.use_preview_denoising = False
    evaluate()
    assert vp.session.denoiser is None
    g = vp.session.wait(lambda f: f.divider == 1 and f.samples >= 4 and f.generation == vp.session.generation, 120)
    assert g is not None and not g.denoised
    # the denoised frame is smoother than the noisy one at the same sample count
    def roughness(img):
        return float(np.abs(np.diff(img[..., :3], axis=1)).mean())
    assert roughness(f.rgba) < roughness(g.rgba)


def _glass_cube() -> MeshData:
    """A closed unit cube (outward counter-clockwise winding)."""
    pos = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)], np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tri = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.int64)
    return MeshData("cube", pos, tri, np.ones(len(tri), np.int64))


def test_a_mirrored_object_renders_as_in_the_final_render():
    """An object whose matrix mirrors: the viewport's static set swaps its triangles' corners as
    the final render's geometry does, so a glass cube refracts the same way in both (before, its
    true normal pointed inward in the viewport's world-space set)."""
    from drt.scene import scene_from_dict

    glass = {"name": "glass", "lobes": [{"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": 1.5}],
             "emission": [0, 0, 0]}
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0]) @ np.array(
        [[0.9, -0.3, 0.2, 0.1], [0.3, 0.9, -0.1, 0.0], [-0.2, 0.2, 0.95, -0.2], [0, 0, 0, 1]])
    live = LiveScene(RenderSettings(width=32, height=32, spp=4, max_bounces=8), [DIFFUSE, glass], [SUN],
                     (0.3, 0.3, 0.3))
    live.set_object("floor", "floor", grid_mesh(4, 4.0), translate(z=-1.0))
    live.set_object("cube", "cube", _glass_cube(), mirror)
    got = render_live(live, top_camera(), spp=4)
    cube, floor = _glass_cube(), grid_mesh(4, 4.0)
    header = {"format": "drt-scene", "version": 1,
              "render": {"resolution": [32, 32], "spp": 4, "max_bounces": 8},
              "camera": {"type": "PERSP", "matrix_world": translate(0, 0, 3.0).tolist(), "lens": 50.0},
              "world": {"color": [0.3, 0.3, 0.3]}, "materials": [DIFFUSE, glass], "lights": [SUN],
              "meshes": [{"name": "floor"}, {"name": "cube"}],
              "objects": [{"name": "floor", "mesh": 0, "matrix_world": translate(z=-1.0).tolist()},
                          {"name": "cube", "mesh": 1, "matrix_world": mirror.tolist()}]}
    arrays = {"mesh0.positions": floor.positions.astype(np.float32), "mesh0.triangles": floor.triangles.astype(np.int32),
              "mesh0.material_index": np.zeros(len(floor.triangles), np.int32),
              "mesh1.positions": cube.positions.astype(np.float32), "mesh1.triangles": cube.triangles.astype(np.int32),
              "mesh1.material_index": np.ones(len(cube.triangles), np.int32)}
    ref = render(scene_from_dict(header, arrays), spp=4, threads=1).combined
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-5)
