"""The material table: every material of the scene as flat arrays, and the vectorised
eval / sample / pdf of a material (= the sum of its lobes) for batches of hits.

A material is a sum of lobes (scene-format.md): DIFFUSE (Lambert), GLOSSY (GGX reflection, no
Fresnel) and GLASS (GGX dielectric), each with its own colour; a Mix shader arrives as lobes whose
colours carry the mix weight. Arrays, M materials × L lobe slots (L = most lobes in one material;
lobes whose average colour is below 1e-5 are dropped, like Cycles's CLOSURE_WEIGHT_CUTOFF, and
the remaining lobes are packed into the first slots):

    lobe_type   (M, L) int8     BSDF_NONE / BSDF_DIFFUSE / BSDF_GLOSSY / BSDF_GLASS / ... (the
                                BSDF_* constants below; TRANSLUCENT, REFRACTION and HOLDOUT:
                                docs/materials.md, "More shader nodes"; SHEEN, VELVET:
                                "Principled coat and sheen")
    lobe_color  (M, L, 3)       linear RGB weight of the lobe
    lobe_alpha  (M, L)          GGX alpha = roughness² (0 for diffuse)
    lobe_ior    (M, L)          index of refraction of GLASS lobes (1 otherwise)
    lobe_delta  (M, L) bool     lobe is a delta (mirror / smooth glass: alpha² ≤ 2e-10)
    lobe_select (M, L)          probability of picking the lobe when sampling
    lobe_count  (M,)            number of used slots
    emission    (M, 3)          emitted radiance W/(m²·sr) (colour × strength)
    has_emission (M,) bool

``MaterialTable.data`` (a ``MaterialData``) holds the same arrays with the dtypes the compiled
kernels expect, plus the derived per-material flags; it is the first argument of the scalar
kernels ``bsdf_eval`` and ``bsdf_sample``, which the integrator calls per path and which
``MaterialTable.eval`` / ``sample`` apply to batches.

Directions are unit vectors in the *local shading frame* (z = shading normal on the geometric
front side, see docs/architecture.md): ``wo`` points toward where the path came from, ``wi``
toward the next vertex. Diffuse and glossy lobes reflect on whichever side wo is; glass enters
when wo.z > 0 and exits when wo.z < 0.

Lobe selection, as Cycles's closure selection (``bsdf_alloc``: ``sample_weight =
average(weight)``): probability ∝ the *average* of the lobe colour's RGB channels; in a layered
material (``has_layers``) ∝ that × the layers' weight above the lobe at wo × a Fresnel lobe's
albedo at wo (``view_weight``), so the choice follows the view as Cycles's does. The pdf
reported for a non-delta sample is the whole material's, Σ_l p_l pdf_l over the non-delta lobes
(one-sample MIS over lobes), and its weight is (Σ_l f_l)·|cos θi| / that pdf, so that an
estimator using sample() is unbiased for every mix. A delta sample (mirror, smooth glass) has
weight color_l / p_l (the Fresnel choice cancels the Fresnel factor, as in Cycles) and is_delta;
its ``pdf`` is then the *discrete* probability of the event (p_l × Fresnel choice), not a
density: consumers must not use it for MIS.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from ..kernels import inline_kernel, kernel
from ..kernels.vec3 import build_frame, load, store, to_local, to_world
from .caustics import TINT_ONLY, with_caustics_twins
from .dielectric import IOR_ONE_EPS, fresnel, glass_eval, glass_sample, refraction_eval, refraction_sample
from .diffuse import INV_PI, diffuse_eval, diffuse_sample, translucent_eval, translucent_sample
from .dielectric_specular import (average_albedo, dielectric_spec_delta_weight, dielectric_spec_eval,
                                  glass_select_weight, glossy_energy, layer_albedo_max, layer_weight,
                                  metallic_average_albedo, metallic_delta_weight, metallic_eval)
from .glass_ms import glass_energy_factor
from .sheen import (average_albedo as sheen_average_albedo, sheen_albedo, sheen_eval, sheen_sample,
                    velvet_average_albedo, velvet_eval, velvet_sample)
from .subsurface_lobe import BSSRDF_MIN_RADIUS, SSS_METHODS, effective_radius, sss_entry_sample
from .ggx import (
    ALPHA_SQ_SINGULAR,
    f64_array,
    glossy_eval,
    glossy_sample,
    scalar_rows,
    vec3_rows,
)

# lobe_type values
BSDF_NONE = 0
BSDF_DIFFUSE = 1
BSDF_GLOSSY = 2
BSDF_GLASS = 3
BSDF_SUBSURFACE = 4  # random-walk SSS entry (drt.subsurface); never evaluated, only sampled
BSDF_DIELECTRIC_SPECULAR = 5  # GGX × dielectric Fresnel, the Principled specular layer
BSDF_METALLIC = 6  # GGX × F82-tint conductor Fresnel, the Principled metallic lobe
BSDF_TRANSLUCENT = 7  # Lambert transmission (Cycles's Translucent BSDF)
BSDF_REFRACTION = 8  # GGX refraction only, no Fresnel factor (Cycles's Refraction BSDF)
BSDF_SHEEN = 9  # Cycles's microfiber sheen (LTC), drt.materials.sheen
BSDF_VELVET = 10  # Ashikhmin velvet (Sheen BSDF "Ashikhmin", legacy Velvet), drt.materials.sheen
BSDF_HOLDOUT = 11  # Cycles's Holdout closure: never sampled or evaluated; its colour (a grey
#                    weight) cuts camera-visible hits out of the film's alpha (drt.path_stages)
BSDF_COAT_TINT = 12  # a coat Cycles drops for a Reflective Caustics switch, whose tint still
#                      absorbs: a layer of albedo 0 (drt.materials.caustics; never in a file)
BSDF_TYPES = {"DIFFUSE": BSDF_DIFFUSE, "GLOSSY": BSDF_GLOSSY, "GLASS": BSDF_GLASS,
              "SUBSURFACE": BSDF_SUBSURFACE, "DIELECTRIC_SPECULAR": BSDF_DIELECTRIC_SPECULAR,
              "METALLIC": BSDF_METALLIC, "TRANSLUCENT": BSDF_TRANSLUCENT,
              "REFRACTION": BSDF_REFRACTION, "HOLDOUT": BSDF_HOLDOUT,
              "SHEEN": BSDF_SHEEN, "VELVET": BSDF_VELVET}
#: lobe types that transmit (wi on the other side from wo)
TRANSMITTING = (BSDF_GLASS, BSDF_TRANSLUCENT, BSDF_REFRACTION)
#: lobe types that may be a layer over others (a lobe's "layer")
LAYER_TYPES = ("DIELECTRIC_SPECULAR", "SHEEN")
#: name of the white Lambert material appended to tables with SSS: shades SSS exit points
SSS_EXIT_MATERIAL = "__drt_sss_exit__"
#: columns of lobe_sss (M, L, 8)
SSS_RADIUS, SSS_G, SSS_IOR, SSS_METHOD, SSS_WEIGHT, SSS_ALPHA = 0, 3, 4, 5, 6, 7

#: lobes whose average colour is below this are dropped (Cycles's CLOSURE_WEIGHT_CUTOFF).
CLOSURE_WEIGHT_CUTOFF = 1e-5

#: the microfacet lobes Filter Glossy widens (``filtered_alpha``; Cycles's bsdf_blur)
BLURRED_LOBES = (BSDF_GLOSSY, BSDF_GLASS, BSDF_DIELECTRIC_SPECULAR, BSDF_METALLIC, BSDF_REFRACTION)

# BSDFSample.lobe_kind values, for Cycles's bounce counting
LOBE_NONE = 0
LOBE_DIFFUSE = 1
LOBE_GLOSSY = 2          # glossy reflection and glass reflection
LOBE_TRANSMISSION = 3    # glass refraction
LOBE_SUBSURFACE = 4      # entered a SUBSURFACE lobe: the path continues with a random walk
LOBE_TRANSLUCENT = 5     # diffuse transmission (Cycles's TRANSMIT | DIFFUSE label: counts as a
#                          transmission bounce, and the ray is a diffuse + transmission ray)


@dataclass
class BSDFSample:
    """A batch of n BSDF samples, local frame.

    wi (n, 3): sampled direction, away from the surface. weight (n, 3): f·|cos θi| / pdf, the
    throughput multiplier (0 where invalid). pdf (n,): solid-angle pdf of the whole material
    (selection-weighted, for MIS); for delta samples the discrete probability of the event.
    lobe_kind (n,) int8: LOBE_DIFFUSE / LOBE_GLOSSY / LOBE_TRANSMISSION (LOBE_NONE if invalid).
    is_delta (n,) bool: specular event (no MIS, no NEE). valid (n,) bool."""

    wi: np.ndarray
    weight: np.ndarray
    pdf: np.ndarray
    lobe_kind: np.ndarray
    is_delta: np.ndarray
    valid: np.ndarray


#: Largest float64 below 1: the rescaled lobe-selection number stays a valid sample.
_ONE_MINUS_EPS = math.nextafter(1.0, 0.0)

#: Per-scene material arrays for the compiled kernels (``MaterialTable.data``); M materials,
#: L lobe slots (either may be 0). Lobe arrays as in the module docstring; dtypes fixed so that
#: one compiled variant serves every scene:
#:   lobe_type (M, L) int64, lobe_color (M, L, 3) f64, lobe_alpha (M, L) f64, lobe_ior (M, L)
#:   f64, lobe_delta (M, L) bool, lobe_select (M, L) f64,
#:   lobe_cdf (M, L) f64: cumulative lobe_select, exactly 1 at the last used slot, +inf in unused
#:   slots; lobe_count (M,) int64; emission (M, 3) f64 W/(m²·sr); has_emission (M,) bool;
#:   albedo (M, 3) f64: sum of the lobe colours; delta_only (M,) bool: no lobe can be evaluated;
#:   pure_diffuse (M,) bool: exactly one lobe, Lambert; transmission_or_delta (M,) bool: a glass
#:   or delta lobe is present; has_diffuse (M,) bool;
#:   summary (M, 4) f64: (kd, kg, alpha, kt) as ``MaterialTable.lobe_summary`` gives;
#:   lobe_sss (M, L, 8) f64: SUBSURFACE lobes' (effective radius r, g, b (metres, after
#:   Cycles's bssrdf_setup_radius), anisotropy, ior, method code, weight, entry GGX alpha);
#:   sss_exit (1,) int64: the white Lambert row shading SSS exits (−1: no SSS in the scene);
#:   lobe_fresnel (M, L, 5) f64: DIELECTRIC_SPECULAR lobes' (f0·tint r, g, b, multiscatter 0/1,
#:   unused); METALLIC lobes' (F82 tint r, g, b, multiscatter 0/1, scalar weight k: the colour
#:   is k × the base colour, Fresnel F0 = min(colour / k, 1)); GLASS lobes' (multiscatter Fss
#:   r, g, b (0: none, drt.materials.glass_ms), reflection_weight set 0/1, reflection weight k);
#:   GLOSSY lobes' (multiscatter Fss r, g, b (0: single-scatter GGX), unused, unused)
#:   (drt.materials.dielectric_specular); lobe_layer (M, L) int64: slot of the
#:   (drt.materials.dielectric_specular); lobe_layer (M, L) int64: slot of the layer lobe
#:   (DIELECTRIC_SPECULAR or SHEEN) this lobe lies directly under, −1: none. Layers chain (a
#:   layer lobe has its own lobe_layer: diffuse → specular → coat → sheen); a lobe's colour is
#:   scaled per hit by the product over the chain above it of 1 − k·albedo_layer(wo) (× the
#:   coat tint's absorption, see lobe_coat); has_layers (M,) int64: 0 no lobe has a layer,
#:   1 only single untinted k = 1 DIELECTRIC_SPECULAR layers (the plain Principled: the old
#:   scalar fast path for the generic lobes under it; specular, metallic and glass lobes
#:   under a layer always take the RGB walk), 2 anything else (coat, sheen, chains);
#:   lobe_coat (M, L, 4) f64: a layer lobe's (k, tint r, g, b): k its weight relative to what
#:   lies under it (1 for the Principled specular layer, Coat Weight for a coat, Sheen Weight ×
#:   max(Sheen Tint) for a sheen), tint the coat tint whose absorption mix(1, tint^(1/cos θt), k)
#:   the lobes below get (white: none); (1, 1, 1, 1) for other lobes; emission_layer (M,) int64:
#:   slot of the lowest coat / sheen layer over the material's emission (a Principled's), whose
#:   chain attenuates emission seen by camera and BSDF rays (``layered_emission``), −1: none;
#:   lobe_frame (M, L) int64: the normal a lobe is shaded about — FRAME_SHADING (0) the hit's
#:   shading normal, FRAME_COAT the coat normal (a Principled Coat Normal apart from Normal:
#:   ``ProgramData.coat_normal_reg``), FRAME_SHEEN normalize(mix(shading, coat normal, Coat
#:   Weight)) as Cycles's sheen, FRAME_VALID (glossy-class lobes of a material that also has a
#:   DIFFUSE lobe) the valid-reflection normal; only a hit's ``nc_local`` / ``nv_local`` ≠
#:   NO_BUMP make them differ;
#:   caustic_row (M,) int64: the row shading material m right after a diffuse bounce when one of
#:   Cycles's Caustics switches is off (its twin without the lobes they drop; −1: m itself;
#:   drt.materials.caustics), zero-size when both are on;
#:   lobe_avg (M, L, 3) f64: per unit colour, the lobe's cosine-averaged share (the specular
#:   layer's average albedo, 1 − its max for the lobes under it, 1 otherwise): lobe selection
#:   and the albedo pass weigh colours by it (also per hit, in ``programs.eval_material``).
MaterialData = namedtuple("MaterialData", [
    "lobe_type", "lobe_color", "lobe_alpha", "lobe_ior", "lobe_delta", "lobe_select", "lobe_cdf",
    "lobe_count", "emission", "has_emission", "albedo", "delta_only", "pure_diffuse",
    "transmission_or_delta", "has_diffuse", "summary", "lobe_sss", "sss_exit",
    "lobe_fresnel", "lobe_layer", "has_layers", "lobe_avg", "lobe_coat", "emission_layer",
    "lobe_frame", "caustic_row"])


#: ``ns_local`` of a surface without a bump/normal map: the shading frame's own z (also
#: ``nc_local`` of a hit whose coat has no normal of its own)
NO_BUMP = (0.0, 0.0, 1.0)

#: ``MaterialData.lobe_frame`` values: which normal a lobe is shaded about
FRAME_SHADING = 0
FRAME_COAT = 1
FRAME_SHEEN = 2
#: a glossy-class lobe of a material with a diffuse lobe: shaded about the shading normal
#: with Cycles's valid-reflection correction (``maybe_ensure_valid_specular_reflection``, which
#: Cycles applies to every closure but diffuse, sheen and velvet); set by the table, not the file
FRAME_VALID = 3
FRAMES = {"COAT": FRAME_COAT, "SHEEN": FRAME_SHEEN}
#: lobe types Cycles shades about the valid-reflection normal
VALID_FRAME_TYPES = (BSDF_GLOSSY, BSDF_GLASS, BSDF_DIELECTRIC_SPECULAR, BSDF_METALLIC, BSDF_TRANSLUCENT,
                     BSDF_REFRACTION, BSDF_SUBSURFACE)


@kernel
def bump_shadowing(ns_local, wi):
    """Cycles's ``bump_shadowing_term`` for a normal-mapped hit, as (keep, diffuse factor):
    ``ns_local`` is the unmapped (smooth) shading normal in the mapped normal's local frame, wi
    the light direction. A direction on different sides of the two normals is dropped (light
    leaking through the surface); diffuse-class lobes (Cycles's CLOSURE_IS_BSDF_DIFFUSE:
    diffuse, sheen, translucent) are softened toward the terminator by a GGX shadowing term
    whose roughness grows with the normals' deviation."""
    return bump_shadowing_about(ns_local, NO_BUMP, wi)


