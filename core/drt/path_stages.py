"""The compiled stages of the wavefront path tracer (called by ``drt.integrator``).

A batch of paths lives in arrays (``Paths``); per bounce the integrator asks Embree for the
closest hits of all live rays, then ``shade`` does everything else for every live path in one
compiled loop, and Embree answers the shadow rays that ``shade`` queued, which ``add_unoccluded``
adds to the film. Per path and bounce ``shade``:

1. collects the emitters the ray passed or hit — light shapes (lights are transparent emitters,
   as in Cycles), a sun disk and the world for rays that escape, the emission of the surface
   hit — each MIS-weighted against the light sampling done at the previous vertex;
2. stops the path if it had reached a bounce limit (Cycles: a path past a limit still collects
   the emission of its next hit);
3. next-event estimation: samples a light, evaluates the BSDF, weights by the chosen heuristic
   and queues a shadow ray;
4. samples the BSDF to continue, counts bounces like Cycles, applies Russian roulette after
   ``RR_START_BOUNCE`` bounces, and writes the surviving path back *compacted* (live paths stay
   at the front of the arrays: slot j ≤ i is written only after path j was read).

Sample dimensions (each a 2-D point from ``sample_2d``):

| dim | use |
|---|---|
| 0 | pixel filter offset (dims 0–2 are one 5-D sample, see ``sample_5d``) |
| 1 | lens position |
| 2 | (shutter time, unused) |
| 3 + 4b | (unused) at bounce b |
| 4 + 4b | light sample position and light selection (one 3-D sample, ``sample_3d``) |
| 5 + 4b | BSDF direction and lobe selection (one 3-D sample) |
| 6 + 4b | (Russian roulette, unused) |

Directions follow docs/architecture.md: ``wo`` points back along the path, ``wi`` toward the
next vertex; the local frame's z is the shading normal on the geometric front side.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .camera import camera_ray
from .cryptomatte import CRYPTO_IDS, CRYPTO_WEIGHT
from .film import (DATA_HIT, DATA_MATERIAL, DATA_OBJECT, DATA_POSITION, DATA_UV, DATA_WIDTH, LIGHT_DIFFUSE_COLOR,
                   LIGHT_EMISSION, LIGHT_ENVIRONMENT, LIGHT_WIDTH)
from .kernels import inline_kernel, kernel
from .kernels.vec3 import add, build_frame, dot, load, mul, neg, normalize, scale, store, sub, to_local, to_world
from .lights.common import I_VISIBLE_CAMERA
from .scene import VIS_CAMERA, VIS_DIFFUSE, VIS_GLOSSY, VIS_HOLDOUT, VIS_TRANSMISSION, VIS_VOLUME_SCATTER
from .lights.selection import KT_FLOOR
from .lights import (emissive_pdf, light_sample_full, shape_emission, shape_intersect, sun_emission,
                     sun_in_cone, world_pdf, world_radiance)
from .lights.world_map import world_radiance_at
from .lights.textured import textured_light_radiance
from .materials import (LOBE_DIFFUSE, LOBE_GLOSSY, LOBE_TRANSMISSION, NO_BUMP, bsdf_eval_bump,
                        bsdf_sample_bump)
from .materials.program_format import (POINT_DEPTH, POINT_I, POINT_MISC, POINT_N, POINT_NG, POINT_NSMOOTH,
                                       POINT_P, POINT_PATH, POINT_PATH2, POINT_SHADOW, POINT_XFORM,
                                       POINT_OBJECT_XFORM)
from .materials.programs import eval_material
from .materials.transparency import straight_lobe, transparency
from .materials.holdout import holdout_weight
from .materials.table import (BSDF_DIFFUSE, BSDF_SHEEN, BSDF_SUBSURFACE, BSDF_TRANSLUCENT, BSDF_VELVET,
                              LOBE_SUBSURFACE, LOBE_TRANSLUCENT, NO_VIEW_WEIGHTS, bsdf_eval_weights, layer_albedo, layer_cos, layered_emission,
                              pick_lobe_weights, under_weight)
from .subsurface import SSS_DEAD, SSS_EXIT, SSS_EXIT_FLAT, SSS_NONE, SSS_WALK, sss_coefficients
from .sampling.pixel_filter import filter_sample
from .sampling.sequences import sample_2d, sample_3d, sample_5d
from .sampling.warps import cosine_hemisphere, uniform_hemisphere
from .terminator import shading_factor, shadow_origin
from .trace import offset_point
from .volumes.phase import hg_sample
from .volumes.stack import stack_copy, stack_cross
from .volumes.hetero import ratio_tracking, seed_of
from .volumes.stage import D_VOLUME0, MODE_HETERO, VOLUME_DIMS, pass_factor, volume_segment

D_PIXEL, D_LENS, D_TIME, D_BOUNCE0, DIMS_PER_BOUNCE = 0, 1, 2, 3, 4
#: ray segments a path may cross volume-only boundaries on without a bounce (Cycles's
#: VOLUME_BOUNDS_MAX guards the same self-intersection loop)
VOLUME_BOUNDS_MAX = 64
RR_START_BOUNCE = 3
SHADOW_EPSILON = 1e-4  # relative shortening of shadow rays so they stop before the light's surface
# largest radiance a sample may carry: its square (the variance pass) still fits float32
MAX_SAMPLE_RADIANCE = 1e18

# direct-light strategies (scene.DIRECT_STRATEGIES order) and continuation strategies
DIRECT_MIS_POWER, DIRECT_MIS_BALANCE, DIRECT_LIGHT, DIRECT_BSDF = 0, 1, 2, 3
INDIRECT_BSDF, INDIRECT_COSINE, INDIRECT_UNIFORM = 0, 1, 2

StageSettings = namedtuple("StageSettings", [
    "width", "height",                    # image size in pixels
    "max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
    "clamp_direct", "clamp_indirect",     # 0: off
    "direct", "indirect",                 # DIRECT_* / INDIRECT_* codes
    "film_transparent",                   # camera rays that miss take their throughput off the alpha
    "motion",                             # anything moves: draw a shutter time per sample
    "volume_bounces",                     # scatter events a path may have in media (Cycles's)
    "transparent_bounces",                # straight pass-throughs a path may make (Cycles's)
    "transparent_glass",                  # Film > Transparent Glass: the GGX alpha up to which a
                                          # glass transmission keeps the world transparent (−1: off)
    "filter_glossy",                      # Cycles's Filter Glossy (0: off; ``glossy_blur``)
    "mist_start", "mist_inv_depth",       # the Mist pass: (distance − start) · inv_depth, ^falloff,
    "mist_falloff", "mist_ortho",         # distance along the view axis for an orthographic camera
                                          # (``mist_weight``; read only where ``Outputs.mist`` has rows)
    "pass_alpha",                         # the data passes' alpha threshold (``write_data_passes``)
    "ao_distance",                        # the Ambient Occlusion pass's ray length, metres (0: no
                                          # AO pass; ``queue_ao_ray``)
])

Paths = namedtuple("Paths", [
    "o", "d", "tmax", "tau",              # rays (n, 3), (n, 3), (n,), (n,) shutter fraction
    "throughput",                         # (n, 3)
    "prev_pdf", "prev_delta",             # BSDF pdf of the ray / it left the camera or a delta lobe
    "prev_p", "prev_n", "prev_wo", "prev_mat",  # the vertex the ray left (MIS pdfs, selection hint;
                                                # prev_mat: its hint_code)
    "counts",                             # (n, 4) int32: bounces, diffuse, glossy, transmission
    "terminate",                          # (n,) bool: collect emission at the next hit, then stop
    "slot", "pixel", "index",             # batch row, flat pixel id, sample number
    "prev_flags",                         # (n,) int32 RAY_* bits of how the ray was scattered
    "vstack",                             # (n, STACK_SIZE) int64 volume stack (drt.volumes.stack)
    "vcount",                             # (n,) int32 volume scatter events so far
    "vseg",                               # (n,) int32 ray segments so far (volume sample dims)
    # subsurface scattering (drt.subsurface; zero-size arrays in scenes without SSS):
    "sss",                                # (n,) int8 SSS_NONE / _WALK / _EXIT / _EXIT_FLAT / _DEAD
    "sss_coef",                           # (n, 10): σt (3), α (3), throughput factor (3), g
    "sss_n", "sss_p",                     # (n, 3): entry normal (outside) and point; at an exit
                                          # the exit's geometric normal and point
    "sss_prim",                           # (n,) entry triangle; at an exit the exit triangle
    "sss_b",                              # (n, 2) barycentrics (b1, b2) of the exit
    "sss_count",                          # (n,) int32 SSS exits so far (they shift the sample
                                          # dimensions: an exit is a vertex but no bounce)
    "tcount",                             # (n,) int32 transparent surfaces passed (Cycles's
                                          # transparent bounces: no bounce, own sample dims)
    "min_pdf",                            # (n,) smallest pdf of the path's non-delta bounces
                                          # (Cycles's min_ray_pdf, for Filter Glossy; zero-size
                                          # when the render does not filter)
])

# how a ray left its last vertex (Cycles's ray-type flags, for the Light Path node); 0: camera
RAY_DIFFUSE, RAY_GLOSSY, RAY_SINGULAR, RAY_TRANSMIT = 1, 2, 4, 8
#: not a ray kind: a path whose world is still transparent after glass transmissions (Film >
#: Transparent Glass; Cycles's PATH_RAY_TRANSPARENT_BACKGROUND beyond camera rays)
RAY_TRANSPARENT_BG = 16

Outputs = namedtuple("Outputs", ["radiance", "alpha", "depth", "normal", "albedo", "eye", "forward", "mist",
                                 "data",    # (n, DATA_COLUMNS) the data passes, (0, DATA_COLUMNS): none
                                 "light",   # (n, LIGHT_COLUMNS) the Emission, Environment and Diffuse
                                            # Color passes (rgb each; ``add_light_passes``,
                                            # ``diffuse_color``), (0, LIGHT_COLUMNS): none
                                 "crypto"])  # (n, CRYPTO_SURFACES, CRYPTO_COLUMNS) the see-through
                                             # hits Cryptomatte counts (``write_cryptomatte``),
                                             # (0, CRYPTO_SURFACES, CRYPTO_COLUMNS): none

#: columns of ``Outputs.data`` (``write_data_passes``): the film's (drt.film.DATA_*) — written
#: by a pixel's sample 0 only, as Cycles: the Object Index, the Material Index, the Position
#: (shifted world space; the integrator adds the origin shift back) and whether sample 0 hit a
#: surface; by every sample: the UV (u, v, 1 as Cycles's primitive_uv) — then, never filmed,
#: whether the sample's data passes are done (Cycles's PATH_RAY_SINGLE_PASS_DONE)
DATA_DONE = DATA_WIDTH
DATA_COLUMNS = DATA_WIDTH + 1
#: columns of ``Outputs.light`` (the film's ``sum_light``): Emission, Environment, Diffuse Color
LIGHT_COLUMNS = LIGHT_WIDTH

ShadowRays = namedtuple("ShadowRays", ["o", "d", "tmax", "tau", "contrib", "slot",
                                       "vstack"])  # (n, STACK_SIZE): the media the ray starts in

Surfaces = namedtuple("Surfaces", [
    "material",       # (T,) int32 per global triangle
    "normals",        # (T, 3, 3) float32 per-corner shading normals ((0, 3, 3): none in the scene)
    "has_normals",    # (T,) bool
    "terminator",     # (T,) float32 shadow terminator geometry offset ((0,): none; drt.terminator)
    "positions",      # (V, 3) float32 world (camera-shifted) vertices of the static triangles, with
                      # ``terminator`` ((0, 3): none)
    "triangles",      # (T_static, 3) int32 their vertex indices, with ``terminator`` ((0, 3): none)
    "shading_mult",   # (T,) float32 shadow terminator shading-offset multiplier ((0,): none)
    "visibility",     # (T,) uint8 VIS_* bits of the rays that see each triangle, with VIS_HOLDOUT
                      # on holdout objects' ((0,): all see all, no holdout)
    "pass_ids",       # (T, 2) float32 [object, material] pass index ((0, 2): no index pass)
    "uvs",            # (T, 3, 3) float32 (u, v, 1) of the render UV map per corner, zeros on
                      # meshes without one ((0, 3, 3): no UV pass, or no UV map in the scene)
    "crypto_ids",     # (T, 3) float32 Cryptomatte [object, material, asset] ids ((0, 3): none)
])

HitArrays = namedtuple("HitArrays", [
    "prim", "t", "b1", "b2",              # Embree's answer (prim −1: miss)
    "p", "ng",                            # (n, 3) float64 hit point and unit geometric normal
    "normal_xform",                       # (n, 3, 3): local→world normal map of moving hits
    "moving",                             # (n,) bool: normal_xform applies ((0,) when none)
])


@kernel
def power_heuristic(pdf_a, pdf_b):
    """Veach's power heuristic (β = 2) weight of strategy a; 0 where both pdfs are 0."""
    a2 = pdf_a * pdf_a
    denom = a2 + pdf_b * pdf_b
    return a2 / denom if denom > 0.0 else 0.0


