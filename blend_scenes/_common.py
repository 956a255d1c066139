"""Shared helpers of the blend_scenes scripts (bpy 5.0 module and Blender 3.4 binary alike).

Each scene script builds its scene from factory settings, then ``finish()`` applies the
reference render settings, saves ``<name>.blend`` and, when the add-on's exporter can run
(numpy available), ``<name>.npz`` next to it (or in ``--out DIR``).

Run one:   python blend_scenes/cornell_box.py [--out DIR] [--no-npz]
or:        blender -b --factory-startup --python blend_scenes/cornell_box.py -- --out DIR
"""

import argparse
import math
import os
import sys

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def args():
    """Script options: after ``--`` under ``blender --python``, else the script's own argv."""
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    p = argparse.ArgumentParser()
    p.add_argument("--out", default=HERE)
    p.add_argument("--no-npz", action="store_true")
    return p.parse_known_args(argv)[0]


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("World")
    scene.world = world
    set_world(world, (0.0, 0.0, 0.0), 1.0)
    return scene


def _new_material(name):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    return mat, nodes, out


def _rgba(c):
    return (c[0], c[1], c[2], 1.0)


def diffuse(name, color):
    mat, nodes, out = _new_material(name)
    n = nodes.new("ShaderNodeBsdfDiffuse")
    n.inputs["Color"].default_value = _rgba(color)
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    mat.diffuse_color = _rgba(color)
    return mat


def glossy(name, color, roughness):
    mat, nodes, out = _new_material(name)
    n = nodes.new("ShaderNodeBsdfGlossy" if bpy.app.version < (4, 0, 0) else "ShaderNodeBsdfAnisotropic")
    n.distribution = "GGX"
    n.inputs["Color"].default_value = _rgba(color)
    n.inputs["Roughness"].default_value = roughness
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    return mat


def glass(name, color, roughness, ior):
    mat, nodes, out = _new_material(name)
    n = nodes.new("ShaderNodeBsdfGlass")
    n.distribution = "GGX" if roughness > 0 else ("SHARP" if bpy.app.version < (4, 0, 0) else "GGX")
    n.inputs["Color"].default_value = _rgba(color)
    n.inputs["Roughness"].default_value = roughness
    n.inputs["IOR"].default_value = ior
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    return mat


def emission(name, color, strength):
    mat, nodes, out = _new_material(name)
    n = nodes.new("ShaderNodeEmission")
    n.inputs["Color"].default_value = _rgba(color)
    n.inputs["Strength"].default_value = strength
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    return mat


def mix(name, fac, a, b):
    """Mix Shader of two single-node materials' shaders (copied into one tree)."""
    mat, nodes, out = _new_material(name)
    m = nodes.new("ShaderNodeMixShader")
    m.inputs[0].default_value = fac
    for i, src in ((1, a), (2, b)):
        node = src["node"]
        n = nodes.new(node)
        for k, v in src.items():
            if k != "node":
                if k == "distribution":
                    n.distribution = v
                else:
                    n.inputs[k].default_value = v
        mat.node_tree.links.new(n.outputs[0], m.inputs[i])
    mat.node_tree.links.new(m.outputs[0], out.inputs["Surface"])
    return mat


def volume_material(name, node="ShaderNodeVolumePrincipled", surface=None, **inputs):
    """A material with a volume shader on its Volume output (and optionally a surface node
    dict {"node": ..., input: value} on its Surface output; None: volume only)."""
    mat, nodes, out = _new_material(name)
    v = nodes.new(node)
    for k, val in inputs.items():
        v.inputs[k.replace("_", " ")].default_value = _rgba(val) if isinstance(val, tuple) and len(val) == 3 else val
    mat.node_tree.links.new(v.outputs[0], out.inputs["Volume"])
    if surface is not None:
        s = nodes.new(surface["node"])
        for k, val in surface.items():
            if k != "node":
                s.inputs[k].default_value = val
        mat.node_tree.links.new(s.outputs[0], out.inputs["Surface"])
    return mat


def set_world(world, color, strength):
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nodes = world.node_tree.nodes
    nodes.clear()
    out = nodes.new("ShaderNodeOutputWorld")
    bg = nodes.new("ShaderNodeBackground")
    bg.inputs["Color"].default_value = _rgba(color)
    bg.inputs["Strength"].default_value = strength
    world.node_tree.links.new(bg.outputs[0], out.inputs["Surface"])
    world.color = color


def mesh_object(name, verts, faces, materials, face_materials=None, smooth=False):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    for m in materials:
        mesh.materials.append(m)
    if face_materials is not None:
        mesh.polygons.foreach_set("material_index", face_materials)
    if smooth:
        mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def quad(name, center, size, material, rotation=(0.0, 0.0, 0.0)):
    """A square (or (sx, sy) rectangle) in its local XY plane, facing +Z, then rotated."""
    sx, sy = (size, size) if not hasattr(size, "__len__") else size
    v = [(-sx / 2, -sy / 2, 0), (sx / 2, -sy / 2, 0), (sx / 2, sy / 2, 0), (-sx / 2, sy / 2, 0)]
    obj = mesh_object(name, v, [(0, 1, 2, 3)], [material])
    obj.location = center
    obj.rotation_euler = rotation
    return obj


