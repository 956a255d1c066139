"""Triangle meshes handed to Embree without embreex's element-by-element copy.

embreex's ``TriangleMesh`` copies vertices and indices into Embree's buffers one numpy element
at a time through Python indexing: ~1.3 s of CPU for a 1M-triangle mesh, more than Embree's
BVH build itself. Embree can instead read the renderer's own arrays in place
(``rtcSetSharedGeometryBuffer``). embreex exposes no handle for that, so this module calls the
Embree library that embreex loaded through ctypes, with the scene and device handles read from
embreex's objects; every assumption about their layout is checked before use (``_handles``)
and any mismatch (another embreex build, no library found) falls back to ``TriangleMesh``.
Only opaque handles and enum values cross the boundary, no Embree structs.
"""

from __future__ import annotations

import ctypes
import glob
import os

import numpy as np
from embreex import rtcore as _rtc
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

# Embree 4 enum values (rtcore_geometry.h, rtcore_buffer.h, rtcore_common.h, rtcore_device.h)
_BUILD_QUALITY_LOW = 0
_GEOMETRY_TYPE_TRIANGLE, _GEOMETRY_TYPE_INSTANCE = 0, 121
_BUFFER_TYPE_INDEX, _BUFFER_TYPE_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_FORMAT_FLOAT3X4_ROW_MAJOR, _FORMAT_FLOAT3X4_COLUMN_MAJOR = 0x9134, 0x9234
_DEVICE_PROPERTY_VERSION_MAJOR = 1

_PTR = ctypes.sizeof(ctypes.c_void_p)
_api = None  # (library, scene handle offset, device handle offset) once checked; False: unusable


def _library():
    """The Embree library embreex's extension modules are linked against (already loaded in this
    process, so ctypes gets the same copy and its devices), or None."""
    here = os.path.dirname(_rtc.__file__)
    patterns = [os.path.join(here, "..", "embreex.libs", "*embree4*"), os.path.join(here, ".dylibs", "*embree4*"),
                os.path.join(here, "*embree4*")]
    for path in sorted(p for pat in patterns for p in glob.glob(pat)):
        if path.endswith((".so", ".dylib", ".dll")) or ".so." in path:
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            vp, u, sz = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
            for name, res, args in (
                ("rtcGetDeviceProperty", ctypes.c_ssize_t, [vp, ctypes.c_int]),
                ("rtcGetSceneDevice", vp, [vp]),
                ("rtcReleaseDevice", None, [vp]),
                ("rtcGetDeviceError", ctypes.c_int, [vp]),
                ("rtcNewGeometry", vp, [vp, ctypes.c_int]),
                ("rtcSetSharedGeometryBuffer", None, [vp, ctypes.c_int, u, ctypes.c_int, vp, sz, sz, sz]),
                ("rtcCommitGeometry", None, [vp]),
                ("rtcAttachGeometry", u, [vp, vp]),
                ("rtcReleaseGeometry", None, [vp]),
                ("rtcSetGeometryTimeStepCount", None, [vp, u]),
                ("rtcSetGeometryBuildQuality", None, [vp, ctypes.c_int]),
                ("rtcSetSceneBuildQuality", None, [vp, ctypes.c_int]),
                ("rtcSetGeometryInstancedScene", None, [vp, vp]),
                ("rtcSetGeometryTransform", None, [vp, u, ctypes.c_int, vp]),
                ("rtcSetGeometryTransformQuaternion", None, [vp, u, vp]),
            ):
                fn = getattr(lib, name, None)
                if fn is None:
                    break
                fn.restype, fn.argtypes = res, args
            else:
                return lib
    return None


def _words(obj) -> list[int]:
    """The pointer-sized words of a Python object's C struct (its basic size only)."""
    raw = ctypes.string_at(id(obj), type(obj).__basicsize__)
    return [int.from_bytes(raw[i:i + _PTR], "little" if np.little_endian else "big")
            for i in range(0, len(raw) - _PTR + 1, _PTR)]


def _handles():
    """(library, byte offset of the RTCScene in an EmbreeScene, of the RTCDevice in an
    EmbreeDevice) once embreex's object layout is confirmed, else None (see ``_probe``)."""
    global _api
    if _api is None:
        try:
            _api = _probe() or False
        except Exception:  # noqa: BLE001 - any surprise means: use embreex's own copy
            _api = False
    return _api or None


