"""drt.lights against the measured Cycles radiometry (shared blender-conventions.md, Lights table),
closed forms, and self-consistency of sample() / intersect() / pdf (MIS needs them to agree).

Irradiance checks: a white Lambert plane (albedo 1) at the origin facing +Z, outgoing radiance
E/π with E = ∫ L cos dω estimated from LightSet.sample.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from stats_util import assert_within_ci, chi2_test_sphere, mean_ci

from drt.lights import EmissiveTriangles, LightSet

N = 100_000


def translate(x=0.0, y=0.0, z=0.0, rot_x=0.0, scale=(1.0, 1.0, 1.0)):
    """Blender matrix_world: rotation about X by rot_x (radians), then translation."""
    c, s = math.cos(rot_x), math.sin(rot_x)
    r = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ np.diag(scale)
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = (x, y, z)
    return m.tolist()


def plane_radiance_samples(ls, p=(0.0, 0.0, 0.0), n=(0.0, 0.0, 1.0), count=N, seed=1):
    """Per-sample estimates of the outgoing radiance E/π of a white Lambert plane at p."""
    rng = np.random.default_rng(seed)
    P = np.tile(np.asarray(p, float), (count, 1))
    Nn = np.tile(np.asarray(n, float), (count, 1))
    s = ls.sample(P, Nn, rng.random(count), rng.random((count, 2)))
    cos = np.maximum((s.wi * Nn).sum(axis=1), 0.0)
    safe = np.where(s.valid, s.pdf, 1.0)
    return np.where(s.valid, s.radiance[:, 0] * cos / safe, 0.0) / math.pi


def emissive_quad(z=2.0, size=1.0, radiance=10.0, facing_down=True, ids=(7, 8)):
    h = 0.5 * size
    a, b, c, d = (np.array([x, y, z]) for x, y in ((-h, -h), (h, -h), (h, h), (-h, h)))
    tris = [(a, c, b), (a, d, c)] if facing_down else [(a, b, c), (a, c, d)]
    return EmissiveTriangles(np.array(tris, float), np.full((2, 3), radiance), np.array(ids))


# ---------------------------------------------------------------------------------------------
# The conventions table: light 2 m above the plane (unless stated), P = 100 W
# (label, light dict, shading point, normal, pred., Cycles)
_C60, _S60 = math.cos(math.pi / 3), math.sin(math.pi / 3)
TABLE = [
    ("point r=0", dict(type="POINT", matrix_world=translate(z=2), power=100, radius=0.0),
     (0, 0, 0), 0.63326, 0.63325),
    ("sphere r=0.5 d=0.7", dict(type="POINT", matrix_world=translate(z=0.7), power=100, radius=0.5,
                                soft_falloff=False), (0, 0, 0), 5.16945, 5.16922),
    ("soft r=0.5 d=2", dict(type="POINT", matrix_world=translate(z=2), power=100, radius=0.5,
                            soft_falloff=True), (0, 0, 0), 0.59601, 0.59601),
    ("soft r=0.5 d=0.7", dict(type="POINT", matrix_world=translate(z=0.7), power=100, radius=0.5,
                              soft_falloff=True), (0, 0, 0), 3.42271, 3.42271),
    *[(f"spot θ={th}°", dict(type="SPOT", matrix_world=translate(z=2), power=100, radius=0.0,
                             spot_size=math.pi / 2, spot_blend=0.5),
       (2 * math.tan(math.radians(th)), 0, 0), pred, pred)
      for th, pred in ((20, 0.52546), (30, 0.41131), (40, 0.10121))],
    ("area square 1", dict(type="AREA", matrix_world=translate(z=2), power=100, shape="SQUARE",
                           size=1.0), (0, 0, 0), 2.33887, 2.33892),
    ("area rect 2x0.5", dict(type="AREA", matrix_world=translate(z=2), power=100,
                             shape="RECTANGLE", size=2.0, size_y=0.5), (0, 0, 0), 2.16661, 2.16654),
    ("area disk 1", dict(type="AREA", matrix_world=translate(z=2), power=100, shape="DISK",
                         size=1.0), (0, 0, 0), 2.38403, 2.38399),
    ("area ellipse 2x0.5", dict(type="AREA", matrix_world=translate(z=2), power=100,
                                shape="ELLIPSE", size=2.0, size_y=0.5), (0, 0, 0), 2.24811, 2.24807),
    ("area spread 90°", dict(type="AREA", matrix_world=translate(z=2), power=100, shape="SQUARE",
                             size=1.0, spread=math.pi / 2), (0, 0, 0), 8.85174, 8.85177),
    ("sun normal", dict(type="SUN", matrix_world=translate(), strength=3.0, angle=0.00918),
     (0, 0, 0), 0.95493, 0.95493),
    ("sun 60°", dict(type="SUN", matrix_world=translate(rot_x=math.pi / 3), strength=3.0,
                     angle=0.00918), (0, 0, 0), 0.47746, 0.47746),
]


@pytest.mark.parametrize("label,light,p,pred,cycles", TABLE, ids=[t[0] for t in TABLE])
def test_conventions_table(label, light, p, pred, cycles):
    est = plane_radiance_samples(LightSet([light], (0, 0, 0), None), p=p)
    # atol: the table prints 5 significant digits (zero-variance delta lights hit it exactly)
    assert_within_ci(est, pred, k=4.0, atol=6e-6, label=label)
    mean, _ = mean_ci(est)
    assert abs(mean - cycles) <= 0.005 * cycles, (label, mean, cycles)


@pytest.mark.parametrize("facing_down", [True, False])
def test_emissive_quad_two_sided(facing_down):
    # 1×1 quad, strength 10, 2 m above: Lambert's polygon formula 0.73478, Cycles 0.73480 —
    # and Cycles gives the same (0.73475) when the quad faces away: emission is two-sided.
    ls = LightSet([], (0, 0, 0), emissive_quad(facing_down=facing_down))
    est = plane_radiance_samples(ls)
    assert_within_ci(est, 0.73478, k=4.0)
    assert abs(est.mean() - 0.73480) <= 0.005 * 0.73480


# ---------------------------------------------------------------------------------------------
def lambert_polygon_irradiance(p, n, corners, radiance):
    """E = L/2 · |Σ γ_i n·(v_i × v_{i+1})/|v_i × v_{i+1}||, polygon fully above the horizon."""
    v = corners - p
    v /= np.linalg.norm(v, axis=1)[:, None]
    total = 0.0
    for i in range(len(v)):
        a, b = v[i], v[(i + 1) % len(v)]
        cr = np.cross(a, b)
        total += math.acos(np.clip(a @ b, -1, 1)) * (n @ cr) / np.linalg.norm(cr)
    return 0.5 * radiance * abs(total)


def test_rectangle_matches_lambert_polygon_formula():
    # tilted, scaled, off-axis rectangle (solid-angle sampling) vs the closed form
    light = dict(type="AREA", matrix_world=translate(0.7, -0.3, 1.5, rot_x=0.5, scale=(1.5, 0.8, 1)),
                 power=60.0, shape="RECTANGLE", size=1.0, size_y=0.7)
    ls = LightSet([light], (0, 0, 0), None)
    area = ls.lights[0]
    hx, hy = 0.5 * area.len_x * area.ex, 0.5 * area.len_y * area.ey
    corners = np.array([area.center + sx * hx + sy * hy for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    n = np.array([0.0, 0.2, 1.0]) / math.hypot(0.2, 1.0)
    expected = lambert_polygon_irradiance(np.zeros(3), n, corners, area.radiance[0]) / math.pi
    est = plane_radiance_samples(ls, n=n)
    assert_within_ci(est, expected, k=4.0)
    assert abs(est.mean() - expected) < 2e-3 * expected


def test_point_inverse_square_law():
    for d in (0.5, 1.0, 2.0, 4.0, 8.0):
        ls = LightSet([dict(type="POINT", matrix_world=translate(z=d), power=100, radius=0.0)],
                      (0, 0, 0), None)
        est = plane_radiance_samples(ls, count=16)
        assert np.allclose(est, 100 / (4 * math.pi) / d ** 2 / math.pi, rtol=1e-12)


def test_world_irradiance_and_pdf():
    ls = LightSet([], (0.5, 0.5, 0.5), None)
    est = plane_radiance_samples(ls, count=20_000)
    assert np.allclose(est.mean(), 0.5, rtol=1e-9)                  # cosine sampling: exact
    rng = np.random.default_rng(3)
    p = rng.normal(size=(1000, 3))
    n = np.tile([0.0, 0.0, 1.0], (1000, 1))
    s = ls.sample(p, n, rng.random(1000), rng.random((1000, 2)))
    assert np.allclose(ls.world_pdf(p, n, s.wi), s.pdf)
    s = ls.sample(p, None, rng.random(1000), rng.random((1000, 2)))
    assert np.allclose(s.pdf, 1 / (4 * math.pi)) and np.allclose(ls.world_pdf(p, None, s.wi), s.pdf)


# ---------------------------------------------------------------------------------------------
SHAPES = {
    "sphere": dict(type="POINT", matrix_world=translate(0.2, 0.1, 2.0), power=50, radius=0.6,
                   soft_falloff=False),
    "soft disk": dict(type="POINT", matrix_world=translate(0.2, 0.1, 2.0), power=50, radius=0.6,
                      soft_falloff=True),
    "spot sphere": dict(type="SPOT", matrix_world=translate(0.0, 0.0, 2.0), power=50, radius=0.3,
                        soft_falloff=False, spot_size=2.0, spot_blend=0.3),
    "rect": dict(type="AREA", matrix_world=translate(0.3, 0.2, 1.8, rot_x=0.4, scale=(1.2, 1, 1)),
                 power=80, shape="RECTANGLE", size=1.0, size_y=0.6),
    "rect spread": dict(type="AREA", matrix_world=translate(0.3, 0.2, 1.8, rot_x=0.4), power=80,
                        shape="RECTANGLE", size=1.0, size_y=0.6, spread=1.2),
    "disk": dict(type="AREA", matrix_world=translate(0.1, -0.2, 1.5, rot_x=-0.3), power=80,
                 shape="DISK", size=1.2),
    "ellipse": dict(type="AREA", matrix_world=translate(0.1, -0.2, 1.5, rot_x=-0.3), power=80,
                    shape="ELLIPSE", size=1.2, size_y=0.5),
}


@pytest.mark.parametrize("name", list(SHAPES))
def test_intersect_agrees_with_sample(name):
    ls = LightSet([SHAPES[name]], (0, 0, 0), None)
    rng = np.random.default_rng(5)
    m = 4000
    p = rng.uniform(-1.0, 1.0, size=(m, 3)) * [1.0, 1.0, 0.3]
    s = ls.sample(p, None, rng.random(m), rng.random((m, 2)))
    assert s.valid.mean() > 0.3
    v = s.valid
    hit = ls.intersect(p[v], s.wi[v], np.inf)
    assert hit.hit.all() and (hit.light == 0).all()
    assert np.allclose(hit.t, s.dist[v], rtol=1e-7, atol=1e-9)
    assert np.allclose(hit.pdf, s.pdf[v], rtol=1e-6)
    assert np.allclose(hit.radiance, s.radiance[v], rtol=1e-6)
    # a closer blocker hides the light
    assert not ls.intersect(p[v], s.wi[v], s.dist[v] * 0.999).hit.any()


def _local_dirs(ls, p, axis):
    """sample_fn and pdf_fn in a frame whose +z is `axis` (for stats_util.chi2_test_sphere)."""
    from drt.sampling.warps import build_frame
    z = np.asarray(axis, float) / np.linalg.norm(axis)
    t, b = (v[0] for v in build_frame(z[None, :]))
    rot = np.stack([t, b, z])                                       # world → local

    def sample_fn(u):
        m = len(u)
        P = np.tile(p, (m, 1))
        s = ls.sample(P, None, np.zeros(m), u)
        return s.wi @ rot.T, s.valid

    def pdf_fn(d):
        P = np.tile(p, (len(d), 1))
        h = ls.intersect(P, d @ rot, np.inf)
        return np.where(h.hit, h.pdf, 0.0)
    return sample_fn, pdf_fn


@pytest.mark.parametrize("name,theta_max", [("sphere", 0.35), ("rect", 0.55), ("disk", 0.6),
                                            ("soft disk", 0.35)])
def test_chi2_directions(name, theta_max):
    ls = LightSet([SHAPES[name]], (0, 0, 0), None)
    p = np.array([0.05, -0.1, 0.0])
    center = np.asarray(SHAPES[name]["matrix_world"])[:3, 3]
    sample_fn, pdf_fn = _local_dirs(ls, p, center - p)
    pval = chi2_test_sphere(sample_fn, pdf_fn, n_samples=60_000, bins_theta=12, bins_phi=24,
                            theta_max=theta_max, resolution=8, refine=4)
    assert pval > 0.01, (name, pval)


def test_rect_solid_angle_sampling_is_uniform():
    # spherical-rectangle sampling has a constant pdf = 1/Ω; Ω from Lambert-free geometry:
    # a centred square of side a at height h subtends 4·asin(a²/(a² + 4h²))
    ls = LightSet([dict(type="AREA", matrix_world=translate(z=2), power=1, size=1.0)], (0, 0, 0), None)
    s = ls.sample(np.zeros((100, 3)), None, np.zeros(100), np.random.default_rng(0).random((100, 2)))
    omega = 4 * math.asin(1 / (1 + 16))
    assert np.allclose(s.pdf, 1 / omega, rtol=1e-9)


@pytest.mark.parametrize("h", [0.05, 2.0, 300.0, 2000.0])
def test_rect_solid_angle_is_exact_near_and_far(h):
    # the solid angle (one atan2 over two Van Oosterom–Strackee triangles) against the closed
    # form for a centred square, 4·asin(a²/(a² + 4h²)), to 1e-12 from 50 mm to 2 km away (Ω
    # from 6.1 sr down to 2.5e-7 sr; Ureña's four-acos sum lost ~1e-9 relative at 1e-6 sr)
    ls = LightSet([dict(type="AREA", matrix_world=translate(z=h), power=1, size=1.0)], (0, 0, 0), None)
    s = ls.sample(np.zeros((16, 3)), None, np.zeros(16), np.random.default_rng(1).random((16, 2)))
    omega = 4 * math.asin(1 / (1 + 4 * h * h))
    assert s.valid.all()
    np.testing.assert_allclose(s.pdf, 1 / omega, rtol=1e-12)
    # the sampled directions land on the square (Ureña's inversion with k from the angle sum)
    hit = ls.intersect(np.zeros((16, 3)), s.wi, np.inf)
    assert hit.hit.all()
    np.testing.assert_allclose(hit.pdf, s.pdf, rtol=1e-12)


def _urena_point(corner, ex, ey, o, u, v):
    """Ureña, Fajardo and King's sampler as the paper writes it (SphQuadInit / SphQuadSample:
    four acos, cu clamped, the point o + xu·x + yv·y + z0·z), for one point and one (u, v)."""
    exl, eyl = np.linalg.norm(ex), np.linalg.norm(ey)
    x, y = ex / exl, ey / eyl
    z = np.cross(x, y)
    d = corner - o
    z0 = d @ z
    if z0 > 0:
        z, z0 = -z, -z0
    x0, y0 = d @ x, d @ y
    x1, y1 = x0 + exl, y0 + eyl
    v00, v01, v10, v11 = (np.array(c) for c in ((x0, y0, z0), (x0, y1, z0), (x1, y0, z0), (x1, y1, z0)))
    unit = lambda a: a / np.linalg.norm(a)  # noqa: E731
    n0, n1 = unit(np.cross(v00, v10)), unit(np.cross(v10, v11))
    n2, n3 = unit(np.cross(v11, v01)), unit(np.cross(v01, v00))
    g0, g1 = math.acos(-(n0 @ n1)), math.acos(-(n1 @ n2))
    g2, g3 = math.acos(-(n2 @ n3)), math.acos(-(n3 @ n0))
    b0, b1 = n0[2], n2[2]
    k = 2 * math.pi - g2 - g3
    au = u * (g0 + g1 - k) + k
    fu = (math.cos(au) * b0 - b1) / math.sin(au)
    cu = min(max((1.0 if fu > 0 else -1.0) / math.sqrt(fu * fu + b0 * b0), -1.0), 1.0)
    xu = min(max(-(cu * z0) / math.sqrt(1 - cu * cu), x0), x1)
    dd = math.sqrt(xu * xu + z0 * z0)
    h0, h1 = y0 / math.sqrt(dd * dd + y0 * y0), y1 / math.sqrt(dd * dd + y1 * y1)
    hv = h0 + v * (h1 - h0)
    yv = hv * dd / math.sqrt(1 - hv * hv) if hv * hv < 1 - 1e-12 else y1
    return o + xu * x + yv * y + z0 * z


def test_rect_sampling_follows_the_paper():
    # drt's sampler folds the paper's roots and divisions and never forms the point: the same
    # direction and distance as the paper's point, over points near and far, and (u, v) up to
    # the rectangle's corners
    from drt.lights.area import AreaLight
    light = SHAPES["rect"]
    a = AreaLight(light)
    ls = LightSet([light], (0, 0, 0), None)
    rng = np.random.default_rng(7)
    m = 600
    p = a.center + (rng.uniform(-1, 1, (m, 3)) + [0, 0, 0]) * np.exp(rng.uniform(-3, 3, (m, 1)))
    uv = rng.random((m, 2))
    uv[:8] = [[0, 0], [0, 1 - 1e-16], [1 - 1e-16, 0], [1 - 1e-16, 1 - 1e-16], [0.5, 0], [0, 0.5],
              [0.5, 1 - 1e-16], [1 - 1e-16, 0.5]]
    s = ls.sample(p, None, np.zeros(m), uv)
    front = (p - a.center) @ a.normal > 0
    assert s.valid[front].all() and not s.valid[~front].any()
    for i in np.flatnonzero(front):
        q = _urena_point(a.corner, a.len_x * a.ex, a.len_y * a.ey, p[i], *uv[i])
        dist = np.linalg.norm(q - p[i])
        np.testing.assert_allclose(s.wi[i], (q - p[i]) / dist, rtol=0, atol=1e-9)
        np.testing.assert_allclose(s.dist[i], dist, rtol=1e-9)


@pytest.mark.parametrize("distance", [0.5, 40.0, 3000.0])
def test_shape_tests_keep_their_edges(distance):
    # the shape tests take no root and no division for a miss (drt.lights.point / area): rays
    # aimed 1e-6 inside and outside a soft point light's facing disk and a rectangle's edges hit
    # and miss, with the distance of the plane they hit, near and far
    from drt.lights.area import AreaLight
    r = 0.25
    soft = dict(type="POINT", matrix_world=translate(0.3, -0.2, 1.0), power=50, radius=r,
                soft_falloff=True)
    rect = SHAPES["rect"]
    rng = np.random.default_rng(3)
    for light in (soft, rect):
        ls = LightSet([light], (0, 0, 0), None)
        center = np.asarray(light["matrix_world"])[:3, 3]
        if light is rect:
            a = AreaLight(light)
            o = center + a.normal * distance + rng.normal(size=3) * 0.1 * distance * [1, 1, 0]
            # points on the edges' midlines, a little inside and outside
            edge = [a.ex * a.len_x / 2, -a.ex * a.len_x / 2, a.ey * a.len_y / 2, -a.ey * a.len_y / 2]
            plane_n = a.normal
        else:
            o = center + distance * np.array([0.6, 0.0, 0.8])
            plane_n = (o - center) / np.linalg.norm(o - center)
            u = np.cross(plane_n, [0.0, 1.0, 0.0])
            u /= np.linalg.norm(u)
            v = np.cross(plane_n, u)
            edge = [r * u, -r * u, r * v, r * (u + v) / math.sqrt(2)]
        for e in edge:
            for scale, expect in ((1 - 1e-6, True), (1 + 1e-6, False)):
                q = center + scale * e
                d = (q - o) / np.linalg.norm(q - o)
                h = ls.intersect(o[None, :], d[None, :], np.inf)
                assert bool(h.hit[0]) == expect, (light["type"], distance, scale)
                if expect:
                    t_plane = ((center - o) @ plane_n) / (d @ plane_n)
                    assert h.t[0] == pytest.approx(t_plane, rel=1e-12)


def test_area_back_side_is_dark_and_transparent():
    """Cycles: seen from behind an area light does not exist (a camera looking at the back of a
    visible area light sees the lit floor behind it: measured 1.036 at the centre pixel, bpy
    5.0.1), so rays pass through."""
    ls = LightSet([SHAPES["rect"]], (0, 0, 0), None)
    p = np.array([[0.3, 0.2, 4.0]] * 100)                            # above: behind the emitter
    s = ls.sample(p, None, np.zeros(100), np.random.default_rng(1).random((100, 2)))
    assert not s.valid.any()
    h = ls.intersect(p, np.tile([0.0, 0.0, -1.0], (100, 1)), np.inf)
    assert not h.hit.any()
    below = np.array([[0.3, 0.2, 0.0]] * 100)
    front = ls.intersect(below, np.tile([0.0, 0.0, 1.0], (100, 1)), np.inf)
    assert front.hit.all() and np.all(front.radiance > 0.0)


def test_emissive_pdf_agrees_with_sample():
    tris = emissive_quad(z=1.0, ids=(40, 3))
    ls = LightSet([dict(type="POINT", matrix_world=translate(z=3), power=10, radius=0.0)],
                  (0.1, 0.1, 0.1), tris)
    rng = np.random.default_rng(2)
    m = 20_000
    p = rng.uniform(-1, 1, size=(m, 3)) * [1, 1, 0.2]
    s = ls.sample(p, None, rng.random(m), rng.random((m, 2)))
    em = s.light == ls.emissive_index
    assert em.any() and set(np.unique(s.prim[em])) == {3, 40}
    ng = np.tile([0.0, 0.0, 1.0], (em.sum(), 1))
    pdf = ls.emissive_pdf(s.prim[em], p[em], p[em] + s.wi[em] * s.dist[em, None], ng)
    assert np.allclose(pdf, s.pdf[em], rtol=1e-9)
    assert np.all(ls.emissive_pdf(np.array([5]), p[:1], p[:1] + 1, ng[:1]) == 0.0)


# ---------------------------------------------------------------------------------------------
def test_selection_follows_power():
    lights = [dict(type="POINT", matrix_world=translate(z=2), power=w, radius=0.0) for w in (1.0, 9.0)]
    ls = LightSet(lights, (0, 0, 0), None)
    m = 100_000
    s = ls.sample(np.zeros((m, 3)), None, np.random.default_rng(4).random(m), np.zeros((m, 2)))
    picked_strong = (s.light == 1).astype(float)
    assert_within_ci(picked_strong, 0.9, k=4.0)
    assert np.allclose(s.pdf[s.light == 1], 0.9) and np.allclose(s.pdf[s.light == 0], 0.1)


def test_single_light_costs_nothing():
    ls = LightSet([dict(type="POINT", matrix_world=translate(z=2), power=3.0, radius=0.0)],
                  (0, 0, 0), None)
    u = np.random.default_rng(0).random(1000)
    s = ls.sample(np.zeros((1000, 3)), None, u, np.zeros((1000, 2)))
    assert np.all(s.pdf == 1.0) and s.is_delta.all() and ls.pmf.tolist() == [1.0]


def test_sun_is_hit_only_by_escaping_rays():
    sun = dict(type="SUN", matrix_world=translate(rot_x=0.3), strength=2.0, angle=0.05)
    ls = LightSet([sun], (0.2, 0.2, 0.2), None)
    s = ls.sample(np.zeros((50, 3)), None, np.random.default_rng(0).random(50),
                  np.random.default_rng(1).random((50, 2)))
    sun_picked = s.light == 0
    h = ls.intersect(np.zeros((50, 3)), s.wi, np.inf)
    assert h.hit[sun_picked].all() and np.isinf(h.t).all()
    assert np.allclose(h.pdf[sun_picked], s.pdf[sun_picked])
    assert not ls.intersect(np.zeros((50, 3)), s.wi, 10.0).hit.any()


def test_origin_shift_and_camera_visibility():
    area = dict(type="AREA", matrix_world=translate(100.0, 0.0, 2.0), power=100, size=1.0)
    ls = LightSet([area, dict(area, visible_camera=True)], (0, 0, 0), None,
                  origin_shift=(100.0, 0.0, 0.0))
    assert ls.visible_to_camera.tolist() == [False, True]          # Blender 5.0 default: hidden
    h = ls.intersect(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), np.inf)
    assert h.hit[0] and abs(h.t[0] - 2.0) < 1e-12
    assert np.allclose(h.radiance[0], 100 / math.pi)


def test_lights_are_transparent_emitters_along_a_ray():
    """Cycles (integrator/shade_light.h) adds a light's emission and continues the ray past it.
    `hits_along` yields every light a ray passes, nearest first, each once: two stacked area
    lights facing down are both collected by an upward ray; a sphere light is passed once
    (its far side is not hit again from inside)."""
    area = lambda z, power: {"type": "AREA", "matrix_world": translate(0, 0, z),  # noqa: E731
                             "power": power, "size": 2.0}
    sphere = {"type": "POINT", "matrix_world": translate(0, 0, 6.0), "power": 30.0, "radius": 0.5,
              "soft_falloff": False}
    ls = LightSet([area(2.0, 10.0), area(4.0, 40.0), sphere], (0, 0, 0), None)
    p = np.zeros((3, 3))
    d = np.tile([0.0, 0.0, 1.0], (3, 1))
    tmax = np.array([np.inf, 3.0, np.inf])  # ray 1 stops at a surface between the lights
    layers = list(ls.hits_along(p, d, tmax))
    seen = {r: [] for r in range(3)}
    for rows, lh in layers:
        for r, hit, light, t in zip(rows, lh.hit, lh.light, lh.t):
            if hit:
                seen[int(r)].append((int(light), round(float(t), 6)))
    assert seen[0] == [(0, 2.0), (1, 4.0), (2, 5.5)]
    assert seen[1] == [(0, 2.0)]
    # radiance of each layer is that light's own
    first = layers[0][1]
    assert np.allclose(first.radiance[0], ls.lights[0].radiance)


def test_camera_sees_through_a_visible_area_light():
    """A visible area light filling the view, in front of a white world: each pixel is the
    light's radiance plus the world's (the light does not block what is behind it)."""
    import sys
    sys.path.insert(0, __file__.rsplit("/", 1)[0])
    from scene_builders import base_header, look_at
    from drt.render import render
    from drt.scene import scene_from_dict
    h = base_header(4, 4, 4, camera={"type": "PERSP", "matrix_world": look_at((0, 0, 1), (0, 0, 5)),
                                     "lens": 50.0}, world=(0.25, 0.25, 0.25))
    h["lights"].append({"type": "AREA", "matrix_world": translate(0, 0, 2.0),  # emits down, at the camera
                        "power": 2000.0, "size": 50.0, "visible_camera": True})
    film = render(scene_from_dict(h, {}), threads=1)
    light = LightSet(h["lights"], (0, 0, 0), None).lights[0]
    expected = light.radiance + 0.25
    assert np.allclose(film.combined[..., :3], expected, rtol=1e-6)
