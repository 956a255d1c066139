"""Node-level parity harness (bpy): an emission-only tile per case, seen by an orthographic
camera, rendered by Cycles and by DRT; each pixel shows the node graph's value at the pixel
centre's UV (see docs/materials.md, "Testing").

``render_tiles(cases, n)`` lays the cases out on an n×n grid of planes (each with UV 0..1 and
Generated coordinates 0..1 over the tile), renders 16×16 pixels per tile with a 0.01-pixel
filter and one sample (no noise: only emission, no bounces) and returns the two (H, W, 3)
images, top row first. A case is ``fn(nt, uv) -> socket``: it builds its nodes in the material
tree ``nt`` (``uv`` is a Texture Coordinate UV output) and returns the socket to show; every
component v is shown as atan(v)·0.3 + 0.5 so that any real value lands in (0, 1) and stays
comparable. A case with a ``setup(mesh)`` attribute gets its plane's mesh to add data to
(colour attributes).
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
for p in (REPO, os.path.join(REPO, "blend_scenes")):
    if p not in sys.path:
        sys.path.insert(0, p)

from addon.export.node_programs import socket  # noqa: E402

TILE = 16


def f12_in_both(sc, tmp_path):
    """F12 in Cycles, then in DRT, on the same scene: (engine, channels, header) of each one's
    multilayer EXR in ``tmp_path``."""
    from test_addon import render_to

    for engine in ("CYCLES", "DRT"):
        sc.render.engine = engine
        chans, header = render_to(sc, tmp_path / f"{engine}.exr", multilayer=True)
        yield engine, chans, header


def shader_material(name, shader, inputs):
    """A material whose surface is one ``shader`` node with ``inputs`` ({name: value})."""
    m = bpy.data.materials.new(name)
    nt = m.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(node(nt, shader, inputs).outputs[0], out.inputs["Surface"])
    return m


def grey_principled(name, alpha=1.0, pass_index=0):
    """A material of one grey (0.5) Principled BSDF with ``alpha``: the pass tests' surfaces."""
    m = bpy.data.materials.new(name)
    nt = m.node_tree
    nt.nodes.clear()
    bsdf = node(nt, "ShaderNodeBsdfPrincipled", {"Base Color": (0.5, 0.5, 0.5, 1), "Alpha": alpha})
    nt.links.new(bsdf.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    m.pass_index = pass_index
    return m


def node(nt, kind, inputs=None, **props):
    """A new node of ``kind`` with properties set and inputs {index or name: socket or value}."""
    n = nt.nodes.new(kind)
    for k, v in props.items():
        setattr(n, k, v)
    for key, v in (inputs or {}).items():
        sock = n.inputs[key] if isinstance(key, int) else socket(n.inputs, key)
        if isinstance(v, bpy.types.NodeSocket):
            nt.links.new(v, sock)
        else:
            sock.default_value = v
    return n


def squash(nt, sock):
    """Per component atan(v)·0.3 + 0.5 as a colour socket."""
    sep = node(nt, "ShaderNodeSeparateXYZ", {0: sock})
    comb = node(nt, "ShaderNodeCombineXYZ")
    for i in range(3):
        a = node(nt, "ShaderNodeMath", {0: sep.outputs[i]}, operation="ARCTANGENT")
        m = node(nt, "ShaderNodeMath", {0: a.outputs[0], 1: 0.3, 2: 0.5}, operation="MULTIPLY_ADD")
        nt.links.new(m.outputs[0], comb.inputs[i])
    return comb.outputs[0]


def _material(name, case, shader=False):
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    if shader:  # the case builds the whole surface shader
        nt.links.new(case(nt, nt.nodes.new("ShaderNodeTexCoord").outputs["UV"]), out.inputs["Surface"])
        return mat
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 1.0
    uv = nt.nodes.new("ShaderNodeTexCoord").outputs["UV"]
    sock = case(nt, uv)
    nt.links.new(squash(nt, sock), em.inputs["Color"])
    nt.links.new(em.outputs[0], out.inputs["Surface"])
    return mat


def setup_scene(n):
    """Factory scene with an orthographic camera over [−1, 1]² and n×n·TILE pixels."""
    from test_addon import ensure_registered

    ensure_registered()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 1
    sc.cycles.use_denoising = False
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.max_bounces = 0
    sc.cycles.filter_width = 0.01  # both engines read Cycles's pixel filter
    sc.render.resolution_x = sc.render.resolution_y = n * TILE
    sc.render.resolution_percentage = 100
    sc.render.threads_mode = "FIXED"
    sc.render.threads = 1
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.world = bpy.data.worlds.new("w")
    sc.world.node_tree.nodes["Background"].inputs[1].default_value = 0.0
    cam = bpy.data.cameras.new("c")
    cam.type = "ORTHO"
    cam.ortho_scale = 2.0
    obj = bpy.data.objects.new("c", cam)
    obj.location = (0, 0, 1)
    sc.collection.objects.link(obj)
    sc.camera = obj
    sc.drt.samples = 1
    sc.drt.max_bounces = 0
    return sc


def _add_shape(shape, size, loc):
    """One tile's object: a plane (UV 0..1), a smooth UV sphere (normals and incoming
    directions vary over it), a plane seen from its back (backfacing) or an n-gon cap."""
    if shape == "ngon":  # an octagonal prism seen along its axis: the cap is an n-gon
        bpy.ops.mesh.primitive_cylinder_add(vertices=8, radius=0.45 * size, depth=0.1 * size, location=loc,
                                            end_fill_type="NGON", calc_uvs=True, rotation=(0, 0, 0.3))
        return
    if shape == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.45 * size, location=loc, segments=48, ring_count=24,
                                             rotation=(0.4, 0.3, 0.2))
        bpy.ops.object.shade_smooth()
    else:
        bpy.ops.mesh.primitive_plane_add(size=size, location=loc,
                                         rotation=(math.pi, 0, 0) if shape == "back_plane" else (0, 0, 0))


