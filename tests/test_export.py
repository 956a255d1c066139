"""The exporter (depsgraph → header + arrays) with the bpy module: committed exports, materials,
motion, instancing, visibility, lights, camera. Skipped without bpy."""

import json
import math
import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(REPO, "blend_scenes")
for p in (REPO, SCENES):
    if p not in sys.path:
        sys.path.insert(0, p)

import _common as C  # noqa: E402  (blend_scenes helpers)
from addon.export import ExportError, export_depsgraph  # noqa: E402
from addon.export.blend import export_current  # noqa: E402
from test_addon import ensure_registered, open_scene  # noqa: E402

pytestmark = pytest.mark.blender

SCENE_NAMES = ["cornell_box", "dof", "motion_blur", "glossy_glass", "all_lights", "showcase", "textured", "procedural",
               "sss_head", "volume_noise", "coat_sheen"]


def read_npz(path):
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays.pop("header").tobytes().decode("utf-8"))
    return header, arrays


def assert_close(a, b, path="header"):
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{path}: keys {set(a) ^ set(b)}"
        for k in a:
            assert_close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{path}: length"
        for i, (x, y) in enumerate(zip(a, b)):
            assert_close(x, y, f"{path}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9), f"{path}: {a} != {b}"
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


@pytest.fixture
def fresh():
    ensure_registered()
    scene = C.reset()
    C.camera((0, -5, 1), (0, 0, 0))
    return scene


@pytest.mark.parametrize("name", SCENE_NAMES)
def test_export_matches_committed_file(name):
    open_scene(name)
    res = export_current()
    header, arrays = read_npz(os.path.join(SCENES, f"{name}.npz"))
    assert_close(res.header, header)
    assert set(res.arrays) == set(arrays)
    for k, v in arrays.items():
        np.testing.assert_array_equal(res.arrays[k], v, err_msg=k)


def test_committed_exports_validate_in_core():
    scene_file = pytest.importorskip("drt.scene_file")
    for name in SCENE_NAMES:
        scene_file.load_scene(os.path.join(SCENES, f"{name}.npz"))


def test_instanced_meshes_stored_once():
    open_scene("all_lights")
    res = export_current()
    posts = [o for o in res.header["objects"] if o["name"].startswith("Post")]
    assert len(posts) == 6  # three linked duplicates + three through the collection instance
    assert len({o["mesh"] for o in posts}) == 1


def test_motion_only_for_moving_objects():
    open_scene("motion_blur")
    res = export_current()
    h = res.header
    assert h["render"]["shutter"] == [-0.25, 0.25]
    motion = {o["name"]: o["motion"] for o in h["objects"]}
    assert motion["Static"] is None and motion["Floor"] is None
    m = motion["Mover"]
    dx = m["matrix_close"][0][3] - m["matrix_open"][0][3]
    assert dx == pytest.approx(0.5 * 0.25, rel=1e-4)  # 0.25 units/frame × 0.5 frame
    assert motion["Spinner"] is not None
    deforming = {mm["name"]: mm["deforming"] for mm in h["meshes"]}
    assert deforming["Twister"] and not deforming["Mover"]
    k = next(i for i, mm in enumerate(h["meshes"]) if mm["name"] == "Twister")
    assert f"mesh{k}.positions_close" in res.arrays
    assert bpy.context.scene.frame_current == 5  # time restored


@pytest.mark.parametrize("position,centre", [("START", 0.25), ("CENTER", 0.0), ("END", -0.25)])
def test_motion_blur_position(position, centre):
    open_scene("motion_blur")
    bpy.context.scene.render.motion_blur_position = position
    s = export_current().header["render"]["shutter"]
    assert (s[0] + s[1]) / 2 == pytest.approx(centre)
    assert s[1] - s[0] == pytest.approx(0.5)


def test_hidden_objects_excluded_and_holdouts_kept(fresh):
    """Hidden objects are not exported; a holdout is (it occludes, casts shadows and is seen in
    bounces: the core cuts it out of camera hits only)."""
    mat = C.diffuse("M", (0.5, 0.5, 0.5))
    C.quad("Visible", (0, 0, 0), 1.0, mat)
    C.quad("Hidden", (0, 0, 1), 1.0, mat).hide_render = True
    C.quad("Holdout", (0, 0, 2), 1.0, mat).is_holdout = True
    objs = {o["name"]: o for o in export_current().header["objects"]}
    assert sorted(objs) == ["Holdout", "Visible"]
    assert objs["Holdout"]["holdout"] is True and "holdout" not in objs["Visible"]


def test_collection_holdout_indirect_only_and_instancers_as_cycles(fresh):
    """As Cycles's sync_object: a holdout collection makes its objects holdouts; an indirect-only
    collection hides its objects from camera rays; an instance takes its instancer's holdout
    flag and ray visibility (ANDed with its own)."""
    mat = C.diffuse("M", (0.5, 0.5, 0.5))
    scene, layer = bpy.context.scene, bpy.context.view_layer
    cols = {}
    for name in ("HoldCol", "IndirectCol", "Source"):
        cols[name] = bpy.data.collections.new(name)
        scene.collection.children.link(cols[name])
    for name, col, z in (("InHold", "HoldCol", 0), ("InIndirect", "IndirectCol", 1), ("Src", "Source", 2)):
        ob = C.quad(name, (0, 0, z), 1.0, mat)
        for c in list(ob.users_collection):
            c.objects.unlink(ob)
        cols[col].objects.link(ob)
    cols["Source"].objects["Src"].visible_shadow = False
    layer.layer_collection.children["HoldCol"].holdout = True
    layer.layer_collection.children["IndirectCol"].indirect_only = True
    layer.layer_collection.children["Source"].exclude = True
    inst = bpy.data.objects.new("Instancer", None)
    inst.instance_type, inst.instance_collection = "COLLECTION", cols["Source"]
    inst.is_holdout, inst.visible_glossy = True, False
    scene.collection.objects.link(inst)
    objs = {o["name"].split("@")[0]: o for o in export_current().header["objects"]}
    assert objs["InHold"].get("holdout") is True and "visibility" not in objs["InHold"]
    assert "holdout" not in objs["InIndirect"]
    assert objs["InIndirect"]["visibility"]["camera"] is False
    assert objs["Src"].get("holdout") is True
    vis = objs["Src"]["visibility"]
    assert vis["glossy"] is False and vis["shadow"] is False and vis["camera"] is True


def test_panoramic_camera_is_exported_and_central_cylindrical_refused(fresh):
    """A panoramic camera exports its projection and Blender's parameters; Central Cylindrical,
    not rendered, is an export error that names it (not a traceback)."""
    cam = bpy.context.scene.camera.data
    cam.type, cam.panorama_type = "PANO", "FISHEYE_EQUISOLID"
    cam.fisheye_lens, cam.fisheye_fov = 8.0, 3.0
    pano = export_current().header["camera"]["panorama"]
    assert pano["type"] == "FISHEYE_EQUISOLID"
    assert pano["fisheye_lens"] == pytest.approx(8.0) and pano["fisheye_fov"] == pytest.approx(3.0)
    assert len(pano["polynomial"]) == 5
    cam.panorama_type = "CENTRAL_CYLINDRICAL"
    with pytest.raises(ExportError, match="CENTRAL_CYLINDRICAL"):
        export_current()


def test_ray_visibility_is_exported_and_the_shadow_catcher_warns(fresh):
    """Cycles's per-object ray visibility goes into the object's "visibility" (only when some
    ray kind is off); the shadow catcher, not rendered yet, is named in one warning."""
    mat = C.diffuse("M", (0.5, 0.5, 0.5))
    C.quad("Plain", (0, 0, 0), 1.0, mat)
    card = C.quad("Card", (0, 0, 1), 1.0, mat)
    card.visible_camera = card.visible_shadow = False
    res = export_current()
    objs = {o["name"]: o for o in res.header["objects"]}
    assert "visibility" not in objs["Plain"]
    assert objs["Card"]["visibility"] == {"camera": False, "diffuse": True, "glossy": True,
                                          "transmission": True, "volume_scatter": True, "shadow": False}
    assert not [w for w in res.warnings if "shadow catcher" in w]
    from drt.scene import VIS_ALL, VIS_CAMERA, VIS_SHADOW, scene_from_dict
    vis = {o.name: o.visibility for o in scene_from_dict(res.header, res.arrays).objects}
    assert vis == {"Plain": VIS_ALL, "Card": VIS_ALL & ~VIS_CAMERA & ~VIS_SHADOW}
    C.quad("Catcher", (0, 0, 2), 1.0, mat).is_shadow_catcher = True
    found = [w for w in export_current().warnings if "shadow catcher" in w]
    assert len(found) == 1 and "'Catcher' (shadow catcher)" in found[0] and "Card" not in found[0]


def test_transparent_glass_is_exported_with_a_transparent_film(fresh):
    """Film > Transparent Glass (Cycles) goes into the render settings as its roughness
    threshold, only with a transparent film (without one it changes nothing), and no longer warns."""
    C.quad("Plain", (0, 0, 0), 1.0, C.diffuse("M", (0.5, 0.5, 0.5)))
    sc = bpy.context.scene
    sc.cycles.film_transparent_glass = True
    sc.cycles.film_transparent_roughness = 0.25
    res = export_current()
    assert "film_transparent_roughness" not in res.header["render"]  # opaque film
    sc.render.film_transparent = True
    res = export_current()
    assert res.header["render"]["film_transparent_roughness"] == pytest.approx(0.25)
    assert not [w for w in res.warnings if "Transparent Glass" in w]


def test_no_camera_is_an_export_error():
    ensure_registered()
    C.reset()
    with pytest.raises(ExportError, match="camera"):
        export_depsgraph(bpy.context.evaluated_depsgraph_get())


def test_smooth_normals_and_uvs(fresh):
    C.uv_sphere("Ball", 1.0, (0, 0, 0), C.diffuse("M", (0.5, 0.5, 0.5)), segments=16, rings=8)
    res = export_current()
    n = res.arrays["mesh0.normals"]
    pos = res.arrays["mesh0.positions"][res.arrays["mesh0.triangles"]]
    # smooth sphere: corner normals are unit, nearly radial, shared by the corners of a vertex
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-5)
    radial = pos / np.linalg.norm(pos, axis=-1, keepdims=True)
    assert np.min(np.sum(n * radial, axis=-1)) > 0.98
    tri = res.arrays["mesh0.triangles"]
    first = {}
    for v, nv in zip(tri.reshape(-1), n.reshape(-1, 3)):
        np.testing.assert_allclose(first.setdefault(v, nv), nv, atol=1e-6)
    assert res.arrays["mesh0.uvs"].shape == (len(n), 3, 2)


