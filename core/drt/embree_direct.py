"""Single rays traced by Embree from inside compiled kernels.

Most of the renderer hands Embree whole batches of rays between kernels (embreex's ``run``).
That costs a Python round trip per batch, which is nothing for a camera or bounce wavefront but
dominates loops in which every step needs one more ray and most rows stop early: the subsurface
random walk takes up to 256 steps, a few dozen on average, and a wavefront over it spent ~170 µs
of Python per step for a few hundred rays (``benchmarks/kernel_throughput.py`` on sss_head:
82 % of the render outside shading and Embree, and no thread scaling, the GIL being held).

This module lets a kernel call Embree's ``rtcIntersect1`` itself, with the GIL released:

* ``intersect1_address()``: the C address of ``rtcIntersect1`` in the Embree library embreex
  loaded (found as ``drt.embree_mesh`` finds it), or 0 when that library or its handles cannot
  be confirmed — callers then keep their wavefront;
* ``scene_address(scene)``: the ``RTCScene`` handle of an embreex scene, committed;
* ``scratch()``, ``ray_buffer(words)``, ``trace1(...)``: one ``RTCRayHit`` in a small scratch
  array (kernels do not allocate), filled and read back by inline kernels.

Only the first 76 bytes of ``RTCRayHit`` are touched (the ray, then the hit's normal, u, v,
primID and geomID); their layout is the same in every Embree 4 build, whatever its instancing
options add after them, and the scratch leaves room for those. The function pointer is passed
into kernels as an integer and called through a small LLVM intrinsic, so the compiled kernels
hold no process-specific address and stay cacheable. ``trace1`` gives exactly what embreex's
``run`` gives for the same float32 ray (``tests/test_embree_direct.py``)."""

from __future__ import annotations

import ctypes
import math
import os

import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from . import embree_mesh
from .kernels import inline_kernel, kernel

#: RTCRayHit as 32-bit words (rtcore_ray.h): the ray (org xyz, tnear, dir xyz, time, tfar,
#: mask, id, flags), then the hit (Ng xyz, u, v, primID, geomID, instID[…] …)
_ORG, _TNEAR, _DIR, _TIME, _TFAR, _MASK, _ID, _FLAGS = 0, 3, 4, 7, 8, 9, 10, 11
_U, _V, _PRIM, _GEOM, _INST = 15, 16, 17, 18, 19
#: words of scratch: an RTCRayHit is 80-96 bytes (by instancing options), 16-byte aligned
BUFFER_WORDS = 48
_INVALID = 0xFFFFFFFF  # RTC_INVALID_GEOMETRY_ID
_FAR = 3.0e38          # the largest float32 Embree takes as "unbounded" (as trace._rays32)

_addresses: dict = {}


def _function_address(name: str) -> int:
    if os.environ.get("DRT_EMBREE_DIRECT", "1").strip() == "0":
        return 0
    if name not in _addresses:
        api = embree_mesh._handles()
        fn = getattr(api[0], name, None) if api else None
        _addresses[name] = int(ctypes.cast(fn, ctypes.c_void_p).value or 0) if fn is not None else 0
    return _addresses[name]


def intersect1_address() -> int:
    """Address of Embree's ``rtcIntersect1`` (0: not usable here; use embreex's ``run``).
    ``DRT_EMBREE_DIRECT=0`` in the environment turns the direct path off (a diagnostic switch:
    the wavefront gives the same images, only slower)."""
    return _function_address("rtcIntersect1")


def occluded1_address() -> int:
    """Address of Embree's ``rtcOccluded1`` (0: not usable here), as ``intersect1_address``."""
    return _function_address("rtcOccluded1")


def scene_address(scene) -> int:
    """The RTCScene handle of an embreex ``EmbreeScene`` (0 when the handles are unconfirmed).
    The scene is committed first: embreex commits on a scene's first query, and Embree may only
    be asked about committed scenes."""
    api = embree_mesh._handles()
    if not api:
        return 0
    embree_mesh.commit(scene)
    return int(ctypes.c_void_p.from_address(id(scene) + api[1]).value or 0)


