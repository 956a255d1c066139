"""Material programs in the core, without Blender: scene-file validation of programs and images,
and the interpreter on hand-written programs (opcodes in drt.materials.program_format)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import scene_builders as B
from drt.materials import program_format as F
from drt.render import render
from drt.scene import SceneError, scene_from_dict


def _checker_scene(width=8):
    """An orthographic view of a UV-mapped quad whose emission is a 2×2 checker of red/blue."""
    h = B.base_header(width=width, height=width, spp=1, max_bounces=0,
                      camera={"type": "ORTHO", "matrix_world": B.translation(0, 0, 5), "ortho_scale": 2.0},
                      filter={"type": "BOX", "width": 0.01})
    a = {}
    prog = {"registers": 6, "constants": [[1, 1, 0, 0], [2, 0, 0, 1], [3, 2, 2, 2]],
            "ops": [[F.OP_UV, 0, 0, -1, -1, -1, -1, -1, -1, -1, 0],
                    [F.OP_CHECKER, 0, 4, 5, 0, 1, 2, 3, -1, -1, 0]], "data": []}
    h["materials"].append({"name": "e", "lobes": [], "emission": [0, 0, 0], "emission_reg": 4,
                           "program": prog})
    pos, tri = B.quad((0, 0, 0), (1, 0, 0), (0, 1, 0))
    B.add_mesh(h, a, "plane", pos, tri)
    a["mesh0.uvs"] = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], np.float32)
    return h, a


def test_checker_program_renders_per_pixel():
    h, a = _checker_scene()
    img = render(scene_from_dict(h, a), threads=1).combined[..., :3]
    # Cycles's checker ((xi%2 == yi%2) == zi%2, z = 0 here) at scale 2 over UV 0..1: Color1
    # (red) where floor(2u) + floor(2v) is odd
    y, x = np.mgrid[0:8, 0:8]
    u, v = (x + 0.5) / 8, 1 - (y + 0.5) / 8
    red = (np.floor(2 * u) + np.floor(2 * v)) % 2 == 1
    expect = np.where(red[..., None], [1.0, 0, 0], [0, 0, 1.0])
    np.testing.assert_allclose(img, expect, atol=1e-6)


@pytest.mark.parametrize("change, field", [
    (lambda p: p.update(registers=0), "registers"),
    (lambda p: p["ops"].append([199] + [0] * 10), "unknown opcode 199"),
    (lambda p: p["ops"].append([F.OP_MATH, 0, 7, -1, 0, 0, 0, -1, -1, -1, 0]), "register out of range"),
    (lambda p: p["ops"].append([F.OP_IMAGE, 0, 1, 2, 0, -1, -1, -1, -1, -1, 0]), "image 0 does not exist"),
    (lambda p: p["ops"].append([F.OP_RAMP, 1, 1, 2, 0, -1, -1, -1, -1, -1, 0]), "data table"),
    (lambda p: p["ops"].append([F.OP_BRICK, 0, 1, 2, 0, 0, 0, 0, 0, 0, 0]), "data table"),
    (lambda p: p["ops"].append([F.OP_CURVES, 0, 1, -1, 0, 0, -1, -1, -1, -1, 0]), "data table"),
    (lambda p: p["ops"].append([F.OP_VORONOI, 0, 1, 2, 0, 0, 0, 0, -1, -1, 6]), "register out of range"),
    (lambda p: p["constants"].append([0, float("nan"), 0, 0]), "finite"),
    (lambda p: p["ops"].append([F.OP_POINT, F.POINT_ROWS, 1, -1, -1, -1, -1, -1, -1, -1, -1]),
     "shading-point row"),
    (lambda p: p["ops"].append([F.OP_POINT, F.POINT_N, 1, -1, -1, -1, -1, -1, -1, -1, 3]),
     "shading-point row"),
    (lambda p: p["ops"].append([F.OP_NORMAL_MAP, 5, 1, -1, 0, 0, -1, -1, -1, -1, 0]), "normal map space"),
    (lambda p: p["ops"].append([F.OP_LAYER_WEIGHT, 0, 1, -1, 0, -1, -1, -1, -1, -1, 0]), "missing"),
])
def test_bad_programs_are_refused_by_name(change, field):
    h, a = _checker_scene()
    change(h["materials"][0]["program"])
    with pytest.raises(SceneError, match="materials\\[0\\].program") as e:
        scene_from_dict(h, a)
    assert field in str(e.value)


def test_images_validated_and_shared():
    h, a = _checker_scene()
    h2 = copy.deepcopy(h)
    h2["images"] = [{"name": "i", "width": 2, "height": 3, "srgb": True, "array": "image0.pixels"}]
    a2 = dict(a, **{"image0.pixels": np.zeros((3, 2, 4), np.uint8)})
    assert len(scene_from_dict(h2, a2).images) == 1
    a2["image0.pixels"] = np.zeros((3, 2, 4), np.float64)
    with pytest.raises(SceneError, match="uint8 or float16"):
        scene_from_dict(h2, a2)


def test_scene_without_programs_has_empty_program_data():
    from drt.geometry import build_geometry
    from drt.materials import MaterialTable

    h, a = B.cornell_box(width=8, height=8, spp=1)
    scene = scene_from_dict(h, a)
    pd = MaterialTable.from_scene(scene.materials).program_data(build_geometry(scene).uvs)
    assert pd.prog_of.shape == (0,) and pd.ops.shape == (0, F.OP_WIDTH)


def test_program_data_says_whether_a_program_uses_a_procedural_texture():
    """``ProgramData.procedural`` is True exactly when some program (a material's or the
    world's) has a procedural opcode: the kernels compile those textures only then."""
    assert not F.uses_procedural(np.zeros((0, F.OP_WIDTH), np.int64))
    combine = [F.OP_COMBINE, 0, 1, -1, 0, 0, 0, -1, -1, -1, 0]
    assert not F.uses_procedural([combine])
    for op in sorted(F.PROCEDURAL_OPCODES):
        assert F.uses_procedural([combine, [op] + combine[1:]]), op
    assert F.empty_program_data().procedural is None

    class Table:  # what build_program_data reads of a MaterialTable
        lobe_type = np.zeros((2, 1), np.int64)
        lobe_slot_of = [{}, {}]

    def program(op):
        return {"registers": 2, "constants": np.zeros((0, 4)), "data": np.zeros(0),
                "ops": np.array([[op, 3, 1, -1, 0, 0, -1, -1, -1, -1, 0]], np.int64)}

    plain = {"name": "a", "lobes": []}
    textured = dict(plain, program=program(F.OP_COMBINE))
    noisy = dict(plain, program=program(F.OP_WHITE_NOISE))
    assert F.build_program_data([plain, plain], Table, [], None, None, None) is None
    assert F.build_program_data([textured, plain], Table, [], None, None, None).procedural is None
    assert F.build_program_data([textured, noisy], Table, [], None, None, None).procedural is True
    assert F.build_program_data([textured, plain], Table, [], None, None, None,
                                world=program(F.OP_NOISE)).procedural is True


def _lit_plane(material):
    """A UV-mapped quad under a soft sun, seen at an angle (glossy highlights vary over it)."""
    h = B.base_header(width=16, height=16, spp=16, filter={"type": "BOX", "width": 0.01},
                      camera={"type": "PERSP", "matrix_world": B.look_at((0, -2.5, 1.5), (0, 0, 0)),
                              "lens": 35.0})
    h["lights"].append({"name": "sun", "type": "SUN", "matrix_world": B.look_at((0, 1, 1), (0, 0, 0)),
                        "color": [1, 1, 1], "strength": 3.0, "angle": 0.2})
    h["materials"].append(material)
    a = {}
    pos, tri = B.quad((0, 0, 0), (1, 0, 0), (0, 1, 0))
    B.add_mesh(h, a, "plane", pos, tri)
    a["mesh0.uvs"] = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], np.float32)
    return h, a


