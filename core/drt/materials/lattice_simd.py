"""Perlin noise's lattice corners in SIMD: the 2^dim Jenkins hashes and gradients of one cell at
once (2D: 4 corners, 3D: 8, 4D: 16), written as LLVM vector code.

Perlin noise spends most of its time hashing its corners: one lookup3 ``hash_uint{2,3,4}`` per
corner, ~35 dependent 32-bit integer operations each, then a gradient. The corners are
independent, so they are computed as lanes of ``<n x i32>`` / ``<n x double>`` vectors (numba
leaves LLVM's SLP vectoriser off, so straight-line scalar code would stay scalar); on an AVX2
machine the eight 3D hashes are one pass of 256-bit integer operations. The values are exactly
those of the scalar code (``procedural.hash_uint*`` and the ``GRAD*`` tables): wrapping 32-bit
arithmetic is what the scalar code emulates with int64 masks, and a gradient is the same one or
two (three in 4D) signed coordinates added in the same order (Cycles's ``grad2/3/4``).

Corner k of the cell (X, Y, Z, W) is (X + bit0(k), Y + bit1(k), Z + bit2(k), W + bit3(k)), its
gradient taken at (rx − bit0(k), ry − bit1(k), ...) — the order the bi/tri/quad mix reads them.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

_I32 = ir.IntType(32)
_F64 = ir.DoubleType()
_SEED = {2: 0xDEADBEEF + (2 << 2) + 13, 3: 0xDEADBEEF + (3 << 2) + 13, 4: 0xDEADBEEF + (4 << 2) + 13}


def _splat(builder, value, vty):
    """A vector of ``vty`` with every lane ``value``."""
    v = builder.insert_element(ir.Constant(vty, ir.Undefined), value, ir.Constant(_I32, 0))
    return builder.shuffle_vector(v, ir.Constant(vty, ir.Undefined),
                                  ir.Constant(ir.VectorType(_I32, vty.count), [0] * vty.count))


def _ivec(n, values):
    return ir.Constant(ir.VectorType(_I32, n), [v & 0xFFFFFFFF for v in values])


def _rot(builder, x, k, n):
    """32-bit rotate left of every lane."""
    return builder.or_(builder.shl(x, _ivec(n, [k] * n)), builder.lshr(x, _ivec(n, [32 - k] * n)))


def _final(builder, a, b, c, n):
    """lookup3's final(a, b, c); returns c."""
    for x, y, k in (("c", "b", 14), ("a", "c", 11), ("b", "a", 25), ("c", "b", 16),
                    ("a", "c", 4), ("b", "a", 14), ("c", "b", 24)):
        r = {"a": a, "b": b, "c": c}
        v = builder.sub(builder.xor(r[x], r[y]), _rot(builder, r[y], k, n))
        if x == "a":
            a = v
        elif x == "b":
            b = v
        else:
            c = v
    return c


def _mix(builder, a, b, c, n):
    """lookup3's mix(a, b, c) (hash_uint4 only)."""
    for k in (4, 6, 8, 16, 19, 4):
        a = builder.xor(builder.sub(a, c), _rot(builder, c, k, n))
        c = builder.add(c, b)
        a, b, c = b, c, a  # the macro's rotation of roles: (a, b, c) → (b, c, a)
    return a, b, c