@kernel
def balance_heuristic(pdf_a, pdf_b):
    """Veach's balance heuristic weight of strategy a; 0 where both pdfs are 0."""
    denom = pdf_a + pdf_b
    return pdf_a / denom if denom > 0.0 else 0.0


@inline_kernel
def hit_weight(direct, prev_delta, bsdf_pdf, light_pdf):
    """MIS weight of an emitter found by a BSDF-sampled ray (1 after camera/delta rays)."""
    if prev_delta or direct == DIRECT_BSDF:
        return 1.0
    if direct == DIRECT_LIGHT:  # next-event estimation counted it, unless it could not sample it
        return 0.0 if light_pdf > 0.0 else 1.0
    if direct == DIRECT_MIS_BALANCE:
        return balance_heuristic(bsdf_pdf, light_pdf)
    return power_heuristic(bsdf_pdf, light_pdf)


@inline_kernel
def nee_weight(direct, light_delta, light_pdf, bsdf_pdf):
    """MIS weight of a next-event sample (1 for delta lights and light-only estimation)."""
    if light_delta or direct == DIRECT_LIGHT:
        return 1.0
    if direct == DIRECT_MIS_BALANCE:
        return balance_heuristic(light_pdf, bsdf_pdf)
    return power_heuristic(light_pdf, bsdf_pdf)


@inline_kernel
def clamp(settings, c, indirect):
    """Cycles's sample clamping: light found at the first vertex (by NEE there, or by the BSDF
    ray leaving it) is direct, deeper is indirect; a limit ≤ 0 is off."""
    limit = settings.clamp_indirect if indirect else settings.clamp_direct
    if limit > 0.0:
        peak = max(c[0], max(c[1], c[2]))
        if peak > limit:
            return scale(c, limit / peak)
    return c


@kernel
def continuation_probability(thr):
    """Russian roulette's survival probability for a path of throughput ``thr`` (3-tuple, the
    BSDF weight of the new direction included): √(max channel), at most 1, as Cycles's
    ``path_state_continuation_probability``. The square root terminates fewer dim paths than
    max(thr) itself would; a path that survives with probability q carries 1/q, and on scenes
    whose light arrives through dark bounces (caustics on a grey floor) 1/q is most of the
    variance (docs/estimators.md, "Per-sample error on glossy_glass")."""
    return min(math.sqrt(max(max(thr[0], max(thr[1], thr[2])), 0.0)), 1.0)


@kernel
def any_positive(c):
    return c[0] > 0.0 or c[1] > 0.0 or c[2] > 0.0


@kernel
def unseen_hits(visibility, paths, live, sss_on, prim, p, ng, rows, o_next, tmax_next, t_done):
    """Rows of paths[:live] whose hit (``prim``, at ``p`` with normal ``ng``) is on a triangle
    their kind of ray does not see (``visibility``: VIS_* bits per triangle; Cycles's ray
    visibility): their indices go to ``rows[:n]``, and per row the origin just past the hit
    (``o_next``), the distance left (``tmax_next``) and the distance from the ray's origin to
    that new origin (``t_done``). A row leaving a subsurface walk is skipped (its hit is the
    walk's exit, patched after). Returns n."""
    n = 0
    for i in range(live):
        q = prim[i]
        if q < 0:
            continue
        if sss_on and (paths.sss[i] == SSS_EXIT or paths.sss[i] == SSS_EXIT_FLAT):
            continue
        camera = paths.counts[i, 0] + (paths.sss_count[i] if sss_on else 0) == 0
        if visibility[q] & ray_visibility(camera, paths.prev_flags[i]):
            continue
        d = load(paths.d, i)
        o_past = offset_point(load(p, i), load(ng, i), d)
        done = dot(sub(o_past, load(paths.o, i)), d)
        rows[n] = i
        store(o_next, n, o_past)
        tmax_next[n] = paths.tmax[i] - done
        t_done[n] = done
        n += 1
    return n


@inline_kernel
def ray_visibility(camera, flags):
    """The VIS_* bits of which an object needs one for this ray to see it (Cycles's
    path_state_ray_visibility): a camera ray (still one through transparent surfaces) camera;
    after a transmission (``flags``: the RAY_* bits of the last scattering) transmission; after
    a diffuse or a glossy (or singular) reflection that kind; after a volume scatter (no surface
    bits) volume scatter or diffuse, as Cycles."""
    if camera:
        return VIS_CAMERA
    if flags & RAY_TRANSMIT:
        return VIS_TRANSMISSION
    if flags & RAY_DIFFUSE:
        return VIS_DIFFUSE
    if flags & (RAY_GLOSSY | RAY_SINGULAR):
        return VIS_GLOSSY
    return VIS_DIFFUSE | VIS_VOLUME_SCATTER


@inline_kernel
def shading_normal(surf, hits, i, prim, ng):
    """Interpolated shading normal at hit i, on the geometric front side (ng if flat shaded)."""
    if surf.normals.shape[0] == 0 or not surf.has_normals[prim]:
        return ng
    b1, b2 = hits.b1[i], hits.b2[i]
    b0 = 1.0 - b1 - b2
    nc = surf.normals[prim]
    n = (b0 * nc[0, 0] + b1 * nc[1, 0] + b2 * nc[2, 0],
         b0 * nc[0, 1] + b1 * nc[1, 1] + b2 * nc[2, 1],
         b0 * nc[0, 2] + b1 * nc[1, 2] + b2 * nc[2, 2])
    if hits.moving.shape[0] and hits.moving[i]:
        m = hits.normal_xform[i]
        n = (m[0, 0] * n[0] + m[0, 1] * n[1] + m[0, 2] * n[2],
             m[1, 0] * n[0] + m[1, 1] * n[1] + m[1, 2] * n[2],
             m[2, 0] * n[0] + m[2, 1] * n[1] + m[2, 2] * n[2])
    n, length = normalize(n)
    if not length > 1e-12:
        return ng
    if dot(n, ng) < 0.0:  # shading normals live on the geometric front side
        return neg(n)
    return n