@kernel
def bump_shadowing_about(ns_local, n, wi):
    """``bump_shadowing`` for a lobe shaded about the unit normal ``n`` (local frame; Cycles's
    closure normal sc->N) instead of the frame's z."""
    cos_nsi = ns_local[0] * wi[0] + ns_local[1] * wi[1] + ns_local[2] * wi[2]
    cos_nsn = ns_local[0] * n[0] + ns_local[1] * n[1] + ns_local[2] * n[2]
    if cos_nsi * cos_nsn * (n[0] * wi[0] + n[1] * wi[1] + n[2] * wi[2]) < 0.0:
        return False, 0.0
    cos_i = abs(cos_nsi)
    cos_d = abs(cos_nsn)
    if cos_d >= 1.0 or cos_i >= 1.0:
        return True, 1.0
    if cos_i < 1e-6:
        return True, 0.0
    alpha2 = min(max(0.125 * (1.0 / (cos_d * cos_d) - 1.0), 0.0), 1.0)
    lam = 0.5 * (math.sqrt(1.0 + alpha2 * max(1.0 / (cos_i * cos_i) - 1.0, 0.0)) - 1.0)
    return True, 1.0 / (1.0 + lam)


@inline_kernel
def bsdf_eval(md, m, wo, wi):
    """md: MaterialData; m: material index; wo, wi: local unit 3-tuples. Returns (f, pdf): f the
    3-tuple Σ color_l·f_l·|cos θi| over the material's non-delta lobes, pdf = Σ p_l·pdf_l per
    unit solid angle of wi (exactly what ``bsdf_sample`` reports for a non-delta sample)."""
    return bsdf_eval_bump(md, m, wo, wi, NO_BUMP, NO_BUMP, NO_BUMP, 1.0 if wo[2] >= 0.0 else -1.0, 0.0)


@kernel
def facing_front(wo, front):
    """``wo`` as a diffuse-class lobe sees it: mirrored through the tangent plane when it lies
    below the side ``front`` (±1, the local z's sign of Cycles's closure normal N', the shading
    normal on the geometric side of wo). A Lambertian or translucent lobe depends on wo only
    through that side: Cycles's ``bsdf_diffuse_eval`` lights every wi above N' and
    ``bsdf_translucent_eval`` every wi below it, whatever wo's own angle to N'. At a smooth
    mesh's silhouette wo is above the facet but below the smooth normal; there this, not wo's
    side, picks the hemisphere (docs/lights.md, "silhouettes of smooth meshes")."""
    if wo[2] * front < 0.0:
        return (wo[0], wo[1], -wo[2])
    return wo


@inline_kernel
def sheen_facing(wo, front):
    """``wo`` as the sheen lobe sees it: on N''s side (``facing_front``) and, at a silhouette,
    tangential. Cycles reads the sheen's LTC tables at cos θo = dot(N', wo), which
    ``lookup_table_read_2D`` clamps to 0 there, builds the LTC frame toward wo's tangential
    direction and lights every wi above N'; a z of front·1e-9 does the same here (tables read
    at 0, side tests on N''s side)."""
    if wo[2] * front < 0.0:
        return (wo[0], wo[1], front * 1e-9)
    return wo


@kernel
def slot_normal(lobe_frame, lobe_coat, m, s, nc_local, nv_local):
    """The unit normal slot s is shaded about, in the hit's local frame (z = the shading
    normal): z itself (FRAME_SHADING), the coat normal ``nc_local`` (FRAME_COAT), the
    valid-reflection normal ``nv_local`` (FRAME_VALID), or Cycles's sheen normal
    normalize(mix(z, coat normal, Coat Weight)) (FRAME_SHEEN; the weight is the coat slot's k,
    per hit when textured). Takes ``md.lobe_frame`` and ``md.lobe_coat``, not the whole
    MaterialData: a plain kernel (not inlined: it sits inside every inlined layer weight, and
    inlining it there doubled the cold compile time), cheap to call with two arrays."""
    f = lobe_frame[m, s]
    if f == FRAME_SHADING:
        return NO_BUMP
    if f == FRAME_COAT:
        return nc_local
    if f == FRAME_VALID:
        return nv_local
    k = 0.0
    for j in range(lobe_frame.shape[1]):
        if lobe_frame[m, j] == FRAME_COAT:
            k = min(max(lobe_coat[m, j, 0], 0.0), 1.0)
    n0 = k * nc_local[0]
    n1 = k * nc_local[1]
    n2 = 1.0 - k + k * nc_local[2]
    length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if not length > 1e-12:
        return NO_BUMP
    return (n0 / length, n1 / length, n2 / length)


@kernel
def slot_cos(lobe_frame, lobe_coat, m, s, wo, nc_local, nv_local):
    """cos θo of slot s: wo's component along the normal the slot is shaded about (a plain
    kernel, as ``slot_normal``)."""
    if (nc_local[2] >= 1.0 and nv_local[2] >= 1.0) or lobe_frame[m, s] == FRAME_SHADING:
        return wo[2]
    n = slot_normal(lobe_frame, lobe_coat, m, s, nc_local, nv_local)
    return wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]


@inline_kernel
def bsdf_eval_bump(md, m, wo, wi, ns_local, nc_local, nv_local, front, blur):
    """``bsdf_eval`` at a normal-mapped hit (``bsdf_eval_weights`` without the lobe weights)."""
    f, pdf, _ = bsdf_eval_weights(md, m, wo, wi, ns_local, nc_local, nv_local, front, blur)
    return f, pdf


@inline_kernel
def filtered_alpha(md, m, s, blur):
    """(alpha, delta) of slot s as shaded at a vertex whose Filter Glossy blur is ``blur`` (a
    GGX alpha; 0: none): Cycles's bsdf_blur widens every microfacet lobe to at least that alpha
    (GLOSSY, GLASS, REFRACTION, the Principled's specular and metal; never diffuse-class lobes,
    and an IOR-1 glass stays a straight pass), so a mirror or a clear glass met after a diffuse
    bounce is evaluated and lit by next-event estimation like a rough one. Only the lobe's
    shape changes: its multiscatter compensation, layer weights and selection weight stay
    those of its own alpha, as Cycles computes them when it sets the closure up."""
    a = md.lobe_alpha[m, s]
    delta = md.lobe_delta[m, s]
    if blur > a:
        t = md.lobe_type[m, s]
        refracting = t == BSDF_GLASS or t == BSDF_REFRACTION
        if (t == BSDF_GLOSSY or t == BSDF_DIELECTRIC_SPECULAR or t == BSDF_METALLIC
                or (refracting and not abs(md.lobe_ior[m, s] - 1.0) < IOR_ONE_EPS)):
            a = blur
            delta = a * a <= ALPHA_SQ_SINGULAR
    return a, delta


#: ``bsdf_eval_weights``'s "no lobe weights to reuse": ``pick_lobe_view`` weighs the lobes itself
NO_VIEW_WEIGHTS = (-1.0, 0.0, 0.0, 0.0, 0.0)