def _rna_triangle_corners(mesh):
    out = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", out)
    return out.reshape(-1, 3)


@pytest.mark.parametrize("face_normals_cached", [False, True])
def test_loop_triangles_from_raw_arrays_are_blenders(fresh, monkeypatch, face_normals_cached):
    """A large mesh's loop triangles are rebuilt from its raw arrays (drt.mesh_tessellation)
    instead of read through RNA: exactly Blender's, on convex and concave quads, a bumpy
    subdivided grid and a sphere, whichever of its two quad tests Blender ran (it depends on
    whether the face normals are cached); meshes it cannot be sure of fall back to Blender's."""
    from addon import compat

    monkeypatch.setattr(compat, "RAW_TRIANGLES_MIN", 1)
    rng = np.random.default_rng(3)
    # darts: planar quads with a reflex corner at a random position, randomly rotated
    dart = np.array([(0, 0, 0), (0.8, 0.8, 0), (2, 0, 0), (1, 2, 0)], float)
    verts, faces = [], []
    for k in range(400):
        q = np.roll(dart, rng.integers(4), axis=0) * rng.uniform(0.01, 3.0)
        a, b = rng.uniform(0, 2 * np.pi, 2)
        rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
        verts.extend(q @ (rx @ rz).T + rng.normal(size=3) * 5)
        faces.append([4 * k, 4 * k + 1, 4 * k + 2, 4 * k + 3])
    darts = C.mesh_object("Darts", [tuple(v) for v in verts], faces, [C.diffuse("M", (0.5, 0.5, 0.5))])
    # the same darts with custom normals pointing against their faces (an imported mesh has
    # custom normals; Blender's cut must not follow them)
    flipped = C.mesh_object("Flipped", [tuple(v) for v in verts], faces, [C.diffuse("M", (0.5, 0.5, 0.5))])
    q = np.asarray(verts).reshape(-1, 4, 3)
    face_n = np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1])
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    flipped.data.normals_split_custom_set(np.repeat(-face_n, 4, axis=0).tolist())
    assert flipped.data.has_custom_normals
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=60, y_subdivisions=60, size=4)
    grid = bpy.context.object
    co = np.empty(len(grid.data.vertices) * 3, np.float32)
    grid.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 2] += rng.normal(size=len(co)).astype(np.float32) * 0.005
    grid.data.vertices.foreach_set("co", co.ravel())
    grid.data.update()
    grid.modifiers.new("Subdivision", "SUBSURF").levels = 1
    ball = C.uv_sphere("Ball", 1.0, (0, 0, 3), C.diffuse("B", (0.5, 0.5, 0.5)), segments=48, rings=24)
    pentagon = C.mesh_object("Pentagon", [(0, 0, 0), (1, 0, 0), (1.5, 1, 0), (0.5, 1.5, 0), (-0.5, 1, 0)],
                             [[0, 1, 2, 3, 4]], [C.diffuse("P", (0.5, 0.5, 0.5))])
    depsgraph = bpy.context.evaluated_depsgraph_get()
    rebuilt = {}
    for obj in (darts, flipped, grid, ball, pentagon):
        mesh = obj.evaluated_get(depsgraph).to_mesh()
        try:
            if face_normals_cached:
                mesh.polygons[0].normal  # noqa: B018 -- computes (and caches) every face normal
            compat.prepare_mesh(mesh)
            fast = compat._triangle_corners_from_faces(mesh, len(mesh.loop_triangles))
            rebuilt[obj.name] = fast is not None
            np.testing.assert_array_equal(compat.triangle_corners(mesh), _rna_triangle_corners(mesh))
        finally:
            obj.evaluated_get(depsgraph).to_mesh_clear()
    assert rebuilt == {"Darts": True, "Flipped": compat.BLENDER_VERSION < (5, 1, 0), "Grid": True, "Ball": True,
                       "Pentagon": False}