def add_sun(sc, strength, rotation):
    """A sun lamp of ``strength`` W/m² and angle 0 (a delta light: direct light is exact),
    turned by Euler ``rotation``, in the scene ``sc``."""
    light = bpy.data.lights.new("sun", "SUN")
    light.energy, light.angle = strength, 0.0
    obj = bpy.data.objects.new("sun", light)
    obj.rotation_euler = rotation
    sc.collection.objects.link(obj)
    return obj


def render_tiles(cases, n, tmp_path, tag="tiles", shader=False, sun=None, shape="plane"):
    """Cycles and DRT images (H, W, 3), top row first, of the cases on an n×n grid. shader: the
    cases return surface shader sockets (shown as they are, not squashed); sun: (strength,
    rotation) of a sun lamp with a zero angle (a delta light: direct light is exact); shape:
    what each tile shows (see ``_add_shape``)."""
    from addon.export import export_depsgraph
    from drt.render import render
    from drt.scene import scene_from_dict

    assert len(cases) <= n * n
    sc = setup_scene(n)
    size = 2.0 / n
    for k, case in enumerate(cases):
        r, c = divmod(k, n)
        _add_shape(shape, size, (-1 + (c + 0.5) * size, 1 - (r + 0.5) * size, 0))
        bpy.context.object.data.materials.append(_material(f"case{k}", case, shader))
        if hasattr(case, "setup"):  # a case that needs mesh data (colour attributes, ...)
            case.setup(bpy.context.object.data)
    if sun is not None:
        add_sun(sc, *sun)
    path = str(tmp_path / f"{tag}.exr")
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    w = h = n * TILE
    cycles = np.array(img.pixels[:], dtype=np.float64).reshape(h, w, 4)[::-1, :, :3]
    bpy.data.images.remove(img)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    film = render(scene_from_dict(res.header, res.arrays), threads=1)
    drt = np.asarray(film.combined, dtype=np.float64)[..., :3]
    return cycles, drt, res


def render_rgba_both(sc, path):
    """The current scene ``sc`` rendered RGBA by Cycles (written to ``path``, an EXR) and by
    DRT through the exporter: two (H, W, 4) float64 images, top row first. The export must
    warn of nothing."""
    from addon.export import export_depsgraph
    from drt.render import render
    from drt.scene import scene_from_dict

    sc.render.filepath = str(path)
    sc.render.image_settings.color_mode = "RGBA"
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(str(path))
    h, w = sc.render.resolution_y, sc.render.resolution_x
    cycles = np.array(img.pixels[:], dtype=np.float64).reshape(h, w, 4)[::-1]
    bpy.data.images.remove(img)
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    assert not res.warnings, res.warnings
    drt = np.asarray(render(scene_from_dict(res.header, res.arrays), threads=1).combined, np.float64)
    return cycles, drt


def tile(img, k, n):
    r, c = divmod(k, n)
    return img[r * TILE:(r + 1) * TILE, c * TILE:(c + 1) * TILE]


def tile_errors(cycles, drt, count, n):
    """Per case, the largest absolute difference over its tile."""
    return [float(np.abs(tile(cycles, k, n) - tile(drt, k, n)).max()) for k in range(count)]


def make_image(name, w=8, h=6, colorspace="sRGB", seed=1, path=None):
    """A byte image of random colours (alpha 1), saved as PNG at ``path`` and reloaded (so it
    behaves as a user's image file), or kept generated when path is None."""
    rng = np.random.default_rng(seed)
    px = np.ones((h, w, 4), np.float32)
    px[..., :3] = rng.integers(0, 256, (h, w, 3)) / 255.0
    img = bpy.data.images.new(name, w, h, alpha=False, float_buffer=False)
    img.pixels.foreach_set(px.reshape(-1))
    if path is not None:
        img.filepath_raw = path
        img.file_format = "PNG"
        img.save()
        bpy.data.images.remove(img)
        img = bpy.data.images.load(path)
    img.colorspace_settings.name = colorspace
    return img


def mapping(nt, sock, loc=(0, 0, 0), rot=(0, 0, 0), scale=(1, 1, 1), kind="POINT"):
    return node(nt, "ShaderNodeMapping", {"Vector": sock, "Location": loc, "Rotation": rot, "Scale": scale},
                vector_type=kind).outputs[0]


def centred(nt, uv):
    """UV mapped to [−1, 1]² (z 0): the domain radial/spherical gradients are interesting on."""
    return mapping(nt, uv, loc=(-1, -1, 0), scale=(2, 2, 1))


__all__ = ["math", "node", "squash", "render_tiles", "tile_errors", "make_image", "mapping", "centred"]
