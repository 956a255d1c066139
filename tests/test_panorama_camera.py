"""Blender's panoramic camera (drt.panorama): every projection DRT renders against Cycles, pixel
by pixel, on a room of emissive checkered walls seen from inside (no light transport: the
image is the projection alone); and the core's own checks (the view axis, the samples outside a
fisheye's disc, spherical clipping, the scene format)."""

import math

import numpy as np
import pytest

from drt.camera import Camera
from drt.panorama import PANORAMA_TYPES
from drt.render import render
from drt.scene import CameraSpec, PanoramaSpec, RenderSettings, SceneError, scene_from_dict
from scene_builders import add_material, add_mesh, base_header, look_at, quad


def _camera(kind, w=64, h=32, **pano):
    spec = CameraSpec(type="PANO", matrix=np.eye(4), panorama=PanoramaSpec(type=kind, **pano))
    return Camera(spec, RenderSettings(width=w, height=h, spp=1), np.zeros(3))


@pytest.mark.parametrize("kind", PANORAMA_TYPES)
def test_the_image_centre_looks_along_the_view_axis(kind):
    """Every projection's centre pixel looks along the camera's −Z (Cycles's panoramic cameras
    point their +x, or the mirror ball its −y, there)."""
    cam = _camera(kind, 33, 33)
    rays = cam.generate(np.array([16.5]), np.array([16.5]), np.full((1, 2), 0.5), np.zeros(1))
    np.testing.assert_allclose(rays.d[0], (0, 0, -1), atol=2e-5)  # (the polynomial lens: k0 ≠ 0)


def test_equirectangular_directions_are_longitude_and_latitude():
    """The full sphere, as Cycles's equirectangular range: a quarter of the width left of the
    centre looks 90° to the left (camera −X), a quarter right to the right, the top edge straight
    up (+Y) and the bottom edge down."""
    cam = _camera("EQUIRECTANGULAR", 64, 32)
    rays = cam.generate(np.array([16.0, 48.0, 32.0, 32.0]), np.array([16.0, 16.0, 32.0, 0.0]),
                        np.full((4, 2), 0.5), np.zeros(4))
    np.testing.assert_allclose(rays.d, [(-1, 0, 0), (1, 0, 0), (0, 1, 0), (0, -1, 0)], atol=1e-9)


def test_outside_a_fisheye_disc_a_sample_is_black_and_opaque():
    """A square equidistant fisheye image: the corners lie outside the disc, where Cycles
    traces no ray (black, alpha 1 even with a transparent film); inside, the world."""
    h = base_header(16, 16, 4, camera={"type": "PANO", "matrix_world": np.eye(4).tolist(),
                                       "panorama": {"type": "FISHEYE_EQUIDISTANT"}},
                    world=(0.5, 0.5, 0.5), film_transparent=False)
    img = np.asarray(render(scene_from_dict(h, {}), threads=1).combined)
    np.testing.assert_array_equal(img[0, 0], [0, 0, 0, 1])
    np.testing.assert_allclose(img[8, 8], [0.5, 0.5, 0.5, 1.0], rtol=1e-6)
    h["render"]["film_transparent"] = True
    img = np.asarray(render(scene_from_dict(h, {}), threads=1).combined)
    np.testing.assert_array_equal(img[0, 0], [0, 0, 0, 1])
    assert img[8, 8, 3] == 0.0


def test_clipping_is_spherical():
    """A panorama clips by distance along each ray (no image plane): a wall 1 m ahead is cut
    away by clip_start 1.5 at the centre, and kept by clip_start 0.5."""
    def img(clip_start):
        h = base_header(32, 16, 1, camera={"type": "PANO", "matrix_world": np.eye(4).tolist(),
                                           "clip_start": clip_start,
                                           "panorama": {"type": "EQUIRECTANGULAR"}})
        a = {}
        glow = add_material(h, "glow", [], emission=[1.0, 1.0, 1.0])
        add_mesh(h, a, "wall", *quad((0, 0, -1), (0, 5, 0), (5, 0, 0)), material=glow)
        return np.asarray(render(scene_from_dict(h, a), threads=1).combined)
    assert img(0.5)[8, 16, 0] == pytest.approx(1.0)
    assert img(1.5)[8, 16, 0] == 0.0


def test_panorama_fields_are_checked():
    cam = {"type": "PANO", "matrix_world": np.eye(4).tolist(), "panorama": {"type": "CYLINDER"}}
    with pytest.raises(SceneError) as e:
        scene_from_dict(base_header(4, 4, 1, camera=cam), {})
    assert e.value.field == "camera.panorama.type"
    cam["panorama"] = {"type": "EQUIRECTANGULAR", "latitude_max": 2.0}
    with pytest.raises(SceneError) as e:
        scene_from_dict(base_header(4, 4, 1, camera=cam), {})
    assert e.value.field == "camera.panorama.latitude_max"
    spec = scene_from_dict(base_header(4, 4, 1, camera={"type": "PANO", "matrix_world": np.eye(4).tolist()}), {})
    assert spec.camera.panorama == PanoramaSpec()  # Blender's defaults