@intrinsic
def _call_intersect1(typingctx, fn, scene, rayhit):
    """fn(scene, rayhit, NULL) for three integers holding C addresses (void return): Embree's
    ``rtcIntersect1`` and ``rtcOccluded1`` both have this signature."""
    sig = types.void(types.intp, types.intp, types.intp)

    def codegen(context, builder, signature, args):
        fn_addr, scene_addr, rayhit_addr = args
        ptr = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [ptr, ptr, ptr])
        callee = builder.inttoptr(fn_addr, fnty.as_pointer())
        builder.call(callee, [builder.inttoptr(scene_addr, ptr), builder.inttoptr(rayhit_addr, ptr),
                              ir.Constant(ptr, None)])
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _float_bits(typingctx, x):
    """The 32 bits of float32 x as a uint32 (a register bitcast)."""
    sig = types.uint32(types.float32)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(32))

    return sig, codegen


@intrinsic
def _bits_float(typingctx, x):
    """The float32 whose bits are uint32 x (a register bitcast)."""
    sig = types.float32(types.uint32)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.FloatType())

    return sig, codegen


def scratch() -> np.ndarray:
    """A ray's scratch for ``trace1`` (kernels do not allocate): one per kernel call, reused for
    every ray that call traces (so one per thread). uint32 words: the float fields are written
    and read as their bits (``_float_bits``), not through a float32 view of the array — numba's
    ``view`` brings a runtime environment whose loading imports ``numba.np.arrayobj`` (30–55 ms
    at the start of every process that loads such a kernel from the cache)."""
    return np.zeros(BUFFER_WORDS, np.uint32)


@inline_kernel
def ray_buffer(words):
    """The RTCRayHit inside a ``scratch`` array: (the same array, first word of the 16-byte
    aligned RTCRayHit, its address)."""
    addr = words.ctypes.data
    base = ((16 - addr % 16) % 16) // 4
    return words, base, addr + 4 * base


@inline_kernel
def trace1(fn, scene, words, bits, base, addr, o, d, tmax):
    """Closest hit of the ray o + t·d, t in [0, tmax) (3-tuples, float64; tmax may be inf), as
    Embree answers a float32 ray: (t, prim, u, v), t = inf and prim = −1 on a miss."""
    return trace1_at(fn, scene, words, bits, base, addr, o, d, tmax, 0.0)


@inline_kernel
def _fill_ray(bits, base, o, d, tmax, time):
    """The ray part of the RTCRayHit in ``bits`` (shared with RTCRay): o + t·d for t in
    [0, tmax), at ``time``, every mask bit, no flags."""
    for a in range(3):
        bits[base + _ORG + a] = _float_bits(np.float32(o[a]))
        bits[base + _DIR + a] = _float_bits(np.float32(d[a]))
    bits[base + _TNEAR] = _float_bits(np.float32(0.0))
    bits[base + _TIME] = _float_bits(np.float32(time))
    bits[base + _TFAR] = _float_bits(np.float32(min(tmax, _FAR)))
    bits[base + _MASK] = _INVALID
    bits[base + _ID] = 0
    bits[base + _FLAGS] = 0


@inline_kernel
def trace1_at(fn, scene, words, bits, base, addr, o, d, tmax, time):
    """``trace1`` at ``time`` in [0, 1] (Embree's ray time: where a geometry with time steps —
    a deforming mesh, ``embree_mesh.deforming_scene`` — is seen; others ignore it). ``words``
    and ``bits`` are ``ray_buffer``'s (the same uint32 scratch)."""
    t, prim, u, v, _ = trace1_instance(fn, scene, words, bits, base, addr, o, d, tmax, time)
    return t, prim, u, v