def test_flat_mesh_has_no_normals(fresh):
    C.box("Box", (1, 1, 1), (0, 0, 0), C.diffuse("M", (0.5, 0.5, 0.5)))
    res = export_current()
    assert "mesh0.normals" not in res.arrays
    assert res.arrays["mesh0.triangles"].shape == (12, 3)


def _material(res, name):
    return next(m for m in res.header["materials"] if m["name"] == name)


def test_principled_mapping(fresh):
    mat, nodes, out = C._new_material("P")
    p = nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Base Color"].default_value = (0.5, 0.2, 0.1, 1)
    p.inputs["Metallic"].default_value = 0.25
    p.inputs["Alpha"].default_value = 0.8
    mat.node_tree.links.new(p.outputs[0], out.inputs["Surface"])
    C.quad("Q", (0, 0, 0), 1.0, mat)
    m = _material(export_current(), "P")
    kinds = [lb["type"] for lb in m["lobes"]]
    assert kinds == ["METALLIC", "DIELECTRIC_SPECULAR", "DIFFUSE", "GLASS"]
    metal, spec, diffuse, clear = m["lobes"]
    # F82-tint metal: colour = weight × the clamped base colour (its F0)
    np.testing.assert_allclose(metal["color"], 0.8 * 0.25 * np.array([0.5, 0.2, 0.1]), rtol=1e-5)
    assert metal["weight"] == pytest.approx(0.8 * 0.25) and metal["tint"] == [1, 1, 1]
    # Principled v2: the specular layer (weight 1 of the dielectric share) over the diffuse base,
    # which the core scales per hit by 1 − the layer's albedo ("layer" names the specular lobe)
    np.testing.assert_allclose(spec["color"], [0.8 * 0.75] * 3, rtol=1e-5)
    assert spec["ior"] == pytest.approx(1.5) and spec["multiscatter"] and spec["tint"] == [1, 1, 1]
    np.testing.assert_allclose(diffuse["color"], 0.8 * 0.75 * np.array([0.5, 0.2, 0.1]), rtol=1e-5)
    assert diffuse["layer"] == 1
    assert clear["ior"] == 1.0 and clear["color"] == pytest.approx([0.2] * 3)


