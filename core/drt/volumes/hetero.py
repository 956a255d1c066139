"""Heterogeneous media: a density from the material's program (texture nodes), sampled by
null-collision tracking against a per-row majorant (Cycles 5.0 samples heterogeneous volumes by
delta / ratio tracking against a majorant too; see docs/volumes.md).

A heterogeneous row r of ``MediumData`` stores its coefficients *per unit density* (all of
Cycles's volume closures are linear in density) and ``density_reg[r]``: the register of its
material's program ``density_prog[r]`` whose x channel is the density at a point. The program
runs off any triangle (``run_program(pd, regs, prog, -1, 0, 0, point)``) with the point's
Generated and Object coordinates in ``point`` rows POINT_GENERATED / POINT_OBJECT, from the
object's affine map ``coord_map[object]`` (shifted world → texture space / object space), fitted
at load from the object's exported per-corner ``generated`` / ``object_coords`` attributes.

Estimators (all unbiased while the density stays below the majorant; a density above it is
clamped, which biases, as any majorant-based tracker):

* **indirect vertex**: spectral tracking (Kutz et al. 2017, "history-aware" probabilities):
  tentative collisions at rate σ̄; at each the event absorb / scatter / null is chosen with
  probabilities ∝ mean(σa·w), mean(σs·w), mean(σn·w) (w: throughput so far, per channel, σn =
  σ̄ − σt) and the weight is multiplied by σx / (σ̄·Px); absorption ends the path. Grey extinction
  gives plain delta tracking with weight albedo;
* **attenuation only** (a path past its bounce limits, a non-scattering medium, shadow rays):
  ratio tracking, T̂ = Π (1 − σt(x_k)/σ̄) per channel;
* **emission** of homogeneous rows in the same stack: the collision estimator Σ w·σe/σ̄;
* **emitters crossed** (light shapes before the segment's end): T̂ by an independent ratio
  tracking, counted whatever the tracked path does;
* **next-event estimation** at the real scatter vertex (MIS against the phase-sampled ray).

Random numbers beyond the sampler's two per segment come from a 32-bit PCG hash seeded by the
pixel, sample and segment (tracking needs an unbounded count).
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import inline_kernel, kernel
from ..materials.program_format import POINT_GENERATED, POINT_OBJECT, POINT_UV
from ..materials.programs import run_program

_MASK = 0xFFFFFFFF
#: tentative collisions per tracked segment before giving up (a run-away majorant)
MAX_STEPS = 1 << 20
#: ratio tracking plays Russian roulette once its weight falls below this fraction
RR_BELOW = 0.05


@kernel
def pcg_next(state):
    """(u in [0, 1), next state) of a 32-bit PCG-RXS-M-XS step (int64 arithmetic, no overflow)."""
    state = (state * 747796405 + 2891336453) & _MASK
    word = ((((state >> ((state >> 28) + 4)) ^ state) & _MASK) * 277803737) & _MASK
    word = ((word >> 22) ^ word) & _MASK
    return word * (1.0 / 4294967296.0), state


@kernel
def seed_of(a, b, c):
    """A 32-bit seed mixing three integers (each through a PCG step)."""
    s = (a * 2654435761 + 12345) & _MASK
    _, s = pcg_next(s)
    s = (s ^ ((b * 2246822519) & _MASK)) & _MASK
    _, s = pcg_next(s)
    s = (s ^ ((c * 3266489917) & _MASK)) & _MASK
    _, s = pcg_next(s)
    return s


@kernel
def seed_of_point(p, k):
    """A seed from a position (shadow rays start at random points) and an integer."""
    a = int((abs(p[0]) * 1.0e6) % 2147483647.0)
    b = int((abs(p[1]) * 1.0e6) % 2147483647.0)
    c = int((abs(p[2]) * 1.0e6) % 2147483647.0)
    return seed_of(a ^ k, b, c)


@kernel
def row_coefficients(vd, pd, regs, point, key, x):
    """(σs, σt, density) of stack key ``key`` at shifted world point x: a homogeneous row's
    constants (density 1), else its program's density (``density_reg``, 1 if −1) times, with a
    textured colour c (``color_reg``), σs = S·c and σa = A·max(1 − c, 0) (S = sigma_s, A =
    sigma_t − sigma_s per unit density and colour), clamped to the row's share of the majorant."""
    r = key % vd.stride
    s0, s1, s2 = vd.sigma_s[r, 0], vd.sigma_s[r, 1], vd.sigma_s[r, 2]
    t0, t1, t2 = vd.sigma_t[r, 0], vd.sigma_t[r, 1], vd.sigma_t[r, 2]
    prog = vd.density_prog[r]
    if prog < 0:
        return (s0, s1, s2), (t0, t1, t2), 1.0
    obj = key // vd.stride
    m = vd.coord_map[obj]
    for c in range(3):
        point[POINT_GENERATED, c] = m[c, 0] * x[0] + m[c, 1] * x[1] + m[c, 2] * x[2] + m[c, 3]
        point[POINT_OBJECT, c] = m[3 + c, 0] * x[0] + m[3 + c, 1] * x[1] + m[3 + c, 2] * x[2] + m[3 + c, 3]
        point[POINT_UV, c] = 0.0
    run_program(pd, regs, prog, -1, 0.0, 0.0, point)
    k = 1.0
    dreg = vd.density_reg[r]
    if dreg >= 0:
        v = regs[dreg, 0]
        k = max(v, 0.0) if v == v else 0.0
    creg = vd.color_reg[r]
    if creg >= 0:
        c0, c1, c2 = regs[creg, 0], regs[creg, 1], regs[creg, 2]
        c0 = max(c0, 0.0) if c0 == c0 else 0.0
        c1 = max(c1, 0.0) if c1 == c1 else 0.0
        c2 = max(c2, 0.0) if c2 == c2 else 0.0
        a0, a1, a2 = t0 - s0, t1 - s1, t2 - s2
        s0, s1, s2 = s0 * c0, s1 * c1, s2 * c2
        t0 = s0 + a0 * max(1.0 - c0, 0.0)
        t1 = s1 + a1 * max(1.0 - c1, 0.0)
        t2 = s2 + a2 * max(1.0 - c2, 0.0)
    bound = vd.majorant[r] * max(vd.sigma_t[r, 0], max(vd.sigma_t[r, 1], vd.sigma_t[r, 2]))
    top = k * max(t0, max(t1, t2))
    if top > bound:  # above the majorant: clamp (biased; the grid bound has a safety factor)
        k *= bound / top
    return (k * s0, k * s1, k * s2), (k * t0, k * t1, k * t2), k