def _probe():
    """Confirm embreex's layout: ``EmbreeDevice`` = object header + RTCDevice; ``EmbreeScene``
    = object header + RTCScene + ``is_committed`` (int) + the EmbreeDevice object. Checked with
    reads inside the objects (sizes, the device object's address, marker values written to
    ``is_committed``) before Embree sees any handle; then Embree itself confirms them: the device
    reports major version 4 and the scene reports that device."""
    lib = _library()
    if lib is None:
        return None
    device = _rtc.EmbreeDevice()
    scene = rtcs.EmbreeScene(device)
    if type(device).__basicsize__ != 3 * _PTR or type(scene).__basicsize__ != 5 * _PTR:
        return None
    if _words(scene)[4] != id(device):
        return None
    for marker in (0x5A17C3E1, 0x2B6D9F04):
        scene.is_committed = marker
        if _words(scene)[3] & 0xFFFFFFFF != marker:
            return None
    scene.is_committed = 0
    scene_handle, device_handle = _words(scene)[2], _words(device)[2]
    if not scene_handle or not device_handle:
        return None
    if lib.rtcGetDeviceProperty(device_handle, _DEVICE_PROPERTY_VERSION_MAJOR) != 4:
        return None
    owner = lib.rtcGetSceneDevice(scene_handle)
    if owner:
        lib.rtcReleaseDevice(owner)  # rtcGetSceneDevice retains the device it returns
    if owner != device_handle:
        return None
    return lib, 2 * _PTR, 2 * _PTR


class _Scene(rtcs.EmbreeScene):
    """An embreex scene that also holds the arrays Embree reads in place, so they live exactly
    as long as the scene (a Python subclass: the C layout of its EmbreeScene part is unchanged)."""


def new_device():
    """An Embree device (embreex ``EmbreeDevice``) for scenes that must share one: a scene of
    instances (``instance_scene``) can only instance scenes of its own device."""
    return _rtc.EmbreeDevice()


def triangle_scene(positions: np.ndarray, triangles: np.ndarray, fast_build: bool = False,
                   device=None) -> rtcs.EmbreeScene:
    """An Embree scene (embreex ``EmbreeScene``, for ``run``) of one triangle mesh.

    positions: (V, 3) vertex positions, stored as float32; triangles: (T, 3) vertex indices in
    [0, V). Embree reads float32 positions (plus 4 bytes of padding) and int32 indices from
    arrays kept on the scene; without the checked handles it copies them (``TriangleMesh``).

    fast_build: Embree's low build quality (a Morton-code BVH, what Cycles's viewport uses)
    instead of its default (binned SAH). On a 1M-triangle mesh it builds in 0.04-0.13 s
    instead of 0.18-0.28 s on two cores and answers queries ~8 % slower: worth it when the
    render traces few rays per triangle (``drt.trace.Tracer``'s rule). Hits are the same:
    only the tree differs, not the ray-triangle test.

    device: the ``new_device`` to build on (default: a device of the scene's own)."""
    device = device or _rtc.EmbreeDevice()
    scene = _Scene(device)  # the scene keeps its device alive
    api = _handles()
    if api is None or not len(triangles) or not _attach_shared(api, scene, device, positions, triangles,
                                                               fast_build=fast_build):
        TriangleMesh(scene, np.asarray(positions, np.float32), np.asarray(triangles, np.int32))
    return scene


def deforming_scene(positions: np.ndarray, positions_close: np.ndarray, triangles: np.ndarray, device=None):
    """An Embree scene of one triangle mesh whose vertices move linearly from ``positions``
    (ray time 0) to ``positions_close`` (ray time 1): Embree's motion blur with two time steps,
    queried by ``drt.embree_direct`` with each ray's shutter fraction as its time (embreex's
    ``run`` has no ray times). None without the checked handles. device: as ``triangle_scene``'s."""
    api = _handles()
    if api is None or not len(triangles):
        return None
    device = device or _rtc.EmbreeDevice()
    scene = _Scene(device)
    if not _attach_shared(api, scene, device, positions, triangles, positions_close):
        return None
    return scene


def _attach_shared(api, scene, device, positions, triangles, positions_close=None, fast_build=False) -> bool:
    lib, scene_offset, device_offset = api
    v = len(positions)

    def vertex_buffer(points):
        # Embree loads 16 bytes at a vertex (SSE): the buffer has 4 spare bytes after the last one
        flat = np.zeros(3 * v + 1, dtype=np.float32)
        flat[:3 * v] = np.asarray(points).reshape(-1)
        return flat

    steps = [vertex_buffer(positions)]
    if positions_close is not None:
        steps.append(vertex_buffer(positions_close))
    index = np.ascontiguousarray(triangles, dtype=np.int32).view(np.uint32)
    scene_handle = ctypes.c_void_p.from_address(id(scene) + scene_offset).value
    device_handle = ctypes.c_void_p.from_address(id(device) + device_offset).value
    geom = lib.rtcNewGeometry(device_handle, _GEOMETRY_TYPE_TRIANGLE)
    if not geom:
        lib.rtcGetDeviceError(device_handle)  # clears the error code
        return False
    if len(steps) > 1:
        lib.rtcSetGeometryTimeStepCount(geom, len(steps))
    for slot, flat in enumerate(steps):
        lib.rtcSetSharedGeometryBuffer(geom, _BUFFER_TYPE_VERTEX, slot, _FORMAT_FLOAT3, flat.ctypes.data, 0, 12, v)
    lib.rtcSetSharedGeometryBuffer(geom, _BUFFER_TYPE_INDEX, 0, _FORMAT_UINT3, index.ctypes.data, 0, 12, len(index))
    if fast_build:  # the geometry's quality counts only in a scene of low quality (two-level BVH)
        lib.rtcSetGeometryBuildQuality(geom, _BUILD_QUALITY_LOW)
        lib.rtcSetSceneBuildQuality(scene_handle, _BUILD_QUALITY_LOW)
    lib.rtcCommitGeometry(geom)
    ok = lib.rtcGetDeviceError(device_handle) == 0
    if ok:
        lib.rtcAttachGeometry(scene_handle, geom)
        ok = lib.rtcGetDeviceError(device_handle) == 0
    lib.rtcReleaseGeometry(geom)
    if ok:
        scene.shared_buffers = (*steps, index)  # read by Embree until the scene is freed
    return ok