@inline_kernel
def trace1_instance(fn, scene, words, bits, base, addr, o, d, tmax, time):
    """``trace1_at`` with the instance hit: (t, prim, u, v, instance). On a scene of instances
    (``embree_mesh.instance_scene``) prim is the triangle within the instanced scene and
    instance the geometry ID of the instance in the top scene (on other scenes instance means
    nothing); prim = instance = −1 on a miss."""
    _fill_ray(bits, base, o, d, tmax, time)
    bits[base + _PRIM] = _INVALID
    bits[base + _GEOM] = _INVALID
    bits[base + _INST] = _INVALID
    _call_intersect1(fn, scene, addr)
    if bits[base + _GEOM] == _INVALID:
        return math.inf, -1, 0.0, 0.0, -1
    return (float(_bits_float(bits[base + _TFAR])), int(bits[base + _PRIM]),
            float(_bits_float(bits[base + _U])), float(_bits_float(bits[base + _V])),
            int(bits[base + _INST]))


@inline_kernel
def occluded1_at(fn, scene, words, bits, base, addr, o, d, tmax, time):
    """Is anything hit by the ray o + t·d, t in [0, tmax), at ``time``? ``fn``: the address of
    ``rtcOccluded1``, which takes the ray part of the same buffer (RTCRay) and sets its tfar to
    −inf when it finds a hit."""
    _fill_ray(bits, base, o, d, tmax, time)
    _call_intersect1(fn, scene, addr)  # (the same C signature: scene, ray, NULL arguments)
    return _bits_float(bits[base + _TFAR]) == -math.inf


@kernel
def trace_rows(fn, scene, words, o, d, tmax, t, prim, u, v):
    """``trace1`` over rows (o, d: (n, 3); tmax: (n,)), into t, prim, u, v (n,): for checks
    against embreex's batch answer (``matches_embreex``); words: a ``scratch``."""
    bits, base, addr = ray_buffer(words)
    for i in range(o.shape[0]):
        t[i], prim[i], u[i], v[i] = trace1(fn, scene, words, bits, base, addr,
                                           (o[i, 0], o[i, 1], o[i, 2]), (d[i, 0], d[i, 1], d[i, 2]), tmax[i])


@kernel
def trace_rows_at(fn, scene, words, o, d, tmax, time, t, prim, u, v):
    """``trace_rows`` with a ray time per row (time: (n,), in [0, 1])."""
    bits, base, addr = ray_buffer(words)
    for i in range(o.shape[0]):
        t[i], prim[i], u[i], v[i] = trace1_at(fn, scene, words, bits, base, addr,
                                              (o[i, 0], o[i, 1], o[i, 2]), (d[i, 0], d[i, 1], d[i, 2]),
                                              tmax[i], time[i])


def matches_embreex(scene, o, d, tmax) -> bool:
    """Does ``trace1`` answer the float32 rays (o, d, tmax) exactly as embreex's ``run`` does
    (same prim, and bit-equal t, u, v on hits)? The callers' last check before trusting the
    direct path on a scene."""
    fn, handle = intersect1_address(), scene_address(scene)
    if not fn or not handle:
        return False
    o32 = np.ascontiguousarray(o, np.float32)
    d32 = np.ascontiguousarray(d, np.float32)
    t32 = np.minimum(np.asarray(tmax, np.float64), _FAR).astype(np.float32)
    ref = scene.run(o32.copy(), d32.copy(), dists=t32.copy(), output=1)
    n = len(o32)
    t, prim, u, v = np.empty(n), np.empty(n, np.int64), np.empty(n), np.empty(n)
    trace_rows(fn, handle, scratch(), o32.astype(np.float64), d32.astype(np.float64), t32.astype(np.float64),
               t, prim, u, v)
    hit = ref["primID"] >= 0
    return bool(np.array_equal(prim, np.where(hit, ref["primID"], -1))
                and np.array_equal(t[hit], ref["tfar"][hit].astype(np.float64))
                and np.array_equal(u[hit], ref["u"][hit].astype(np.float64))
                and np.array_equal(v[hit], ref["v"][hit].astype(np.float64)))