def test_mix_add_emission_and_rgb_input(fresh):
    mat, nodes, out = C._new_material("MixAdd")
    rgb = nodes.new("ShaderNodeRGB")
    rgb.outputs[0].default_value = (0.1, 0.2, 0.3, 1)
    d = nodes.new("ShaderNodeBsdfDiffuse")
    mat.node_tree.links.new(rgb.outputs[0], d.inputs["Color"])
    e = nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (1, 0.5, 0.25, 1)
    e.inputs["Strength"].default_value = 4.0
    add = nodes.new("ShaderNodeAddShader")
    mat.node_tree.links.new(d.outputs[0], add.inputs[0])
    mat.node_tree.links.new(e.outputs[0], add.inputs[1])
    g = nodes.new("ShaderNodeBsdfGlass")
    mix = nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.25
    mat.node_tree.links.new(add.outputs[0], mix.inputs[1])
    mat.node_tree.links.new(g.outputs[0], mix.inputs[2])
    mat.node_tree.links.new(mix.outputs[0], out.inputs["Surface"])
    C.quad("Q", (0, 0, 0), 1.0, mat)
    res = export_current()
    m = _material(res, "MixAdd")
    assert m["lobes"][0] == {"type": "DIFFUSE", "color": pytest.approx([0.075, 0.15, 0.225])}
    assert m["lobes"][1]["type"] == "GLASS" and m["lobes"][1]["color"] == pytest.approx([0.25] * 3)
    assert m["emission"] == pytest.approx([3.0, 1.5, 0.75])
    assert not res.warnings