def _codegen(dim):
    n = 1 << dim
    vi = ir.VectorType(_I32, n)
    vd = ir.VectorType(_F64, n)

    def codegen(context, builder, signature, args):
        cells, rel = args[:dim], args[dim:]
        seed = _splat(builder, ir.Constant(_I32, _SEED[dim]), vi)
        keys = [builder.add(_splat(builder, builder.trunc(cells[i], _I32), vi),
                            _ivec(n, [(k >> i) & 1 for k in range(n)])) for i in range(dim)]
        if dim == 2:
            a, b, c = builder.add(seed, keys[0]), builder.add(seed, keys[1]), seed
        else:
            a, b, c = builder.add(seed, keys[0]), builder.add(seed, keys[1]), builder.add(seed, keys[2])
        if dim == 4:
            a, b, c = _mix(builder, a, b, c, n)
            a = builder.add(a, keys[3])
        h = _final(builder, a, b, c, n)
        g = [builder.fsub(_splat(builder, rel[i], vd), ir.Constant(vd, [float((k >> i) & 1) for k in range(n)]))
             for i in range(dim)]

        def below(m):
            return builder.icmp_unsigned("<", h, _ivec(n, [m] * n))

        def negate_if(v, bit):
            flag = builder.icmp_unsigned("!=", builder.and_(h, _ivec(n, [bit] * n)), _ivec(n, [0] * n))
            return builder.select(flag, builder.fneg(v), v)

        if dim == 2:  # grad2: h = hash & 7 (bits above 3 are not read: only h & 4 decides)
            h = builder.and_(h, _ivec(n, [7] * n))
            first = below(4)
            u = builder.select(first, g[0], g[1])
            yx = builder.select(first, g[1], g[0])
            v = builder.fmul(ir.Constant(vd, [2.0] * n), yx)
            r = builder.fadd(negate_if(u, 1), negate_if(v, 2))
        elif dim == 3:  # grad3: h = hash & 15
            h = builder.and_(h, _ivec(n, [15] * n))
            u = builder.select(below(8), g[0], g[1])
            x_or_z = builder.select(builder.or_(builder.icmp_unsigned("==", h, _ivec(n, [12] * n)),
                                                builder.icmp_unsigned("==", h, _ivec(n, [14] * n))), g[0], g[2])
            v = builder.select(below(4), g[1], x_or_z)
            r = builder.fadd(negate_if(u, 1), negate_if(v, 2))
        else:  # grad4: h = hash & 31
            h = builder.and_(h, _ivec(n, [31] * n))
            u = builder.select(below(24), g[0], g[1])
            v = builder.select(below(16), g[1], g[2])
            s = builder.select(below(8), g[2], g[3])
            r = builder.fadd(builder.fadd(negate_if(u, 1), negate_if(v, 2)), negate_if(s, 4))
        out = [builder.extract_element(r, ir.Constant(_I32, k)) for k in range(n)]
        return context.make_tuple(builder, signature.return_type, out)
    return codegen


def _typer(dim):
    def typer(typingctx, *args):
        if len(args) != 2 * dim:
            return None
        if not all(isinstance(a, types.Integer) for a in args[:dim]):
            return None
        if not all(a == types.float64 for a in args[dim:]):
            return None
        sig = types.UniTuple(types.float64, 1 << dim)(*([types.int64] * dim + [types.float64] * dim))
        return sig, _codegen(dim)
    return typer


@intrinsic
def corner_gradients2(typingctx, X, Y, rx, ry):
    """The four 2D corners' grad2(hash_uint2(corner), offset) (see the module docstring)."""
    return _typer(2)(typingctx, X, Y, rx, ry)


@intrinsic
def corner_gradients3(typingctx, X, Y, Z, rx, ry, rz):
    """The eight 3D corners' grad3(hash_uint3(corner), offset)."""
    return _typer(3)(typingctx, X, Y, Z, rx, ry, rz)


@intrinsic
def corner_gradients4(typingctx, X, Y, Z, W, rx, ry, rz, rw):
    """The sixteen 4D corners' grad4(hash_uint4(corner), offset)."""
    return _typer(4)(typingctx, X, Y, Z, W, rx, ry, rz, rw)


# --- Voronoi: the feature-point distances of the 3^dim cells around a point ---------------------