@inline_kernel
def world_emission(ld, pd, regs, point, d, flags, counts, camera):
    """Radiance the world sends along −d: its program's for a textured world (``point`` gets
    the direction's rows and the ray's Light Path rows, as `fill_point` for a hit), else the
    constant colour. ``pd`` None: no programs in the scene, so not a textured world."""
    if pd is not None and ld.world_prog >= 0:
        _put(point, POINT_PATH, (1.0 if camera else 0.0, 1.0 if flags & RAY_DIFFUSE else 0.0,
                                 1.0 if flags & (RAY_GLOSSY | RAY_SINGULAR) else 0.0))
        _put(point, POINT_PATH2, (1.0 if flags & RAY_SINGULAR else 0.0,
                                  1.0 if not camera and not flags & RAY_TRANSMIT else 0.0,
                                  1.0 if flags & RAY_TRANSMIT else 0.0))
        _put(point, POINT_DEPTH, (float(counts[0]), float(counts[1]), float(counts[2])))
        _put(point, POINT_MISC, (float(counts[3]), 1e10, 0.0))  # Cycles: FLT_MAX ray length
        return world_radiance_at(pd, regs, ld.world_prog, ld.world_reg, d, point)
    return world_radiance(ld, d)


#: added to a hint's material code (``prev_mat``) when a lobe of that point may reflect light
#: from below ``n``'s horizon (``hint_code``)
HINT_TILTED = 1 << 32


@inline_kernel
def hint_code(mat, tilted):
    """The material code of a shading point for ``material_hint``: the material, + HINT_TILTED
    when not all of its lobes are shaded about the hint's normal n_wo — at a smooth mesh's
    silhouette (wo below the shading normal: there a glossy lobe reflects below n_wo) or where
    a valid-reflection or coat normal differs from it. Light selection then keeps the defensive
    share for lights below the horizon."""
    return mat + HINT_TILTED if tilted and mat >= 0 else mat


@inline_kernel
def material_hint(md, code, n, wo):
    """The light-selection hint of a shading point (all zero: nothing known, e.g. camera rays)
    from its ``hint_code``. A tilted point's kt is at least ``KT_FLOOR``: kt = 0 tells the
    selection that nothing below n's horizon is lit (``drt.lights.selection.reflect_only``).
    A summary that knows nothing (kd = kg = kt = 0: no lobe light sampling can reach) stays
    so, tilted or not: the floor would make the selection BSDF-aware on no information."""
    if code < 0:
        return ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0)
    mat = code - HINT_TILTED if code >= HINT_TILTED else code
    s = md.summary[mat]
    kt = s[3]
    if code >= HINT_TILTED and s[0] + s[1] > 0.0:
        kt = max(kt, KT_FLOOR)
    return (n, wo, s[0], s[1], s[2], kt)


@inline_kernel
def _put(point, r, v):
    point[r, 0] = v[0]
    point[r, 1] = v[1]
    point[r, 2] = v[2]


@inline_kernel
def fill_point(point, pd, surf, hits, i, prim, p, ng, ns, wo, flags, counts, ray_length, camera):
    """The shading-point rows (``drt.materials.program_format.POINT_*``) of hit i for the
    material programs, in Cycles's orientation (normals on the side the ray came from)."""
    backfacing = dot(wo, ng) < 0.0
    sgn = -1.0 if backfacing else 1.0
    _put(point, POINT_P, add(p, (pd.origin[0], pd.origin[1], pd.origin[2])))
    _put(point, POINT_N, scale(ns, sgn))
    _put(point, POINT_NG, scale(ng, sgn))
    _put(point, POINT_I, wo)
    moving = hits.moving.shape[0] and hits.moving[i]
    if surf.normals.shape[0] and surf.has_normals[prim]:
        b1, b2 = hits.b1[i], hits.b2[i]
        b0 = 1.0 - b1 - b2
        nc = surf.normals[prim]
        n = (b0 * nc[0, 0] + b1 * nc[1, 0] + b2 * nc[2, 0], b0 * nc[0, 1] + b1 * nc[1, 1] + b2 * nc[2, 1],
             b0 * nc[0, 2] + b1 * nc[1, 2] + b2 * nc[2, 2])
        if moving:
            m = hits.normal_xform[i]
            n = (m[0, 0] * n[0] + m[0, 1] * n[1] + m[0, 2] * n[2], m[1, 0] * n[0] + m[1, 1] * n[1] + m[1, 2] * n[2],
                 m[2, 0] * n[0] + m[2, 1] * n[1] + m[2, 2] * n[2])
        _put(point, POINT_NSMOOTH, n)
    else:
        _put(point, POINT_NSMOOTH, ng)
    for r in range(3):
        for c in range(3):
            point[POINT_XFORM + r, c] = hits.normal_xform[i, r, c] if moving else (1.0 if r == c else 0.0)
    # the object's own normal transform (object-space inputs): a static object's from its row
    # of the per-object table (when the scene keeps one), a moving one's at this ray's time
    obj_rows = pd.object_of.shape[0] > prim and pd.object_info.shape[1] >= 18 and not moving
    for r in range(3):
        for c in range(3):
            if moving:
                point[POINT_OBJECT_XFORM + r, c] = hits.normal_xform[i, r, c]
            elif obj_rows:
                point[POINT_OBJECT_XFORM + r, c] = pd.object_info[pd.object_of[prim], 9 + 3 * r + c]
            else:
                point[POINT_OBJECT_XFORM + r, c] = 1.0 if r == c else 0.0
    _put(point, POINT_PATH, (1.0 if camera else 0.0, 1.0 if flags & RAY_DIFFUSE else 0.0,
                             1.0 if flags & (RAY_GLOSSY | RAY_SINGULAR) else 0.0))
    _put(point, POINT_PATH2, (1.0 if flags & RAY_SINGULAR else 0.0,
                              1.0 if not camera and not flags & RAY_TRANSMIT else 0.0,
                              1.0 if flags & RAY_TRANSMIT else 0.0))
    _put(point, POINT_DEPTH, (float(counts[0]), float(counts[1]), float(counts[2])))
    _put(point, POINT_MISC, (float(counts[3]), ray_length, 1.0 if backfacing else 0.0))
    _put(point, POINT_SHADOW, (0.0, 0.0, 0.0))


@kernel
def frame_normal(v, t, b, n):
    """The unit vector v in the frame (t, b, n), or NO_BUMP when v is n within round-off (a
    lobe frame that would not turn anything)."""
    v_local = to_local(v, t, b, n)
    return NO_BUMP if v_local[2] >= 1.0 - 1e-12 else v_local


@kernel
def valid_specular_normal(ng, wi, n):
    """Cycles's ``ensure_valid_specular_reflection`` (bump map correction): n (unit, on wi's
    side like ng) tilted toward ng just enough that the mirror reflection of wi stays above the
    surface."""
    r = sub(scale(n, 2.0 * dot(n, wi)), wi)
    iz = dot(wi, ng)
    threshold = min(0.9 * iz, 0.01)
    if dot(ng, r) >= threshold:
        return n
    x, xl = normalize(sub(n, scale(ng, dot(n, ng))))
    if xl == 0.0:
        x = n
    ix = dot(wi, x)
    a = ix * ix + iz * iz
    b = 2.0 * (a + iz * threshold)
    c = (threshold + iz) * (threshold + iz)
    disc = math.sqrt(max(b * b - 4.0 * a * c, 0.0))
    nz2 = 0.25 * (b + disc) / a if ix < 0.0 else 0.25 * (b - disc) / a
    nx = math.sqrt(max(1.0 - nz2, 0.0))
    nz = math.sqrt(max(nz2, 0.0))
    return add(scale(x, nx), scale(ng, nz))


@kernel
def copy_path(paths, i, j):
    """Copy path row i to row j (every field; j ≤ i in compaction)."""
    if i == j:
        return
    for a in (paths.o, paths.d, paths.throughput, paths.prev_p, paths.prev_n, paths.prev_wo):
        for c in range(3):
            a[j, c] = a[i, c]
    paths.tmax[j] = paths.tmax[i]
    paths.tau[j] = paths.tau[i]
    paths.prev_pdf[j] = paths.prev_pdf[i]
    paths.prev_delta[j] = paths.prev_delta[i]
    paths.prev_mat[j] = paths.prev_mat[i]
    for c in range(paths.counts.shape[1]):
        paths.counts[j, c] = paths.counts[i, c]
    paths.terminate[j] = paths.terminate[i]
    paths.slot[j] = paths.slot[i]
    paths.pixel[j] = paths.pixel[i]
    paths.index[j] = paths.index[i]
    paths.prev_flags[j] = paths.prev_flags[i]
    for c in range(paths.vstack.shape[1]):
        paths.vstack[j, c] = paths.vstack[i, c]
    paths.vcount[j] = paths.vcount[i]
    paths.vseg[j] = paths.vseg[i]
    if paths.sss.shape[0]:
        paths.sss[j] = paths.sss[i]
        paths.sss_count[j] = paths.sss_count[i]
    paths.tcount[j] = paths.tcount[i]
    if paths.min_pdf.shape[0]:
        paths.min_pdf[j] = paths.min_pdf[i]