def test_textured_lobes_equal_the_constant_material_at_each_hit():
    """A checker choosing colour and roughness per hit renders, pixel for pixel and bit for bit,
    what the two constant materials render (same samples; the per-thread row rewrite is exact)."""
    cells = [({"type": "DIFFUSE", "color": [0.7, 0.2, 0.1]}, {"type": "GLOSSY", "color": [0.3, 0.3, 0.3], "roughness": 0.2}),
             ({"type": "DIFFUSE", "color": [0.1, 0.3, 0.6]}, {"type": "GLOSSY", "color": [0.1, 0.1, 0.1], "roughness": 0.6})]
    # registers: 0 uv, 1-2 diffuse colours, 3-4 glossy colours, 5-6 roughness, 7 scale,
    # 8/9 diffuse colour, 10/11 glossy colour, 12/13 roughness (checker Color, Fac pairs)
    consts = [[1] + cells[0][0]["color"], [2] + cells[1][0]["color"], [3] + cells[0][1]["color"],
              [4] + cells[1][1]["color"], [5, 0.2, 0.2, 0.2], [6, 0.6, 0.6, 0.6], [7, 3.0, 3.0, 3.0]]
    ops = [[F.OP_UV, 0, 0, -1, -1, -1, -1, -1, -1, -1, 0],
           [F.OP_CHECKER, 0, 8, 9, 0, 1, 2, 7, -1, -1, 0],
           [F.OP_CHECKER, 0, 10, 11, 0, 3, 4, 7, -1, -1, 0],
           [F.OP_CHECKER, 0, 12, 13, 0, 5, 6, 7, -1, -1, 0]]
    textured = {"name": "t", "emission": [0, 0, 0],
                "lobes": [{"type": "DIFFUSE", "color": [0.5] * 3, "color_reg": 8},
                          {"type": "GLOSSY", "color": [0.5] * 3, "roughness": 0.5, "color_reg": 10,
                           "roughness_reg": 12}],
                "program": {"registers": 14, "constants": consts, "ops": ops, "data": []}}
    img = render(scene_from_dict(*_lit_plane(textured)), threads=1).combined[..., :3]
    refs = [render(scene_from_dict(*_lit_plane({"name": f"c{k}", "emission": [0, 0, 0],
                                                 "lobes": list(c)})), threads=1).combined[..., :3]
            for k, c in enumerate(cells)]
    # which cell each pixel's hit is in: from the textured render itself, tested against both
    same = [np.all(img == r, axis=2) for r in refs]
    hit = np.any(img > 0, axis=2)
    assert np.all(same[0] | same[1] | ~hit)
    assert same[0][hit].mean() > 0.2 and same[1][hit].mean() > 0.2  # both cells are seen


