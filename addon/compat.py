"""Everything that differs between the Blender versions DRT supports (3.4 and 4.2+ / 5.0).

Keep version branches here and nowhere else: the rest of the add-on asks this module.
Checks are by feature (``hasattr``), not by version number, where Blender allows it.
"""

import importlib
import os
import sys

import bpy
import numpy as np

BLENDER_VERSION = bpy.app.version

# EEVEE's engine id: BLENDER_EEVEE in <= 4.1 and again in 5.0, BLENDER_EEVEE_NEXT in 4.2-4.4.
EEVEE_ID = "BLENDER_EEVEE_NEXT" if (4, 2, 0) <= BLENDER_VERSION < (5, 0, 0) else "BLENDER_EEVEE"


# --- the core renderer --------------------------------------------------------------------------

def _load_embree_isolated() -> None:
    """Import embreex so that its bundled Embree/TBB bind to their own symbols.

    Blender links its own TBB (and Embree); without RTLD_DEEPBIND the wheel's libembree4
    resolves TBB symbols to Blender's copy of a different version and crashes on the first
    ray query (seen with Debian's Blender 3.4.1). Linux only; elsewhere a plain import.
    """
    if "embreex.rtcore_scene" in sys.modules:
        return
    deepbind = getattr(os, "RTLD_DEEPBIND", 0)
    if not deepbind or not sys.platform.startswith("linux"):
        return
    old = sys.getdlopenflags()
    sys.setdlopenflags(os.RTLD_NOW | deepbind)
    try:
        importlib.import_module("embreex.rtcore")
        importlib.import_module("embreex.rtcore_scene")
        importlib.import_module("embreex.mesh_construction")
    except ImportError:
        pass  # reported by the core's own import with its message
    finally:
        sys.setdlopenflags(old)


def core_module(name: str = ""):
    """Import the core (``drt``) or one of its modules (``core_module("render")``).

    Inside an installed extension / legacy add-on the core is bundled as the sub-package
    ``<addon>.drt``; in a development checkout the pip-installed ``drt`` is used.
    """
    _load_embree_isolated()
    try:
        from . import drt as drt_core  # bundled sub-package
    except ImportError:
        import drt as drt_core  # development mode: pip install -e .
    if not name:
        return drt_core
    return importlib.import_module(f"{drt_core.__name__}.{name}")


# --- meshes -------------------------------------------------------------------------------------

def prepare_mesh(mesh) -> None:
    """Make loop triangles (and, on 3.4, split normals) available on an evaluated mesh."""
    if hasattr(mesh, "calc_normals_split"):  # <= 4.0
        mesh.calc_normals_split()
    mesh.calc_loop_triangles()


def mesh_is_flat(mesh) -> bool:
    """True when every face is flat shaded (no smooth faces, no custom normals)."""
    if hasattr(mesh, "normals_domain"):  # 4.1+
        return mesh.normals_domain == "FACE"
    if getattr(mesh, "has_custom_normals", False):
        return False
    n = len(mesh.polygons)
    if n == 0:
        return True
    smooth = np.empty(n, dtype=bool)
    mesh.polygons.foreach_get("use_smooth", smooth)
    return not smooth.any()


def _attribute(mesh, name, domain, kind, width):
    """A built-in attribute as a flat numpy array, or None when the mesh lacks it (3.4)."""
    attrs = getattr(mesh, "attributes", None)
    attr = attrs.get(name) if attrs is not None else None
    if attr is None or attr.domain != domain:
        return None
    out = np.empty(len(attr.data) * width, dtype=np.float32 if kind == "vector" else np.int32)
    attr.data.foreach_get(kind, out)
    return out


def positions(mesh) -> np.ndarray:
    """Vertex positions, (V, 3) float32, object local space."""
    out = _attribute(mesh, "position", "POINT", "vector", 3)
    if out is None:
        out = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", out)
    return out.reshape(-1, 3)


#: meshes with at least this many loop triangles get them from their raw arrays
#: (``drt.mesh_tessellation``) instead of ``loop_triangles.foreach_get``, which walks Blender's RNA
#: per triangle (~70 ms a million); below it the RNA read costs less than the first use of the
#: compiled kernel in a fresh install
RAW_TRIANGLES_MIN = 100_000


