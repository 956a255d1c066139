"""The Object Info node's per-object values, as Cycles's Blender sync computes them.

Random: a non-instanced object's random id is Cycles's ``hash_uint2(hash_string(name), 0)``
(Jenkins's lookup3 final mix; ``hash_string`` is ``h = h·37 + byte``), an instance's is
Blender's ``DepsgraphObjectInstance.random_id``; the node's value is ``id / 0xFFFFFFFF`` in
float32.
"""

import numpy as np

_MASK = 0xFFFFFFFF


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _MASK


def hash_uint2(kx: int, ky: int) -> int:
    """Cycles's ``hash_uint2`` (Bob Jenkins's lookup3 ``final`` on two words), uint32."""
    a = b = c = (0xDEADBEEF + (2 << 2) + 13) & _MASK
    b = (b + ky) & _MASK
    a = (a + kx) & _MASK
    c ^= b; c = (c - _rot(b, 14)) & _MASK  # noqa: E702 (the macro's steps, one per line pair)
    a ^= c; a = (a - _rot(c, 11)) & _MASK  # noqa: E702
    b ^= a; b = (b - _rot(a, 25)) & _MASK  # noqa: E702
    c ^= b; c = (c - _rot(b, 16)) & _MASK  # noqa: E702
    a ^= c; a = (a - _rot(c, 4)) & _MASK  # noqa: E702
    b ^= a; b = (b - _rot(a, 14)) & _MASK  # noqa: E702
    c ^= b; c = (c - _rot(b, 24)) & _MASK  # noqa: E702
    return c


def hash_string(s: str) -> int:
    """Cycles's ``hash_string`` over the UTF-8 bytes, uint32."""
    h = 0
    for ch in s.encode("utf-8"):
        h = (h * 37 + ch) & _MASK
    return h


def random_id(inst) -> int:
    if inst.is_instance:
        return int(inst.random_id) & _MASK
    return hash_uint2(hash_string(inst.object.name), 0)


def object_info(inst) -> dict:
    """The scene file's ``info`` of an object instance (docs/scene-format.md)."""
    obj = inst.object
    color = [float(x) for x in obj.color[:3]]
    rnd = float(np.float32(random_id(inst)) * np.float32(1.0 / _MASK))
    return {"color": color, "alpha": float(obj.color[3]), "pass_index": float(obj.pass_index), "random": rnd}
