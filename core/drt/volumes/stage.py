"""What the path tracer does per ray segment inside media (called from ``drt.path_stages``), and
the shadow-ray transmittance stage. Cycles 5.0's homogeneous integrator
(kernel/integrator/shade_volume.h, volume_integrate_homogeneous) is the model:

* **emission** of the segment [0, L) is integrated analytically: thr·σe·(1 − e^(−σt·L))/σt;
* **indirect** (the path's next vertex): scatter inside the segment with probability 1 − T(L)
  in a channel picked ∝ (albedo·(1 − T) + T)·throughput, at a distance drawn from that
  channel's exponential; the weights divide by the channel-averaged pdf, so the estimator is
  unbiased for every colour. Otherwise the path transmits to the segment's end with weight
  T(L)/P(transmit);
* **direct** (next-event estimation, decoupled from the indirect vertex as in Cycles): a second
  point on the segment, by distance sampling or — when the light sample has a position —
  equiangular sampling toward it, chosen with probability ½ each and weighted by the power
  heuristic between the two densities (× 2 for the ½). The light is sampled again from that
  point; its contribution is thr·σs·T(t)/pdf(t) · phase · Le / pdf_light.
* a path that may not scatter any more (a bounce limit) or a medium that does not scatter only
  attenuates (weight T(L)) and collects emission, like Cycles's PATH_RAY_TERMINATE paths.

Emitters the ray passes before its end (light shapes, the sun, the world) are weighted by
T(t)/P(the path gets past t) (``pass_factor``) so that all estimators stay unbiased.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import inline_kernel, kernel
from ..kernels.vec3 import load, store
from ..kernels.vec3 import load_col3
from ..lights import light_sample, light_sample_full
from ..scene import VIS_SHADOW
from ..lights.common import AREA, I_KIND, L_COS_HALF, L_NORMAL, L_POS, L_RADIUS, L_SPOT_DIR, SPOT
from ..sampling.sequences import sample_2d
from .hetero import ratio_tracking, seed_of, seed_of_point, stack_is_hetero, stack_scatters, track_segment
from .distance import (channel_probs, equiangular_pdf, equiangular_sample, equiangular_setup, exp_pdf,
                       exp_sample, pick_channel)
from ..materials.program_format import (POINT_I, POINT_MISC, POINT_N, POINT_NG, POINT_NSMOOTH, POINT_P,
                                        POINT_SHADOW, POINT_XFORM, POINT_OBJECT_XFORM)
from ..materials.programs import eval_material
from ..materials.transparency import transparency
from .phase import hg_pdf
from .stack import stack_coefficients, stack_cross

#: volume sample dimensions start far above the surface ones (3 + 4·bounce), so that scenes
#: without media keep their sample pattern; per ray segment k of a path they are
#: D_VOLUME0 + VOLUME_DIMS·k + (0: (scatter, channel), 1: (light select, direct method/distance),
#: 2: light position, 3: phase direction, 4: (Russian roulette, unused))
D_VOLUME0 = 1 << 20
VOLUME_DIMS = 5

#: MODE_HETERO: the segment was tracked through a heterogeneous medium (drt.volumes.hetero):
#: emitters before its end take an independent ratio-tracking estimate, not ``pass_factor``
MODE_NONE, MODE_ATTENUATE, MODE_SCATTER, MODE_HETERO = 0, 1, 2, 3

_ZERO3 = (0.0, 0.0, 0.0)
_NO_HINT = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0)


@kernel
def transmittance(sig_t, t):
    """e^(−σt·t) per channel (t may be inf: 0 where σt > 0, 1 where σt = 0)."""
    if sig_t[0] == sig_t[1] and sig_t[1] == sig_t[2]:
        # a grey medium (most fog and smoke): one exponential, the same value in every channel
        e = math.exp(-sig_t[0] * t) if sig_t[0] > 0.0 else 1.0
        return (e, e, e)
    return (math.exp(-sig_t[0] * t) if sig_t[0] > 0.0 else 1.0,
            math.exp(-sig_t[1] * t) if sig_t[1] > 0.0 else 1.0,
            math.exp(-sig_t[2] * t) if sig_t[2] > 0.0 else 1.0)


@kernel
def segment_emission(sig_t, emis, length):
    """∫_0^L T(s)·σe ds per channel (a channel with no extinction over an infinite segment
    gives 0: such emission has no finite value, Cycles leaves it to its ray length)."""
    out0 = out1 = out2 = 0.0
    for c in range(3):
        e = emis[c]
        s = sig_t[c]
        if e > 0.0:
            if s > 0.0:
                v = e * (-math.expm1(-s * length)) / s if math.isfinite(length) else e / s
            else:
                v = e * length if math.isfinite(length) else 0.0
            if c == 0:
                out0 = v
            elif c == 1:
                out1 = v
            else:
                out2 = v
    return (out0, out1, out2)


@kernel
def pass_factor(mode, sig_t, chp, t):
    """Weight of an emitter at distance t on the segment (see the module docstring)."""
    tr = transmittance(sig_t, t)
    if mode == MODE_ATTENUATE:
        return tr
    if mode == MODE_SCATTER:
        surv = chp[0] * tr[0] + chp[1] * tr[1] + chp[2] * tr[2]
        if not surv > 0.0:
            return _ZERO3
        return (tr[0] / surv, tr[1] / surv, tr[2] / surv)
    return (1.0, 1.0, 1.0)


@kernel
def spot_interval(ld, i, o, d, t0, t1):
    """[t0, t1) clipped to the part of the ray inside spot light i's cone (Cycles's
    spot_light_valid_ray_segment: the cone's apex moved back by radius / sin(half angle) so that
    it encloses the light from every point of its sphere); (t0, t0) when empty."""
    c = load_col3(ld.lf, i, L_POS)
    axis = load_col3(ld.lf, i, L_SPOT_DIR)
    cos_h = ld.lf[i, L_COS_HALF]
    sin_h = math.sqrt(max(1.0 - cos_h * cos_h, 0.0))
    if cos_h <= 1e-2 or sin_h <= 0.0:
        return t0, t1  # a (nearly) hemispherical cone: keep the segment
    back = ld.lf[i, L_RADIUS] / sin_h
    p = (o[0] - c[0] + axis[0] * back, o[1] - c[1] + axis[1] * back, o[2] - c[2] + axis[2] * back)
    cos2 = cos_h * cos_h
    ad = axis[0] * d[0] + axis[1] * d[1] + axis[2] * d[2]
    ap = axis[0] * p[0] + axis[1] * p[1] + axis[2] * p[2]
    dp = d[0] * p[0] + d[1] * p[1] + d[2] * p[2]
    pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
    qa = ad * ad - cos2
    qb = 2.0 * (ad * ap - cos2 * dp)
    qc = ap * ap - cos2 * pp
    # points t with (axis·(p + t·d))² ≥ cos²·|p + t·d|² and axis·(p + t·d) > 0
    lo, hi = -math.inf, math.inf
    if abs(qa) < 1e-12:
        if abs(qb) < 1e-300:
            return (t0, t1) if qc >= 0.0 and ap > 0.0 else (t0, t0)
        r = -qc / qb
        lo, hi = (r, math.inf) if qb > 0.0 else (-math.inf, r)
    else:
        disc = qb * qb - 4.0 * qa * qc
        if disc < 0.0:
            if qa > 0.0:  # the quadratic is ≥ 0 everywhere: the whole double cone's... check side
                lo, hi = -math.inf, math.inf
            else:
                return t0, t0
        else:
            sq = math.sqrt(disc)
            r0 = (-qb - sq) / (2.0 * qa)
            r1 = (-qb + sq) / (2.0 * qa)
            if r0 > r1:
                r0, r1 = r1, r0
            if qa < 0.0:  # inside between the roots
                lo, hi = r0, r1
            else:  # inside outside the roots: keep the part on the cone's (forward) nappe
                if ap + r1 * ad > 0.0 and ad > 0.0:
                    lo, hi = r1, math.inf
                elif ap + r0 * ad > 0.0 and ad < 0.0:
                    lo, hi = -math.inf, r0
                else:
                    return t0, t0
    # the interval must lie on the forward nappe (axis·(p + t·d) > 0)
    if lo > -math.inf and ap + lo * ad < 0.0 and hi < math.inf and ap + hi * ad < 0.0:
        return t0, t0
    if lo == -math.inf and hi < math.inf and ap + hi * ad < 0.0:
        return t0, t0
    if hi == math.inf and lo > -math.inf and ap + lo * ad < 0.0:
        return t0, t0
    a = max(t0, lo)
    b = min(t1, hi)
    return (a, b) if b > a else (t0, t0)


@kernel
def area_interval(ld, i, o, d, t0, t1):
    """[t0, t1) clipped to the half-space an area light emits into (in front of its plane)."""
    c = load_col3(ld.lf, i, L_POS)
    n = load_col3(ld.lf, i, L_NORMAL)
    h = (o[0] - c[0]) * n[0] + (o[1] - c[1]) * n[1] + (o[2] - c[2]) * n[2]
    dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2]
    if dn == 0.0:
        return (t0, t1) if h > 0.0 else (t0, t0)
    r = -h / dn
    a, b = (max(t0, r), t1) if dn > 0.0 else (t0, min(t1, r))
    return (a, b) if b > a else (t0, t0)


@inline_kernel
def hetero_segment(sd, ld, vd, pd, regs, point, stack, i, o, d, length, thr, terminate, nee, pixel, idx, seg):
    """``volume_segment`` through a stack holding a heterogeneous medium: spectral tracking for
    the indirect vertex, next-event estimation at the real scatter point (drt.volumes.hetero).
    Same returns as ``volume_segment`` (mode MODE_HETERO; σt and channel probabilities unused)."""
    base = D_VOLUME0 + VOLUME_DIMS * seg
    u_sc, u_ch = sample_2d(sd, pixel, idx, base)
    state = seed_of(pixel, idx, seg * 65599 + int(u_sc * 1.0e9) + int(u_ch * 7.0e8))
    attenuate = terminate or not stack_scatters(vd, stack, i)
    acc, scattered, t_s, thr_n, g, state = track_segment(vd, pd, regs, point, stack, i, o, d, length, thr,
                                                         attenuate, state)
    nee_ok = False
    x = o
    wi = d
    dist = 0.0
    f_nee = _ZERO3
    lpdf = 0.0
    ph = 0.0
    l_delta = False
    if scattered:
        x = (o[0] + d[0] * t_s, o[1] + d[1] * t_s, o[2] + d[2] * t_s)
        if nee and ld.n_strategies > 0:
            u_sel, _ = sample_2d(sd, pixel, idx, base + 1)
            ul0, ul1 = sample_2d(sd, pixel, idx, base + 2)
            wi, dist, le, lpdf, l_delta, l_valid = light_sample(ld, x, _ZERO3, _NO_HINT, u_sel, ul0, ul1)
            if l_valid and lpdf > 0.0:
                ph = hg_pdf(d[0] * wi[0] + d[1] * wi[1] + d[2] * wi[2], g)
                k = ph / lpdf
                f_nee = (thr_n[0] * le[0] * k, thr_n[1] * le[1] * k, thr_n[2] * le[2] * k)
                nee_ok = f_nee[0] > 0.0 or f_nee[1] > 0.0 or f_nee[2] > 0.0
    return (acc, MODE_HETERO, _ZERO3, (1.0, 0.0, 0.0), g, scattered, t_s, thr_n,
            nee_ok, x, wi, dist, f_nee, lpdf, ph, l_delta)


@inline_kernel
def volume_segment(sd, ld, vd, pd, regs, point, stack, i, o, d, length, thr, terminate, nee, pixel, idx, seg):
    """One ray segment o + t·d, t ∈ [0, length), inside the media of stack row i.

    Returns (emission collected (3-tuple, already × thr), mode, σt, channel probabilities, g,
    scattered, t_scatter, thr after the segment (× T/P(transmit) or × σs·T/pdf at the scatter
    point), nee_ok, x, wi, dist, f_nee (thr·σs·T/pdf · phase · Le / light pdf, no MIS weight),
    light pdf, phase pdf, light is delta). ``nee``: next-event estimation wanted. ``pd``,
    ``regs``, ``point``: material programs, register file and point rows (heterogeneous media
    evaluate their density there; a stack of homogeneous media never touches them). ``pd``
    None: a scene without programs, hence without heterogeneous media, whose variant of the
    kernels holds no density code."""
    if pd is not None and vd.hetero and stack_is_hetero(vd, stack, i):
        return hetero_segment(sd, ld, vd, pd, regs, point, stack, i, o, d, length, thr, terminate, nee,
                              pixel, idx, seg)
    sig_s, sig_t, emis, g = stack_coefficients(vd, stack, i)
    em = segment_emission(sig_t, emis, length)
    acc = (thr[0] * em[0], thr[1] * em[1], thr[2] * em[2])
    tr = transmittance(sig_t, length)
    no_chp = (1.0, 0.0, 0.0)
    if terminate or not (sig_s[0] > 0.0 or sig_s[1] > 0.0 or sig_s[2] > 0.0):
        thr_t = (thr[0] * tr[0], thr[1] * tr[1], thr[2] * tr[2])
        return (acc, MODE_ATTENUATE, sig_t, no_chp, g, False, math.inf, thr_t,
                False, o, d, 0.0, _ZERO3, 0.0, 0.0, False)
    base = D_VOLUME0 + VOLUME_DIMS * seg
    alb = (sig_s[0] / sig_t[0] if sig_t[0] > 0.0 else 0.0,
           sig_s[1] / sig_t[1] if sig_t[1] > 0.0 else 0.0,
           sig_s[2] / sig_t[2] if sig_t[2] > 0.0 else 0.0)

    # --- indirect: scatter somewhere in the segment, or transmit through it
    u_sc, u_ch = sample_2d(sd, pixel, idx, base)
    chp = channel_probs((alb[0] * (1.0 - tr[0]) + tr[0]) * thr[0],
                        (alb[1] * (1.0 - tr[1]) + tr[1]) * thr[1],
                        (alb[2] * (1.0 - tr[2]) + tr[2]) * thr[2])
    ch, _ = pick_channel(chp, u_ch)
    p_sc = 1.0 - tr[ch]
    scattered = False
    t_s = math.inf
    if u_sc < p_sc:
        t_s = exp_sample(min(u_sc / p_sc, 1.0 - 1e-16), sig_t[ch], length)
        # (1 − T_c)·truncated pdf_c = σt_c·e^(−σt_c·t): the channel mixture's scatter density
        ts = transmittance(sig_t, t_s)
        pdf = chp[0] * sig_t[0] * ts[0] + chp[1] * sig_t[1] * ts[1] + chp[2] * sig_t[2] * ts[2]
        if pdf > 0.0 and t_s < length:
            scattered = True
            thr_n = (thr[0] * sig_s[0] * ts[0] / pdf, thr[1] * sig_s[1] * ts[1] / pdf,
                     thr[2] * sig_s[2] * ts[2] / pdf)
        else:
            thr_n = _ZERO3
    else:
        pdf = chp[0] * tr[0] + chp[1] * tr[1] + chp[2] * tr[2]
        thr_n = (thr[0] * tr[0] / pdf, thr[1] * tr[1] / pdf, thr[2] * tr[2] / pdf) if pdf > 0.0 else _ZERO3

    # --- direct: a second point for next-event estimation
    nee_ok = False
    x = o
    wi = d
    dist = 0.0
    f_nee = _ZERO3
    lpdf = 0.0
    ph = 0.0
    l_delta = False
    if nee and ld.n_strategies > 0:
        u_sel, u_dir = sample_2d(sd, pixel, idx, base + 1)
        ul0, ul1 = sample_2d(sd, pixel, idx, base + 2)
        chd = channel_probs(alb[0] * (1.0 - tr[0]) * thr[0], alb[1] * (1.0 - tr[1]) * thr[1],
                            alb[2] * (1.0 - tr[2]) * thr[2])
        # equiangular sampling needs a light position: sample the light from the segment start
        # (its position, even where it sends no light to o: a spot's cone may still reach the
        # segment, as Cycles, which checks only that the sample has a position)
        w0, dist0, _, _, _, _, s0, _ = light_sample_full(ld, o, _ZERO3, _NO_HINT, u_sel, ul0, ul1)
        # where the same light is picked at every point (selection not per point), sample only
        # the part of the segment it can light (Cycles's volume_valid_direct_ray_segment)
        ta, tb = 0.0, length
        if (not ld.per_point or ld.n_strategies == 1) and 0 <= s0 < ld.n_lights:
            if ld.li[s0, I_KIND] == SPOT:
                ta, tb = spot_interval(ld, s0, o, d, ta, tb)
            elif ld.li[s0, I_KIND] == AREA:
                ta, tb = area_interval(ld, s0, o, d, ta, tb)
        # sample on the sub-segment [ta, tb): positions relative to its start oa
        oa = (o[0] + d[0] * ta, o[1] + d[1] * ta, o[2] + d[2] * ta)
        la = tb - ta
        delta = span_d = th_a = th_b = 0.0
        equi = math.isfinite(dist0) and dist0 > 0.0
        if equi:
            c = (o[0] + w0[0] * dist0, o[1] + w0[1] * dist0, o[2] + w0[2] * dist0)
            delta, span_d, th_a, th_b = equiangular_setup(oa, d, c, la)
            equi = span_d > 1e-9 and th_b > th_a
        use_equi = False
        u = u_dir
        if equi:
            if u_dir < 0.5:
                u = 2.0 * u_dir
            else:
                use_equi = True
                u = 2.0 * u_dir - 1.0
            u = min(u, 1.0 - 1e-16)
        if use_equi:
            t = equiangular_sample(u, delta, span_d, th_a, th_b)
        else:
            chn, u2 = pick_channel(chd, u)
            t = exp_sample(u2, sig_t[chn], la)
        if sig_t[0] == sig_t[1] and sig_t[1] == sig_t[2]:  # grey: one density, same sum
            e = exp_pdf(t, sig_t[0], la)
            p_dist = chd[0] * e + chd[1] * e + chd[2] * e
        else:
            p_dist = (chd[0] * exp_pdf(t, sig_t[0], la) + chd[1] * exp_pdf(t, sig_t[1], la)
                      + chd[2] * exp_pdf(t, sig_t[2], la))
        p_equi = equiangular_pdf(t, delta, span_d, th_a, th_b, la) if equi else 0.0
        t_rel = t
        t = ta + t_rel
        if equi:
            a, b = (p_equi, p_dist) if use_equi else (p_dist, p_equi)
            # one-sample MIS over the two strategies (probability ½ each), power heuristic
            w_over_pdf = 2.0 * a / (a * a + b * b) if a > 0.0 else 0.0
        else:
            w_over_pdf = 1.0 / p_dist if p_dist > 0.0 else 0.0
        if w_over_pdf > 0.0 and t_rel < la and t < length:
            x = (o[0] + d[0] * t, o[1] + d[1] * t, o[2] + d[2] * t)
            wi, dist, le, lpdf, l_delta, l_valid = light_sample(ld, x, _ZERO3, _NO_HINT, u_sel, ul0, ul1)
            if l_valid and lpdf > 0.0:
                ph = hg_pdf(d[0] * wi[0] + d[1] * wi[1] + d[2] * wi[2], g)
                tt = transmittance(sig_t, t)
                k = w_over_pdf * ph / lpdf
                f_nee = (thr[0] * sig_s[0] * tt[0] * le[0] * k, thr[1] * sig_s[1] * tt[1] * le[1] * k,
                         thr[2] * sig_s[2] * tt[2] * le[2] * k)
                nee_ok = f_nee[0] > 0.0 or f_nee[1] > 0.0 or f_nee[2] > 0.0
    return (acc, MODE_SCATTER, sig_t, chp, g, scattered, t_s, thr_n,
            nee_ok, x, wi, dist, f_nee, lpdf, ph, l_delta)


# ---------------------------------------------------------------------- shadow rays in media

@kernel
def fill_shadow_point(point, pd, o, d, t, ng):
    """The shading-point rows of a shadow ray's hit (drt.materials.program_format.POINT_*):
    position, normals on the ray's side, incoming direction, ray length, Is Shadow Ray = 1;
    everything else as for a hit of an unscattered ray."""
    for r in range(point.shape[0]):
        for c in range(3):
            point[r, c] = 0.0
    back = d[0] * ng[0] + d[1] * ng[1] + d[2] * ng[2] > 0.0
    sgn = -1.0 if back else 1.0
    for c in range(3):
        point[POINT_P, c] = o[c] + d[c] * t + pd.origin[c]
        point[POINT_N, c] = sgn * ng[c]
        point[POINT_NG, c] = sgn * ng[c]
        point[POINT_NSMOOTH, c] = ng[c]
        point[POINT_I, c] = -d[c]
        point[POINT_XFORM + c, c] = 1.0
        point[POINT_OBJECT_XFORM + c, c] = 1.0
    point[POINT_MISC, 1] = t
    point[POINT_MISC, 2] = 1.0 if back else 0.0
    point[POINT_SHADOW, 0] = 1.0


@kernel
def shadow_step(vd, material, visibility, active, count, prim, t, ng, o, d, tmax, stack, trans, blocked,
                transparent, md, pd, regs, point, b1, b2):
    """One round of shadow rays through media and transparent surfaces: rows active[0:count]
    of the shadow arrays were traced (closest hits prim/t/ng/b1/b2, row k of the hit arrays
    for active[k]). Attenuates each by its stack's media up to the hit (or tmax), then: an
    opaque hit blocks; a transparent surface (``transparent[mat]``: alpha, Transparent BSDF)
    multiplies by its transparent colour (a textured one: its program run at the hit, with the
    shading point's Is Shadow Ray set) and the ray moves past it; a pass-through boundary
    updates the stack and moves the ray past it, as does an object shadow rays do not see
    (``visibility``: VIS_* bits per triangle, (0,): every object casts shadows); no hit: done. ``md``/``regs``/``point``: the
    thread's material workspace; ``vd`` None: the scene has no media (nothing of them is
    compiled into this variant), as ``pd`` None for a scene without programs. Returns the number of rows still active (compacted to the
    front of ``active``). A stack holding a heterogeneous medium attenuates by ratio tracking
    (drt.volumes.hetero; it writes ``point``'s coordinate rows before the hit fills them)."""
    n_next = 0
    check_visibility = visibility.shape[0] > 0
    for k in range(count):
        s = active[k]
        p = prim[k]
        hit = p >= 0 and t[k] < tmax[s]
        seg = t[k] if hit else tmax[s]
        if vd is not None and vd.enabled and stack[s, 0] >= 0:
            if pd is not None and vd.hetero and stack_is_hetero(vd, stack, s):
                oo = load(o, s)
                tr, _ = ratio_tracking(vd, pd, regs, point, stack, s, oo, load(d, s), seg,
                                       seed_of_point(oo, s))
            else:
                _, sig_t, _, _ = stack_coefficients(vd, stack, s)
                tr = transmittance(sig_t, seg)
            for c in range(3):
                trans[s, c] *= tr[c]
        if not hit:
            continue
        mat = np.int64(material[p])  # int64, as every material index: one compile per kernel
        dd = load(d, s)
        n = load(ng, k)
        unseen = check_visibility and not (visibility[p] & VIS_SHADOW)
        if not unseen and (vd is None or not (vd.enabled and vd.pass_through[mat])):
            if not (transparent.shape[0] and transparent[mat]):
                blocked[s] = True
                continue
            if pd is not None and pd.prog_of.shape[0] and pd.prog_of[mat] >= 0:
                if pd.reads_point[mat]:
                    fill_shadow_point(point, pd, load(o, s), dd, t[k], n)
                eval_material(pd, md, regs, mat, p, b1[k], b2[k], point)
            tc = transparency(md, mat)
            for c in range(3):
                trans[s, c] *= tc[c]
        if trans[s, 0] == 0.0 and trans[s, 1] == 0.0 and trans[s, 2] == 0.0:
            continue  # nothing gets through: done (the contribution is 0)
        if vd is not None and vd.enabled:
            stack_cross(vd, stack, s, p, mat, dd, n)
        oo = load(o, s)
        tk = t[k]
        # restart just past the boundary along the ray (relative offset, as trace.offset_point)
        eps = 1e-5 + 2e-6 * max(abs(oo[0] + dd[0] * tk), max(abs(oo[1] + dd[1] * tk), abs(oo[2] + dd[2] * tk)))
        adv = tk + eps / max(abs(dd[0] * n[0] + dd[1] * n[1] + dd[2] * n[2]), 1e-3)
        store(o, s, (oo[0] + dd[0] * adv, oo[1] + dd[1] * adv, oo[2] + dd[2] * adv))
        tmax[s] = tmax[s] - adv
        if tmax[s] > 0.0:
            active[n_next] = s
            n_next += 1
    return n_next


@kernel
def add_transmitted(shadow, count, blocked, trans, radiance):
    """Add every unblocked shadow ray's contribution × its transmittance."""
    for s in range(count):
        if not blocked[s]:
            slot = shadow.slot[s]
            c = load(shadow.contrib, s)
            v = (c[0] * trans[s, 0], c[1] * trans[s, 1], c[2] * trans[s, 2])
            store(radiance, slot, (radiance[slot, 0] + v[0], radiance[slot, 1] + v[1], radiance[slot, 2] + v[2]))


@kernel
def transmit_rows(sd, ld, vd, pd, regs, point, stack, o, d, length, thr, out_transmit, out_scatter, out_t):
    """The indirect decision of ``volume_segment`` for rows k = 0..n−1 (pixel k, sample 0) on
    the same segment, for tests: out_transmit[k] = throughput after the segment if the path
    transmitted (else 0), out_scatter[k] = throughput at the scatter point (else 0), out_t[k] =
    the scatter distance (inf: transmitted)."""
    for k in range(out_transmit.shape[0]):
        res = volume_segment(sd, ld, vd, pd, regs, point, stack, 0, o, d, length, thr, False, False, k, 0, 0)
        scattered, t_s, thr_n = res[5], res[6], res[7]
        for c in range(3):
            out_transmit[k, c] = 0.0 if scattered else thr_n[c]
            out_scatter[k, c] = thr_n[c] if scattered else 0.0
        out_t[k] = t_s