def test_unsupported_node_warns_once_and_falls_back(fresh):
    mat, nodes, out = C._new_material("Odd")
    t = nodes.new("ShaderNodeBsdfToon")
    t.inputs["Color"].default_value = (0.3, 0.4, 0.5, 1)
    tex = nodes.new("ShaderNodeTexGabor")  # a texture programs do not compile (yet)
    p = nodes.new("ShaderNodeBsdfDiffuse")
    mat.node_tree.links.new(tex.outputs["Value"], p.inputs["Color"])
    mix = nodes.new("ShaderNodeMixShader")
    mat.node_tree.links.new(t.outputs[0], mix.inputs[1])
    mat.node_tree.links.new(p.outputs[0], mix.inputs[2])
    mat.node_tree.links.new(mix.outputs[0], out.inputs["Surface"])
    C.quad("Q", (0, 0, 0), 1.0, mat)
    C.quad("Q2", (0, 0, 1), 1.0, mat)
    res = export_current()
    m = _material(res, "Odd")
    assert m["lobes"][0] == {"type": "DIFFUSE", "color": pytest.approx([0.15, 0.2, 0.25])}
    odd = [w for w in res.warnings if "'Odd'" in w]
    assert len(odd) == 1 and "Toon" in odd[0] and "Gabor" in odd[0]