def _pcg_codegen(dim, bound):
    """Distances from the point (lx, ly[, lz]) in its cell to the feature points of the 3^dim
    neighbour cells (offsets −1..1, x fastest: Cycles's scan order), Euclidean, squared when
    ``bound`` (voronoi_distance_bound): hash_pcg{2,3}d_i of each cell as lanes of int32 vectors
    (wrapping multiplies, arithmetic shifts: C's int), the same float steps as
    ``procedural._cell_point`` and ``_vdist``."""
    n = 3 ** dim
    vi = ir.VectorType(_I32, n)
    vf = ir.VectorType(ir.FloatType(), n)
    vd = ir.VectorType(_F64, n)
    offs = [[(k // 3 ** i) % 3 - 1 for k in range(n)] for i in range(dim)]

    def codegen(context, builder, signature, args):
        cells, rel, rnd = args[:dim], args[dim:2 * dim], args[2 * dim]
        mul, inc = _ivec(n, [1664525] * n), _ivec(n, [1013904223] * n)
        v = [builder.add(builder.mul(builder.add(_splat(builder, builder.trunc(cells[i], _I32), vi),
                                                  _ivec(n, offs[i])), mul), inc) for i in range(dim)]
        for r in range(2):
            if dim == 2:
                v[0] = builder.add(v[0], builder.mul(v[1], mul))
                v[1] = builder.add(v[1], builder.mul(v[0], mul))
            else:
                v[0] = builder.add(v[0], builder.mul(v[1], v[2]))
                v[1] = builder.add(v[1], builder.mul(v[2], v[0]))
                v[2] = builder.add(v[2], builder.mul(v[0], v[1]))
            if r == 0:
                v = [builder.xor(c, builder.ashr(c, _ivec(n, [16] * n))) for c in v]
        scale = ir.Constant(vd, [4.656612873077393e-10] * n)
        rv = _splat(builder, rnd, vd)
        total = None
        for i in range(dim):
            h = builder.fpext(builder.sitofp(builder.and_(v[i], _ivec(n, [0x7FFFFFFF] * n)), vf), vd)
            p = builder.fmul(builder.fmul(h, scale), rv)  # (f32(h) · 2⁻³¹) · randomness
            pp = builder.fadd(ir.Constant(vd, [float(o) for o in offs[i]]), p)  # offset + point
            dl = builder.fsub(pp, _splat(builder, rel[i], vd))
            sq = builder.fmul(dl, dl)
            total = sq if total is None else builder.fadd(total, sq)
        if dim == 2:  # _vdist adds the unused z² (0) before w² (0)
            total = builder.fadd(total, ir.Constant(vd, [0.0] * n))
        total = builder.fadd(total, ir.Constant(vd, [0.0] * n))
        if not bound:
            fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vd, [vd]), f"llvm.sqrt.v{n}f64")
            total = builder.call(fn, [total])
        out = [builder.extract_element(total, ir.Constant(_I32, k)) for k in range(n)]
        return context.make_tuple(builder, signature.return_type, out)
    return codegen


def _cells_typer(dim, bound):
    def typer(typingctx, *args):
        if len(args) != 2 * dim + 1 or not all(isinstance(a, types.Integer) for a in args[:dim]):
            return None
        if not all(a == types.float64 for a in args[dim:]):
            return None
        sig = types.UniTuple(types.float64, 3 ** dim)(*([types.int64] * dim + [types.float64] * (dim + 1)))
        return sig, _pcg_codegen(dim, bound)
    return typer


@intrinsic
def cell_distances2(typingctx, cx, cy, lx, ly, randomness):
    """The nine 2D Voronoi cells' Euclidean distances (see ``_pcg_codegen``)."""
    return _cells_typer(2, False)(typingctx, cx, cy, lx, ly, randomness)


@intrinsic
def cell_distances2_sq(typingctx, cx, cy, lx, ly, randomness):
    """The nine 2D Voronoi cells' squared distances."""
    return _cells_typer(2, True)(typingctx, cx, cy, lx, ly, randomness)


@intrinsic
def cell_distances3(typingctx, cx, cy, cz, lx, ly, lz, randomness):
    """The 27 3D Voronoi cells' Euclidean distances."""
    return _cells_typer(3, False)(typingctx, cx, cy, cz, lx, ly, lz, randomness)


@intrinsic
def cell_distances3_sq(typingctx, cx, cy, cz, lx, ly, lz, randomness):
    """The 27 3D Voronoi cells' squared distances."""
    return _cells_typer(3, True)(typingctx, cx, cy, cz, lx, ly, lz, randomness)