@inline_kernel
def stack_majorant(vd, stack, i):
    """σ̄: the sum over row i's media of max-channel σt × the row's density bound (1/m)."""
    tot = 0.0
    for s in range(stack.shape[1]):
        key = stack[i, s]
        if key < 0:
            break
        r = key % vd.stride
        tot += max(vd.sigma_t[r, 0], max(vd.sigma_t[r, 1], vd.sigma_t[r, 2])) * vd.majorant[r]
    return tot


@inline_kernel
def stack_is_hetero(vd, stack, i):
    if not vd.hetero:
        return False
    for s in range(stack.shape[1]):
        key = stack[i, s]
        if key < 0:
            break
        if vd.density_prog[key % vd.stride] >= 0:
            return True
    return False


@inline_kernel
def coefficients_at(vd, pd, regs, point, stack, i, x):
    """(σs, σt, σe, g) of row i's media at x (heterogeneous rows × their density there)."""
    s0 = s1 = s2 = 0.0
    t0 = t1 = t2 = 0.0
    e0 = e1 = e2 = 0.0
    gw = 0.0
    for s in range(stack.shape[1]):
        key = stack[i, s]
        if key < 0:
            break
        r = key % vd.stride
        ss, st, k = row_coefficients(vd, pd, regs, point, key, x)
        s0 += ss[0]
        s1 += ss[1]
        s2 += ss[2]
        t0 += st[0]
        t1 += st[1]
        t2 += st[2]
        e0 += k * vd.emission[r, 0]
        e1 += k * vd.emission[r, 1]
        e2 += k * vd.emission[r, 2]
        gw += vd.g[r] * (ss[0] + ss[1] + ss[2])
    ssum = s0 + s1 + s2
    g = gw / ssum if ssum > 0.0 else 0.0
    return (s0, s1, s2), (t0, t1, t2), (e0, e1, e2), g


@inline_kernel
def stack_scatters(vd, stack, i):
    """Whether any medium of row i scatters (else tracking only attenuates)."""
    for s in range(stack.shape[1]):
        key = stack[i, s]
        if key < 0:
            break
        r = key % vd.stride
        if vd.sigma_s[r, 0] > 0.0 or vd.sigma_s[r, 1] > 0.0 or vd.sigma_s[r, 2] > 0.0:
            return True
    return False


