"""Random-walk subsurface scattering (SSS) with Cycles's semantics (Blender 5.0's Cycles, see
docs/subsurface.md): the coefficients, the entry bounce and the compiled walk steps.

A SUBSURFACE lobe (scene-format.md) carries the closure weight ``color`` (what Cycles calls the
BSSRDF weight: base colour × subsurface weight × layering), the scalar ``weight`` that colour was
scaled by (so the *albedo* of the walk is ``clamp(color / weight, 0, 1)``, also for textured
colours), the user ``radius`` (per channel, metres, already × Subsurface Scale), the method, the
entry IOR and roughness and the phase anisotropy.

Cycles's chain, reproduced here:

1. ``bssrdf_setup``: anisotropy clamped to [0, 0.9], IOR to [1.01, 3.8]; channels whose radius
   is below ``BSSRDF_MIN_RADIUS`` become a Lambert lobe (done when the table is built); the
   BSSRDF is picked with sample weight average(colour) × (number of SSS channels).
2. ``bssrdf_setup_radius``: RANDOM_WALK (and BURLEY, mapped to it) scales the radius by 1/(4π);
   RANDOM_WALK_SKIN scales it by sqrt(3(1 − α')) where α' solves the classical dipole's diffuse
   reflectance Rd(α') = albedo for the IOR (Jensen's F_dr fit, bisection as Cycles).
3. ``subsurface_random_walk_remap``: per channel, the single-scattering albedo α from the
   multiple-scattering albedo by Chiang et al.'s fit (polynomials in g), σt = 1 / (r (1 − g));
   the path throughput is divided by the albedo and α is raised to at least 0.2 (the
   throughput scaled by α/0.2 to compensate).
4. Entry: RANDOM_WALK refracts through a GGX microfacet normal (alpha = roughness², the
   Principled roughness; IOR the Principled IOR); SKIN takes a cosine direction into the
   surface with probability ½, else refracts with alpha 1 and the Subsurface IOR. No Fresnel
   and no BSDF/pdf factor: Cycles only uses the direction.
5. The walk: per step a colour channel is chosen ∝ α·throughput (MIS over channels, balance
   heuristic), the direction from Henyey-Greenstein ("classic") or from Dwivedi's guided
   distribution toward the entry plane (and, when the first ray found the opposite side, the
   mirrored one), the distance exponentially with σt (stretched for guided samples); one-sample
   MIS over {classic, guided, backward guided} × {r, g, b}. Hits are restricted to the entered
   object (``scene_intersect_local``). After 9 steps the anisotropy is replaced by the
   similarity-relation isotropic medium. At most 256 steps; a walk whose throughput falls below
   1e-6 dies.
6. The exit vertex is shaded as a white Lambert surface (normal: the exit point's shading
   normal, on the outside); no emission there. The entry is not a bounce; the diffuse sample at
   the exit counts one (diffuse) bounce, as Cycles's ``path_state_next`` does.

Random numbers of the walk: three 2-D samples per step at dimensions of their own
(``walk_dim0``, ``walk_pair``), for the first STRATIFIED_STEPS steps from the path's own sample
sequence (``Sampler``), so those steps are stratified over the pixel's samples as in Cycles,
whose walk advances its sequence's dimension offset per step; later steps hash them
(``random_2d``).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from . import embree_direct
from .embree_direct import ray_buffer, trace1
from .kernels import inline_kernel, kernel
from .kernels.vec3 import build_frame, dot, load, normalize, store, to_world
from .materials.subsurface_lobe import MIN_ALPHA, remap
from .materials.table import SSS_G, SSS_RADIUS, SSS_WEIGHT
from .sampling.sequences import random_2d, sample_2d
from .trace import OFFSET_ABSOLUTE, OFFSET_RELATIVE, probe_pattern, static_hit_row

BSSRDF_MAX_BOUNCES = 256
VOLUME_THROUGHPUT_EPSILON = 1e-6
SIMILARITY_LEVEL = 9

# walk row states (Paths.sss); EXIT_FLAT: an exit on a moving object, shaded with its
# geometric normal (docs/subsurface.md)
SSS_NONE, SSS_WALK, SSS_EXIT, SSS_DEAD, SSS_EXIT_FLAT = 0, 1, 2, 3, 4



# ----------------------------------------------------------------------------- the walk

@inline_kernel
def sss_coefficients(md, m, slot, coef, j):
    """Row j of ``coef`` (n, 10) ← (σt, α, throughput factor, g) of the SUBSURFACE lobe ``slot``
    of material m, from its colour at this hit (textures may have rewritten it): albedo =
    clamp(colour / weight, 0, 1), Cycles's per-channel remap, factor 1/albedo with the α ≥ 0.2
    compensation (``coefficients`` is the numpy twin)."""
    k = md.lobe_sss[m, slot, SSS_WEIGHT]
    g = md.lobe_sss[m, slot, SSS_G]
    for c in range(3):
        a = min(max(md.lobe_color[m, slot, c] / k, 0.0), 1.0)
        st, al = remap(a, md.lobe_sss[m, slot, SSS_RADIUS + c], g)
        fac = 1.0 / a if a != 0.0 else 0.0
        if al < MIN_ALPHA:
            fac *= al / MIN_ALPHA
            al = MIN_ALPHA
        coef[j, c] = st
        coef[j, 3 + c] = al
        coef[j, 6 + c] = fac
    coef[j, 9] = g


#: The state of the walking rows (compacted, n rows). Arrays:
#:   o, d (n, 3): current walk point and direction; tmax (n,): length of the next ray;
#:   thr (n, 3): path throughput; sigma_t, alpha (n, 3); g (n,) anisotropy;
#:   n_entry, p_entry (n, 3): entry shading normal (outside) and point; step (n,) int64;
#:   opposite (n,) bool, opp_dist (n,); pixel, index (n,) int64: the path's pixel and sample
#:   (the walk's random numbers come from the sampler at them); dim0 (n,) int64: the walk's
#:   first sample dimension (``walk_dim0``);
#:   t_sample (n,): sampled free flight; pend (n, 8): per-step terms kept across the ray cast
#:   (channel pdf r, g, b, forward/backward pdf factors, forward/backward stretching,
#:   backward fraction); guided_frac (n,): the step's guided fraction; diff_len (n,) Dwivedi
#:   diffusion length, phase_log (n,); state (n,) int8: SSS_WALK, SSS_EXIT, SSS_DEAD;
#:   guided0 (n,): the guided fraction of the steps before the similarity relation,
#:   1 − max(½, |g|^⅛) (a power per walk, not two per step).
WalkState = namedtuple("WalkState", [
    "o", "d", "tmax", "thr", "sigma_t", "alpha", "g", "n_entry", "p_entry", "step", "opposite",
    "opp_dist", "pixel", "index", "dim0", "t_sample", "pend", "guided_frac", "diff_len", "phase_log", "state",
    "guided0"])


#: sample dimensions of the walks: those of loop pass ``depth`` start at
#: D_SSS0 + WALK_DIMS·BSSRDF_MAX_BOUNCES·depth (above the volumes' 2^20 + 5·segment), and step s
#: takes three 2-D samples, + WALK_DIMS·s + (0: (channel, free flight), 1: (guided, backward),
#: 2: direction)
D_SSS0 = 1 << 21
WALK_DIMS = 3


def walk_dim0(depth: int) -> int:
    """First sample dimension of the walks started in loop pass ``depth``."""
    return D_SSS0 + WALK_DIMS * BSSRDF_MAX_BOUNCES * int(depth)


#: walk steps whose numbers come from the sample sequence; later steps hash (stratification
#: matters most early: a walk's exit depends most on its first flights; the sequence's
#: scrambling costs ~2x a hash, and walks average ~27 steps)
STRATIFIED_STEPS = 8


@inline_kernel
def walk_pair(ws, sd, i, step, k):
    """Walk i's 2-D sample k (0 … WALK_DIMS − 1) of this step: for the first STRATIFIED_STEPS
    steps the path's own sample sequence (pixel, sample index) at dimension
    dim0 + WALK_DIMS·step + k, so those steps are stratified over the pixel's samples, as
    Cycles's walk draws them from its sequence; then a hash of (dimension, pixel, sample)."""
    dim = ws.dim0[i] + WALK_DIMS * step + k
    if step < STRATIFIED_STEPS:
        return sample_2d(sd, ws.pixel[i], ws.index[i], dim)
    return random_2d(sd, ws.pixel[i], ws.index[i], dim)