@inline_kernel
def glossy_blur(settings, paths, i):
    """Filter Glossy's alpha at path i's vertex (0: none): Cycles's surface_shader_prepare_closures.
    A path that reached this vertex through an unlikely bounce (a diffuse one, a rough glossy one:
    the smallest pdf so far, ``Paths.min_pdf``) sees its glossy lobes widened to at least
    ½·sqrt(1 − min_pdf / Filter Glossy), which trades the fireflies of caustics for blur (a bias
    Cycles has by default, 1.0). Camera rays and paths of delta bounces only are never blurred."""
    if not paths.min_pdf.shape[0]:
        return 0.0
    blur_pdf = paths.min_pdf[i] / settings.filter_glossy
    if not blur_pdf < 1.0:
        return 0.0
    return 0.5 * math.sqrt(1.0 - blur_pdf)


@kernel
def camera_stage(sd, fd, cd, settings, x, row, index, u, paths, out):
    """Primary rays for camera samples (x column from the left, row from the TOP, sample index);
    initialises the outputs of every batch row and the path state of the samples that have a
    ray, compacted to the front (a panoramic camera has none outside its image: such a sample
    carries nothing, black with alpha 1, as Cycles's). Returns how many paths there are.
    ``u``: (n, 5) float64 scratch rows for the samples (their values on return: the 5-D
    samples, u2–u4 zero where the camera has no lens or the scene no motion)."""
    W, H = settings.width, settings.height
    # pixel filter, lens and shutter time from one jointly stratified 5-D sample (D_PIXEL,
    # D_LENS, D_TIME): with depth of field or motion blur the image depends on them together.
    # All samples first, in a loop of their own: each is one long chain of integer hashes, and
    # a short loop body lets the processor run several samples' chains at once
    with_lens = cd.lens_radius > 0
    for i in range(x.shape[0]):
        u[i, 0], u[i, 1], u[i, 2], u[i, 3], u[i, 4] = sample_5d(sd, row[i] * W + x[i], index[i], D_PIXEL,
                                                                with_lens, settings.motion)
    j = 0
    for i in range(x.shape[0]):
        pixel = row[i] * W + x[i]
        idx = index[i]
        u0, u1, l0, l1, tau = u[i, 0], u[i, 1], u[i, 2], u[i, 3], u[i, 4]
        dx, dy = filter_sample(fd, u0, u1)
        px = x[i] + 0.5 + dx
        py = (H - 1 - row[i]) + 0.5 + dy  # the camera wants v from the bottom
        o, d, tmax, eye, forward = camera_ray(cd, px, py, l0, l1, tau)
        store(out.radiance, i, (0.0, 0.0, 0.0))
        out.alpha[i] = 1.0
        out.depth[i] = np.inf
        store(out.normal, i, (0.0, 0.0, 0.0))
        store(out.albedo, i, (0.0, 0.0, 0.0))
        store(out.eye, i, eye)
        store(out.forward, i, forward)
        if out.mist.shape[0]:
            out.mist[i] = 0.0
        if out.data.shape[0]:
            for c in range(DATA_COLUMNS):
                out.data[i, c] = 0.0
        if out.light.shape[0]:
            for c in range(LIGHT_COLUMNS):
                out.light[i, c] = 0.0
        if out.crypto.shape[0]:
            for e in range(out.crypto.shape[1]):
                out.crypto[i, e, CRYPTO_WEIGHT] = 0.0
        if tmax < 0.0:
            continue
        store(paths.o, j, o)
        store(paths.d, j, d)
        paths.tmax[j] = tmax
        paths.tau[j] = tau
        store(paths.throughput, j, (1.0, 1.0, 1.0))
        paths.prev_pdf[j] = 0.0
        paths.prev_delta[j] = True
        store(paths.prev_p, j, o)
        store(paths.prev_n, j, (0.0, 0.0, 0.0))
        store(paths.prev_wo, j, (0.0, 0.0, 0.0))
        paths.prev_mat[j] = -1
        for c in range(4):
            paths.counts[j, c] = 0
        paths.terminate[j] = False
        paths.prev_flags[j] = 0
        paths.tcount[j] = 0
        if paths.min_pdf.shape[0]:
            paths.min_pdf[j] = np.inf
        paths.slot[j] = i
        paths.pixel[j] = pixel
        paths.index[j] = idx
        j += 1
    return j


@kernel
def glass_alpha(md, mat, u_lobe, wo, nc_local, nv_local, front, view_weights):
    """The GGX alpha of the lobe ``bsdf_sample_bump`` picked with ``u_lobe`` (its pick again)."""
    slot, _, _ = pick_lobe_weights(md, mat, u_lobe, wo, nc_local, nv_local, front, view_weights)
    return md.lobe_alpha[mat, slot]


@kernel
def mist_weight(settings, md, m, thr, p, eye, forward):
    """What a see-through hit (a camera ray, or one past transparency or Transparent Glass) at
    ``p`` adds to its sample's Mist sum, as Cycles's film_write_data_passes: (1 − mist) ×
    average(throughput × alpha), mist = clamp((distance − start) / depth, 0, 1) ^ falloff, the
    distance from the lens point ``eye`` (along the view axis ``forward`` for an orthographic
    camera), alpha = 1 − the material's transparency (this hit's row). The pass is 1 − the
    pixel's mean of these sums: 1 where only the world is seen."""
    v = sub(p, eye)
    dist = abs(dot(v, forward)) if settings.mist_ortho else math.sqrt(dot(v, v))
    mist = min(max((dist - settings.mist_start) * settings.mist_inv_depth, 0.0), 1.0)
    f = settings.mist_falloff
    if f == 2.0:
        mist = mist * mist
    elif f == 0.5:
        mist = math.sqrt(mist)
    elif f != 1.0:
        mist = mist ** f
    t = transparency(md, m)
    a = (thr[0] * min(max(1.0 - t[0], 0.0), 1.0) + thr[1] * min(max(1.0 - t[1], 0.0), 1.0)
         + thr[2] * min(max(1.0 - t[2], 0.0), 1.0)) * (1.0 / 3.0)
    return (1.0 - mist) * a


@inline_kernel
def add_light_passes(out, slot, emitted, env):
    """Cycles's Emission and Environment passes (film_write_emission_or_background_pass before
    the path's first scattering, PATH_RAY_ANY_PASS unset): what a camera ray (still one past
    transparency) brings from emitters (surfaces, light shapes, media, suns) and from the world.
    Columns of ``Outputs.light``: emission rgb, environment rgb."""
    for c in range(3):
        out.light[slot, LIGHT_EMISSION + c] += emitted[c]
        out.light[slot, LIGHT_ENVIRONMENT + c] += env[c]


@kernel
def diffuse_color(md, m, wo, nc_local, nv_local, front):
    """Cycles's surface_shader_diffuse for this hit's row ``m`` seen from ``wo`` (local frame):
    the summed weights of the diffuse-class lobes (Lambert, translucent, subsurface, sheen and
    velvet: Cycles's CLOSURE_IS_BSDF_DIFFUSE and BSSRDF), each scaled by what the layers over it
    leave at wo (``under_weight``: Cycles's closure weights carry the layers' albedo scaling), a
    microfiber sheen also by its own albedo at wo (Cycles's bsdf_albedo). RGB."""
    c0 = c1 = c2 = 0.0
    for l in range(md.lobe_count[m]):
        t = md.lobe_type[m, l]
        if (t == BSDF_DIFFUSE or t == BSDF_TRANSLUCENT or t == BSDF_SUBSURFACE or t == BSDF_SHEEN
                or t == BSDF_VELVET):
            w = under_weight(md, m, l, wo, nc_local, nv_local, front)
            if t == BSDF_SHEEN:  # (Cycles's bsdf_albedo: a sheen's weight × its albedo at wo)
                a = layer_albedo(md, m, l, layer_cos(md, m, l, wo, nc_local, nv_local), front)
                w = (w[0] * a, w[1] * a, w[2] * a)
            c0 += md.lobe_color[m, l, 0] * w[0]
            c1 += md.lobe_color[m, l, 1] * w[1]
            c2 += md.lobe_color[m, l, 2] * w[2]
    return (c0, c1, c2)


@inline_kernel
def add_light(out, slot, acc, camera):
    """Add a vertex's light ``acc`` (emitters met along the ray and at the hit) to its sample,
    and on a camera ray to the Emission pass too, when the render asks for the light passes."""
    store(out.radiance, slot, add(load(out.radiance, slot), acc))
    if out.light.shape[0] and camera:
        add_light_passes(out, slot, acc, (0.0, 0.0, 0.0))


@kernel
def write_data_passes(settings, surf, md, mat, hits, i, prim, p, first, out, slot):
    """Cycles's data passes (film_write_data_passes) at a see-through surface hit (a camera ray,
    or one still seeing the world through transparency or Transparent Glass) whose sample has
    not finished them: the pixel's sample 0 (``first``) overwrites the Object and Material Index,
    the Position and the hit flag at every such surface; at the first surface whose alpha
    (1 − average transparency of this hit's row ``mat``) reaches the alpha threshold (or any
    surface with the threshold 0) the sample adds its UV and its passes are done. Columns:
    ``DATA_*``."""
    if first:
        if surf.pass_ids.shape[0]:
            out.data[slot, DATA_OBJECT] = surf.pass_ids[prim, 0]
            out.data[slot, DATA_MATERIAL] = surf.pass_ids[prim, 1]
        for c in range(3):
            out.data[slot, DATA_POSITION + c] = p[c]
        out.data[slot, DATA_HIT] = 1.0
    if settings.pass_alpha > 0.0:
        t = transparency(md, mat)
        if 1.0 - (t[0] + t[1] + t[2]) * (1.0 / 3.0) < settings.pass_alpha:
            return
    if surf.uvs.shape[0]:
        b1 = hits.b1[i]
        b2 = hits.b2[i]
        b0 = 1.0 - b1 - b2
        c = surf.uvs[prim]
        for k in range(3):
            out.data[slot, DATA_UV + k] = b0 * c[0, k] + b1 * c[1, k] + b2 * c[2, k]
    out.data[slot, DATA_DONE] = 1.0