def box(name, size, location, material, rotation_z=0.0):
    sx, sy, sz = size
    v = [(x * sx / 2, y * sy / 2, z * sz / 2) for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)]
    f = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    obj = mesh_object(name, v, f, [material])
    obj.location = location
    obj.rotation_euler = (0.0, 0.0, rotation_z)
    return obj


def uv_sphere(name, radius, location, material, segments=32, rings=16):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=location,
                                         segments=segments, ring_count=rings)
    obj = bpy.context.active_object
    obj.name = name
    obj.data.name = name
    obj.data.materials.append(material)
    obj.data.polygons.foreach_set("use_smooth", [True] * len(obj.data.polygons))
    obj.data.update()
    return obj


def camera(location, target, lens=50.0, name="Camera"):
    from mathutils import Vector
    cam = bpy.data.cameras.new(name)
    cam.lens = lens
    obj = bpy.data.objects.new(name, cam)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    d = Vector(target) - Vector(location)
    obj.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = obj
    return obj


def light(name, kind, location, rotation=(0.0, 0.0, 0.0), **props):
    data = bpy.data.lights.new(name, kind)
    for k, v in props.items():
        if hasattr(data, k):
            setattr(data, k, v)
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    obj.rotation_euler = rotation
    return obj


def reference_settings(scene, samples=1024):
    """Cycles settings that make it a fair reference (blender-conventions.md)."""
    c = getattr(scene, "cycles", None)
    if c is not None:
        c.samples = samples
        c.use_denoising = False
        c.sample_clamp_direct = 0.0
        c.sample_clamp_indirect = 0.0
        c.blur_glossy = 0.0
        c.use_adaptive_sampling = False
        c.filter_width = 1.5
        c.max_bounces, c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces = 12, 4, 4, 12
        # DRT's Volume bounces (Cycles's default 0 when the add-on is not registered)
        c.volume_bounces = int(getattr(getattr(scene, "drt", None), "volume_bounces", 0))
        c.transparent_max_bounces = int(getattr(getattr(scene, "drt", None), "transparent_bounces", 8))
        c.caustics_reflective = True
        c.caustics_refractive = True
        if hasattr(c, "use_light_tree"):
            c.use_light_tree = True
    scene.render.filter_size = 1.5
    scene.render.threads_mode = "FIXED"
    scene.render.threads = 2


def finish(scene, name, resolution=(96, 96), samples=16, out=None, npz=True):
    """Render settings, save ``name``.blend and export ``name``.npz; returns the paths."""
    opts = args()
    out = out or opts.out
    os.makedirs(out, exist_ok=True)
    r = scene.render
    r.resolution_x, r.resolution_y = resolution
    r.resolution_percentage = 100
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    reference_settings(scene)
    if _ensure_addon():
        scene.render.engine = "DRT"
        scene.drt.samples = samples
    blend = os.path.join(out, f"{name}.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, compress=True)
    npz_path = None
    if npz and not opts.no_npz and _ensure_addon():
        npz_path = os.path.join(out, f"{name}.npz")
        # Export what the saved file holds (mesh generators need not be deterministic).
        bpy.ops.wm.open_mainfile(filepath=blend)
        export_npz(npz_path)
    print(f"saved {blend}" + (f" and {npz_path}" if npz_path else ""))
    return blend, npz_path


def _ensure_addon() -> bool:
    """Register the add-on from the checkout if it is not already (False if it cannot run)."""
    if hasattr(bpy.types.Scene, "drt"):
        return True
    try:
        import numpy  # noqa: F401
    except ImportError:
        return False
    if REPO not in sys.path:
        sys.path.insert(0, REPO)
    import addon
    addon.register()
    return True


def export_npz(path):
    """Export the current file's scene (at its current frame) to a DRT scene file."""
    if REPO not in sys.path:
        sys.path.insert(0, REPO)
    from addon.export.blend import export_current, save_npz
    res = export_current()
    save_npz(path, res.header, res.arrays)
    return res


def make_linear(idblock):
    """Set every keyframe of an ID's action to LINEAR (Cycles conventions: test with linear keys)."""
    ad = idblock.animation_data
    if ad is None or ad.action is None:
        return
    action = ad.action
    if hasattr(action, "layers") and len(action.layers):  # 4.4+ layered actions
        from bpy_extras.anim_utils import action_get_channelbag_for_slot
        fcurves = action_get_channelbag_for_slot(action, ad.action_slot).fcurves
    else:
        fcurves = action.fcurves
    for fc in fcurves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


def deg(x):
    return math.radians(x)