@inline_kernel
def bsdf_eval_weights(md, m, wo, wi, ns_local, nc_local, nv_local, front, blur):
    """(f, pdf, view weights): ``bsdf_eval`` at a normal-mapped hit (the local frame's z is the mapped normal;
    ``ns_local`` the unmapped one in that frame, ``NO_BUMP`` when there is no map): Cycles's
    bump map correction (``bump_shadowing``) applied. ``nc_local``: the coat normal in that
    frame (``NO_BUMP``: the coat has none of its own); ``nv_local`` the valid-reflection
    normal of glossy-class lobes (FRAME_VALID; NO_BUMP: the shading normal itself). Lobes with a
    ``lobe_frame`` are evaluated with wo and wi in their own normal's frame, and get Cycles's
    bump side check and diffuse softening against their own normal. ``front``: ±1, the z sign of
    Cycles's N' (the shading normal on wo's geometric side) — it differs from wo's own side only
    at a smooth silhouette, where diffuse-class lobes follow it (``facing_front``). ``blur``:
    the vertex's Filter Glossy alpha (``filtered_alpha``; 0: none).

    The view weights are (total, w0, w1, w2, w3): a layered material's ``view_weight`` of slots
    0–3 and their sum, which this walk computes anyway for its pdf and which are the same for
    every wi at this vertex: ``bsdf_sample_bump`` at the same (m, wo, normals, front) picks its
    lobe from them instead of weighing the lobes again. ``NO_VIEW_WEIGHTS`` (total < 0) where
    there are none to reuse (no layers, more than four lobes, an early return)."""
    g_diffuse = 1.0
    keep = True
    bumped = ns_local[2] < 1.0
    if bumped:
        keep, g_diffuse = bump_shadowing(ns_local, wi)
    framed = nc_local[2] < 1.0 or nv_local[2] < 1.0
    if not keep and not framed:
        return (0.0, 0.0, 0.0), 0.0, NO_VIEW_WEIGHTS
    wo_main = wo
    wi_main = wi
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    pdf = 0.0
    memo_top = -1  # the last layer chain weight computed (memo_under_weight)
    memo_w = (1.0, 1.0, 1.0)
    layered = md.has_layers[m] > 0
    total = 0.0  # a layered material's view_weight sum: its lobe choice depends on wo
    w0 = w1 = w2 = w3 = 0.0  # (the first four weights, for the sample's pick: no arrays)
    for s in range(md.lobe_type.shape[1]):
        t = md.lobe_type[m, s]
        if t == BSDF_NONE:
            continue
        if layered:  # every lobe counts in the total, also those not evaluated below
            sel, uw_s, memo_top, memo_w = view_weight(md, m, s, wo_main, nc_local, nv_local, front, memo_top,
                                                      memo_w)
            total += sel
            w0, w1, w2, w3 = keep_first_four(s, sel, w0, w1, w2, w3)
        else:
            sel = md.lobe_select[m, s]
            uw_s = (1.0, 1.0, 1.0)  # (no lobe has a layer)
        alpha = md.lobe_alpha[m, s]
        if md.lobe_delta[m, s] or blur > alpha:  # (Filter Glossy widens microfacet lobes)
            alpha, delta = filtered_alpha(md, m, s, blur)
            if delta:
                continue  # a delta lobe has no density to evaluate
        wo = wo_main
        wi = wi_main
        g = g_diffuse
        c0, c1, c2 = md.lobe_color[m, s, 0], md.lobe_color[m, s, 1], md.lobe_color[m, s, 2]
        if framed and md.lobe_frame[m, s] != FRAME_SHADING:
            n = slot_normal(md.lobe_frame, md.lobe_coat, m, s, nc_local, nv_local)
            if n[2] < 1.0:
                # Cycles's bump_shadowing_term against this lobe's own normal (sc->N)
                ok, g = bump_shadowing_about(ns_local, n, wi)
                if not ok:
                    continue
                tx, bx = build_frame(n)
                wo = to_local(wo_main, tx, bx, n)
                wi = to_local(wi_main, tx, bx, n)
            elif not keep:
                continue
        elif not keep:
            continue
        if t == BSDF_DIELECTRIC_SPECULAR:
            fc, p = dielectric_spec_eval(wo, wi, alpha, md.lobe_alpha[m, s], md.lobe_ior[m, s],
                                         lobe_f0(md, m, s), md.lobe_fresnel[m, s, 3] > 0.0)
            if md.has_layers[m] and md.lobe_layer[m, s] >= 0:  # under a coat / sheen
                fc = (fc[0] * uw_s[0], fc[1] * uw_s[1], fc[2] * uw_s[2])  # (view_weight's)
            f0 += md.lobe_color[m, s, 0] * fc[0]
            f1 += md.lobe_color[m, s, 1] * fc[1]
            f2 += md.lobe_color[m, s, 2] * fc[2]
            pdf += sel * p
            continue
        if t == BSDF_METALLIC:
            k = md.lobe_fresnel[m, s, 4]
            fc, p = metallic_eval(wo, wi, alpha, md.lobe_alpha[m, s], metal_f0(md, m, s), lobe_f0(md, m, s),
                                  md.lobe_fresnel[m, s, 3] > 0.0)
            if md.has_layers[m] and md.lobe_layer[m, s] >= 0:
                fc = (fc[0] * uw_s[0], fc[1] * uw_s[1], fc[2] * uw_s[2])  # (view_weight's)
            f0 += k * fc[0]
            f1 += k * fc[1]
            f2 += k * fc[2]
            pdf += sel * p
            continue
        if t == BSDF_DIFFUSE:
            v, p = diffuse_eval(facing_front(wo, front), wi)
            v *= g
        elif t == BSDF_GLOSSY:
            v, p = glossy_eval(wo, wi, alpha)
            fss = (md.lobe_fresnel[m, s, 0], md.lobe_fresnel[m, s, 1], md.lobe_fresnel[m, s, 2])
            if fss[0] + fss[1] + fss[2] > 0.0:  # Multiscatter GGX: a factor per channel
                k = glossy_energy(md.lobe_alpha[m, s], wo[2], fss)
                c0, c1, c2 = c0 * k[0], c1 * k[1], c2 * k[2]
        elif t == BSDF_GLASS:
            v, p = glass_eval(wo, wi, alpha, md.lobe_ior[m, s])
            if md.lobe_fresnel[m, s, 3] > 0.0 and wo[2] * wi[2] > 0.0:
                # a Principled transmission: the reflection is weighted by the lobe's
                # scalar weight (untinted), only the refraction by its colour
                c0 = c1 = c2 = md.lobe_fresnel[m, s, 4]
            fss = (md.lobe_fresnel[m, s, 0], md.lobe_fresnel[m, s, 1], md.lobe_fresnel[m, s, 2])
            if fss[0] + fss[1] + fss[2] > 0.0:  # Multiscatter GGX glass (drt.materials.glass_ms)
                k = glass_energy_factor(md.lobe_alpha[m, s], md.lobe_ior[m, s], wo[2], fss)
                c0, c1, c2 = c0 * k[0], c1 * k[1], c2 * k[2]
        elif t == BSDF_TRANSLUCENT:  # diffuse-class in Cycles: softened like diffuse
            v, p = translucent_eval(facing_front(wo, front), wi)
            v *= g
        elif t == BSDF_REFRACTION:
            v, p = refraction_eval(wo, wi, alpha, md.lobe_ior[m, s])
        elif t == BSDF_SHEEN:  # diffuse-class in Cycles: softened like diffuse
            v, p = sheen_eval(sheen_facing(wo, front), wi, md.lobe_alpha[m, s])
            v *= g
        elif t == BSDF_VELVET:
            v, p = velvet_eval(wo, wi, md.lobe_alpha[m, s])
        else:
            continue
        if md.has_layers[m] and md.lobe_layer[m, s] >= 0:  # under a coat / sheen
            if md.has_layers[m] == 1:  # one plain specular layer: a scalar factor
                # (view_weight's chain is that factor where cos θo is wo's own: no second lookup)
                v *= uw_s[0] if not framed else single_layer_weight(md, m, md.lobe_layer[m, s], wo_main)
                f0 += c0 * v
                f1 += c1 * v
                f2 += c2 * v
            else:
                f0 += c0 * (v * uw_s[0])  # (view_weight's under_weight of this slot)
                f1 += c1 * (v * uw_s[1])
                f2 += c2 * (v * uw_s[2])
        else:
            f0 += c0 * v
            f1 += c1 * v
            f2 += c2 * v
        pdf += sel * p
    weights = NO_VIEW_WEIGHTS
    if layered:
        pdf = pdf / total if total > 0.0 else 0.0
        if md.lobe_count[m] <= 4:
            weights = (total, w0, w1, w2, w3)
    return (f0, f1, f2), pdf, weights


@inline_kernel
def lobe_f0(md, m, s):
    """f0·tint of a DIELECTRIC_SPECULAR slot as a 3-tuple."""
    return (md.lobe_fresnel[m, s, 0], md.lobe_fresnel[m, s, 1], md.lobe_fresnel[m, s, 2])


@inline_kernel
def metal_f0(md, m, s):
    """F0 of a METALLIC slot: its colour / its scalar weight, clamped to [0, 1] (Cycles's
    clamped base colour)."""
    k = md.lobe_fresnel[m, s, 4]
    inv = 1.0 / k if k > 0.0 else 0.0
    return (min(md.lobe_color[m, s, 0] * inv, 1.0), min(md.lobe_color[m, s, 1] * inv, 1.0),
            min(md.lobe_color[m, s, 2] * inv, 1.0))


@inline_kernel
def under_weight(md, m, s, wo, nc_local, nv_local, front):
    """Scale (3-tuple) of slot s for this wo: the product over the layers above it (the chain
    md.lobe_layer[m, s], its lobe_layer, ...) of Cycles's closure_layering_weight
    1 − k·max_c albedo_c(wo), and for a tinted coat its absorption mix(1, tint^(1/cos θt), k)
    with θt the view direction refracted into the coat (Cycles's principled_bsdf_emission)."""
    return chain_weight(md, m, md.lobe_layer[m, s], wo, nc_local, nv_local, front)


@inline_kernel
def layered_emission(md, m, le, wo, nc_local, nv_local, front):
    """Emission le (3-tuple) of material m seen from wo (local frame; ``nc_local`` the coat
    normal and ``nv_local`` the valid-reflection normal in it, or NO_BUMP, and then any vector
    whose z is cos θo will do): attenuated by the coat / sheen layers over it (Cycles 5.0 does so for camera and
    BSDF rays; its light samples see the unattenuated emission — Cycles fixed that after 5.1)."""
    top = md.emission_layer[m]
    if top < 0:
        return le
    w = chain_weight(md, m, top, wo, nc_local, nv_local, front)
    return (le[0] * w[0], le[1] * w[1], le[2] * w[2])


@inline_kernel
def single_layer_weight(md, m, top, wo):
    """The factor 1 − albedo(wo) of a DIELECTRIC_SPECULAR layer with k = 1, no tint and nothing
    above it (``has_layers`` 1): what ``chain_weight`` gives, as one scalar."""
    return layer_weight(md.lobe_alpha[m, top], md.lobe_ior[m, top], lobe_f0(md, m, top),
                        md.lobe_fresnel[m, top, 3] > 0.0, wo[2])


@inline_kernel
def chain_weight(md, m, top, wo, nc_local, nv_local, front):
    """Product of the layer weights of the chain starting at slot ``top`` (−1: (1, 1, 1))."""
    w0 = 1.0
    w1 = 1.0
    w2 = 1.0
    while top >= 0:
        f = layer_factor(md, m, top, wo, nc_local, nv_local, front)
        w0 *= f[0]
        w1 *= f[1]
        w2 *= f[2]
        top = md.lobe_layer[m, top]
    return w0, w1, w2