@inline_kernel
def diffusion_length_dwivedi(alpha):
    """d'Eon & Křivánek 2020, Eq. 67 (as Cycles)."""
    return 1.0 / math.sqrt(1.0 - alpha ** (2.44294 - 0.0215813 * alpha + 0.578637 / alpha))


@inline_kernel
def hg_pdf(cos_theta, g):
    if abs(g) < 1e-3:
        return 0.25 / math.pi
    fac = 1.0 + g * (g - 2.0 * cos_theta)
    return (1.0 - g * g) / (4.0 * math.pi * fac * math.sqrt(max(fac, 0.0)))


@inline_kernel
def direction_from_cosine(axis, cos_theta, u):
    """The unit direction at cosine cos_theta to ``axis`` and azimuth 2π·u about it. The azimuth's
    sine and cosine are taken in float32 (glibc's sincosf, ~11 ns against ~22 for the float64
    sincos, ~4 % of a walk step): the walk's rays are float32 for Embree anyway, and an azimuth
    rounded to 2^-24 turns leaves its distribution uniform."""
    sin_theta = math.sqrt(max(0.0, 1.0 - cos_theta * cos_theta))
    phi = np.float32(2.0 * math.pi * u)
    cos_phi = float(math.cos(phi))
    sin_phi = float(math.sin(phi))
    t, b = build_frame(axis)
    return to_world((sin_theta * cos_phi, sin_theta * sin_phi, cos_theta), t, b, axis)