class _QuaternionDecomposition(ctypes.Structure):
    """Embree's RTCQuaternionDecomposition (rtcore_quaternion.h): the transform
    T · R(quaternion) · S, S the upper-triangular scale/skew matrix plus a shift. Embree
    interpolates S, the shift and T linearly between time steps and the quaternion by slerp."""
    _fields_ = [(name, ctypes.c_float) for name in (
        "scale_x", "scale_y", "scale_z", "skew_xy", "skew_xz", "skew_yz", "shift_x", "shift_y", "shift_z",
        "quaternion_r", "quaternion_i", "quaternion_j", "quaternion_k",
        "translation_x", "translation_y", "translation_z")]


def instance_scene(device, parts) -> rtcs.EmbreeScene | None:
    """One Embree scene that instances others, so that a single query answers for all of them.

    device: the ``new_device`` every instanced scene was built on. parts: (scene, motion) per
    instance, in order (instance k gets Embree's geometry ID k, which hits report as instID):
    motion None instances the scene as it is (identity); a (3, 4) array places it by that
    local→world affine map (rows: the linear part beside the translation); otherwise ((q0, scale0, trans0),
    (q1, scale1, trans1)) — unit quaternions (w, x, y, z), per-axis scales and translations
    at shutter open and close — makes a motion-blurred instance whose transform at ray time τ
    is T(lerp) · R(slerp) · diag(lerp), DRT's rigid motion (``drt.motion``), evaluated by
    Embree in float32 (its slerp uses polynomial approximations: the caller checks the answers).

    Returns an embreex scene (queried through ``drt.embree_direct``) that keeps the instanced
    scenes alive, or None without the checked handles or when Embree refuses any part."""
    api = _handles()
    if api is None:
        return None
    lib, scene_offset, device_offset = api
    top = _Scene(device)
    top_handle = ctypes.c_void_p.from_address(id(top) + scene_offset).value
    device_handle = ctypes.c_void_p.from_address(id(device) + device_offset).value
    identity = np.array([1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], np.float32)
    for k, (child, motion) in enumerate(parts):
        child_handle = ctypes.c_void_p.from_address(id(child) + scene_offset).value
        commit(child)
        geom = lib.rtcNewGeometry(device_handle, _GEOMETRY_TYPE_INSTANCE)
        if not geom:
            lib.rtcGetDeviceError(device_handle)
            return None
        lib.rtcSetGeometryInstancedScene(geom, child_handle)
        if motion is None:
            lib.rtcSetGeometryTransform(geom, 0, _FORMAT_FLOAT3X4_COLUMN_MAJOR, identity.ctypes.data)
        elif isinstance(motion, np.ndarray):
            rows = np.ascontiguousarray(motion, dtype=np.float32).reshape(3, 4)
            lib.rtcSetGeometryTransform(geom, 0, _FORMAT_FLOAT3X4_ROW_MAJOR, rows.ctypes.data)
        else:
            lib.rtcSetGeometryTimeStepCount(geom, 2)
            for step, (q, scale, trans) in enumerate(motion):
                qd = _QuaternionDecomposition(scale_x=scale[0], scale_y=scale[1], scale_z=scale[2],
                                              quaternion_r=q[0], quaternion_i=q[1], quaternion_j=q[2],
                                              quaternion_k=q[3], translation_x=trans[0],
                                              translation_y=trans[1], translation_z=trans[2])
                lib.rtcSetGeometryTransformQuaternion(geom, step, ctypes.byref(qd))
        lib.rtcCommitGeometry(geom)
        ok = lib.rtcGetDeviceError(device_handle) == 0
        if ok and lib.rtcAttachGeometry(top_handle, geom) != k:
            ok = False
        ok = ok and lib.rtcGetDeviceError(device_handle) == 0
        lib.rtcReleaseGeometry(geom)
        if not ok:
            return None
    top.instanced = [child for child, _ in parts]  # Embree reads them until the scene is freed
    commit(top)
    return top


def commit(scene) -> None:
    """Commit an embreex scene (embreex commits on a scene's first query)."""
    if not scene.is_committed:
        scene.run(np.zeros((1, 3), np.float32), np.array([[0.0, 0.0, 1.0]], np.float32),
                  dists=np.array([1.0], np.float32), output=1)