@inline_kernel
def ratio_tracking(vd, pd, regs, point, stack, i, o, d, length, state):
    """(T̂ per channel (unbiased estimate of e^(−∫σt)), next RNG state) over [0, length)."""
    maj = stack_majorant(vd, stack, i)
    w0 = w1 = w2 = 1.0
    if not maj > 0.0:
        return (1.0, 1.0, 1.0), state
    t = 0.0
    for _ in range(MAX_STEPS):
        u, state = pcg_next(state)
        t -= math.log(1.0 - u) / maj
        if not t < length:
            break
        x = (o[0] + d[0] * t, o[1] + d[1] * t, o[2] + d[2] * t)
        _, st, _, _ = coefficients_at(vd, pd, regs, point, stack, i, x)
        w0 *= max(1.0 - st[0] / maj, 0.0)
        w1 *= max(1.0 - st[1] / maj, 0.0)
        w2 *= max(1.0 - st[2] / maj, 0.0)
        q = max(w0, max(w1, w2))
        if q < RR_BELOW:  # Russian roulette: a dense medium costs O(1/RR_BELOW) steps, not σ̄·L
            u, state = pcg_next(state)
            if not u * RR_BELOW < q:
                return (0.0, 0.0, 0.0), state
            k = RR_BELOW / q
            w0 *= k
            w1 *= k
            w2 *= k
    return (w0, w1, w2), state


@inline_kernel
def track_segment(vd, pd, regs, point, stack, i, o, d, length, thr, attenuate, state):
    """Spectral tracking over [0, length) for a path with throughput thr (see the module
    docstring). Returns (emission collected (× thr), scattered, t, throughput after (at the
    scatter point, or at the end; 0 when absorbed), g at the scatter point, next RNG state).
    ``attenuate``: only transmittance (ratio tracking, no scattering)."""
    maj = stack_majorant(vd, stack, i)
    a0 = a1 = a2 = 0.0
    w0, w1, w2 = thr[0], thr[1], thr[2]
    if not maj > 0.0:
        return (0.0, 0.0, 0.0), False, math.inf, (w0, w1, w2), 0.0, state
    t = 0.0
    for _ in range(MAX_STEPS):
        u, state = pcg_next(state)
        t -= math.log(1.0 - u) / maj
        if not t < length:
            break
        x = (o[0] + d[0] * t, o[1] + d[1] * t, o[2] + d[2] * t)
        ss, st, se, g = coefficients_at(vd, pd, regs, point, stack, i, x)
        # collision estimator of the emission: E[Σ w(t_k)·σe(t_k)/σ̄] = ∫ T·σe
        a0 += w0 * se[0] / maj
        a1 += w1 * se[1] / maj
        a2 += w2 * se[2] / maj
        n0 = max(maj - st[0], 0.0)
        n1 = max(maj - st[1], 0.0)
        n2 = max(maj - st[2], 0.0)
        if attenuate:
            w0 *= n0 / maj
            w1 *= n1 / maj
            w2 *= n2 / maj
            q = max(w0, max(w1, w2))
            if q < RR_BELOW * max(thr[0], max(thr[1], thr[2])):  # Russian roulette, as above
                q = q / (RR_BELOW * max(thr[0], max(thr[1], thr[2])))
                u, state = pcg_next(state)
                if not u < q:
                    return (a0, a1, a2), False, math.inf, (0.0, 0.0, 0.0), 0.0, state
                w0 /= q
                w1 /= q
                w2 /= q
            continue
        pa = (st[0] - ss[0]) * w0 + (st[1] - ss[1]) * w1 + (st[2] - ss[2]) * w2
        ps = ss[0] * w0 + ss[1] * w1 + ss[2] * w2
        pn = n0 * w0 + n1 * w1 + n2 * w2
        pa = max(pa, 0.0)
        c = pa + ps + pn
        if not c > 0.0:
            return (a0, a1, a2), False, math.inf, (0.0, 0.0, 0.0), 0.0, state
        u, state = pcg_next(state)
        u *= c
        if u < pa:  # absorbed: the path ends (its emission so far is kept)
            return (a0, a1, a2), False, math.inf, (0.0, 0.0, 0.0), 0.0, state
        if u < pa + ps:
            k = c / (maj * ps)
            return (a0, a1, a2), True, t, (w0 * ss[0] * k, w1 * ss[1] * k, w2 * ss[2] * k), g, state
        k = c / (maj * pn)
        w0 *= n0 * k
        w1 *= n1 * k
        w2 *= n2 * k
    return (a0, a1, a2), False, math.inf, (w0, w1, w2), 0.0, state


@kernel
def _extinction_points(vd, pd, regs, point, key, xs, out):
    """out[k] = the largest channel of σt at xs[k] (the majorant search)."""
    for k in range(xs.shape[0]):
        _, st, _ = row_coefficients(vd, pd, regs, point, key, (xs[k, 0], xs[k, 1], xs[k, 2]))
        out[k] = max(st[0], max(st[1], st[2]))