@kernel
def walk_start(ws, count, thr_factor):
    """Per row: throughput × the coefficient factor, Dwivedi terms; rows whose diffusion length
    is 1 die (Cycles returns early)."""
    for i in range(count):
        for c in range(3):
            ws.thr[i, c] *= thr_factor[i, c]
        amax = max(ws.alpha[i, 0], max(ws.alpha[i, 1], ws.alpha[i, 2]))
        v = diffusion_length_dwivedi(amax)
        ws.diff_len[i] = v
        if not (v > 1.0 and math.isfinite(v)):
            ws.state[i] = SSS_DEAD
            continue
        ws.phase_log[i] = math.log((v + 1.0) / (v - 1.0))
        ws.guided0[i] = 1.0 - max(0.5, abs(ws.g[i]) ** 0.125)
        ws.step[i] = 0
        ws.opposite[i] = False
        ws.opp_dist[i] = 0.0
        ws.state[i] = SSS_WALK


@inline_kernel
def _exp32(x):
    """exp(x) for x ≤ 80 in float32 (glibc's expf: about half the cost of exp). The walk's
    exponentials only enter ratios and sampling warps, where float32's relative precision is
    far below the Monte Carlo noise."""
    return float(math.exp(np.float32(x)))


@inline_kernel
def _transmittance(sigma_t):
    """exp(−σ·t) of a flight (σ·t ≥ 0) in float32 (glibc's expf, about half the cost of exp;
    the advance takes up to nine a step, which were ~11 % of sss_head's render). Only ratios of
    these values enter the throughput, to float32's relative precision; a flight past ~87
    mean free paths underflows to 0 as in Cycles's float32 walk."""
    return _exp32(-sigma_t)


@inline_kernel
def _coeffs(ws, i, step):
    """(σt, σs, g, guided fraction) of row i at this step (similarity relation after
    SIMILARITY_LEVEL steps)."""
    g0 = ws.g[i]
    st = (ws.sigma_t[i, 0], ws.sigma_t[i, 1], ws.sigma_t[i, 2])
    ss = (st[0] * ws.alpha[i, 0], st[1] * ws.alpha[i, 1], st[2] * ws.alpha[i, 2])
    if step <= SIMILARITY_LEVEL:
        return st, ss, g0, ws.guided0[i]
    ss2 = (ss[0] * (1.0 - g0), ss[1] * (1.0 - g0), ss[2] * (1.0 - g0))
    st2 = (st[0] - ss[0] + ss2[0], st[1] - ss[1] + ss2[1], st[2] - ss[2] + ss2[2])
    return st2, ss2, 0.0, 0.75