@inline_kernel
def memo_under_weight(md, m, s, wo, nc_local, nv_local, front, memo_top, memo_w):
    """``under_weight`` of slot s reusing the chain weight of the last layer asked for
    (memo_top, memo_w; −1 and (1, 1, 1) at first): lobes come top layer first, so each layer's
    chain is the one above it, already known, times its own factor. Returns (weight, memo_top,
    memo_w) for the next call."""
    top = md.lobe_layer[m, s]
    if top == memo_top:
        return memo_w, memo_top, memo_w
    up = md.lobe_layer[m, top]
    if up < 0:  # a single layer (the plain Principled's specular layer): its factor
        w = layer_factor(md, m, top, wo, nc_local, nv_local, front)
        return w, top, w
    if up == memo_top:
        f = layer_factor(md, m, top, wo, nc_local, nv_local, front)
        w = (memo_w[0] * f[0], memo_w[1] * f[1], memo_w[2] * f[2])
    else:
        w = chain_weight(md, m, top, wo, nc_local, nv_local, front)
    return w, top, w


@inline_kernel
def layer_factor(md, m, top, wo, nc_local, nv_local, front):
    """One layer's factor (3-tuple): 1 − k·albedo(wo), × the coat tint's absorption; cos θo
    taken about the layer's own normal (``slot_cos``), as Cycles's albedo of the closure. A
    sheen layer's albedo is read at cos θo clamped to 0 where wo is below N' (``front``, a
    silhouette), as the sheen lobe itself (``sheen_facing``)."""
    cos_o = layer_cos(md, m, top, wo, nc_local, nv_local)
    return factor_of_albedo(md, m, top, layer_albedo(md, m, top, cos_o, front), cos_o)


@inline_kernel
def layer_cos(md, m, s, wo, nc_local, nv_local):
    """cos θo of slot s about its own normal (``slot_cos``; wo[2] without coat / valid normals)."""
    if nc_local[2] >= 1.0 and nv_local[2] >= 1.0:
        return wo[2]
    return slot_cos(md.lobe_frame, md.lobe_coat, m, s, wo, nc_local, nv_local)


@inline_kernel
def layer_albedo(md, m, top, cos_o, front):
    """Albedo at cos θo (``layer_cos``) of a layer lobe per unit weight: a sheen's
    ``sheen_albedo`` (cos θo clamped to 0 below N', ``front``), a specular layer's largest RGB
    albedo (``layer_albedo_max``), a COAT_TINT's 0."""
    t = md.lobe_type[m, top]
    if t == BSDF_SHEEN:
        return sheen_albedo(md.lobe_alpha[m, top], cos_o if cos_o * front >= 0.0 else 0.0)
    if t == BSDF_COAT_TINT:  # a coat the caustics switches dropped: only its tint absorbs
        return 0.0
    return layer_albedo_max(md.lobe_alpha[m, top], md.lobe_ior[m, top], lobe_f0(md, m, top),
                            md.lobe_fresnel[m, top, 3] > 0.0, cos_o)


@inline_kernel
def factor_of_albedo(md, m, top, a, cos_o):
    """``layer_factor`` of layer slot ``top`` from its albedo a at cos θo."""
    k = md.lobe_coat[m, top, 0]
    lw = min(max(1.0 - k * a, 0.0), 1.0)
    t0 = md.lobe_coat[m, top, 1]
    t1 = md.lobe_coat[m, top, 2]
    t2 = md.lobe_coat[m, top, 3]
    if t0 != 1.0 or t1 != 1.0 or t2 != 1.0:
        inv = 1.0 / md.lobe_ior[m, top]
        c = min(abs(cos_o), 1.0)
        depth = 1.0 / math.sqrt(max(1.0 - inv * inv * (1.0 - c * c), 1e-12))
        return (lw * (1.0 + k * (t0 ** depth - 1.0)), lw * (1.0 + k * (t1 ** depth - 1.0)),
                lw * (1.0 + k * (t2 ** depth - 1.0)))
    return lw, lw, lw


@inline_kernel
def view_weight(md, m, s, wo, nc_local, nv_local, front, memo_top, memo_w):
    """Unnormalised probability of picking slot s of a layered material (``has_layers`` > 0)
    at view wo, as Cycles's closure sample_weight: the lobe's scalar weight × the layers above
    it (their chain weight at wo, averaged over RGB) × for a Fresnel lobe its albedo at wo
    (``bsdf_microfacet_adjust_weight``; a sheen's ``sheen_albedo``). A coat seen at a grazing
    angle reflects many times its average, so a constant, cosine-averaged choice would pick it
    too rarely and return it with a large weight (fireflies). Any positive choice keeps the
    estimator unbiased; ``pick_lobe_view`` and ``bsdf_eval_bump`` only have to agree.

    Returns (weight, uw, memo_top, memo_w): uw the slot's ``under_weight`` (3-tuple), and
    ``memo_under_weight``'s memo, left holding a layer lobe's own chain (its factor, from the
    albedo just read, × uw) so that the lobes under it, which come next, read it for free."""
    t = md.lobe_type[m, s]
    uw = (1.0, 1.0, 1.0)
    if t == BSDF_NONE or t == BSDF_HOLDOUT:
        return 0.0, uw, memo_top, memo_w
    if md.lobe_layer[m, s] >= 0:
        uw, memo_top, memo_w = memo_under_weight(md, m, s, wo, nc_local, nv_local, front, memo_top, memo_w)
    c = (md.lobe_color[m, s, 0] + md.lobe_color[m, s, 1] + md.lobe_color[m, s, 2]) * (1.0 / 3.0)
    if t == BSDF_DIELECTRIC_SPECULAR or t == BSDF_SHEEN or t == BSDF_COAT_TINT:
        cos_o = layer_cos(md, m, s, wo, nc_local, nv_local)
        a = layer_albedo(md, m, s, cos_o, front)
        f = factor_of_albedo(md, m, s, a, cos_o)
        memo_top = s
        memo_w = (uw[0] * f[0], uw[1] * f[1], uw[2] * f[2])
        if t == BSDF_DIELECTRIC_SPECULAR:  # (a sheen's 0, where Cycles drops it, is its eval's too;
            a = max(a, 1e-6)  # a COAT_TINT's 0: never picked)
    elif t == BSDF_METALLIC:  # f is k × F(f0): the weight is k × Schlick's F averaged over RGB
        f0 = metal_f0(md, m, s)
        x = 1.0 - min(abs(layer_cos(md, m, s, wo, nc_local, nv_local)), 1.0)
        x5 = x * x * x * x * x
        c = md.lobe_fresnel[m, s, 4]
        a = max((f0[0] + f0[1] + f0[2]) * (1.0 / 3.0) * (1.0 - x5) + x5, 1e-6)
    elif md.lobe_layer[m, s] < 0:
        a = (md.lobe_avg[m, s, 0] + md.lobe_avg[m, s, 1] + md.lobe_avg[m, s, 2]) * (1.0 / 3.0)
    else:
        a = 1.0  # (lobe_avg of a lobe under layers holds their average; uw has them at wo)
    if t == BSDF_GLASS and md.lobe_fresnel[m, s, 3] > 0.0:  # a Principled glass: as Cycles's albedo
        cos_o = layer_cos(md, m, s, wo, nc_local, nv_local)
        ior = md.lobe_ior[m, s]
        f = fresnel(cos_o, ior if cos_o >= 0.0 else 1.0 / ior)
        c = c * (1.0 - f) + md.lobe_fresnel[m, s, 4] * f
    if t == BSDF_SUBSURFACE:  # Cycles's bssrdf_setup: × the number of channels with a radius
        a *= ((1.0 if md.lobe_sss[m, s, SSS_RADIUS] > 0.0 else 0.0)
              + (1.0 if md.lobe_sss[m, s, SSS_RADIUS + 1] > 0.0 else 0.0)
              + (1.0 if md.lobe_sss[m, s, SSS_RADIUS + 2] > 0.0 else 0.0))
    if md.lobe_layer[m, s] >= 0:
        a *= max((uw[0] + uw[1] + uw[2]) * (1.0 / 3.0), 1e-6)
    return c * a, uw, memo_top, memo_w


@inline_kernel
def keep_first_four(s, w, w0, w1, w2, w3):
    """(w0, w1, w2, w3) with slot s's weight w stored if s < 4: a kernel has no arrays of its
    own, so a lobe walk keeps the weights it needs again in scalars."""
    if s == 0:
        return w, w1, w2, w3
    if s == 1:
        return w0, w, w2, w3
    if s == 2:
        return w0, w1, w, w3
    if s == 3:
        return w0, w1, w2, w
    return w0, w1, w2, w3


@inline_kernel
def _invert_lobe_weights(md, m, u_lobe, wo, nc_local, nv_local, front, total, w0, w1, w2, w3, memo_top,
                         memo_w):
    """(slot, u_rest, p_sel) for u_lobe over the view weights of material m's lobes, whose sum is
    total: slots 0-3 from (w0..w3), any further ones weighed again (with the walk's memo)."""
    if not total > 0.0:
        return 0, 0.0, 0.0
    target = u_lobe * total
    cum = 0.0
    last = 0
    last_w = 0.0
    for s in range(md.lobe_count[m]):
        if s < 4:
            w = w0 if s == 0 else (w1 if s == 1 else (w2 if s == 2 else w3))
        else:
            w, _, memo_top, memo_w = view_weight(md, m, s, wo, nc_local, nv_local, front, memo_top, memo_w)
        if w > 0.0:
            if target < cum + w:
                return s, min(max((target - cum) / w, 0.0), _ONE_MINUS_EPS), w / total
            last = s
            last_w = w
        cum += w
    return last, _ONE_MINUS_EPS, last_w / total  # (rounding left u_lobe past the last lobe)


@inline_kernel
def pick_lobe_view(md, m, u_lobe, wo, nc_local, nv_local, front):
    """(slot, u_rest, p_sel): the lobe u_lobe selects at view wo (local frame; the normals as
    ``bsdf_eval_bump``), u_lobe rescaled inside its interval, and its probability. A layered
    material picks by ``view_weight``, any other by its constant ``lobe_select``. p_sel 0: no
    lobe can be picked."""
    if not md.has_layers[m]:
        slot, u_rest = pick_lobe(md, m, u_lobe)
        return slot, u_rest, md.lobe_select[m, slot]
    count = md.lobe_count[m]
    total = 0.0
    memo_top = -1
    memo_w = (1.0, 1.0, 1.0)
    # the first four weights are kept for the second walk; more lobes than that are weighed again
    w0 = w1 = w2 = w3 = 0.0
    for s in range(count):
        w, _, memo_top, memo_w = view_weight(md, m, s, wo, nc_local, nv_local, front, memo_top, memo_w)
        w0, w1, w2, w3 = keep_first_four(s, w, w0, w1, w2, w3)
        total += w
    return _invert_lobe_weights(md, m, u_lobe, wo, nc_local, nv_local, front, total, w0, w1, w2, w3, memo_top,
                                memo_w)


@inline_kernel
def pick_lobe_weights(md, m, u_lobe, wo, nc_local, nv_local, front, weights):
    """``pick_lobe_view`` from the view weights ``bsdf_eval_weights`` returned at this vertex
    (the same choice, without weighing the lobes again), or by itself where there are none."""
    if not (weights[0] >= 0.0 and md.has_layers[m]):
        return pick_lobe_view(md, m, u_lobe, wo, nc_local, nv_local, front)
    # (at most four lobes: bsdf_eval_weights gives none for more)
    return _invert_lobe_weights(md, m, u_lobe, wo, nc_local, nv_local, front, weights[0], weights[1], weights[2],
                                weights[3], weights[4], -1, (1.0, 1.0, 1.0))


@inline_kernel
def pick_lobe(md, m, u_lobe):
    """(slot, u_rest): the lobe u_lobe selects and u_lobe rescaled inside its interval."""
    count = md.lobe_count[m]
    slot = 0
    for j in range(md.lobe_cdf.shape[1]):
        if u_lobe >= md.lobe_cdf[m, j]:
            slot += 1
    slot = min(slot, count - 1)
    p_sel = md.lobe_select[m, slot]
    cdf_lo = md.lobe_cdf[m, slot - 1] if slot > 0 else 0.0
    u_rest = (u_lobe - cdf_lo) / (p_sel if p_sel > 0.0 else 1.0)
    return slot, min(max(u_rest, 0.0), _ONE_MINUS_EPS)