def triangle_corners(mesh) -> np.ndarray:
    """Corner (loop) indices of each loop triangle, (T, 3) int32: Blender's own loop triangles,
    rebuilt from the raw arrays for a large mesh of triangles and quads (exactly Blender's; see
    ``drt.mesh_tessellation``), read through RNA otherwise."""
    n_tri = len(mesh.loop_triangles)
    if n_tri >= RAW_TRIANGLES_MIN:
        fast = _triangle_corners_from_faces(mesh, n_tri)
        if fast is not None:
            return fast
    out = np.empty(n_tri * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", out)
    return out.reshape(-1, 3)


def _triangle_corners_from_faces(mesh, n_tri: int) -> np.ndarray | None:
    """``triangle_corners`` from each triangle's face, the corners' vertices and the positions
    (all raw copies), or None where that cannot be exact: an n-gon, a quad whose cut depends on
    rounding, or a Blender without these arrays. Custom normals (every imported OBJ, FBX or
    glTF mesh has them) leave the cut alone up to Blender 5.0 (checked: flipped and random
    custom normals, tests/test_export.py); later versions may derive cached face normals from
    them, so there such meshes keep the RNA read."""
    if not hasattr(mesh, "loop_triangle_polygons"):
        return None
    if getattr(mesh, "has_custom_normals", False) and BLENDER_VERSION >= (5, 1, 0):
        return None
    cv = _attribute(mesh, ".corner_vert", "CORNER", "value", 1)
    pos = _attribute(mesh, "position", "POINT", "vector", 3)
    if cv is None or pos is None:
        return None
    faces = np.empty(n_tri, dtype=np.int32)
    mesh.loop_triangle_polygons.foreach_get("value", faces)
    return core_module("mesh_tessellation").corner_triangles(faces, cv, pos)


def corner_verts(mesh) -> np.ndarray:
    """Vertex index of each corner, (L,) int32."""
    out = _attribute(mesh, ".corner_vert", "CORNER", "value", 1)
    if out is None:
        out = np.empty(len(mesh.loops), dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", out)
    return out


def triangle_material_slots(mesh) -> np.ndarray:
    """Material slot index of each loop triangle, (T,) int32."""
    n_tri = len(mesh.loop_triangles)
    if hasattr(mesh, "loop_triangle_polygons"):  # 3.6+: fast face lookup
        face = np.empty(n_tri, dtype=np.int32)
        mesh.loop_triangle_polygons.foreach_get("value", face)
        slots = _attribute(mesh, "material_index", "FACE", "value", 1)
        return np.zeros(n_tri, np.int32) if slots is None else slots[face]
    out = np.empty(n_tri, dtype=np.int32)
    mesh.loop_triangles.foreach_get("material_index", out)
    return out


def triangle_normals(mesh, tri_corners: np.ndarray, tri_verts: np.ndarray) -> np.ndarray | None:
    """Per-corner shading normals of each triangle (T, 3, 3) float32, None when all flat."""
    if mesh_is_flat(mesh):
        return None
    if hasattr(mesh, "corner_normals"):  # 4.1+
        if mesh.normals_domain == "POINT":
            vn = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
            mesh.vertex_normals.foreach_get("vector", vn)
            return np.take(vn.reshape(-1, 3), tri_verts, axis=0)
        cn = np.empty(len(mesh.loops) * 3, dtype=np.float32)
        mesh.corner_normals.foreach_get("vector", cn)
    else:  # <= 4.0: calc_normals_split() filled loop normals
        cn = np.empty(len(mesh.loops) * 3, dtype=np.float32)
        mesh.loops.foreach_get("normal", cn)
    return np.take(cn.reshape(-1, 3), tri_corners, axis=0)


def active_uvs(mesh) -> np.ndarray | None:
    """The active *render* UV map per corner (Cycles's default UV), (L, 2) float32, or None."""
    layer = next((uv for uv in mesh.uv_layers if uv.active_render), None) or mesh.uv_layers.active
    if layer is None or len(mesh.loops) == 0:
        return None
    return uv_layer_values(mesh, layer)


def triangle_tangents(mesh, uv_name: str, tri_corners: np.ndarray):
    """MikkTSpace tangents of a UV map (``""``: the active render map, as Cycles's Normal Map
    default) at each triangle corner: ((T, 3, 3) float32 tangents, (T, 3) float32 bitangent
    signs), or None when the mesh has no such map. Blender computes tangents only on triangles
    and quads; a mesh with n-gons gets them from a copy made of its loop triangles (what the
    renderer draws)."""
    layer = (mesh.uv_layers.get(uv_name) if uv_name else
             next((uv for uv in mesh.uv_layers if uv.active_render), None) or mesh.uv_layers.active)
    if layer is None:
        return None
    try:
        mesh.calc_tangents(uvmap=layer.name)
    except RuntimeError:  # n-gons
        return _tangents_of_triangles(mesh, layer, tri_corners)
    n = len(mesh.loops)
    tangent = np.empty(n * 3, np.float32)
    sign = np.empty(n, np.float32)
    mesh.loops.foreach_get("tangent", tangent)
    mesh.loops.foreach_get("bitangent_sign", sign)
    mesh.free_tangents()
    return np.take(tangent.reshape(n, 3), tri_corners, axis=0), np.take(sign, tri_corners)


def _tangents_of_triangles(mesh, layer, tri_corners: np.ndarray):
    """``triangle_tangents`` through a temporary mesh whose faces are ``mesh``'s loop
    triangles (same vertices, UVs and smooth flags)."""
    import bpy

    t = len(tri_corners)
    tri_verts = corner_verts(mesh)[tri_corners]
    pos = positions(mesh)
    uv = uv_layer_values(mesh, layer)[tri_corners].reshape(-1, 2)
    smooth = np.zeros(len(mesh.polygons), bool)
    mesh.polygons.foreach_get("use_smooth", smooth)
    if hasattr(mesh, "loop_triangle_polygons"):
        poly = np.empty(t, np.int32)
        mesh.loop_triangle_polygons.foreach_get("value", poly)
    else:
        poly = np.empty(t, np.int32)
        mesh.loop_triangles.foreach_get("polygon_index", poly)
    tmp = bpy.data.meshes.new("drt_tangents")
    try:
        tmp.vertices.add(len(pos))
        tmp.vertices.foreach_set("co", np.ascontiguousarray(pos, np.float32).reshape(-1))
        tmp.loops.add(3 * t)
        tmp.loops.foreach_set("vertex_index", tri_verts.astype(np.int32).reshape(-1))
        tmp.polygons.add(t)
        tmp.polygons.foreach_set("loop_start", np.arange(0, 3 * t, 3, dtype=np.int32))
        tmp.polygons.foreach_set("use_smooth", smooth[poly])
        tmp.update()
        tl = tmp.uv_layers.new(name="uv")
        tl.data.foreach_set("uv", np.ascontiguousarray(uv, np.float32).reshape(-1))
        tmp.calc_tangents(uvmap="uv")
        tangent = np.empty(9 * t, np.float32)
        sign = np.empty(3 * t, np.float32)
        tmp.loops.foreach_get("tangent", tangent)
        tmp.loops.foreach_get("bitangent_sign", sign)
        return tangent.reshape(t, 3, 3), sign.reshape(t, 3)
    except RuntimeError:
        return None
    finally:
        bpy.data.meshes.remove(tmp)


def uv_layer_values(mesh, layer) -> np.ndarray:
    """UV map ``layer`` per corner, (L, 2) float32."""
    out = np.empty(len(mesh.loops) * 2, dtype=np.float32)
    if hasattr(layer, "uv"):  # 3.5+: a float2 attribute, much faster than .data
        layer.uv.foreach_get("vector", out)
    else:
        layer.data.foreach_get("uv", out)
    return out.reshape(-1, 2)


# --- materials ----------------------------------------------------------------------------------

# Principled BSDF socket names: 4.0 renamed several inputs.
PRINCIPLED_INPUTS = {
    "transmission": ("Transmission Weight", "Transmission"),
    "emission_color": ("Emission Color", "Emission"),
    "specular": ("Specular IOR Level", "Specular"),
    "specular_tint": ("Specular Tint",),
    "coat": ("Coat Weight", "Clearcoat"),
    "sheen": ("Sheen Weight", "Sheen"),
    "subsurface": ("Subsurface Weight", "Subsurface"),
}


def find_input(node, key_or_names):
    """A node input socket by a key of PRINCIPLED_INPUTS or a tuple of candidate names."""
    names = PRINCIPLED_INPUTS.get(key_or_names, (key_or_names,)) if isinstance(key_or_names, str) \
        else key_or_names
    for name in names:
        sock = node.inputs.get(name)
        if sock is not None:
            return sock
    return None


def material_node_tree(material):
    """The material's shader node tree, or None when it has none (viewport color only).

    5.0 deprecates ``Material.use_nodes`` (always node based); older files may switch it off.
    """
    tree = material.node_tree
    if tree is None:
        return None
    if BLENDER_VERSION < (5, 0, 0) and not material.use_nodes:
        return None
    return tree


def world_node_tree(world):
    tree = world.node_tree
    if tree is None:
        return None
    if BLENDER_VERSION < (5, 0, 0) and not world.use_nodes:
        return None
    return tree


# --- lights -------------------------------------------------------------------------------------

def light_color(light) -> list:
    """Light color including the blackbody temperature tint (4.5+)."""
    c = np.array(light.color[:], dtype=np.float64)
    if getattr(light, "use_temperature", False):
        c = c * np.array(light.temperature_color[:], dtype=np.float64)
    return c.tolist()


def light_power_scale(light) -> float:
    """Multiplier on ``energy``: 2^exposure (4.0+)."""
    return float(2.0 ** getattr(light, "exposure", 0.0))


def light_normalized(light) -> bool:
    """4.0+ area lights can switch off power normalisation by area."""
    return bool(getattr(light, "normalize", True))


def light_soft_falloff(light) -> bool:
    """4.0+ point/spot ``use_soft_falloff``; 3.4 always behaves as soft falloff on."""
    return bool(getattr(light, "use_soft_falloff", True))


# --- render engine ------------------------------------------------------------------------------

def set_engine_flags(cls) -> None:
    """Class flags that exist only in some versions."""
    cls.bl_use_shading_nodes_custom = False  # read standard Cycles/EEVEE node trees
    cls.bl_use_eevee_viewport = True  # Material Preview without our own viewport code
    cls.bl_use_postprocess = True
    cls.bl_use_preview = False


def preview_pixel_size(engine, scene) -> int:
    """Blender's viewport pixel size (Render > Performance > Viewport > Pixel Size; AUTO follows
    the UI scale / retina factor). ``RenderEngine.get_preview_pixel_size`` exists in 3.4 and
    5.0; 1 when a build lacks it."""
    fn = getattr(engine, "get_preview_pixel_size", None)
    return max(1, int(fn(scene))) if fn is not None else 1


def set_pass_pixels(render_pass, img: np.ndarray) -> None:
    """Write an (h, w, c) float32 bottom-row-first image into a RenderPass.

    4.x/5.0 accept a flat ``rect.foreach_set``; 3.4 wants ``rect`` assigned (h·w, c) rows.
    """
    flat = img.reshape(-1)
    try:
        render_pass.rect.foreach_set(flat)
    except (TypeError, AttributeError):
        render_pass.rect = img.reshape(-1, img.shape[-1])


#: view-layer passes Cycles renders and DRT does not (yet): (property, name in the warning)
_UNRENDERED_PASSES = (
    ("use_pass_vector", "Vector"),
    ("use_pass_diffuse_direct", "Diffuse Direct"), ("use_pass_diffuse_indirect", "Diffuse Indirect"),
    ("use_pass_glossy_direct", "Glossy Direct"), ("use_pass_glossy_indirect", "Glossy Indirect"),
    ("use_pass_glossy_color", "Glossy Color"), ("use_pass_transmission_direct", "Transmission Direct"),
    ("use_pass_transmission_indirect", "Transmission Indirect"),
    ("use_pass_transmission_color", "Transmission Color"), ("use_pass_shadow", "Shadow"),
)
_UNRENDERED_CYCLES_PASSES = (
    ("use_pass_volume_direct", "Volume Direct"), ("use_pass_volume_indirect", "Volume Indirect"),
    ("use_pass_shadow_catcher", "Shadow Catcher"),
)


#: render passes Blender renamed (its RE_PASSNAME_* names; bpy 5.0 measured: Cycles writes
#: "Diffuse Color", "Object Index", "Material Index"); DRT registers each under the running
#: Blender's name, as Cycles does, so a compositing tree made with Cycles finds its sockets
_RENAMED_PASSES = {"DiffCol": "Diffuse Color", "IndexOB": "Object Index", "IndexMA": "Material Index",
                   "Emit": "Emission", "Env": "Environment", "AO": "Ambient Occlusion"}
_PASSES_RENAMED_IN = (4, 2, 0)


def pass_name(name: str) -> str:
    """The running Blender's name of render pass ``name`` (given by its pre-4.2 name)."""
    return _RENAMED_PASSES.get(name, name) if BLENDER_VERSION >= _PASSES_RENAMED_IN else name


def unrendered_passes(view_layer) -> list:
    """Names of the passes the view layer enables that DRT does not render (they are left out
    of the render result), AOVs and light groups included."""
    names = [name for prop, name in _UNRENDERED_PASSES if getattr(view_layer, prop, False)]
    cyc = getattr(view_layer, "cycles", None)
    names += [name for prop, name in _UNRENDERED_CYCLES_PASSES if getattr(cyc, prop, False)]
    names += [f"AOV '{a.name}'" for a in getattr(view_layer, "aovs", ())]
    names += [f"light group '{g.name}'" for g in getattr(view_layer, "lightgroups", ())]
    return names


def view_layer_pass_flags(view_layer) -> dict:
    """Which of the passes DRT can fill are enabled in the view layer."""
    return {
        "depth": bool(getattr(view_layer, "use_pass_z", False)),
        "normal": bool(getattr(view_layer, "use_pass_normal", False)),
        "albedo": bool(getattr(view_layer, "use_pass_diffuse_color", False)),
        "mist": bool(getattr(view_layer, "use_pass_mist", False)),
        "object_index": bool(getattr(view_layer, "use_pass_object_index", False)),
        "material_index": bool(getattr(view_layer, "use_pass_material_index", False)),
        "position": bool(getattr(view_layer, "use_pass_position", False)),
        "uv": bool(getattr(view_layer, "use_pass_uv", False)),
        "emission": bool(getattr(view_layer, "use_pass_emit", False)),
        "environment": bool(getattr(view_layer, "use_pass_environment", False)),
        "ao": bool(getattr(view_layer, "use_pass_ambient_occlusion", False)),
    }