def test_lights_units(fresh):
    C.light("Area", "AREA", (0, 0, 2), shape="DISK", size=0.5, energy=10.0)
    C.light("Spot", "SPOT", (0, 0, 2), energy=100.0, spot_size=math.radians(45), spot_blend=0.2)
    C.light("Sun", "SUN", (0, 0, 2), energy=3.0, angle=math.radians(2))
    bpy.data.lights["Spot"].exposure = 1.0
    lights = {lt["name"]: lt for lt in export_current().header["lights"]}
    assert lights["Area"]["size_y"] == lights["Area"]["size"] == pytest.approx(0.5)
    assert lights["Spot"]["power"] == pytest.approx(200.0)  # 2^exposure
    assert lights["Spot"]["spot_size"] == pytest.approx(math.radians(45))
    assert lights["Sun"]["strength"] == pytest.approx(3.0)
    assert lights["Sun"]["angle"] == pytest.approx(math.radians(2))
    assert lights["Area"]["spread"] <= math.pi


def test_camera_focus_object_and_resolution(fresh):
    cam = bpy.context.scene.camera
    target = bpy.data.objects.new("T", None)
    bpy.context.scene.collection.objects.link(target)
    target.location = (0, 3, 1)  # camera at (0,-5,1) looking at the origin
    cam.data.dof.use_dof = True
    cam.data.dof.focus_object = target
    r = bpy.context.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = 1000, 500, 50
    h = export_current().header
    view = np.array([0, 5, -1]) / math.sqrt(26)
    assert h["camera"]["dof"]["focus_distance"] == pytest.approx(float(np.dot(view, [0, 8, 0])), rel=1e-5)
    assert h["render"]["resolution"] == [500, 250]


@pytest.mark.slow
def test_export_speed_one_million_triangles():
    import time

    import large_mesh
    ensure_registered()
    large_mesh.build()
    export_current()
    t0 = time.perf_counter()
    res = export_current()
    dt = time.perf_counter() - t0
    assert len(res.arrays["mesh0.triangles"]) >= 1_000_000
    assert dt < 2.0, f"export took {dt:.2f} s"


def test_geometry_without_a_primitive_warns_by_name(fresh):
    """Hair particles, hair-curves objects and point clouds (which Cycles renders as curves and
    spheres) are named in one warning instead of vanishing silently; empty ones (nothing to
    render in Cycles either) are not."""
    bpy.ops.mesh.primitive_uv_sphere_add(location=(-2, 0, 0))
    sphere = bpy.context.object
    sphere.name = "Furry"
    sphere.modifiers.new("hair", "PARTICLE_SYSTEM")
    sphere.particle_systems[0].settings.type = "HAIR"
    sphere.particle_systems[0].settings.count = 20
    bpy.ops.object.pointcloud_random_add(location=(2, 0, 0))
    bpy.context.object.name = "Dust"
    bpy.context.view_layer.objects.active = sphere
    bpy.ops.object.curves_empty_hair_add(location=(0, 2, 0))  # no curves: nothing to render
    bpy.ops.object.volume_add(location=(0, -2, 0))  # no grids
    res = export_current()
    warned = [w for w in res.warnings if w.startswith("not rendered (DRT has no curve")]
    assert len(warned) == 1, res.warnings
    assert "hair on 'Furry'" in warned[0] and "point cloud 'Dust'" in warned[0]
    assert "Curves" not in warned[0] and "volume" not in warned[0]
    assert [o["name"] for o in res.header["objects"]] == ["Furry"]  # the emitter itself renders