@inline_kernel
def _sample_row(ws, sd, i):
    """Sample channel, direction and free flight of walk i; sets o/d/tmax of the ray to cast
    (tmax: the flight, or on the first step ≥ 10 mean free paths to look for the opposite
    side)."""
    step = ws.step[i]
    st, ss, g, guided_frac = _coeffs(ws, i, step)
    # channel ∝ |throughput · α| (balance-heuristic MIS over channels)
    w0 = abs(ws.thr[i, 0] * ws.alpha[i, 0])
    w1 = abs(ws.thr[i, 1] * ws.alpha[i, 1])
    w2 = abs(ws.thr[i, 2] * ws.alpha[i, 2])
    total = w0 + w1 + w2
    if total > 1e-30:
        p0, p1, p2 = w0 / total, w1 / total, w2 / total
    else:
        p0 = p1 = p2 = 1.0 / 3.0
    u, ut = walk_pair(ws, sd, i, step, 0)
    if u < p0:
        sample_st = st[0]
    elif u < p0 + p1:
        sample_st = st[1]
    else:
        sample_st = st[2]
    fwd_factor = 0.0
    bwd_factor = 0.0
    fwd_stretch = 1.0
    bwd_stretch = 1.0
    bwd_frac = 0.0
    if step > 0:
        v = ws.diff_len[i]
        plog = ws.phase_log[i]
        u_guided, u_backward = walk_pair(ws, sd, i, step, 1)
        guided = u_guided < guided_frac
        n = load(ws.n_entry, i)
        backward = False
        if ws.opposite[i]:
            od = ws.opp_dist[i]
            x = -((ws.o[i, 0] - ws.p_entry[i, 0]) * n[0] + (ws.o[i, 1] - ws.p_entry[i, 1]) * n[1]
                  + (ws.o[i, 2] - ws.p_entry[i, 2]) * n[2])
            x = min(max(x, 0.0), od)
            bwd_frac = 1.0 / (1.0 + _exp32(min((od - 2.0 * x) / v, 80.0)))
            backward = u_backward < bwd_frac
        us0, us1 = walk_pair(ws, sd, i, step, 2)
        d_old = load(ws.d, i)
        if guided:
            cos_theta = v - (v + 1.0) * _exp32(-us0 * plog)
            if backward:
                cos_theta = -cos_theta
            nd = direction_from_cosine(n, cos_theta, us1)
            hg = hg_pdf(dot(d_old, nd), g)
        else:
            ct = 1.0 - 2.0 * us0
            if abs(g) >= 1e-3:
                k = (1.0 - g * g) / (1.0 - g * ct)
                ct = (1.0 + g * g - k * k) / (2.0 * g)
            ct = min(max(ct, -1.0), 1.0)
            hg = hg_pdf(ct, g)
            nd = direction_from_cosine(d_old, ct, us1)
            cos_theta = dot(nd, n)
        nd, _ = normalize(nd)
        store(ws.d, i, nd)
        # guided / classic pdf ratio of the direction (channel independent)
        fwd_factor = (0.5 / math.pi) / ((v - cos_theta) * plog) / hg
        bwd_factor = (0.5 / math.pi) / ((v + cos_theta) * plog) / hg
        fwd_stretch = 1.0 - cos_theta / v
        bwd_stretch = 1.0 + cos_theta / v
        if guided:
            sample_st *= bwd_stretch if backward else fwd_stretch
    t = -float(math.log(np.float32(1.0 - ut))) / sample_st
    if step == 0:
        st_min = min(st[0], min(st[1], st[2]))
        ws.tmax[i] = max(t, 10.0 / st_min)
    else:
        ws.tmax[i] = t
    ws.t_sample[i] = t
    ws.guided_frac[i] = guided_frac if step > 0 else 0.0
    ws.pend[i, 0] = p0
    ws.pend[i, 1] = p1
    ws.pend[i, 2] = p2
    ws.pend[i, 3] = fwd_factor
    ws.pend[i, 4] = bwd_factor
    ws.pend[i, 5] = fwd_stretch
    ws.pend[i, 6] = bwd_stretch
    ws.pend[i, 7] = bwd_frac


@kernel
def walk_sample(ws, sd, rows):
    """``_sample_row`` for every walk in ``rows`` (one wavefront step); sd: ``Sampler.data``."""
    for r in range(rows.shape[0]):
        _sample_row(ws, sd, rows[r])


@inline_kernel
def _flight_pdf(sigma, t, hit):
    """Per channel: transmittance, or σ·transmittance for a scattering event."""
    tr = _transmittance(sigma * t)
    return tr if hit else sigma * tr