@kernel
def write_cryptomatte(surf, md, mat, prim, thr, out, slot):
    """Record a see-through surface hit for Cryptomatte (drt.cryptomatte; Cycles's
    film_write_data_passes): weight average(throughput) × (1 − average transparency of this hit's
    row ``mat``) and the triangle's object, material and asset ids, in the sample's first free
    entry of ``out.crypto`` (none free: dropped)."""
    t = transparency(md, mat)
    w = (thr[0] + thr[1] + thr[2]) * (1.0 / 3.0) * (1.0 - (t[0] + t[1] + t[2]) * (1.0 / 3.0))
    if not w > 0.0:
        return
    for e in range(out.crypto.shape[1]):
        if out.crypto[slot, e, CRYPTO_WEIGHT] == 0.0:
            out.crypto[slot, e, CRYPTO_WEIGHT] = w
            for c in range(3):
                out.crypto[slot, e, CRYPTO_IDS + c] = surf.crypto_ids[prim, c]
            return


@kernel
def queue_ao_ray(md, mat, thr, p, ng, wo, ns, t_ax, b_ax, front, u0, u1, settings, paths, i, slot, ao_rays, k, vd):
    """Queue row k of ``ao_rays`` for Cycles's Ambient Occlusion pass (integrate_surface_ao) at a
    surface a camera ray meets (still one past transparent surfaces): a cosine-distributed
    direction about the shading normal on the viewer's side (frame ``t_ax``, ``b_ax``, ``ns``;
    ``front`` its side), ``settings.ao_distance`` long, carrying throughput × alpha (1 −
    transparency of row ``mat``) to the pass where nothing blocks it. Returns whether it
    queued one: a direction below the facet, or a surface without opacity, queues none (the
    pass adds 0 there, as for an occluded ray)."""
    t = transparency(md, mat)
    c = (thr[0] * max(1.0 - t[0], 0.0), thr[1] * max(1.0 - t[1], 0.0), thr[2] * max(1.0 - t[2], 0.0))
    if not any_positive(c):
        return False
    local = cosine_hemisphere(u0, u1)
    wi = to_world((local[0], local[1], local[2] * front), t_ax, b_ax, ns)
    if dot(wi, ng) * dot(wo, ng) <= 0.0:
        return False
    store(ao_rays.o, k, offset_point(p, ng, wi))
    store(ao_rays.d, k, wi)
    ao_rays.tmax[k] = settings.ao_distance
    ao_rays.tau[k] = paths.tau[i]
    store(ao_rays.contrib, k, c)
    ao_rays.slot[k] = slot
    if vd is not None and vd.enabled:  # (the ray starts in the media the path is in)
        stack_copy(paths.vstack, i, ao_rays.vstack, k)
    return True


@kernel
def holdout_object_hit(md, mat, thr, acc, settings, paths, i, j, vd, prim, p, ng, d, t_geom, out, slot):
    """Path i's see-through ray (a camera ray, or one past Transparent Glass) hit a holdout
    object (``Surfaces.visibility`` & VIS_HOLDOUT) of
    material ``mat`` at ``p``: Cycles's surface_shader_apply_holdout. The hit's opaque part
    (weight 1 − the material's transparency, ``md`` already this hit's row) leaves the alpha,
    none of its light is added (``acc``, what the segment before it brought, is stored), and
    the ray goes on through the transparency only, as a transparent bounce, into row j.
    Returns whether it does."""
    t0, t1, t2 = transparency(md, mat)
    out.alpha[slot] -= (max(1.0 - t0, 0.0) * thr[0] + max(1.0 - t1, 0.0) * thr[1]
                        + max(1.0 - t2, 0.0) * thr[2]) * (1.0 / 3.0)
    store(out.radiance, slot, add(load(out.radiance, slot), acc))
    weight = (min(t0, 1.0), min(t1, 1.0), min(t2, 1.0))
    if not any_positive(weight) or paths.tcount[i] + 1 > settings.transparent_bounces:
        return False
    copy_path(paths, i, j)
    if vd is not None and vd.enabled:
        stack_cross(vd, paths.vstack, j, prim, mat, d, ng)
    store(paths.o, j, offset_point(p, ng, d))
    paths.tmax[j] = max(paths.tmax[i] - t_geom, 0.0)
    store(paths.throughput, j, mul(thr, weight))
    paths.tcount[j] = paths.tcount[i] + 1
    return True


