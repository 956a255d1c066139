"""Cycles (bpy 5.0.1) facts the light code relies on, re-measured with tiny renders.

Slow (a few 32×32 renders, one thread): run with ``pytest -m slow tests/test_lights_cycles.py``.
- Light objects are hidden from camera rays by default (``visible_camera`` False): an area light
  filling the view renders 0; with ``visible_camera`` True its front shows P/(πA), its back 0;
  a soft-falloff point light of radius r shows P/(4π²r²).
- Mesh emission is two-sided: a 1×1, strength-10 quad 2 m above a white plane gives the same
  0.7348 whether it faces the plane or away from it (also seen from the back it shows 10).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytestmark = [pytest.mark.slow, pytest.mark.blender]

UP = (math.pi, 0.0, 0.0)   # camera rotation looking along world +Z


def _reset(samples=16):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = samples
    sc.cycles.use_denoising = False
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.sample_clamp_direct = sc.cycles.sample_clamp_indirect = 0.0
    sc.render.resolution_x = sc.render.resolution_y = 32
    sc.render.resolution_percentage = 100
    sc.render.threads_mode = "FIXED"
    sc.render.threads = 1
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.world = bpy.data.worlds.new("w")
    sc.world.node_tree.nodes["Background"].inputs[1].default_value = 0.0
    return sc


def _camera(sc, loc, rot, lens=50.0):
    cam = bpy.data.cameras.new("c")
    cam.lens = lens
    obj = bpy.data.objects.new("c", cam)
    obj.location, obj.rotation_euler = loc, rot
    sc.collection.objects.link(obj)
    sc.camera = obj


def _centre(sc, tmp_path, tag) -> float:
    path = str(tmp_path / f"{tag}.exr")
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    px = np.array(bpy.data.images.load(path).pixels[:]).reshape(32, 32, 4)
    return float(px[12:20, 12:20, 0].mean())


def _emission_material(strength):
    m = bpy.data.materials.new("e")
    nt = m.node_tree
    nt.nodes.clear()
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs[1].default_value = strength
    nt.links.new(em.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs[0])
    return m


def test_area_light_camera_visibility(tmp_path):
    values = {}
    for tag, visible, loc, rot in [("hidden", None, (0, 0, -3), UP), ("front", True, (0, 0, -3), UP),
                                   ("back", True, (0, 0, 3), (0, 0, 0))]:
        sc = _reset()
        bpy.ops.object.light_add(type="AREA", location=(0, 0, 0))
        obj = bpy.context.object
        obj.data.energy, obj.data.size = 100.0, 1.0
        assert obj.visible_camera is False                 # Blender 5.0 default for lights
        if visible:
            obj.visible_camera = True
        _camera(sc, loc, rot)
        values[tag] = _centre(sc, tmp_path, tag)
    assert values["hidden"] == 0.0
    assert abs(values["front"] - 100 / math.pi) < 1e-3
    assert values["back"] == 0.0


def test_soft_point_light_seen_by_camera(tmp_path):
    sc = _reset()
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 0))
    obj = bpy.context.object
    obj.data.energy, obj.data.shadow_soft_size = 100.0, 0.5
    assert obj.data.use_soft_falloff and obj.visible_camera is False
    obj.visible_camera = True
    _camera(sc, (0, 0, -3), UP)
    assert abs(_centre(sc, tmp_path, "point") - 100 / (4 * math.pi ** 2 * 0.25)) < 1e-3


@pytest.mark.parametrize("facing_plane", [True, False])
def test_mesh_emission_is_two_sided(tmp_path, facing_plane):
    sc = _reset(samples=256)
    sc.cycles.max_bounces = 0
    bpy.ops.mesh.primitive_plane_add(size=1, location=(0, 0, 2),
                                     rotation=((math.pi if facing_plane else 0.0), 0, 0))
    bpy.context.object.data.materials.append(_emission_material(10.0))
    bpy.ops.mesh.primitive_plane_add(size=100, location=(0, 0, 0))
    white = bpy.data.materials.new("d")
    nt = white.node_tree
    nt.nodes.clear()
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs[0].default_value = (1, 1, 1, 1)
    nt.links.new(diffuse.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs[0])
    bpy.context.object.data.materials.append(white)
    _camera(sc, (0, 0, 1), (0, 0, 0), lens=500.0)
    assert abs(_centre(sc, tmp_path, f"quad{facing_plane}") - 0.73478) < 0.01 * 0.73478