@inline_kernel
def bsdf_sample(md, m, wo, u_lobe, u0, u1):
    """``bsdf_sample_bump`` without a normal map (see there)."""
    return bsdf_sample_bump(md, m, wo, u_lobe, u0, u1, NO_BUMP, NO_BUMP, NO_BUMP, 1.0 if wo[2] >= 0.0 else -1.0,
                            NO_VIEW_WEIGHTS, 0.0)


@inline_kernel
def bsdf_sample_bump(md, m, wo, u_lobe, u0, u1, ns_local, nc_local, nv_local, front, weights, blur):
    """md: MaterialData; m: material index; wo: local unit 3-tuple; u_lobe in [0, 1) picks the
    lobe (and, rescaled inside the picked interval, glass's reflect/refract choice); (u0, u1) in
    [0, 1)² picks the direction. Returns (wi, weight, pdf, lobe_kind, is_delta, valid):
    weight = f·|cos θi| / pdf (3-tuple), pdf the whole material's solid-angle pdf, or for a delta
    event its discrete probability; lobe_kind a LOBE_* value. Invalid samples have zero weight
    and pdf, LOBE_NONE and is_delta False (wi is kept where one was drawn). ``ns_local``: the
    unmapped shading normal at a normal-mapped hit (``bsdf_eval_bump``), else ``NO_BUMP``;
    ``nc_local``, ``nv_local`` the coat and valid-reflection normals (``bsdf_eval_bump``): a lobe
    with a ``lobe_frame`` samples wi about its own normal; ``front`` the side diffuse-class lobes
    reflect on (``bsdf_eval_bump``); ``weights`` the view weights ``bsdf_eval_weights`` returned
    for the same (m, wo, normals, front), or ``NO_VIEW_WEIGHTS``; ``blur`` the vertex's Filter
    Glossy alpha (``filtered_alpha``; 0: none)."""
    zero = (0.0, 0.0, 0.0)
    count = md.lobe_count[m]
    if count == 0 or wo[2] == 0.0:
        return zero, zero, 0.0, LOBE_NONE, False, False
    slot, u_rest, p_sel = pick_lobe_weights(md, m, u_lobe, wo, nc_local, nv_local, front, weights)
    if not p_sel > 0.0:
        return zero, zero, 0.0, LOBE_NONE, False, False
    t = md.lobe_type[m, slot]
    alpha, is_delta = filtered_alpha(md, m, slot, blur)
    if is_delta:  # alpha 0 makes the lobe functions take their delta path (also for glass with ior ≈ 1)
        alpha = 0.0
    ior = md.lobe_ior[m, slot]
    refracted = False
    wo_main = wo
    framed = False
    n_slot = NO_BUMP
    tx = NO_BUMP
    bx = NO_BUMP
    if (nc_local[2] < 1.0 or nv_local[2] < 1.0) and md.lobe_frame[m, slot] != FRAME_SHADING:
        # sample in the lobe's own frame; wi goes back to the hit's frame below
        n_slot = slot_normal(md.lobe_frame, md.lobe_coat, m, slot, nc_local, nv_local)
        framed = n_slot[2] < 1.0
        if framed:
            tx, bx = build_frame(n_slot)
            wo = to_local(wo_main, tx, bx, n_slot)
    if t == BSDF_DIFFUSE:
        wo = facing_front(wo, front)
        wi = diffuse_sample(wo, u0, u1)
        kind = LOBE_DIFFUSE
    elif t == BSDF_GLOSSY or t == BSDF_DIELECTRIC_SPECULAR or t == BSDF_METALLIC:
        wi = glossy_sample(wo, alpha, u0, u1)
        kind = LOBE_GLOSSY
    elif t == BSDF_SHEEN:  # Cycles labels sheen diffuse (bounce counting)
        wo = sheen_facing(wo, front)
        wi = sheen_sample(wo, md.lobe_alpha[m, slot], u0, u1)
        kind = LOBE_DIFFUSE
    elif t == BSDF_VELVET:
        wi = velvet_sample(wo, u0, u1)
        kind = LOBE_DIFFUSE
    elif t == BSDF_GLASS:
        wi, refracted = glass_sample(wo, alpha, ior, u_rest, u0, u1)
        kind = LOBE_TRANSMISSION if refracted else LOBE_GLOSSY
    elif t == BSDF_TRANSLUCENT:
        wo = facing_front(wo, front)
        wi = translucent_sample(wo, u0, u1)
        refracted = True
        kind = LOBE_TRANSLUCENT
    elif t == BSDF_REFRACTION:
        wi, ok = refraction_sample(wo, alpha, ior, u0, u1)
        if not ok:
            return wi, zero, 0.0, LOBE_NONE, False, False
        refracted = True
        kind = LOBE_TRANSMISSION
    elif t == BSDF_SUBSURFACE:
        # Cycles's subsurface_bounce: weight = closure weight / selection probability, the
        # entry direction only (no Fresnel, no f/pdf); pdf 1 marks "not for MIS"
        wi, ok = sss_entry_sample(int(md.lobe_sss[m, slot, SSS_METHOD]), md.lobe_sss[m, slot, SSS_ALPHA],
                                  md.lobe_sss[m, slot, SSS_IOR], wo, u_rest, u0, u1)
        if not ok or p_sel <= 0.0:
            return wi, zero, 0.0, LOBE_NONE, False, False
        if framed:  # beside a diffuse lobe: entered about the valid-reflection normal (bssrdf->N)
            wi = to_world(wi, tx, bx, n_slot)
        uw = under_weight(md, m, slot, wo_main, nc_local, nv_local, front) if md.has_layers[m] else (1.0, 1.0, 1.0)
        weight = (md.lobe_color[m, slot, 0] * (uw[0] / p_sel), md.lobe_color[m, slot, 1] * (uw[1] / p_sel),
                  md.lobe_color[m, slot, 2] * (uw[2] / p_sel))
        return wi, weight, 1.0, LOBE_SUBSURFACE, False, True
    else:
        return zero, zero, 0.0, LOBE_NONE, False, False
    side = wo[2] * wi[2]
    if framed:
        wi = to_world(wi, tx, bx, n_slot)
    if not (side < 0.0 if refracted else side > 0.0):
        return wi, zero, 0.0, LOBE_NONE, False, False

    if is_delta:
        # weight colour / p_sel (the Fresnel choice cancels F); pdf = the event's probability
        weight = (md.lobe_color[m, slot, 0] / p_sel, md.lobe_color[m, slot, 1] / p_sel,
                  md.lobe_color[m, slot, 2] / p_sel)
        pdf = p_sel
        if t == BSDF_GLASS:
            fr = fresnel(wo[2], 1.0 / ior if wo[2] < 0.0 else ior)
            pdf *= (1.0 - fr) if refracted else fr
            if not refracted and md.lobe_fresnel[m, slot, 3] > 0.0:  # untinted reflection
                k = md.lobe_fresnel[m, slot, 4] / p_sel
                weight = (k, k, k)
        elif t == BSDF_DIELECTRIC_SPECULAR:  # a smooth specular layer: F(cos θo) × colour
            fc = dielectric_spec_delta_weight(wo[2], ior, lobe_f0(md, m, slot),
                                              md.lobe_fresnel[m, slot, 3] > 0.0)
            weight = (weight[0] * fc[0], weight[1] * fc[1], weight[2] * fc[2])
        elif t == BSDF_METALLIC:  # a smooth metal: k·F82(cos θo)
            fc = metallic_delta_weight(wo[2], metal_f0(md, m, slot), lobe_f0(md, m, slot))
            k = md.lobe_fresnel[m, slot, 4] / p_sel
            weight = (k * fc[0], k * fc[1], k * fc[2])
        if md.has_layers[m] and md.lobe_layer[m, slot] >= 0:  # a smooth lobe under a coat / sheen
            uw = under_weight(md, m, slot, wo_main, nc_local, nv_local, front)
            weight = (weight[0] * uw[0], weight[1] * uw[1], weight[2] * uw[2])
        return wi, weight, pdf, kind, True, True

    if md.pure_diffuse[m] and ns_local[2] >= 1.0:  # (never framed: one Lambert lobe)
        # One Lambert lobe needs no evaluation: pdf = |cos θi|/π, weight = its colour.
        pdf = abs(wi[2]) * INV_PI
        if not pdf > 0.0:
            return wi, zero, 0.0, LOBE_NONE, False, False
        color = (md.lobe_color[m, 0, 0], md.lobe_color[m, 0, 1], md.lobe_color[m, 0, 2])
        return wi, color, pdf, kind, False, True

    # One-sample MIS over lobes: the whole material's f and pdf at the sampled wi.
    f, pdf = bsdf_eval_bump(md, m, wo_main, wi, ns_local, nc_local, nv_local, front, blur)
    if not pdf > 0.0:
        return wi, zero, 0.0, LOBE_NONE, False, False
    return wi, (f[0] / pdf, f[1] / pdf, f[2] / pdf), pdf, kind, False, True


@kernel
def _eval_rows(md, mat, wo, wi, nc, blur, f, pdf):
    for i in range(mat.shape[0]):
        w_o = load(wo, i)
        fi, p = bsdf_eval_bump(md, mat[i], w_o, load(wi, i), NO_BUMP, load(nc, i), NO_BUMP,
                               1.0 if w_o[2] >= 0.0 else -1.0, blur)
        store(f, i, fi)
        pdf[i] = p


@kernel
def _sample_rows(md, mat, wo, u_lobe, u2, nc, light_wi, blur, wi, weight, pdf, kind, is_delta, valid):
    for i in range(mat.shape[0]):
        w_o = load(wo, i)
        front = 1.0 if w_o[2] >= 0.0 else -1.0
        weights = NO_VIEW_WEIGHTS
        if light_wi.shape[0]:  # as shade: the light sample's evaluation first, its weights reused
            _, _, weights = bsdf_eval_weights(md, mat[i], w_o, load(light_wi, i), NO_BUMP, load(nc, i), NO_BUMP,
                                              front, blur)
        w, wt, p, k, d, ok = bsdf_sample_bump(md, mat[i], w_o, u_lobe[i], u2[i, 0], u2[i, 1], NO_BUMP,
                                              load(nc, i), NO_BUMP, front, weights, blur)
        store(wi, i, w)
        store(weight, i, wt)
        pdf[i] = p
        kind[i] = k
        is_delta[i] = d
        valid[i] = ok


def _fail(where: str, msg: str) -> ValueError:
    return ValueError(f"{where}: {msg}")