def _room(bpy, node):
    """Six emissive walls around the origin (a 4 m cube), each a two-colour checker of its own
    hue in object coordinates, and a small white marker off every axis."""
    hues = [(1, 0.2, 0.2), (0.2, 1, 0.2), (0.2, 0.2, 1), (1, 1, 0.2), (0.2, 1, 1), (1, 0.2, 1)]
    rots = [(0, math.pi / 2, 0), (0, -math.pi / 2, 0), (-math.pi / 2, 0, 0), (math.pi / 2, 0, 0),
            (0, 0, 0), (math.pi, 0, 0)]
    locs = [(-2, 0, 0), (2, 0, 0), (0, -2, 0), (0, 2, 0), (0, 0, -2), (0, 0, 2)]
    for k, (hue, rot, loc) in enumerate(zip(hues, rots, locs)):
        mat = bpy.data.materials.new(f"wall{k}")
        nt = mat.node_tree
        nt.nodes.clear()
        coords = nt.nodes.new("ShaderNodeTexCoord").outputs["Object"]
        chk = node(nt, "ShaderNodeTexChecker", {"Vector": coords, "Scale": 3.0,
                                               "Color1": (*hue, 1), "Color2": (*(0.3 * c for c in hue), 1)})
        em = node(nt, "ShaderNodeEmission", {"Color": chk.outputs["Color"], "Strength": 1.0})
        nt.links.new(em.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
        bpy.ops.mesh.primitive_plane_add(size=4.0, location=loc, rotation=rot)
        bpy.context.object.data.materials.append(mat)
    white = bpy.data.materials.new("marker")
    white.node_tree.nodes.clear()
    em = node(white.node_tree, "ShaderNodeEmission", {"Color": (1, 1, 1, 1), "Strength": 3.0})
    white.node_tree.links.new(em.outputs[0], white.node_tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0.9, -1.2, 0.5))
    bpy.context.object.data.materials.append(white)


def _panorama_room(bpy, node, setup_scene, kind, size, spp):
    """The room (``_room``) seen by a panoramic camera of projection ``kind`` at ``size``
    pixels, turned off the axes and a little off the room's centre."""
    sc = setup_scene(1)
    sc.render.resolution_x, sc.render.resolution_y = size
    sc.cycles.samples = sc.drt.samples = spp
    _room(bpy, node)
    cam = sc.camera
    cam.location = (0.3, -0.2, 0.1)
    cam.rotation_euler = (1.3, 0.2, 0.4)
    cam.data.type = "PANO"
    cam.data.panorama_type = kind
    cam.data.clip_start = 0.01
    return sc


PARITY = [("EQUIRECTANGULAR", {}, (64, 32)),
          ("EQUIRECTANGULAR", {"latitude_min": -0.5, "latitude_max": 1.0, "longitude_min": -2.0,
                               "longitude_max": 1.2}, (48, 32)),
          ("EQUIANGULAR_CUBEMAP_FACE", {}, (40, 40)),
          ("MIRRORBALL", {}, (40, 40)),
          ("FISHEYE_EQUIDISTANT", {"fisheye_fov": 3.6}, (48, 40)),
          ("FISHEYE_EQUISOLID", {"fisheye_lens": 8.0, "fisheye_fov": 3.1}, (48, 32)),
          ("FISHEYE_LENS_POLYNOMIAL", {}, (48, 32))]


@pytest.mark.parametrize("kind, settings, size", PARITY, ids=[f"{p[0]}{'_range' if p[1] else ''}" for p in PARITY])
def test_panorama_matches_cycles(tmp_path, kind, settings, size):
    """The room through each projection (camera turned off the axes), RGBA pixel by pixel
    against Cycles: the checker edges and the marker pin the mapping to a pixel."""
    bpy = pytest.importorskip("bpy")
    from node_parity import node, render_rgba_both, setup_scene

    sc = _panorama_room(bpy, node, setup_scene, kind, size, 16)
    for name, value in settings.items():
        setattr(sc.camera.data, name, value)
    cycles, drt = render_rgba_both(sc, tmp_path / f"{kind}.exr")
    print(kind, cycles[..., :3].mean(), drt[..., :3].mean(), np.abs(drt - cycles).max())
    assert abs(drt[..., :3].mean() / cycles[..., :3].mean() - 1) < 0.01
    np.testing.assert_array_equal(drt[..., 3], cycles[..., 3])
    close = np.abs(drt - cycles).max(axis=-1) < 0.02
    assert close.mean() > 0.95, close.mean()  # the rest: checker edges a sample apart


def test_panorama_depth_of_field_matches_cycles(tmp_path):
    """An equirectangular camera with depth of field (focused 1 m away, f/0.5 at 50 mm: a 5 cm
    aperture; the walls 1.6–3.5 m away blur): Cycles's lens for panoramas, the aperture in the
    plane across each pixel's direction. Means and 2 × 2-pixel blocks against Cycles."""
    bpy = pytest.importorskip("bpy")
    from node_parity import node, render_rgba_both, setup_scene

    sc = _panorama_room(bpy, node, setup_scene, "EQUIRECTANGULAR", (48, 24), 256)
    cam = sc.camera
    cam.data.dof.use_dof = True
    cam.data.dof.focus_distance = 1.0
    cam.data.dof.aperture_fstop = 0.5
    cycles, drt = render_rgba_both(sc, tmp_path / "pano_dof.exr")
    blocks = [img[..., :3].reshape(12, 2, 24, 2, 3).mean(axis=(1, 3)) for img in (cycles, drt)]
    err = np.abs(blocks[1] - blocks[0]).max(axis=-1)
    print(drt[..., :3].mean() / cycles[..., :3].mean(), err.mean(), err.max())
    assert abs(drt[..., :3].mean() / cycles[..., :3].mean() - 1) < 0.01
    assert err.mean() < 0.01 and err.max() < 0.05
    sharp = [np.abs(np.diff(img[..., :3], axis=1)).mean() for img in (cycles, drt)]
    assert abs(sharp[1] / sharp[0] - 1) < 0.1, sharp  # as blurred as Cycles's