@inline_kernel
def _advance_row(ws, i, th):
    """After walk i's ray cast (th: distance to the object's surface, inf if none within tmax):
    advance, update the throughput with the MIS pdf, decide exit / death. Returns whether the
    walk goes on."""
    step = ws.step[i]
    st, ss, g, guided_frac = _coeffs(ws, i, step)
    t = ws.t_sample[i]
    hit = th < ws.tmax[i] and math.isfinite(th)
    if step == 0:
        if hit:
            ws.opposite[i] = True
            n = load(ws.n_entry, i)
            ws.opp_dist[i] = -((ws.o[i, 0] + th * ws.d[i, 0] - ws.p_entry[i, 0]) * n[0]
                               + (ws.o[i, 1] + th * ws.d[i, 1] - ws.p_entry[i, 1]) * n[1]
                               + (ws.o[i, 2] + th * ws.d[i, 2] - ws.p_entry[i, 2]) * n[2])
        hit = hit and th < t
    if hit:
        t = th
    fwd_factor = ws.pend[i, 3]
    bwd_factor = ws.pend[i, 4]
    fwd_stretch = ws.pend[i, 5]
    bwd_stretch = ws.pend[i, 6]
    bwd_frac = ws.pend[i, 7]
    denom = 0.0
    contrib = (0.0, 0.0, 0.0)
    for c in range(3):
        s = st[c]
        tr = _transmittance(s * t)
        pdf = tr if hit else s * tr
        if step > 0:
            guided = _flight_pdf(fwd_stretch * s, t, hit)
            if ws.opposite[i]:
                back = _flight_pdf(bwd_stretch * s, t, hit)
                guided = guided * fwd_factor * (1.0 - bwd_frac) + back * bwd_factor * bwd_frac
            else:
                guided *= fwd_factor
            pdf = pdf * (1.0 - guided_frac) + guided * guided_frac
        denom += ws.pend[i, c] * pdf
        val = tr if hit else ss[c] * tr
        if c == 0:
            contrib = (val, contrib[1], contrib[2])
        elif c == 1:
            contrib = (contrib[0], val, contrib[2])
        else:
            contrib = (contrib[0], contrib[1], val)
    for c in range(3):
        ws.o[i, c] += t * ws.d[i, c]
    if not denom > 0.0 or not math.isfinite(denom):
        ws.state[i] = SSS_DEAD
        return False
    for c in range(3):
        ws.thr[i, c] *= contrib[c] / denom
    ws.step[i] = step + 1
    if hit:
        ws.state[i] = SSS_EXIT
        return False
    tmaxc = max(ws.thr[i, 0], max(ws.thr[i, 1], ws.thr[i, 2]))
    if not tmaxc >= VOLUME_THROUGHPUT_EPSILON or step + 1 >= BSSRDF_MAX_BOUNCES:
        ws.state[i] = SSS_DEAD
        return False
    return True


@kernel
def walk_advance(ws, rows, hit_t):
    """``_advance_row`` for every walk in ``rows`` (hit_t[r]: row r's answer). Returns how many
    are still walking."""
    walking = 0
    for r in range(rows.shape[0]):
        if _advance_row(ws, rows[r], hit_t[r]):
            walking += 1
    return walking


@kernel
def walk_local(ws, sd, rows, fn, scene, words, positions, triangles, face_ng, offset, centre, eps0,
               ex_prim, ex_b, ex_p, ex_ng):
    """Every remaining step of the walks in ``rows``, all on one static object whose Embree
    scene (``scene``, its own triangles: prim ids local, ``offset`` added for global ids) this
    kernel queries itself, one ray per step (``drt.embree_direct``): the same steps as the
    wavefront (``walk_sample``, one Embree query, ``walk_advance``) without a Python round trip
    per step. The exit vertex of every hit goes to ex_prim/ex_b/ex_p/ex_ng (as
    ``trace.static_surface`` computes hit points); eps0: the first ray's push off the entry
    point; centre (3,): the origin of the object's scene (``_centred_geometry``) in the walk's
    frame. Returns the number of steps taken."""
    bits, base, addr = ray_buffer(words)
    steps = 0
    for r in range(rows.shape[0]):
        i = rows[r]
        while ws.state[i] == SSS_WALK:
            _sample_row(ws, sd, i)
            d = load(ws.d, i)
            push = 0.0
            tmax = ws.tmax[i]
            if ws.step[i] == 0:
                push = eps0[i]
                tmax = max(tmax - push, 0.0)
            o = (ws.o[i, 0] - centre[0] + push * d[0], ws.o[i, 1] - centre[1] + push * d[1],
                 ws.o[i, 2] - centre[2] + push * d[2])
            t, prim, u, v = trace1(fn, scene, words, bits, base, addr, o, d, tmax)
            th = math.inf
            if prim >= 0 and (ws.step[i] > 0 or tmax > 0.0):  # (as the wavefront's first-ray rule)
                th = t + push
                ex_prim[i] = prim + offset
                ex_b[i, 0] = u
                ex_b[i, 1] = v
                static_hit_row(positions, triangles, face_ng, prim, u, v, d, ex_p, ex_ng, i)
                for c in range(3):
                    ex_p[i, c] += centre[c]
            _advance_row(ws, i, th)
            steps += 1
    return steps