def _number(value, where: str, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _fail(where, f"{field} must be a finite number, got {value!r}")
    return float(value)


def _rgb(value, where: str, field: str) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise _fail(where, f"{field} must be a list of 3 numbers, got {value!r}")
    rgb = np.array([_number(v, where, field) for v in value])
    if np.any(rgb < 0.0):
        raise _fail(where, f"{field} must be >= 0, got {list(value)!r}")
    return rgb


def _subsurface_lobe(lobe: dict, color: np.ndarray, where: str):
    """A SUBSURFACE lobe dict → (lobe_sss row (8,), its colour, the colour of the channels
    that become Lambert (radius < BSSRDF_MIN_RADIUS, as Cycles's bssrdf_setup) or None).
    Clamps as Cycles: anisotropy to [0, 0.9], IOR to [1.01, 3.8]; BURLEY is walked as
    RANDOM_WALK (docs/subsurface.md)."""
    method = lobe.get("method", "RANDOM_WALK")
    if method not in SSS_METHODS:
        raise _fail(where, f"method must be one of {list(SSS_METHODS)}, got {method!r}")
    radius = _rgb(lobe.get("radius", [1.0, 0.2, 0.1]), where, "radius")
    ior = min(max(_number(lobe.get("ior", 1.4), where, "ior"), 1.01), 3.8)
    r = _number(lobe.get("roughness", 1.0), where, "roughness")
    if not 0.0 <= r <= 1.0:
        raise _fail(where, f"roughness must be in [0, 1], got {r!r}")
    g = min(max(_number(lobe.get("anisotropy", 0.0), where, "anisotropy"), 0.0), 0.9)
    k = _number(lobe.get("weight", 1.0), where, "weight")
    if not k > 0.0:
        raise _fail(where, f"weight must be > 0, got {k!r}")
    small = radius < BSSRDF_MIN_RADIUS
    split = None
    if small.any():
        split = np.where(small, color, 0.0)
        color = np.where(small, 0.0, color)
        radius = np.where(small, 0.0, radius)
    albedo = np.clip(color / k, 0.0, 1.0)
    row = np.zeros(8)
    row[SSS_RADIUS:SSS_RADIUS + 3] = np.where(small, 0.0, effective_radius(radius, albedo, ior, method))
    row[SSS_G], row[SSS_IOR], row[SSS_METHOD] = g, ior, SSS_METHODS.index(method)
    row[SSS_WEIGHT], row[SSS_ALPHA] = k, r * r
    return row, color, split


def _dielectric_specular_lobe(lobe: dict, where: str) -> np.ndarray:
    """A DIELECTRIC_SPECULAR lobe's (f0·tint r, g, b, multiscatter, eta): ``ior`` (> 0, the IOR
    after Specular IOR Level), ``tint`` (RGB ≥ 0, default white), ``multiscatter`` (bool,
    default true). f0 = ((ior − 1)/(ior + 1))², f0·tint clamped to [0, 1] as Cycles."""
    if "ior" not in lobe:
        raise _fail(where, "ior is missing")
    eta = _number(lobe["ior"], where, "ior")
    if eta <= 0.0:
        raise _fail(where, f"ior must be > 0, got {eta!r}")
    tint = _rgb(lobe.get("tint", [1.0, 1.0, 1.0]), where, "tint")
    ms = lobe.get("multiscatter", True)
    if not isinstance(ms, bool):
        raise _fail(where, f"multiscatter must be true or false, got {ms!r}")
    f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    return np.concatenate([np.clip(f0 * tint, 0.0, 1.0), [1.0 if ms else 0.0, eta]])


def _layer_of(lobes, j: int, where: str) -> int:
    """The file index of the layer lobe j lies under (−1: none), validated: "layer" must name a
    DIELECTRIC_SPECULAR or SHEEN lobe of the same material, and the chain of layers must not
    loop."""
    if "layer" not in lobes[j]:
        return -1
    under = lobes[j]["layer"]
    seen, cur = {j}, under
    while True:
        if isinstance(cur, bool) or not isinstance(cur, int) or not 0 <= cur < len(lobes) \
                or not isinstance(lobes[cur], dict) or lobes[cur].get("type") not in LAYER_TYPES:
            raise _fail(where, f"layer must be the index of a DIELECTRIC_SPECULAR or SHEEN lobe, got {cur!r}")
        if cur in seen:
            raise _fail(where, f"layer chain loops back to lobe {cur}")
        seen.add(cur)
        if "layer" not in lobes[cur]:
            return under
        cur = lobes[cur]["layer"]


def _layer_slot(lobes, under: int, slot_of: dict) -> int:
    """Table slot of the file lobe ``under`` or, if it was dropped, of the nearest kept layer
    above it (−1: none)."""
    while under >= 0 and under not in slot_of:
        under = lobes[under].get("layer", -1)
    return slot_of.get(under, -1) if under >= 0 else -1


def _layer_params(lobe: dict, kind: str, where: str) -> np.ndarray:
    """A lobe's ``lobe_coat`` row (k, tint r, g, b): ``layer_weight`` k (≥ 0, default 1) and,
    for a DIELECTRIC_SPECULAR coat, ``coat_tint`` (RGB ≥ 0, default white); only layer lobes
    (DIELECTRIC_SPECULAR, SHEEN) take them."""
    row = np.ones(4)
    for key in ("layer_weight", "coat_tint"):
        if key in lobe and kind not in (LAYER_TYPES if key == "layer_weight" else ("DIELECTRIC_SPECULAR",)):
            raise _fail(where, f"{key} is only allowed on {' / '.join(LAYER_TYPES)} lobes, not {kind}")
    if "layer_weight" in lobe:
        row[0] = _number(lobe["layer_weight"], where, "layer_weight")
        if row[0] < 0.0:
            raise _fail(where, f"layer_weight must be >= 0, got {row[0]!r}")
    if "coat_tint" in lobe:
        row[1:] = _rgb(lobe["coat_tint"], where, "coat_tint")
    return row


def _metallic_lobe(lobe: dict, where: str) -> np.ndarray:
    """A METALLIC lobe's (F82 tint r, g, b, multiscatter, weight k): ``tint`` (RGB, clamped to
    [0, 1], default white), ``multiscatter`` (default true), ``weight`` (> 0: the lobe's colour
    is weight × base colour; F0 = min(colour / weight, 1))."""
    tint = np.minimum(_rgb(lobe.get("tint", [1.0, 1.0, 1.0]), where, "tint"), 1.0)
    ms = lobe.get("multiscatter", True)
    if not isinstance(ms, bool):
        raise _fail(where, f"multiscatter must be true or false, got {ms!r}")
    if "weight" not in lobe:
        raise _fail(where, "weight is missing")
    k = _number(lobe["weight"], where, "weight")
    if not k > 0.0:
        raise _fail(where, f"weight must be > 0, got {k!r}")
    return np.concatenate([tint, [1.0 if ms else 0.0, k]])


#: ``MaterialTable.sample``'s "no light sample first" (0 rows)
_NO_ROWS = np.zeros((0, 3))


class MaterialTable:
    """All materials of a scene; see the module docstring for the arrays."""

    def __init__(self, names, lobe_type, lobe_color, lobe_alpha, lobe_ior, emission, lobe_sss=None,
                 lobe_fresnel=None, lobe_layer=None, lobe_coat=None, emission_layer=None,
                 lobe_frame=None):
        self.names = list(names)
        self.lobe_type = np.asarray(lobe_type, dtype=np.int8)
        self.lobe_color = np.asarray(lobe_color, dtype=np.float64)
        self.lobe_alpha = np.asarray(lobe_alpha, dtype=np.float64)
        self.lobe_ior = np.asarray(lobe_ior, dtype=np.float64)
        self.emission = np.asarray(emission, dtype=np.float64)
        m, n_slots = self.lobe_type.shape
        used = self.lobe_type != BSDF_NONE
        self.lobe_count = used.sum(axis=1)
        lambert = (self.lobe_type == BSDF_DIFFUSE) | (self.lobe_type == BSDF_TRANSLUCENT) \
            | (self.lobe_type == BSDF_SHEEN) | (self.lobe_type == BSDF_VELVET)
        # a holdout "lobe" is marked delta: never evaluated, and no reason for NEE (so is a
        # COAT_TINT, which only weighs the lobes under it)
        self.lobe_delta = used & ~lambert & (
            (self.lobe_alpha ** 2 <= ALPHA_SQ_SINGULAR)
            | (((self.lobe_type == BSDF_GLASS) | (self.lobe_type == BSDF_REFRACTION))
               & (np.abs(self.lobe_ior - 1.0) < IOR_ONE_EPS))
            | (self.lobe_type == BSDF_HOLDOUT) | (self.lobe_type == BSDF_COAT_TINT))
        sss = used & (self.lobe_type == BSDF_SUBSURFACE)
        self.lobe_sss = np.zeros((m, n_slots, 8)) if lobe_sss is None else np.asarray(lobe_sss, np.float64)
        self.lobe_fresnel = np.zeros((m, n_slots, 5)) if lobe_fresnel is None \
            else np.asarray(lobe_fresnel, np.float64)
        self.lobe_layer = np.full((m, n_slots), -1, np.int64) if lobe_layer is None \
            else np.asarray(lobe_layer, np.int64)
        self.lobe_coat = np.ones((m, n_slots, 4)) if lobe_coat is None else np.asarray(lobe_coat, np.float64)
        self.emission_layer = np.full(m, -1, np.int64) if emission_layer is None \
            else np.asarray(emission_layer, np.int64)
        self.lobe_frame = np.zeros((m, n_slots), np.int64) if lobe_frame is None \
            else np.array(lobe_frame, np.int64)
        # Cycles keeps the diffuse closures on the shading normal and shades the others about
        # its valid-reflection correction; without a diffuse lobe the kernel corrects the
        # shading normal itself (path_stages.shade), so only mixed materials need the frame
        with_diffuse = np.any(self.lobe_type == BSDF_DIFFUSE, axis=1)[:, None] if n_slots else np.zeros((m, 1), bool)
        self.lobe_frame[with_diffuse & np.isin(self.lobe_type, VALID_FRAME_TYPES)
                        & (self.lobe_frame == FRAME_SHADING)] = FRAME_VALID
        # the specular layer's cosine-averaged albedo per unit colour, and the share its lower
        # layers keep on average: lobe selection and the albedo pass use these averages (the
        # per-hit values depend on wo; any selection probability keeps the estimator unbiased)
        eff = np.ones((m, n_slots, 3))
        for i, j in zip(*np.nonzero(used & (self.lobe_type == BSDF_DIELECTRIC_SPECULAR))):
            eff[i, j] = average_albedo(self.lobe_alpha[i, j], self.lobe_ior[i, j],
                                       self.lobe_fresnel[i, j, :3], self.lobe_fresnel[i, j, 3] > 0)
        metal_avg = {}  # (i, j) → a METALLIC lobe's average albedo per channel (lobe selection)
        for i, j in zip(*np.nonzero(used & (self.lobe_type == BSDF_METALLIC))):
            k = max(self.lobe_fresnel[i, j, 4], 1e-12)
            f0 = np.clip(self.lobe_color[i, j] / k, 0.0, 1.0)
            metal_avg[i, j] = metallic_average_albedo(f0, self.lobe_fresnel[i, j, :3])
            eff[i, j] = np.divide(metal_avg[i, j], f0, out=np.ones(3), where=f0 > 0)
        for i, j in zip(*np.nonzero(used & (self.lobe_type == BSDF_SHEEN))):
            eff[i, j] = sheen_average_albedo(self.lobe_alpha[i, j])
        for i, j in zip(*np.nonzero(used & (self.lobe_type == BSDF_VELVET))):
            eff[i, j] = velvet_average_albedo(self.lobe_alpha[i, j])
        eff[used & (self.lobe_type == BSDF_COAT_TINT)] = 0.0  # (reflects nothing; its tint absorbs)
        own = eff.copy()  # a layer's own average albedo (before the layers above scale it)
        for i, j in zip(*np.nonzero(used & (self.lobe_layer >= 0))):
            top, keep = self.lobe_layer[i, j], np.ones(3)
            while top >= 0:  # the chain of layers above: what each lets through, on average
                k = self.lobe_coat[i, top, 0]
                keep = keep * max(1.0 - k * own[i, top].max(), 0.0) * (1.0 + k * (self.lobe_coat[i, top, 1:] - 1.0))
                top = self.lobe_layer[i, top]
            eff[i, j] = own[i, j] * keep if self.lobe_type[i, j] in (BSDF_DIELECTRIC_SPECULAR, BSDF_METALLIC,
                                                                       BSDF_SHEEN) else keep
        # a holdout (or a COAT_TINT) is no BSDF: never selected, no albedo
        eff[used & ((self.lobe_type == BSDF_HOLDOUT) | (self.lobe_type == BSDF_COAT_TINT))] = 0.0
        self.lobe_effective = self.lobe_color * eff if n_slots else self.lobe_color
        w = np.where(used, self.lobe_effective.mean(axis=2), 0.0)
        for i, j in zip(*np.nonzero(used & (self.lobe_type == BSDF_GLASS) & (self.lobe_fresnel[..., 3] > 0))):
            w[i, j] = glass_select_weight(w[i, j], self.lobe_fresnel[i, j, 4], self.lobe_ior[i, j])
        for i, j in zip(*np.nonzero(used & (self.lobe_type == BSDF_METALLIC) & (self.lobe_layer < 0))):
            # k × its average albedo (= the colour × lobe_avg where F0 > 0; a black metal's F82
            # still reflects at grazing angles)
            w[i, j] = self.lobe_fresnel[i, j, 4] * metal_avg[i, j].mean()
        # Cycles's bssrdf_setup: a BSSRDF's sample weight is average(weight) × its channel count
        w = np.where(sss, w * (self.lobe_sss[..., SSS_RADIUS:SSS_RADIUS + 3] > 0).sum(axis=-1), w)
        total = w.sum(axis=1, keepdims=True)
        self.lobe_select = np.divide(w, total, out=np.zeros_like(w), where=total > 0)
        cdf = np.cumsum(self.lobe_select, axis=1)
        cdf[~used] = np.inf
        last = np.maximum(self.lobe_count - 1, 0)
        rows = np.nonzero(self.lobe_count > 0)[0]
        cdf[rows, last[rows]] = 1.0  # rounding must not leave a gap below u_lobe = 1
        self.has_emission = np.any(self.emission > 0.0, axis=1)
        albedo = np.where(used[..., None], self.lobe_effective, 0.0).sum(axis=1) if n_slots \
            else np.zeros((m, 3))
        pure_diffuse = (self.lobe_count == 1) & (self.lobe_type[:, 0] == BSDF_DIFFUSE) \
            if n_slots else np.zeros(m, dtype=bool)

        def c(a, dtype):
            return np.array(a, dtype=dtype, order="C", copy=True)

        self.data = MaterialData(
            lobe_type=c(self.lobe_type, np.int64),
            lobe_color=c(self.lobe_color.reshape(m, n_slots, 3), np.float64),
            lobe_alpha=c(self.lobe_alpha, np.float64),
            lobe_ior=c(self.lobe_ior, np.float64),
            lobe_delta=c(self.lobe_delta, np.bool_),
            lobe_select=c(self.lobe_select, np.float64),
            lobe_cdf=c(cdf, np.float64),
            lobe_count=c(self.lobe_count, np.int64),
            emission=c(self.emission.reshape(m, 3), np.float64),
            has_emission=c(self.has_emission, np.bool_),
            albedo=c(albedo, np.float64),
            delta_only=c(~np.any(used & ~self.lobe_delta & ~sss, axis=1), np.bool_),
            pure_diffuse=c(pure_diffuse, np.bool_),
            transmission_or_delta=c(
                np.any(used & (np.isin(self.lobe_type, TRANSMITTING) | self.lobe_delta | sss)
                       & (self.lobe_type != BSDF_COAT_TINT), axis=1), np.bool_),
            has_diffuse=c(np.any(self.lobe_type == BSDF_DIFFUSE, axis=1), np.bool_),
            summary=c(np.stack(self._summarise_lobes(used), axis=1).reshape(m, 4), np.float64),
            lobe_sss=c(self.lobe_sss.reshape(m, n_slots, 8), np.float64),
            sss_exit=np.array([self.names.index(SSS_EXIT_MATERIAL) if SSS_EXIT_MATERIAL in self.names
                               else -1], np.int64),
            lobe_fresnel=c(self.lobe_fresnel.reshape(m, n_slots, 5), np.float64),
            lobe_layer=c(np.where(used, self.lobe_layer, -1).reshape(m, n_slots), np.int64),
            has_layers=c(self._layer_level(used), np.int64),
            lobe_avg=c(eff.reshape(m, n_slots, 3), np.float64),
            lobe_coat=c(self.lobe_coat.reshape(m, n_slots, 4), np.float64),
            emission_layer=c(self.emission_layer, np.int64),
            lobe_frame=c(np.where(used, self.lobe_frame, FRAME_SHADING).reshape(m, n_slots), np.int64),
            caustic_row=np.zeros(0, np.int64),
        )
        self.has_subsurface = bool(sss.any())

    def _layer_level(self, used):
        """``MaterialData.has_layers`` per material: 0 none, 1 single plain specular layers
        only, 2 coat / sheen / chains / tints."""
        layered = used & (self.lobe_layer >= 0)
        level = np.where(np.any(layered, axis=1), 1, 0)
        for i, j in zip(*np.nonzero(layered)):
            top = self.lobe_layer[i, j]
            if self.lobe_type[i, top] != BSDF_DIELECTRIC_SPECULAR or self.lobe_layer[i, top] >= 0 \
                    or np.any(self.lobe_coat[i, top] != 1.0):
                level[i] = 2
        return level

    def _summarise_lobes(self, used):
        """Per material, what light selection needs to guess where the BSDF is large (see
        `lobe_summary`): weights of the non-delta diffuse, glossy and glass lobes and the
        weight-averaged alpha of the glossy ones."""
        weight = np.where(used & ~self.lobe_delta, self.lobe_effective.mean(axis=2), 0.0) \
            if self.lobe_type.shape[1] else np.zeros(self.lobe_type.shape)
        kd = np.where((self.lobe_type == BSDF_DIFFUSE) | (self.lobe_type == BSDF_SHEEN)
                      | (self.lobe_type == BSDF_VELVET), weight, 0.0).sum(axis=1)
        wg = np.where((self.lobe_type == BSDF_GLOSSY) | (self.lobe_type == BSDF_DIELECTRIC_SPECULAR)
                      | (self.lobe_type == BSDF_METALLIC), weight, 0.0)
        kg = wg.sum(axis=1)
        alpha = np.divide((wg * self.lobe_alpha).sum(axis=1), kg, out=np.ones_like(kg), where=kg > 0)
        kt = np.where(np.isin(self.lobe_type, TRANSMITTING), weight, 0.0).sum(axis=1)
        return kd, kg, alpha, kt

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_scene(cls, materials: list[dict], images=(), attributes=(),
                   caustics: tuple[bool, bool] = (True, True)) -> "MaterialTable":
        """Build from the header's ``materials`` list (scene-format.md). Raises ValueError naming
        the material and field, e.g. ``material 'Glass' lobe 1: ior must be > 0, got -1.0``.
        Roughness is Blender's (alpha = roughness²) and must lie in [0, 1]; a DIFFUSE lobe's
        roughness, if present, is ignored (Lambert only).

        Materials with a (validated, ``drt.scene``) ``program`` are kept in ``program_source``
        with the scene's ``images``, for ``program_data``; their emission, which varies over
        the surface, is not a light for next-event estimation (``has_emission`` False here,
        ``data.has_emission`` True: hits still collect it).

        ``caustics``: Cycles's (Reflective, Refractive) Caustics switches. Either off: every
        material with a lobe they drop gets a twin row after the scene's materials, shaded
        instead of it right after a diffuse bounce (``data.caustic_row``,
        drt.materials.caustics)."""
        if not isinstance(materials, (list, tuple)):
            raise ValueError(f"materials must be a list, got {type(materials).__name__}")
        names, parsed, emissions, em_layers, slots_of = [], [], [], [], []
        twin_of = None
        if not all(caustics):  # Cycles's Caustics switches: each affected material's twin
            materials, twin_of = with_caustics_twins(materials, *caustics)
        for i, mat in enumerate(materials):
            if not isinstance(mat, dict):
                raise ValueError(f"material {i}: must be an object, got {type(mat).__name__}")
            name = mat.get("name", f"#{i}")
            if not isinstance(name, str):
                raise ValueError(f"material {i}: name must be a string, got {name!r}")
            where = f"material {name!r}"
            lobes = mat.get("lobes", [])
            if not isinstance(lobes, (list, tuple)):
                raise _fail(where, f"lobes must be a list, got {type(lobes).__name__}")
            emissions.append(_rgb(mat.get("emission", [0.0, 0.0, 0.0]), where, "emission"))
            em_layer = mat.get("emission_layer", -1)
            if "emission_layer" in mat and (isinstance(em_layer, bool) or not isinstance(em_layer, int)
                                            or not 0 <= em_layer < len(lobes) or not isinstance(lobes[em_layer], dict)
                                            or lobes[em_layer].get("type") not in LAYER_TYPES):
                raise _fail(where, f"emission_layer must be the index of a DIELECTRIC_SPECULAR or SHEEN lobe, "
                                   f"got {em_layer!r}")
            rows, extra, slot_of = [], [], {}
            for j, lobe in enumerate(lobes):
                lw = f"{where} lobe {j}"
                if not isinstance(lobe, dict):
                    raise _fail(lw, f"must be an object, got {type(lobe).__name__}")
                kind = lobe.get("type")
                if kind not in BSDF_TYPES:
                    raise _fail(lw, f"type must be one of {sorted(BSDF_TYPES)}, got {kind!r}")
                if "color" not in lobe:
                    raise _fail(lw, "color is missing")
                color = _rgb(lobe["color"], lw, "color")
                alpha, ior = 0.0, 1.0
                fr = np.zeros(5)
                if kind in ("GLOSSY", "GLASS", "DIELECTRIC_SPECULAR", "METALLIC", "REFRACTION", "SHEEN", "VELVET"):
                    if "roughness" not in lobe:
                        raise _fail(lw, "roughness is missing")
                    r = _number(lobe["roughness"], lw, "roughness")
                    if not 0.0 <= r <= 1.0:
                        raise _fail(lw, f"roughness must be in [0, 1], got {r!r}")
                    alpha = r * r
                if kind == "DIELECTRIC_SPECULAR":
                    fr = _dielectric_specular_lobe(lobe, lw)
                    ior = fr[4]
                    fr[4] = 0.0
                if kind == "METALLIC":
                    fr = _metallic_lobe(lobe, lw)
                under = _layer_of(lobes, j, lw)
                coat = _layer_params(lobe, kind, lw)
                frame = FRAMES.get(lobe.get("frame"), FRAME_SHADING)
                if "frame" in lobe and (lobe["frame"] not in FRAMES or (kind, lobe["frame"]) not in (
                        ("DIELECTRIC_SPECULAR", "COAT"), ("SHEEN", "SHEEN"))):
                    raise _fail(lw, f"frame must be COAT on a DIELECTRIC_SPECULAR or SHEEN on a SHEEN "
                                    f"lobe, got {lobe['frame']!r} on {kind}")
                if kind == "GLASS" and "reflection_weight" in lobe:
                    # a Principled transmission: reflection × this weight, refraction × colour
                    k = _number(lobe["reflection_weight"], lw, "reflection_weight")
                    if k < 0.0:
                        raise _fail(lw, f"reflection_weight must be >= 0, got {k!r}")
                    fr[3], fr[4] = 1.0, k
                if kind in ("GLASS", "GLOSSY") and "multiscatter_tint" in lobe:
                    # Cycles's Multiscatter GGX glass / glossy: Fss of its energy compensation
                    fr[:3] = np.clip(_rgb(lobe["multiscatter_tint"], lw, "multiscatter_tint"), 0.0, 1.0)
                if kind in ("GLASS", "REFRACTION"):
                    if "ior" not in lobe:
                        raise _fail(lw, "ior is missing")
                    ior = _number(lobe["ior"], lw, "ior")
                    if ior <= 0.0:
                        raise _fail(lw, f"ior must be > 0, got {ior!r}")
                sss = np.zeros(8)
                if kind == "SUBSURFACE":
                    sss, color, split = _subsurface_lobe(lobe, color, lw)
                    if split is not None and split.mean() >= CLOSURE_WEIGHT_CUTOFF:
                        extra.append((BSDF_DIFFUSE, split, 0.0, 1.0, np.zeros(8), fr, under, np.ones(4),
                                      FRAME_SHADING))
                    if not np.any(sss[SSS_RADIUS:SSS_RADIUS + 3] > 0):
                        continue  # every channel became Lambert
                # (a Principled glass's reflection and a metal's Fresnel are weighted by k, not by
                # the colour: a black glass or metal still reflects)
                weight = max(color.mean(), fr[4]) if (kind == "GLASS" and fr[3] > 0) or kind == "METALLIC" \
                    else color.mean()
                code = BSDF_TYPES[kind]
                if kind == "DIELECTRIC_SPECULAR" and lobe.get(TINT_ONLY):  # (drt.materials.caustics)
                    code, weight = BSDF_COAT_TINT, 1.0
                if weight >= CLOSURE_WEIGHT_CUTOFF:
                    slot_of[j] = len(rows)
                    rows.append((code, color, alpha, ior, sss, fr, under, coat, frame))
            # Lambert lobes split off SSS channels go last: program registers address the
            # slots of the file's own lobes
            rows += extra
            # "layer" names a lobe of the file; the table needs its slot (a dropped, black layer
            # passes its lobes on to the layer above it; −1 if none is left)
            rows = [r[:6] + (_layer_slot(lobes, r[6], slot_of),) + r[7:] for r in rows]
            em_layers.append(_layer_slot(lobes, em_layer, slot_of))
            names.append(name)
            parsed.append(rows)
            slots_of.append(slot_of)
        if any(r[0] == BSDF_SUBSURFACE for rows in parsed for r in rows):
            # SSS exit points are shaded by a white Lambert (Cycles's subsurface_shader_data_setup)
            names.append(SSS_EXIT_MATERIAL)
            parsed.append([(BSDF_DIFFUSE, np.ones(3), 0.0, 1.0, np.zeros(8), np.zeros(5), -1, np.ones(4),
                            FRAME_SHADING)])
            emissions.append(np.zeros(3))
            em_layers.append(-1)
        m = len(parsed)
        n_slots = max((len(r) for r in parsed), default=0)
        lobe_type = np.zeros((m, n_slots), np.int8)
        lobe_color = np.zeros((m, n_slots, 3))
        lobe_alpha = np.zeros((m, n_slots))
        lobe_ior = np.ones((m, n_slots))
        lobe_sss = np.zeros((m, n_slots, 8))
        lobe_fresnel = np.zeros((m, n_slots, 5))
        lobe_layer = np.full((m, n_slots), -1, np.int64)
        lobe_coat = np.ones((m, n_slots, 4))
        lobe_frame = np.zeros((m, n_slots), np.int64)
        for i, rows in enumerate(parsed):
            for j, (t, c, a, eta, ss, fr, under, coat, frame) in enumerate(rows):
                lobe_type[i, j], lobe_color[i, j], lobe_alpha[i, j], lobe_ior[i, j] = t, c, a, eta
                lobe_sss[i, j], lobe_fresnel[i, j], lobe_layer[i, j] = ss, fr, under
                lobe_coat[i, j], lobe_frame[i, j] = coat, frame
        emission = np.array(emissions).reshape(m, 3)
        table = cls(names, lobe_type, lobe_color, lobe_alpha, lobe_ior, emission, lobe_sss,
                    lobe_fresnel, lobe_layer, lobe_coat, np.array(em_layers, np.int64).reshape(m),
                    lobe_frame)
        table.lobe_slot_of = slots_of + [{0: 0}] * (m - len(slots_of))  # (file lobe → slot; the SSS exit row)
        if twin_of is not None:
            table.data = table.data._replace(caustic_row=np.concatenate(
                [twin_of, np.full(m - len(twin_of), -1, np.int64)]))
        table.program_source = None
        table.images = list(images)  # a world program may read them without any material program
        for i, mat in enumerate(materials):
            if isinstance(mat, dict) and mat.get("light") is False and table.has_emission[i]:
                # Emission Sampling None: not a light for NEE; hits still collect the emission
                table.has_emission[i] = False
                table.data.has_emission[i] = True
        for i, mat in enumerate(materials):  # a per-hit k / tint: never the scalar fast path
            if table.data.has_layers[i] and any(isinstance(lb, dict) and ("layer_weight_reg" in lb or "coat_tint_reg" in lb)
                                                for lb in mat.get("lobes", [])):
                table.data.has_layers[i] = 2
        if any(isinstance(mat, dict) and mat.get("program") for mat in materials):
            table.program_source = (list(materials), list(images), list(attributes))
            for i, mat in enumerate(materials):
                if mat.get("program") and mat.get("emission_reg") is not None:
                    table.has_emission[i] = False
                    table.data.has_emission[i] = True
        return table

    def program_data(self, uv=None, corner_attrs=None, origin=None, object_of=None, object_info=None,
                     positions=None, triangles=None, footprint=None, camera=None, world=None):
        """The ``ProgramData`` of this scene's material programs (geometry inputs: the global
        per-triangle uv (T, 3, 2) and ``corner_attrs`` of ``SceneGeometry``) and of the
        validated ``world`` program if given (appended last, ``world_program_index``);
        zero-size arrays when there is no program at all."""
        from .program_format import build_program_data, empty_program_data

        src = getattr(self, "program_source", None)
        if src is None and world is None:
            return empty_program_data()
        if src is None:  # only the world has a program: no geometry inputs are read
            return build_program_data([{}] * len(self.names), self, getattr(self, "images", []),
                                      None, None, None, origin=origin,
                                      camera=camera, footprint=footprint, world=world)
        attrs = corner_attrs or {}
        named = None
        n_named = len(src[2]) if len(src) > 2 else 0
        if n_named:
            t = len(uv) if uv is not None else max((len(a) for a in attrs.values()), default=0)
            if t:  # else no triangle has any attribute: the programs read zeros
                named = np.zeros((n_named, t, 3, 3), np.float32)
                for i in range(n_named):
                    if f"attr{i}" in attrs:
                        named[i] = attrs[f"attr{i}"]
        return build_program_data(src[0], self, src[1], uv, attrs.get("generated"),
                                  attrs.get("object_coords"), named, origin,
                                  object_of, object_info, positions, triangles, footprint, camera, world)

    # ------------------------------------------------------------------ queries
    def _mat_rows(self, mat) -> np.ndarray:
        """mat as (n,) contiguous int64 in [0, M), negative indices wrapped as numpy does; an index
        out of range raises IndexError (the kernels do not check bounds)."""
        mat = np.array(mat, dtype=np.int64, order="C", copy=True).reshape(-1)
        m = len(self.names)
        if mat.size and (mat.min() < -m or mat.max() >= m):
            raise IndexError(f"material index out of range for {m} materials")
        if mat.size and mat.min() < 0:
            mat[mat < 0] += m
        return mat

    def albedo(self, mat: np.ndarray) -> np.ndarray:
        """mat (n,) int; returns (n, 3) the sum of the lobe colours (for the albedo pass)."""
        return self.data.albedo[np.asarray(mat, dtype=np.intp)]

    def lobe_summary(self, mat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """mat (n,) int (−1: none); (kd, kg, alpha, kt), each (n,): the summed average colour of the
        material's diffuse, glossy and glass lobes (delta lobes excluded: next-event estimation
        cannot reach them) and the colour-weighted GGX alpha of its glossy lobes (1 if none).
        A rough description for light selection (`drt.lights.selection`), not for shading."""
        mat = np.asarray(mat, dtype=np.intp)
        summary = self.data.summary
        known = (mat >= 0) & (mat < len(self.names))
        if known.all():
            return tuple(summary[mat, k] for k in range(4))
        # no material (camera rays, an empty table): nothing is known, all zero
        if not len(summary):
            return tuple(np.zeros(len(mat)) for _ in range(4))
        safe = np.where(known, mat, 0)
        return tuple(np.where(known, summary[safe, k], 0.0) for k in range(4))

    def is_delta_only(self, mat: np.ndarray) -> np.ndarray:
        """mat (n,) int; (n,) bool: no lobe can be evaluated, so no NEE (also True for
        materials without lobes)."""
        return self.data.delta_only[np.asarray(mat, dtype=np.intp)]

    def has_transmission_or_delta(self, mat: np.ndarray) -> np.ndarray:
        """mat (n,) int; (n,) bool: a glass lobe or a mirror-like (delta) lobe is present, so
        only the material's own sampling reaches all of its directions."""
        return self.data.transmission_or_delta[np.asarray(mat, dtype=np.intp)]

    def has_diffuse(self, mat: np.ndarray) -> np.ndarray:
        """mat (n,) int; (n,) bool: the material has a diffuse lobe."""
        return self.data.has_diffuse[np.asarray(mat, dtype=np.intp)]

    @staticmethod
    def _coat_rows(coat_normal, n: int) -> np.ndarray:
        """(n, 3) rows of the coat normal (NO_BUMP when None)."""
        return np.ascontiguousarray(np.broadcast_to(np.asarray(NO_BUMP if coat_normal is None else coat_normal,
                                                               np.float64), (n, 3)))

    def eval(self, mat: np.ndarray, wo: np.ndarray,
             wi: np.ndarray, coat_normal=None, blur: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """mat (n,) int; wo, wi (n, 3) local unit vectors. Returns (f·|cos θi| (n, 3) summed over
        the non-delta lobes, pdf (n,) per unit solid angle of wi, Σ p_l pdf_l, exactly what
        sample() reports for a non-delta sample). Applies ``bsdf_eval`` to each row;
        ``coat_normal``: a local unit 3-vector the lobes with a ``lobe_frame`` are shaded about
        (``bsdf_eval_bump``'s nc_local; default the frame's z); ``blur``: a Filter Glossy
        alpha (``filtered_alpha``; 0: none)."""
        mat = self._mat_rows(mat)
        n = mat.shape[0]
        f = np.empty((n, 3))
        pdf = np.empty(n)
        _eval_rows(self.data, mat, vec3_rows(wo), vec3_rows(wi), self._coat_rows(coat_normal, n), float(blur),
                   f, pdf)
        return f, pdf

    def sample(self, mat: np.ndarray, wo: np.ndarray, u_lobe: np.ndarray,
               u2: np.ndarray, coat_normal=None, light_wi=None, blur: float = 0.0) -> BSDFSample:
        """mat (n,) int; wo (n, 3) local; u_lobe (n,) in [0, 1) picks the lobe (and, rescaled
        inside the picked interval, glass's reflect/refract choice); u2 (n, 2) in [0, 1)² picks
        the direction. See BSDFSample and the module docstring for weight and pdf. Applies
        ``bsdf_sample`` to each row; wi is 0 in rows where no lobe could be sampled.
        ``coat_normal`` as in ``eval``. ``light_wi`` (n, 3): as the integrator does, evaluate
        each row at this direction first (a light sample) and pick the lobe from the weights
        that evaluation computed (``bsdf_eval_weights``): the same samples, bit for bit.
        ``blur`` as in ``eval``."""
        mat = self._mat_rows(mat)
        n = mat.shape[0]
        wi = np.empty((n, 3))
        weight = np.empty((n, 3))
        pdf = np.empty(n)
        kind = np.empty(n, np.int8)
        is_delta = np.empty(n, bool)
        valid = np.empty(n, bool)
        _sample_rows(self.data, mat, vec3_rows(wo), scalar_rows(u_lobe, n),
                     f64_array(u2).reshape(n, 2), self._coat_rows(coat_normal, n),
                     _NO_ROWS if light_wi is None else vec3_rows(light_wi), float(blur),
                     wi, weight, pdf, kind, is_delta, valid)
        return BSDFSample(wi, weight, pdf, kind, is_delta, valid)