@kernel
def _tracking_rows(vd, pd, regs, point, stack, o, d, length, thr, seed, out_thr, out_t, out_tr):
    """Tests: row k tracks one segment (stack row 0) with seed (seed, k): out_thr[k] = the
    throughput after (scatter point or end), out_t[k] = the scatter distance (inf: none),
    out_tr[k] = a ratio-tracking transmittance estimate of the whole segment."""
    for k in range(out_thr.shape[0]):
        st = seed_of(seed, k, 7)
        _, sc, t, w, _, st = track_segment(vd, pd, regs, point, stack, 0, o, d, length, thr, False, st)
        out_thr[k, 0], out_thr[k, 1], out_thr[k, 2] = w[0], w[1], w[2]
        out_t[k] = t if sc else math.inf
        tr, st = ratio_tracking(vd, pd, regs, point, stack, 0, o, d, length, st)
        out_tr[k, 0], out_tr[k, 1], out_tr[k, 2] = tr[0], tr[1], tr[2]


# ------------------------------------------------------------------ load time (front end)

#: grid points per axis of the majorant search and the safety factor on its maximum
MAJORANT_GRID = 24
MAJORANT_SAFETY = 1.5


def _fit_affine(pos: np.ndarray, val: np.ndarray) -> np.ndarray:
    """The 3×4 least-squares affine map pos → val ((N, 3) each)."""
    a = np.hstack([pos, np.ones((len(pos), 1))])
    m, *_ = np.linalg.lstsq(a, val, rcond=None)
    return m.T


def prepare(vd, pd, geom, n_registers: int, point_rows: int):
    """``vd`` with its heterogeneous rows' programs, coordinate maps and majorants filled in
    (unchanged when no row is heterogeneous). ``pd``: the material programs
    (``drt.materials.programs.ProgramData``), ``geom``: the scene's ``SceneGeometry``."""
    if not vd.hetero:
        return vd
    k = vd.stride
    density_prog = np.full(k, -1, np.int64)
    for r in range(k - 1):
        if vd.density_reg[r] >= 0 or vd.color_reg[r] >= 0:
            density_prog[r] = int(pd.prog_of[r]) if r < len(pd.prog_of) else -1
    hetero_row = density_prog >= 0
    density_reg = np.where(hetero_row, vd.density_reg, -1)
    obj = np.asarray(geom.object_id if geom.object_id is not None else np.zeros(len(geom.material)), np.int64)
    n_obj = int(obj.max()) + 1 if len(obj) else 1
    coord_map = np.zeros((n_obj, 6, 4))
    coord_map[:, 0:3, 0:3] = np.eye(3)
    coord_map[:, 3:6, 0:3] = np.eye(3)
    n_static = len(geom.static_triangles)
    pos_all = np.asarray(geom.static_positions, np.float64)
    gen = geom.corner_attrs.get("generated")
    objco = geom.corner_attrs.get("object_coords")
    mats = np.asarray(geom.material)
    pairs = {(int(o_), int(m_)) for o_, m_ in zip(obj[:n_static], mats[:n_static]) if hetero_row[m_]}
    boxes = {}
    for o_ in {p[0] for p in pairs}:
        tris = np.nonzero(obj[:n_static] == o_)[0]
        pos = pos_all[geom.static_triangles[tris]].reshape(-1, 3)
        boxes[o_] = (pos.min(axis=0), pos.max(axis=0))
        if gen is not None:
            coord_map[o_, 0:3] = _fit_affine(pos, np.asarray(gen[tris], np.float64).reshape(-1, 3))
        if objco is not None:
            coord_map[o_, 3:6] = _fit_affine(pos, np.asarray(objco[tris], np.float64).reshape(-1, 3))
    majorant = np.ones(k)
    big = np.where(hetero_row, np.inf, 1.0)
    vd = vd._replace(density_reg=density_reg, density_prog=density_prog, coord_map=coord_map,
                     color_reg=np.where(hetero_row, vd.color_reg, -1), majorant=big,
                     hetero=bool(hetero_row.any()))
    regs = np.zeros((max(n_registers, 1), 3))
    point = np.zeros((point_rows, 3))
    n = MAJORANT_GRID
    for r in np.nonzero(hetero_row)[0]:
        best = 0.0
        for o_, m_ in pairs:
            if m_ != r:
                continue
            lo, hi = boxes[o_]
            axes = [np.linspace(lo[c], hi[c], n) for c in range(3)]
            xs = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            out = np.zeros(len(xs))
            _extinction_points(vd, pd, regs, point, o_ * k + r, np.ascontiguousarray(xs), out)
            best = max(best, float(out.max()))
        top = float(vd.sigma_t[r].max())
        # the row's majorant share is stored relative to its largest constant channel
        majorant[r] = best * MAJORANT_SAFETY / top if best > 0.0 and top > 0.0 else 0.0
    return vd._replace(majorant=majorant)