def test_textured_emitter_light_flag():
    """A textured emitter joins the emissive group (drt.lights.textured) unless its material
    says ``"light": false`` (Cycles's Emission Sampling None); the flag is validated by name."""
    from drt.render import prepare

    h, a = _checker_scene()
    group = prepare(scene_from_dict(h, a)).integrator.lights.emissive
    assert group is not None and len(group) == 2
    # the 2×2 red/blue checker split by the quad's diagonal: each triangle averages to half red, half blue
    assert np.allclose(group.radiance, [[0.5, 0, 0.5]] * 2, atol=0.05), group.radiance
    h["materials"][-1]["light"] = False
    assert prepare(scene_from_dict(h, a)).integrator.lights.emissive is None
    h["materials"][-1]["light"] = "no"
    with pytest.raises(SceneError, match=r"materials\[\d\]\.light"):
        scene_from_dict(h, a)


def test_textured_emitter_in_the_viewport_matches_the_final_render():
    """A LiveScene makes the same textured emitter a light and renders the final render's image
    (same seed); editing the emitter's texture rebuilds the light set."""
    from drt.interactive import LiveScene
    from drt.scene import MeshData

    h, a = _checker_scene(width=16)
    a["mesh0.positions"] = a["mesh0.positions"] * 0.4
    floor = B.add_material(h, "floor", [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}])
    pos, tri = B.quad((0, 0, -0.5), (2, 0, 0), (0, 2, 0))
    B.add_mesh(h, a, "floor", pos, tri, material=floor)
    scene = scene_from_dict(h, a)
    want = render(scene, spp=8, threads=1).combined
    assert want[..., :3].mean() > 0.01
    live = LiveScene(scene.render, scene.materials, [], scene.world_color)
    for o in scene.objects:
        m = scene.meshes[o.mesh]
        live.set_object(o.name, o.name, MeshData(o.name, m.positions, m.triangles, m.material_index, uvs=m.uvs),
                        o.matrix)
    s, ctx = live.context(scene.camera, 16, 16, spp=8)
    assert len(ctx.integrator.lights.emissive) == 2
    got = render(s, spp=8, context=ctx, threads=1).combined
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    builds = live.counters.light_builds
    mats = copy.deepcopy(scene.materials)
    mats[0]["program"]["constants"][0, 1:] = [0.0, 1.0, 0.0]  # red cells → green
    live.set_materials(mats)
    s, ctx = live.context(scene.camera, 16, 16, spp=1)
    assert live.counters.light_builds == builds + 1
    assert np.allclose(ctx.integrator.lights.emissive.radiance, [[0, 0.5, 0.5]] * 2, atol=0.05)