@kernel
def _patch_exits(state, live, sss_prim, sss_b, sss_p, sss_n, prim, t, b1, b2, p, ng, moving):
    """Hits of the rows that left a walk ← the exit vertex the walk found."""
    for i in range(live):
        if state[i] == SSS_EXIT or state[i] == SSS_EXIT_FLAT:
            prim[i] = sss_prim[i]
            t[i] = 0.0
            b1[i] = sss_b[i, 0]
            b2[i] = sss_b[i, 1]
            for c in range(3):
                p[i, c] = sss_p[i, c]
                ng[i, c] = sss_n[i, c]
            if moving.shape[0]:
                moving[i] = False


def _object_centre(geom, start, end):
    """The bounding-box centre (float64, the scene's shifted frame) of static triangles
    [start, end): the origin of that object's walk scene."""
    used = geom.static_positions[np.unique(geom.static_triangles[start:end])].astype(np.float64)
    return np.ascontiguousarray(0.5 * (used.min(axis=0) + used.max(axis=0)))


def _centred_geometry(geom, start, end, scene_geometry):
    """The static triangles [start, end) of ``geom`` as a scene of their own, vertices moved by
    −``_object_centre``. A walk's rays are float32 for Embree: in the render's frame (shifted to
    the camera) an object 5 m away rounds a ray origin by ~5e-7 m, and a scatter point that close
    to the surface starts its ray outside — the walk slips out of the object (2.3 % of
    sss_head's exits came back in from outside, docs/subsurface.md). About the object's own
    centre the rounding is its size × 6e-8. Triangle indices are the object's own; hits keep
    the object's triangle numbering (start is added back as before). Returns (the scene's
    geometry, the centre)."""
    tris = geom.static_triangles[start:end]
    used, local = np.unique(tris, return_inverse=True)
    centre = _object_centre(geom, start, end)
    positions = (geom.static_positions[used].astype(np.float64) - centre).astype(np.float32)
    sub = scene_geometry(origin_shift=np.asarray(geom.origin_shift, np.float64) + centre,
                         static_positions=np.ascontiguousarray(positions),
                         static_triangles=np.ascontiguousarray(local.reshape(tris.shape).astype(tris.dtype)))
    return sub, centre


def _direct_walk_args(tracer):
    """walk_local's Embree arguments for a local tracer (rtcIntersect1's address, the scene
    handle, positions, triangles, unit face normals), or None to keep the wavefront: when the
    Embree handles are not confirmed or single rays do not answer exactly as embreex's batches
    do on a few hundred probe rays through the object's bounding box."""
    if tracer.static is None or not embree_direct.intersect1_address():
        return None
    geom = tracer.geom
    used = geom.static_positions[np.unique(geom.static_triangles)]
    lo, hi = used.min(axis=0), used.max(axis=0)
    # a fixed pattern (no random generator during a render): R3 points in the box, Fibonacci
    # directions taken in a scrambled order so that neighbouring origins do not share one
    inside, sphere = probe_pattern(256)
    o = lo + (hi - lo) * inside
    d = sphere[(np.arange(256) * 97) % 256]
    tmax = np.where(np.arange(256) % 2 == 0, np.inf, (hi - lo).max() * inside[:, 0])
    try:
        if not embree_direct.matches_embreex(tracer.static, o, d, tmax):
            return None
    except Exception:  # noqa: BLE001 - any surprise: the wavefront is always right
        return None
    return (embree_direct.intersect1_address(), embree_direct.scene_address(tracer.static),
            geom.static_positions, geom.static_triangles, tracer._static_ng)