@kernel
def shade(sd, md, pd, regs, point, ld, surf, settings, depth_i, live, paths, hits, out, shadow, ao_rays, vd,
          holdouts):
    """One bounce for paths [0, live) (see the module docstring). Returns (paths still alive,
    now compacted to the front; shadow rays queued in ``shadow``; Ambient Occlusion pass rays
    queued in ``ao_rays``, a queue of zero rows when the render has no AO pass). ``pd`` holds the material
    programs (``drt.materials.programs``; no programs: zero-size arrays); when there are any,
    ``md`` must be this thread's own copy of the material data and ``regs`` its register file,
    since a textured material's row is rewritten at each of its hits, and ``point`` its
    (POINT_ROWS, 3) shading-point array. ``pd`` None: a scene without any program and without
    media, whose variant of ``shade`` holds no interpreter (as ``vd`` below). ``vd``: the scene's media
    (``drt.volumes.media.MediumData``), or None for a scene without media: every use of ``vd``
    sits under ``vd is not None``, which numba resolves when it compiles, so that variant of
    ``shade`` holds none of the media code (half of the cold compile; docs/kernels.md).
    ``holdouts``: the per-triangle visibility bits (``surf.visibility``) of a scene with a
    holdout object (VIS_HOLDOUT), or None: the same compile-time switch, since even the test of
    the bit at every camera hit cost a scene without holdouts ~2.5 % (cutout, one thread).

    Camera rays and sample dimensions go by the path's bounce count, which equals ``depth_i``
    unless a path crossed volume-only boundaries (those segments are not bounces). A textured world
    (``ld.world_prog`` ≥ 0) runs its program in ``regs`` too, for escaped rays and world light
    samples, with ``point`` filled for the direction (``drt.lights.world_map``)."""
    direct = settings.direct
    n_shadow = 0
    n_ao = 0
    j = 0
    sss_on = paths.sss.shape[0] > 0
    for i in range(live):
        sss_state = paths.sss[i] if sss_on else SSS_NONE
        if sss_state == SSS_DEAD:
            continue  # its random walk found no way out
        exiting = sss_state == SSS_EXIT or sss_state == SSS_EXIT_FLAT
        n_sss = paths.sss_count[i] if sss_on else 0
        slot = paths.slot[i]
        o = load(paths.o, i)
        d = load(paths.d, i)
        thr = load(paths.throughput, i)
        prev_pdf = paths.prev_pdf[i]
        prev_delta = paths.prev_delta[i]
        prev_p = load(paths.prev_p, i)
        prev_n = load(paths.prev_n, i)
        bounce = paths.counts[i, 0]
        # an SSS exit is a vertex without a bounce: it takes the next dimensions, and only the
        # first hit of a camera path writes the camera outputs
        vertex = bounce + n_sss
        camera = vertex == 0  # (a camera ray stays one through transparent surfaces, as Cycles)
        # the world and holdouts cut the alpha: on a camera ray, and past glass with Film >
        # Transparent Glass (Cycles's PATH_RAY_TRANSPARENT_BACKGROUND)
        see_through = camera
        if settings.transparent_glass >= 0.0 and paths.prev_flags[i] & RAY_TRANSPARENT_BG:
            see_through = True
        # a transparent surface passed is a vertex without a bounce too: next dimensions
        base = D_BOUNCE0 + DIMS_PER_BOUNCE * (vertex + paths.tcount[i])
        prev_hint = material_hint(md, paths.prev_mat[i], prev_n, load(paths.prev_wo, i))
        prim = hits.prim[i]
        t_geom = hits.t[i] if prim >= 0 else np.inf
        deep = bounce > 1  # light reached through more than one vertex is "indirect"
        acc = (0.0, 0.0, 0.0)
        pixel = paths.pixel[i]
        idx = paths.index[i]

        # --- the media the ray travels through (drt.volumes.stage)
        in_medium = False
        if vd is not None:
            in_medium = vd.enabled and paths.vstack[i, 0] >= 0
        t_end = t_geom
        v_mode = 0
        v_sig_t = (0.0, 0.0, 0.0)
        v_chp = (1.0, 0.0, 0.0)
        v_g = 0.0
        scattered = False
        thr0 = thr
        if vd is not None and in_medium:
            length = t_geom  # a miss runs to infinity through the media (Cycles: also past clip_end)
            (v_acc, v_mode, v_sig_t, v_chp, v_g, scattered, t_s, thr, nee_ok, x, v_wi, v_dist, f_nee,
             v_lpdf, v_ph, v_ldelta) = volume_segment(
                sd, ld, vd, pd, regs, point, paths.vstack, i, o, d, length, thr0, paths.terminate[i], direct != DIRECT_BSDF,
                pixel, idx, paths.vseg[i])
            acc = add(acc, clamp(settings, v_acc, deep))
            if scattered:
                t_end = t_s
            if nee_ok:
                w = nee_weight(direct, v_ldelta, v_lpdf, v_ph)
                store(shadow.o, n_shadow, x)
                store(shadow.d, n_shadow, v_wi)
                shadow.tmax[n_shadow] = v_dist * (1.0 - SHADOW_EPSILON) if math.isfinite(v_dist) else np.inf
                shadow.tau[n_shadow] = paths.tau[i]
                store(shadow.contrib, n_shadow, clamp(settings, scale(f_nee, w), bounce > 0))
                shadow.slot[n_shadow] = slot
                stack_copy(paths.vstack, i, shadow.vstack, n_shadow)
                n_shadow += 1

        # --- emitters along the ray: light shapes (transparent), then a sun disk and the world
        # (an SSS exit "ray" is no ray: the walk ended on the surface from inside)
        # (through a heterogeneous medium every shape before the surface counts, weighted by an
        # independent transmittance estimate, whatever the tracked path did: drt.volumes.hetero)
        t_shapes = t_geom if v_mode == MODE_HETERO else t_end
        for k in range(0 if exiting else ld.n_shapes):
            t = shape_intersect(ld, k, o, d)
            if t < t_shapes:
                light, le, lpdf = shape_emission(ld, k, o, d, t, prev_p, prev_hint)
                if camera and ld.li[light, I_VISIBLE_CAMERA] == 0:
                    continue
                if vd is not None and pd is not None and v_mode == MODE_HETERO:
                    tr_k, _ = ratio_tracking(vd, pd, regs, point, paths.vstack, i, o, d, t,
                                             seed_of(pixel, idx, 1000003 + 64 * paths.vseg[i] + k))
                    le = mul(le, tr_k)
                elif in_medium:
                    le = mul(le, pass_factor(v_mode, v_sig_t, v_chp, t))
                w = hit_weight(direct, prev_delta, prev_pdf, lpdf)
                acc = add(acc, clamp(settings, scale(mul(thr0, le), w), deep))
        if scattered:
            # --- the path scatters in the medium: sample the phase function to continue
            add_light(out, slot, acc, camera)
            if paths.vseg[i] >= VOLUME_BOUNDS_MAX + settings.max_bounces:
                continue
            vbase = D_VOLUME0 + VOLUME_DIMS * paths.vseg[i]
            x = (o[0] + d[0] * t_end, o[1] + d[1] * t_end, o[2] + d[2] * t_end)
            up0, up1 = sample_2d(sd, pixel, idx, vbase + 3)
            wi, ph = hg_sample(d, v_g, up0, up1)
            n_bounce = bounce + 1
            n_volume = paths.vcount[i] + 1
            limit = n_bounce > settings.max_bounces or n_volume > settings.volume_bounces
            alive = any_positive(thr)
            if bounce + 1 >= RR_START_BOUNCE:
                u_rr = sample_2d(sd, pixel, idx, vbase + 4)[0]
                q = continuation_probability(thr)
                if not u_rr < q:
                    alive = False
                elif q > 0.0:
                    thr = scale(thr, 1.0 / q)
            if not alive:
                continue
            copy_path(paths, i, j)
            store(paths.o, j, x)
            store(paths.d, j, wi)
            paths.tmax[j] = np.inf
            store(paths.throughput, j, thr)
            paths.prev_pdf[j] = ph
            paths.prev_delta[j] = False
            store(paths.prev_p, j, x)
            store(paths.prev_n, j, (0.0, 0.0, 0.0))
            store(paths.prev_wo, j, neg(d))
            paths.prev_mat[j] = -1
            paths.prev_flags[j] = 0  # a volume scatter is none of the surface ray types
            if paths.min_pdf.shape[0]:
                paths.min_pdf[j] = min(paths.min_pdf[i], ph)
            paths.counts[j, 0] = n_bounce
            paths.vcount[j] = n_volume
            paths.vseg[j] = paths.vseg[i] + 1
            paths.terminate[j] = limit
            j += 1
            continue
        if prim < 0:
            emitted = acc  # (media and light shapes along the ray, suns: the Emission pass's share)
            env = (0.0, 0.0, 0.0)  # (the world: the Environment pass's)
            if out.data.shape[0] and see_through and idx == 0 and out.data[slot, DATA_DONE] == 0.0:
                # the world ends the sample's data passes unfinished: no surface (Cycles's
                # film_write_data_passes_background)
                for c in range(DATA_HIT + 1):
                    out.data[slot, c] = 0.0
            sun = sun_in_cone(ld, d)
            if sun >= 0 and not (camera and ld.li[sun, I_VISIBLE_CAMERA] == 0):
                le, lpdf = sun_emission(ld, sun, prev_p, d, prev_hint)
                w = hit_weight(direct, prev_delta, prev_pdf, lpdf)
                c = clamp(settings, scale(mul(thr, le), w), deep)
                acc = add(acc, c)
                emitted = add(emitted, c)  # (Cycles writes a sun hit as surface emission)
            if see_through and settings.film_transparent:
                # the world shows through by what the camera ray still carries (transparent
                # surfaces and media passed): Cycles's film_write_transparent, average(throughput)
                out.alpha[slot] -= (thr[0] + thr[1] + thr[2]) * (1.0 / 3.0)
                if out.light.shape[0] and camera:  # (the Environment pass still sees it, as Cycles)
                    le = world_emission(ld, pd, regs, point, d, paths.prev_flags[i], paths.counts[i], camera)
                    env = add(env, clamp(settings, mul(thr, le), deep))
            else:
                le = world_emission(ld, pd, regs, point, d, paths.prev_flags[i], paths.counts[i], camera)
                wpdf = world_pdf(ld, prev_p, prev_n, d, prev_hint)
                w = hit_weight(direct, prev_delta, prev_pdf, wpdf)
                c = clamp(settings, scale(mul(thr, le), w), deep)
                acc = add(acc, c)
                env = add(env, c)
            store(out.radiance, slot, add(load(out.radiance, slot), acc))
            if out.light.shape[0] and camera:
                add_light_passes(out, slot, emitted, env)
            continue

        # --- the surface hit: its emission (also for paths stopping here at a bounce limit)
        mat = np.int64(surf.material[prim])  # int64, as every material index: one compile per kernel
        if vd is not None and vd.enabled and vd.pass_through[mat] and not exiting:
            # a volume-only mesh has no surface: cross it (update the stack), no bounce
            add_light(out, slot, acc, camera)
            if paths.vseg[i] >= VOLUME_BOUNDS_MAX + settings.max_bounces or not any_positive(thr):
                continue
            p = load(hits.p, i)
            ng = load(hits.ng, i)
            copy_path(paths, i, j)
            stack_cross(vd, paths.vstack, j, prim, mat, d, ng)
            store(paths.o, j, offset_point(p, ng, d))
            paths.tmax[j] = paths.tmax[i] - t_geom
            store(paths.throughput, j, thr)
            paths.vseg[j] = paths.vseg[i] + 1
            j += 1
            continue
        p = load(hits.p, i)
        ng = load(hits.ng, i)
        medium_mat = mat  # (the scene's own material: its medium, whichever row shades the hit)
        if md.caustic_row.shape[0] and paths.prev_flags[i] & RAY_DIFFUSE and md.caustic_row[mat] >= 0:
            # right after a diffuse bounce, with a Caustics switch off, Cycles builds the shader
            # without the closures the switch drops: the material's twin row (materials.caustics)
            mat = md.caustic_row[mat]
        # a see-through ray on a holdout object (Cycles's SD_OBJECT_HOLDOUT_MASK; drt.scene.ObjectSpec)
        obj_holdout = False
        if holdouts is not None:
            obj_holdout = see_through and (holdouts[prim] & VIS_HOLDOUT) != 0
        ns = ng if sss_state == SSS_EXIT_FLAT else shading_normal(surf, hits, i, prim, ng)
        ns_unmapped = ns
        mapped = False
        coat_n = -1  # the coat's own normal: none (ProgramData.coat_normal_reg)
        wo = neg(d)
        if exiting:
            # Cycles shades an SSS exit as a white Lambert without emission, facing the side of
            # the *geometric* normal the walk left through (sd->N flips with Ng), whatever the
            # smooth normal says; the Lambert's only use of wo is that side
            mat = md.sss_exit[0]
            wo = ns if dot(wo, ng) >= 0.0 else neg(ns)
        elif (pd is not None and pd.prog_of.shape[0] and pd.prog_of[mat] >= 0
              and not (paths.terminate[i] and pd.emission_reg[mat] < 0 and not md.has_emission[mat]
                       and not obj_holdout)):
            # a textured material: this hit's parameters (a path ending here reads only the
            # emission, so a material without textured or constant emission skips its program)
            if pd.reads_point[mat]:
                fill_point(point, pd, surf, hits, i, prim, p, ng, ns, wo, paths.prev_flags[i], paths.counts[i],
                           t_geom, camera)
            eval_material(pd, md, regs, mat, prim, hits.b1[i], hits.b2[i], point)
            coat_n = pd.coat_normal_reg[mat]
            nr = pd.normal_reg[mat]
            if nr >= 0:  # a Normal Map: Cycles's orientation (wo's side) → the geometric front side
                nm, nl = normalize((regs[nr, 0], regs[nr, 1], regs[nr, 2]))
                if nl > 0.0 and math.isfinite(nl):
                    side = 1.0 if dot(wo, ng) >= 0.0 else -1.0
                    if not md.has_diffuse[mat]:  # Cycles corrects glossy lobes' normals only
                        nm = valid_specular_normal(scale(ng, side), wo, nm)
                    ns = scale(nm, side)
                    mapped = True
        if (not mapped and not exiting and not md.has_diffuse[mat] and surf.normals.shape[0]
                and surf.has_normals[prim]):
            # Cycles corrects a glossy closure's smooth normal too, not only a mapped one
            # (maybe_ensure_valid_specular_reflection: any N ≠ Ng, with Bump Map Correction on)
            side = 1.0 if dot(wo, ng) >= 0.0 else -1.0
            nv = valid_specular_normal(scale(ng, side), wo, scale(ns, side))
            if dot(nv, ns) * side < 1.0 - 1e-12:
                ns = scale(nv, side)
                mapped = True
        nv = ns
        if (not exiting and md.has_diffuse[mat] and not md.pure_diffuse[mat]
                and (mapped or (surf.normals.shape[0] and surf.has_normals[prim]))):
            # a material with a diffuse lobe keeps ns for it; its glossy-class lobes are shaded
            # about Cycles's valid-reflection correction of ns (FRAME_VALID)
            side = 1.0 if dot(wo, ng) >= 0.0 else -1.0
            nv = scale(valid_specular_normal(scale(ng, side), wo, scale(ns, side)), side)
        nc = ns
        if coat_n != -1:
            # a Principled Coat Normal apart from Normal: the coat (and sheen) lobes are shaded
            # about it (FRAME_COAT), with Cycles's valid-reflection correction (always applied
            # to a coat normal), on the geometric front side like ns
            side = 1.0 if dot(wo, ng) >= 0.0 else -1.0
            nc_wo = scale(ns_unmapped, side)
            if coat_n >= 0:  # a program's normal is on wo's side (Cycles's orientation)
                nm, nl = normalize((regs[coat_n, 0], regs[coat_n, 1], regs[coat_n, 2]))
                if nl > 0.0 and math.isfinite(nl):
                    nc_wo = nm
            nc = scale(valid_specular_normal(scale(ng, side), wo, nc_wo), side)
        if out.mist.shape[0] and see_through and not exiting:
            out.mist[slot] += mist_weight(settings, md, mat, thr, p, load(out.eye, slot), load(out.forward, slot))
        if obj_holdout and not exiting:
            if out.light.shape[0] and camera:  # (holdout_object_hit stores acc, the media's emission)
                add_light_passes(out, slot, acc, (0.0, 0.0, 0.0))
            if holdout_object_hit(md, mat, thr, acc, settings, paths, i, j, vd, prim, p, ng, d, t_geom, out, slot):
                j += 1
            continue
        if see_through and not exiting and md.transmission_or_delta[mat]:
            # a holdout lobe (always delta) cuts a camera-visible hit out of the alpha, as
            # Cycles's integrate_surface_holdout; a full holdout ends the path
            h = holdout_weight(md, mat)
            if h > 0.0:
                out.alpha[slot] -= h * (thr[0] + thr[1] + thr[2]) * (1.0 / 3.0)
                if h >= 1.0:
                    add_light(out, slot, acc, camera)
                    continue
        if out.data.shape[0] and see_through and not exiting and out.data[slot, DATA_DONE] == 0.0:
            write_data_passes(settings, surf, md, mat, hits, i, prim, p, idx == 0, out, slot)
        if out.crypto.shape[0] and see_through and not exiting:
            write_cryptomatte(surf, md, mat, prim, thr, out, slot)
        if md.has_emission[mat] and not exiting:
            le = load(md.emission, mat)
            if md.emission_layer[mat] >= 0:  # a Principled's emission under its coat / sheen
                te, be = build_frame(ns)  # the layers' own normals: in ns's frame
                le = layered_emission(md, mat, le, to_local(wo, te, be, ns), frame_normal(nc, te, be, ns),
                                      frame_normal(nv, te, be, ns), 1.0 if dot(wo, ng) >= 0.0 else -1.0)
            lpdf = emissive_pdf(ld, prim, prev_p, p, ng, prev_hint)
            w = hit_weight(direct, prev_delta, prev_pdf, lpdf)
            acc = add(acc, clamp(settings, scale(mul(thr, le), w), deep))
        add_light(out, slot, acc, camera)
        if paths.terminate[i]:
            continue

        if camera:
            out.depth[slot] = max(dot(sub(p, load(out.eye, slot)), load(out.forward, slot)), 0.0)
            store(out.normal, slot, ns)
            store(out.albedo, slot, load(md.albedo, mat))
        t_ax, b_ax = build_frame(ns)
        wo_l = to_local(wo, t_ax, b_ax, ns)
        # a normal-mapped hit: the unmapped normal in the mapped frame (bump map correction)
        ns_local = to_local(ns_unmapped, t_ax, b_ax, ns) if mapped else NO_BUMP
        # the coat's own normal and the glossy lobes' valid-reflection normal in that frame
        # (NO_BUMP: the lobes are shaded about ns)
        nc_local = frame_normal(nc, t_ax, b_ax, ns)
        nv_local = frame_normal(nv, t_ax, b_ax, ns)
        # front: the z sign of Cycles's closure normal N', the shading normal turned to wo's
        # *geometric* side (sd->N flips with Ng). It equals wo's side of ns except at a smooth
        # mesh's silhouette (wo above the facet, below ns): there reflection means wi above N',
        # as Cycles's diffuse lobe lights it (materials.table.facing_front)
        front = 1.0 if dot(wo, ng) >= 0.0 else -1.0
        # there the two sides disagree by definition, so the side checks below (geometric vs
        # shading reflection) cannot hold for every lobe: the BSDF and the rays decide, as in
        # Cycles, which has no such check (a wi below the facet starts inside the mesh)
        silhouette = wo_l[2] * front < 0.0
        # lights are sampled over N''s hemisphere; transmitted light stays reachable by BSDF
        # sampling, whose MIS weight is then 1
        n_wo = ns if front > 0.0 else neg(ns)
        code = hint_code(mat, silhouette or nv_local[2] < 1.0 or nc_local[2] < 1.0)
        if out.light.shape[0] and see_through and not exiting:
            # the Diffuse Color pass: Cycles adds it at every see-through surface
            dc = mul(thr, diffuse_color(md, mat, wo_l, nc_local, nv_local, front))
            for c in range(3):
                out.light[slot, LIGHT_DIFFUSE_COLOR + c] += dc[c]
        blur = glossy_blur(settings, paths, i)  # Filter Glossy (0: none)

        # --- next-event estimation
        # (a layered material's lobe weights at this wo, from the light sample's evaluation:
        # the BSDF sample below picks its lobe from them)
        view_weights = NO_VIEW_WEIGHTS
        if direct != DIRECT_BSDF and ld.n_strategies > 0 and (not md.delta_only[mat] or blur > 0.0):
            hint = material_hint(md, code, n_wo, wo)
            # (light position, selection): one jointly stratified 3-D sample, as Cycles's
            ul0, ul1, u_light_select = sample_3d(sd, pixel, idx, base + 1)
            wi, dist, le, lpdf, l_delta, l_valid, strategy, l_tri = light_sample_full(
                ld, p, n_wo, hint, u_light_select, ul0, ul1)
            if l_valid and lpdf > 0.0 and strategy == ld.world_index and ld.world_prog >= 0:
                # Cycles evaluates the background for a light sample as an emission ray:
                # every Light Path flag 0 (this hit's rows in ``point`` are no longer needed)
                # (flags as int32, prev_flags' type: one compiled world_emission, not two)
                le = world_emission(ld, pd, regs, point, wi, np.int32(0), paths.counts[i], False)
            elif (l_valid and lpdf > 0.0 and strategy == ld.emissive_index and pd is not None and pd.prog_of.shape[0]
                  and pd.emission_reg[surf.material[l_tri]] >= 0):
                # a textured emitter (drt.lights.textured): its program's emission at the point
                le = textured_light_radiance(pd, regs, point, surf.material[l_tri], l_tri,
                                             add(p, scale(wi, dist)))
            if l_valid and lpdf > 0.0:
                wi_l = to_local(wi, t_ax, b_ax, ns)
                f, bpdf, view_weights = bsdf_eval_weights(md, mat, wo_l, wi_l, ns_local, nc_local, nv_local,
                                                          front, blur)
                f = scale(f, shading_factor(surf, prim, wi_l[2] * front))
                # geometric and shading normals must agree on reflection vs transmission
                same_geo = dot(wi, ng) * dot(wo, ng) > 0.0
                same_sh = wi_l[2] * front > 0.0
                # (a shadow ray lifted toward the smooth surface may reach a light below the
                # facet's plane: drt.terminator)
                o_shadow, lifted = shadow_origin(surf, hits, i, prim, p, ng, ns_unmapped, wo, wi)
                if (same_geo == same_sh or (lifted and same_sh) or silhouette) and any_positive(f):
                    w = nee_weight(direct, l_delta, lpdf, bpdf)
                    c = clamp(settings, scale(mul(mul(thr, f), le), w / lpdf), bounce > 0)
                    store(shadow.o, n_shadow, o_shadow)
                    store(shadow.d, n_shadow, wi)
                    shadow.tmax[n_shadow] = dist * (1.0 - SHADOW_EPSILON) if math.isfinite(dist) else np.inf
                    shadow.tau[n_shadow] = paths.tau[i]
                    store(shadow.contrib, n_shadow, c)
                    shadow.slot[n_shadow] = slot
                    if vd is not None and vd.enabled:  # the shadow ray starts in the media on wi's side
                        stack_copy(paths.vstack, i, shadow.vstack, n_shadow)
                        if not same_geo and not (lifted and same_sh):
                            stack_cross(vd, shadow.vstack, n_shadow, prim, medium_mat, wi, ng)
                    n_shadow += 1

        # --- continue the path by sampling the BSDF
        # (direction, lobe choice): one jointly stratified 3-D sample, as Cycles's; with the
        # lobe drawn from its own padded dimension a pixel's directions stratify within the
        # union of lobes but not within each lobe (glass, mixes: docs/estimators.md)
        ub0, ub1, u_lobe = sample_3d(sd, pixel, idx, base + 2)
        if ao_rays.o.shape[0] and camera and not exiting:
            # the Ambient Occlusion pass, from the BSDF's own dimensions, as Cycles's
            if queue_ao_ray(md, mat, thr, p, ng, wo, ns, t_ax, b_ax, front, ub0, ub1, settings, paths, i, slot,
                            ao_rays, n_ao, vd):
                n_ao += 1
        wi_l, weight, bpdf, kind, b_delta, b_valid = bsdf_sample_bump(md, mat, wo_l, u_lobe, ub0, ub1, ns_local,
                                                                      nc_local, nv_local, front, view_weights, blur)
        if settings.indirect != INDIRECT_BSDF and not md.transmission_or_delta[mat]:
            # the lecture's hemisphere estimators, on wo's side of the surface
            if settings.indirect == INDIRECT_COSINE:
                wi_l = cosine_hemisphere(ub0, ub1)
                bpdf = wi_l[2] / math.pi
            else:
                wi_l = uniform_hemisphere(ub0, ub1)
                bpdf = 0.5 / math.pi
            if front < 0.0:
                wi_l = (wi_l[0], wi_l[1], -wi_l[2])
            f, _ = bsdf_eval_bump(md, mat, wo_l, wi_l, ns_local, nc_local, nv_local, front, blur)
            b_valid = bpdf > 0.0
            weight = scale(f, 1.0 / bpdf) if b_valid else (0.0, 0.0, 0.0)
            b_delta = False
            kind = LOBE_DIFFUSE if md.has_diffuse[mat] else LOBE_GLOSSY
        wi = to_world(wi_l, t_ax, b_ax, ns)
        refl_geo = dot(wi, ng) * dot(wo, ng) > 0.0
        # reflection about the sampled lobe's side: N''s for diffuse-class lobes, else wo's
        lobe_side = front if kind == LOBE_DIFFUSE or kind == LOBE_TRANSLUCENT else wo_l[2]
        refl_sh = wi_l[2] * lobe_side > 0.0
        if refl_sh:  # shadow terminator shading offset (reflections only, as Cycles)
            weight = scale(weight, shading_factor(surf, prim, abs(wi_l[2])))
        alive = b_valid and (refl_geo == refl_sh or silhouette) and any_positive(weight)
        if alive and b_delta and kind == LOBE_TRANSMISSION and straight_lobe(md, mat, u_lobe, wo_l, nc_local,
                                                                            nv_local, front):
            # --- an IOR-1 lobe (alpha, Transparent BSDF): the ray passes straight on, a
            # transparent bounce. No bounce is counted and the MIS state of the last real
            # vertex is kept, so a light hit behind pairs with that vertex's light sampling
            # (whose shadow ray passes this surface too: drt.volumes.stage.shadow_step)
            if paths.tcount[i] + 1 > settings.transparent_bounces:
                continue
            copy_path(paths, i, j)
            if vd is not None and vd.enabled and not refl_geo:
                stack_cross(vd, paths.vstack, j, prim, medium_mat, wi, ng)
            store(paths.o, j, offset_point(p, ng, wi))
            paths.tmax[j] = max(paths.tmax[i] - t_geom, 0.0)
            store(paths.throughput, j, mul(thr, weight))
            paths.tcount[j] = paths.tcount[i] + 1
            j += 1
            continue
        thr = mul(thr, weight)
        # entering SSS is no bounce (Cycles's subsurface_bounce skips path_state_next)
        entering = kind == LOBE_SUBSURFACE
        n_bounce = bounce + (0 if entering else 1)
        # (Cycles counts a translucent bounce, TRANSMIT | DIFFUSE, as a transmission bounce only)
        n_diffuse = paths.counts[i, 1] + (1 if kind == LOBE_DIFFUSE else 0)
        n_glossy = paths.counts[i, 2] + (1 if kind == LOBE_GLOSSY else 0)
        n_transmission = paths.counts[i, 3] + (1 if kind == LOBE_TRANSMISSION or kind == LOBE_TRANSLUCENT else 0)
        limit = (n_bounce > settings.max_bounces or n_diffuse > settings.diffuse_bounces
                 or n_glossy > settings.glossy_bounces or n_transmission > settings.transmission_bounces)
        if vertex + 1 >= RR_START_BOUNCE and not exiting:  # one roulette per SSS event, as Cycles
            u_rr = sample_2d(sd, pixel, idx, base + 3)[0]
            q = continuation_probability(thr)
            if not u_rr < q:
                alive = False
            elif q > 0.0:
                thr = scale(thr, 1.0 / q)
        if not alive:
            continue

        if entering:
            # the walk (drt.subsurface, run by the integrator) starts here, just inside
            s_slot, _, _ = pick_lobe_weights(md, mat, u_lobe, wo_l, nc_local, nv_local, front,
                                             view_weights)  # bsdf_sample's pick
            sss_coefficients(md, mat, s_slot, paths.sss_coef, j)
            # the walk guides about Cycles's sd->N (subsurface_bounce: subsurface.N = sd->N):
            # the interpolated normal on wo's geometric side, without the valid-reflection
            # correction that turned the entry direction (bssrdf->N) and without a normal map
            store(paths.sss_n, j, ns_unmapped if front > 0.0 else neg(ns_unmapped))
            store(paths.sss_p, j, p)
            paths.sss_prim[j] = prim
        if sss_on:
            paths.sss[j] = SSS_WALK if entering else SSS_NONE
            paths.sss_count[j] = n_sss + (1 if entering else 0)  # the exit vertex takes the next dims

        # --- write the continuing path to slot j ≤ i (compaction in place)
        if vd is not None and vd.enabled:
            stack_copy(paths.vstack, i, paths.vstack, j)
            if not refl_geo and not entering:  # transmitted: enters or leaves the material's medium
                stack_cross(vd, paths.vstack, j, prim, medium_mat, wi, ng)
            paths.vcount[j] = paths.vcount[i]
            paths.vseg[j] = paths.vseg[i] + 1
        # a walk starts exactly on the surface (its first ray is pushed along wi by the walker)
        store(paths.o, j, p if entering else offset_point(p, ng, wi))
        store(paths.d, j, wi)
        paths.tmax[j] = np.inf
        paths.tau[j] = paths.tau[i]
        store(paths.throughput, j, thr)
        paths.prev_pdf[j] = bpdf
        paths.prev_delta[j] = b_delta
        if paths.min_pdf.shape[0]:  # (entering SSS is no scattering: Cycles's subsurface_bounce)
            paths.min_pdf[j] = paths.min_pdf[i] if b_delta or entering else min(paths.min_pdf[i], bpdf)
        store(paths.prev_p, j, p)
        store(paths.prev_n, j, n_wo)
        store(paths.prev_wo, j, wo)
        paths.prev_mat[j] = code
        paths.prev_flags[j] = ((RAY_SINGULAR if b_delta else (RAY_DIFFUSE if kind == LOBE_DIFFUSE or kind == LOBE_TRANSLUCENT
                                                              else RAY_GLOSSY))
                               | (0 if refl_sh else RAY_TRANSMIT))
        if see_through and settings.transparent_glass >= 0.0 and kind == LOBE_TRANSMISSION and not refl_sh:
            # Transparent Glass: a glass transmission no rougher than the threshold keeps the
            # world transparent (Cycles's LABEL_TRANSMIT_TRANSPARENT; measured: roughness 0.1
            # passes Blender's default threshold 0.1, 0.15 does not)
            if b_delta or glass_alpha(md, mat, u_lobe, wo_l, nc_local, nv_local, front,
                                      view_weights) <= settings.transparent_glass:
                paths.prev_flags[j] |= RAY_TRANSPARENT_BG
        paths.counts[j, 0] = n_bounce
        paths.counts[j, 1] = n_diffuse
        paths.counts[j, 2] = n_glossy
        paths.counts[j, 3] = n_transmission
        paths.terminate[j] = limit
        paths.slot[j] = slot
        paths.pixel[j] = pixel
        paths.index[j] = idx
        j += 1
    return j, n_shadow, n_ao


@kernel
def add_unoccluded(shadow, count, blocked, radiance):
    """Add the contribution of every queued shadow ray that reached its light."""
    for s in range(count):
        if not blocked[s]:
            slot = shadow.slot[s]
            store(radiance, slot, add(load(radiance, slot), load(shadow.contrib, s)))


@kernel
def good_samples(radiance, good):
    """Mark the samples whose radiance (rows of ``radiance``) is finite and within
    ``MAX_SAMPLE_RADIANCE`` in every channel (``good``, bool); returns how many are. (|v| ≤ the
    limit is False for NaN and ±inf: one comparison a channel, where numpy took five passes over
    the batch and their temporaries.)"""
    n_good = 0
    for i in range(radiance.shape[0]):
        ok = (abs(radiance[i, 0]) <= MAX_SAMPLE_RADIANCE and abs(radiance[i, 1]) <= MAX_SAMPLE_RADIANCE
              and abs(radiance[i, 2]) <= MAX_SAMPLE_RADIANCE)
        good[i] = ok
        if ok:
            n_good += 1
    return n_good