class SubsurfaceWalker:
    """Runs the random walks of the paths ``shade`` marked SSS_WALK. On a static object each
    walk runs whole inside one kernel (``walk_local``) that asks Embree for one ray per step;
    walks on moving objects (or where Embree's C handles are not confirmed) run as a wavefront:
    per step one compiled sampling pass, one Embree query per entered object, one compiled
    update.

    Hits are restricted to the entered object as Cycles's ``scene_intersect_local`` does: every
    static object with an SSS material gets its own Embree scene. Walks on moving objects use
    the whole scene at the path's shutter time (not restricted) and their exits are shaded with
    the geometric normal (docs/subsurface.md)."""

    def __init__(self, geom, tracer, materials):
        from .geometry import SceneGeometry
        from .trace import Tracer

        self.tracer = tracer
        self.static_count = geom.static_count
        sss_mats = np.nonzero(np.any(materials.lobe_type == 4, axis=1))[0]  # BSDF_SUBSURFACE
        ranges = list(getattr(geom, "static_ranges", []) or [])
        self.starts = np.array([s for s, _ in ranges], dtype=np.int64)
        self.local = {}
        self.centre = {}
        for k, (s, e) in enumerate(ranges):
            if e > s and np.isin(geom.material[s:e], sss_mats).any():
                sub, self.centre[k] = _centred_geometry(geom, s, e, SceneGeometry)
                self.local[k] = (Tracer(sub), s)
        # objects whose walks run whole in one kernel, Embree called per step (walk_local)
        self.direct = {k: args for k, (tracer, s) in self.local.items()
                       if (args := _direct_walk_args(tracer)) is not None}
        # statistics: walk steps summed over rows, walks, walks out of steps, other deaths
        self.steps_taken = self.walks = self.capped = self.died = 0

    def patch_hits(self, paths, live, hits):
        """Rows leaving a walk: their next 'hit' is the exit vertex (HitArrays, in place)."""
        _patch_exits(paths.sss, live, paths.sss_prim, paths.sss_b, paths.sss_p, paths.sss_n,
                     hits.prim, hits.t, hits.b1, hits.b2, hits.p, hits.ng, hits.moving)

    def _group(self, prim):
        """Per row: the index of its local tracer (object), −1 for moving objects."""
        if not len(self.starts):
            return np.full(len(prim), -1, np.int64)
        obj = np.searchsorted(self.starts, prim, side="right") - 1
        obj[prim >= self.static_count] = -1
        return obj

    def run(self, paths, live, depth_i, sd):
        """Walk every row of paths[:live] in state SSS_WALK; leaves them SSS_EXIT (/_FLAT) with
        the exit vertex in sss_prim/sss_b/sss_p/sss_n, or SSS_DEAD. sd: ``Sampler.data`` of this
        render (the integrator's current sampler: a render may change its seed or spp)."""
        rows = np.nonzero(paths.sss[:live] == SSS_WALK)[0]
        n = len(rows)
        if not n:
            return
        coef = paths.sss_coef[rows]
        ws = WalkState(
            o=paths.o[rows], d=paths.d[rows], tmax=np.empty(n), thr=paths.throughput[rows],
            sigma_t=np.ascontiguousarray(coef[:, 0:3]), alpha=np.ascontiguousarray(coef[:, 3:6]),
            g=np.ascontiguousarray(coef[:, 9]), n_entry=paths.sss_n[rows], p_entry=paths.sss_p[rows],
            step=np.zeros(n, np.int64), opposite=np.zeros(n, bool), opp_dist=np.zeros(n),
            pixel=np.ascontiguousarray(paths.pixel[rows], dtype=np.int64),
            index=np.ascontiguousarray(paths.index[rows], dtype=np.int64),
            dim0=np.full(n, walk_dim0(depth_i), np.int64),
            t_sample=np.zeros(n), pend=np.zeros((n, 8)), guided_frac=np.zeros(n), diff_len=np.zeros(n),
            phase_log=np.zeros(n), state=np.zeros(n, np.int8), guided0=np.zeros(n))
        walk_start(ws, n, np.ascontiguousarray(coef[:, 6:9]))
        group = self._group(paths.sss_prim[rows])
        tau = paths.tau[rows]
        ex_prim = np.full(n, -1, np.int64)
        ex_b = np.zeros((n, 2))
        ex_p = np.zeros((n, 3))
        ex_ng = np.zeros((n, 3))
        # the first ray leaves the entry point along its own direction by the usual offset
        # distance (trace.offset_point's), measured along the normal: Cycles excludes the entry
        # triangle instead; moving the origin along the normal would start the walk deeper,
        # which matters when the mean free path is below the offset (tiny radii)
        cos = np.abs(np.einsum("ij,ij->i", ws.d, ws.n_entry))
        eps0 = (OFFSET_ABSOLUTE + OFFSET_RELATIVE * np.abs(ws.o).max(axis=1)) / np.maximum(cos, 1e-3)
        kinds = np.unique(group)
        for k in kinds:
            if int(k) in self.direct:  # the usual case: static objects, compiled walks
                fn, scene, positions, triangles, face_ng = self.direct[int(k)]
                mine = np.flatnonzero((group == k) & (ws.state == SSS_WALK))
                self.steps_taken += walk_local(ws, sd, mine, fn, scene, embree_direct.scratch(), positions,
                                               triangles, face_ng, self.local[int(k)][1], self.centre[int(k)], eps0,
                                               ex_prim, ex_b, ex_p, ex_ng)
        kinds = np.array([k for k in kinds if int(k) not in self.direct])
        single = int(kinds[0]) if len(kinds) == 1 else None  # one object left
        for it in range(BSSRDF_MAX_BOUNCES):
            act = np.flatnonzero(ws.state == SSS_WALK)
            if not len(act):
                break
            self.steps_taken += len(act)
            walk_sample(ws, sd, act)
            first = it == 0  # every walk takes its first step in the first pass
            hit_t = np.empty(len(act))
            if single is not None:
                parts = ((single, None),)
            else:
                g_act = group[act]
                parts = tuple((int(k), np.flatnonzero(g_act == k)) for k in np.unique(g_act))
            for k, sel in parts:
                r = act if sel is None else act[sel]
                d = ws.d[r]
                if first:
                    push = eps0[r]
                    o = ws.o[r] + push[:, None] * d
                    tmax = np.maximum(ws.tmax[r] - push, 0.0)
                else:
                    push = 0.0
                    o = ws.o[r]
                    tmax = ws.tmax[r]
                centre = 0.0
                if k >= 0:
                    tracer, offset = self.local[k]
                    centre = self.centre[k]
                    h = tracer.intersect(o - centre, d, None, tmax)
                else:
                    tracer, offset = self.tracer, 0
                    h = tracer.intersect(o, d, tau[r], tmax)
                hit = h.prim >= 0
                if first:
                    hit &= tmax > 0.0
                ht = np.where(hit, h.t + push, np.inf)
                if sel is None:
                    hit_t = ht
                else:
                    hit_t[sel] = ht
                if hit.any():
                    rh = r[hit]
                    ex_prim[rh] = h.prim[hit] + offset
                    ex_b[rh, 0], ex_b[rh, 1] = h.b1[hit], h.b2[hit]
                    ex_p[rh] = h.p[hit] + centre
                    ex_ng[rh] = h.ng[hit]
            walk_advance(ws, act, hit_t)
        ws.state[ws.state == SSS_WALK] = SSS_DEAD  # (walk_advance already stops at the cap)
        dead = ws.state == SSS_DEAD
        self.walks += n
        self.capped += int((dead & (ws.step >= BSSRDF_MAX_BOUNCES)).sum())
        self.died += int(dead.sum())
        out = ws.state == SSS_EXIT
        state = np.where(out, np.where(group < 0, SSS_EXIT_FLAT, SSS_EXIT), SSS_DEAD).astype(np.int8)
        paths.sss[rows] = state
        paths.throughput[rows] = ws.thr
        r_ex = rows[out]
        paths.sss_prim[r_ex] = ex_prim[out]
        paths.sss_b[r_ex] = ex_b[out]
        paths.sss_p[r_ex] = ex_p[out]
        paths.sss_n[r_ex] = ex_ng[out]
        paths.o[r_ex] = ex_p[out]
        paths.d[r_ex] = -ws.d[out]  # as if arriving from outside: wo points out of the surface
        paths.tmax[rows] = 0.0      # their next Embree query is a formality (patch_hits)
