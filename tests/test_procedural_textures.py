"""Procedural textures, curves and attributes in material programs (docs/materials.md,
"Procedural textures"), against Cycles pixel by pixel with the tile harness
(tests/node_parity.py; tolerance and '*' discontinuity convention of test_material_programs).

Cycles evaluates these nodes in float32 and DRT in float64 on float32-rounded coordinates, so
values agree to ~1e-4 after the atan squash; cells (Perlin lattice, Voronoi cells, bricks) are
floors of float32 coordinates as in Cycles. A pixel whose centre lies within Cycles's sample
jitter (0.01 pixel) of a cell edge may pick the other cell: such cases end in '*' (one pixel
allowed up to 3 pixels of 256: fractal Voronoi has many edges). Steep cases are kept moderate
(scale, distortion) because the jitter times the gradient is the comparison's error floor.
The default suite renders one grid of representative tiles per node family; the
sweeps over every mode and dimension are slow-marked.
"""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import node_parity as P  # noqa: E402
from node_parity import mapping, node  # noqa: E402

pytestmark = pytest.mark.blender

TOL = 2e-3


def _check(cases, names, tmp_path, tag):
    n = int(np.ceil(np.sqrt(len(cases))))
    cycles, drt, res = P.render_tiles(cases, n, tmp_path, tag)
    bad = {}
    for k in range(len(cases)):
        err = np.abs(P.tile(cycles, k, n) - P.tile(drt, k, n)).max(axis=2)
        allowed = 3 if names[k].endswith("*") else 0
        if np.count_nonzero(err > TOL) > allowed:
            bad[names[k]] = round(float(np.sort(err.ravel())[-1 - allowed]), 5)
    assert not bad, f"cases differing from Cycles (max abs error): {bad}"
    # every case shows a varying texture (a constant tile would hide a wrong hash)
    flat = [names[k] for k in range(len(cases)) if P.tile(cycles, k, n).std() < 2e-3]
    assert not flat, f"cases constant over their tile: {flat}"
    return res


def _vec(nt, uv, s=1.0):
    """A 3D point varying over the tile (z varies too, so 3D/4D lattices see it)."""
    m = mapping(nt, uv, loc=(-0.31, 0.23, 0.37), rot=(0.4, 0.3, 0.2), scale=(1.3 * s, 1.1 * s, 0.9 * s))
    return m


def _w(nt, uv):
    sep = node(nt, "ShaderNodeSeparateXYZ", {0: uv})
    return node(nt, "ShaderNodeMath", {0: sep.outputs[0], 1: 1.7, 2: 0.31}, operation="MULTIPLY_ADD").outputs[0]


def noise(dim, kind="FBM", out="Fac", **ins):
    def case(nt, uv):
        d = {"Vector": _vec(nt, uv), "W": _w(nt, uv), "Scale": 3.0, "Detail": 2.5}
        d.update(ins)
        props = {k: d.pop(k) for k in ("normalize",) if k in d}
        n = node(nt, "ShaderNodeTexNoise", d, noise_dimensions=dim, noise_type=kind, **props)
        return n.outputs[out]
    return case


def voronoi(dim, feature="F1", metric="EUCLIDEAN", out="Distance", **ins):
    def case(nt, uv):
        d = {"Vector": _vec(nt, uv), "W": _w(nt, uv), "Scale": 4.0}
        d.update(ins)
        props = {k: d.pop(k) for k in ("normalize",) if k in d}
        n = node(nt, "ShaderNodeTexVoronoi", d, voronoi_dimensions=dim, feature=feature, distance=metric,
                 **props)
        return n.outputs[out]
    return case


def white_noise(dim, out="Value"):
    """White noise of a point quantised to an 8×8 grid (exact float inputs: the hash of the
    float bits is then comparable; a continuous input hashes Cycles's own float32 rounding).
    The offsets keep pixel centres off the grid lines."""
    def case(nt, uv):
        q = node(nt, "ShaderNodeVectorMath", {0: mapping(nt, uv, loc=(0.13, 0.37, 0.0), scale=(8, 8, 8))},
                 operation="FLOOR").outputs[0]
        sep = node(nt, "ShaderNodeSeparateXYZ", {0: q})
        w = node(nt, "ShaderNodeMath", {0: sep.outputs[0], 1: sep.outputs[1]}, operation="ADD").outputs[0]
        n = node(nt, "ShaderNodeTexWhiteNoise", {"Vector": q, "W": w}, noise_dimensions=dim)
        return n.outputs[out]
    return case


def wave(kind="BANDS", direction="X", profile="SIN", **ins):
    def case(nt, uv):
        d = {"Vector": _vec(nt, uv), "Scale": 0.7}
        d.update(ins)
        props = {"wave_type": kind, "wave_profile": profile}
        props["bands_direction" if kind == "BANDS" else "rings_direction"] = direction
        return node(nt, "ShaderNodeTexWave", d, **props).outputs["Color"]
    return case


def magic(depth=2, **ins):
    def case(nt, uv):
        d = {"Vector": _vec(nt, uv), "Scale": 1.2}
        d.update(ins)
        return node(nt, "ShaderNodeTexMagic", d, turbulence_depth=depth).outputs["Color"]
    return case


def magic_exact(depth, distortion, scale=1.2):
    """Magic of a point quantised to a 16×16 grid: chaotic settings (depth ≥ 5, distortion > 1)
    amplify any difference of the input, so only an exact input compares; then DRT's emulated
    float32 gives Cycles's values."""
    def case(nt, uv):
        q = node(nt, "ShaderNodeVectorMath", {0: mapping(nt, uv, loc=(0.13, 0.37, 0.0), scale=(16, 16, 16))},
                 operation="FLOOR").outputs[0]
        v = node(nt, "ShaderNodeVectorMath", {0: q, 3: 0.0625}, operation="SCALE").outputs[0]
        return node(nt, "ShaderNodeTexMagic", {"Vector": v, "Scale": scale, "Distortion": distortion},
                    turbulence_depth=depth).outputs["Color"]
    return case


def brick(out="Color", **props):
    def case(nt, uv):
        d = {"Vector": _vec(nt, uv), "Scale": 2.0, "Color1": (0.8, 0.2, 0.1, 1), "Color2": (0.2, 0.5, 0.9, 1),
             "Mortar": (0.05, 0.05, 0.05, 1), "Mortar Size": 0.1, "Mortar Smooth": 1.0, "Bias": 0.1}
        p = dict(props)
        for k in list(p):
            if k[0].isupper():
                d[k] = p.pop(k)
        return node(nt, "ShaderNodeTexBrick", d, **p).outputs[out]
    return case


def _points(curve, pts):
    while len(curve.points) < len(pts):
        curve.points.new(0.5, 0.5)
    for p, (x, y) in zip(curve.points, pts):
        p.location = (x, y)


def rgb_curves(extend="EXTRAPOLATED", fac=0.9, wide=False):
    def case(nt, uv):
        col = node(nt, "ShaderNodeCombineColor", {0: _w(nt, uv), 1: 0.4, 2: 0.8}).outputs[0]
        if wide:  # reach outside [0, 1]: extrapolation
            col = node(nt, "ShaderNodeMix", {"Factor": 1.0, "A": col, "B": (1.5, -0.3, 0.5, 1)}, data_type="RGBA",
                       blend_type="SUBTRACT").outputs[2]
        n = node(nt, "ShaderNodeRGBCurve", {"Fac": fac, "Color": col})
        m = n.mapping
        m.extend = extend
        _points(m.curves[3], [(0.0, 0.1), (0.4, 0.7), (1.0, 0.9)])
        _points(m.curves[0], [(0.0, 0.0), (0.3, 0.6), (1.0, 1.0)])
        _points(m.curves[2], [(0.1, 0.2), (0.8, 0.5)])
        m.update()
        return n.outputs[0]
    return case


def float_curve(extend="EXTRAPOLATED"):
    def case(nt, uv):
        x = node(nt, "ShaderNodeMath", {0: _w(nt, uv), 1: 0.8}, operation="SUBTRACT").outputs[0]
        n = node(nt, "ShaderNodeFloatCurve", {"Value": x, "Factor": 1.0})
        n.mapping.extend = extend
        _points(n.mapping.curves[0], [(-0.2, 0.3), (0.5, 0.9), (1.2, 0.1)])
        n.mapping.update()
        return n.outputs[0]
    return case


def vector_curves():
    def case(nt, uv):
        n = node(nt, "ShaderNodeVectorCurve", {"Vector": mapping(nt, uv, loc=(-0.5, -0.5, 0.2)), "Fac": 1.0})
        _points(n.mapping.curves[0], [(-1.0, -0.5), (0.2, 0.6), (1.0, 1.0)])
        _points(n.mapping.curves[1], [(-1.0, 1.0), (1.0, -1.0)])
        n.mapping.update()
        return n.outputs[0]
    return case


def color_attribute(domain, dtype, name="Col", node_kind="ShaderNodeVertexColor", out="Color", layer=None):
    """A random colour attribute on the tile's plane, read by the Color Attribute node (``layer``:
    its layer name; "" the render colour) or the Attribute node."""
    def case(nt, uv):
        if node_kind == "ShaderNodeVertexColor":
            return node(nt, node_kind, layer_name=name if layer is None else layer).outputs[out]
        return node(nt, node_kind, attribute_name=name).outputs[out]

    def setup(mesh):
        attr = mesh.color_attributes.new(name, dtype, domain)
        rng = np.random.default_rng(len(mesh.vertices) + hash((domain, dtype)) % 97)
        vals = rng.uniform(0.05, 0.95, (len(attr.data), 4)).astype(np.float32)
        attr.data.foreach_set("color", vals.ravel())
        mesh.color_attributes.render_color_index = mesh.color_attributes.find(name)
    case.setup = setup
    return case


def float_attribute(kind, out, domain="POINT"):
    """A generic FLOAT / FLOAT2 / FLOAT_VECTOR attribute read by the Attribute node."""
    def case(nt, uv):
        return node(nt, "ShaderNodeAttribute", attribute_name="gen").outputs[out]

    def setup(mesh):
        if domain == "FACE":  # several faces: a plane has one
            import bmesh
            bm = bmesh.new()
            bm.from_mesh(mesh)
            bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=2, use_grid_fill=True)
            bm.to_mesh(mesh)
            bm.free()
        attr = mesh.attributes.new("gen", kind, domain)
        width = {"FLOAT": 1, "FLOAT2": 2, "FLOAT_VECTOR": 3}[kind]
        key = "value" if kind == "FLOAT" else "vector"
        vals = np.random.default_rng(5).uniform(-1, 2, len(attr.data) * width).astype(np.float32)
        attr.data.foreach_set(key, vals)
    case.setup = setup
    return case


# --- default suite: representative tiles -------------------------------------------------------

def test_procedural_representative_match_cycles(tmp_path):
    cases = [noise("3D"), noise("4D", "RIDGED_MULTIFRACTAL", out="Color", Distortion=0.8),
             noise("2D", "HETERO_TERRAIN", Detail=3.3),
             voronoi("3D"), voronoi("2D", "SMOOTH_F1", "MANHATTAN", out="Color", Smoothness=0.6),
             voronoi("2D", "DISTANCE_TO_EDGE"), voronoi("3D", "F2", out="Position", Detail=1.5, Scale=1.5),
             white_noise("3D", "Color"), wave("RINGS", "SPHERICAL", "SAW", Distortion=2.0, Detail=2.0),
             magic(4, Distortion=1.3), brick(offset_frequency=2, squash=0.7, squash_frequency=3),
             rgb_curves(wide=True), float_curve(),
             color_attribute("CORNER", "BYTE_COLOR"), color_attribute("POINT", "FLOAT_COLOR", layer=""),
             float_attribute("FLOAT2", "Fac")]
    names = ["noise 3D fBM", "noise 4D ridged colour distorted", "noise 2D hetero", "voronoi 3D F1*",
             "voronoi 2D smooth manhattan colour", "voronoi 2D edge*", "voronoi 3D F2 position fractal*",
             "white noise 3D colour", "wave rings saw distorted*", "magic 4", "brick offset squash*",
             "rgb curves extrapolated", "float curve", "colour attribute corner byte",
             "colour attribute point float (render)", "attribute float2 fac"]
    res = _check(cases, names, tmp_path, "procedural")
    # attribute arrays are exported for the outputs used only (no Alpha here)
    assert {"attr:Col", "attr:", "fac:gen"} <= set(res.header["attributes"])
    assert not any(a.startswith("alpha:") for a in res.header["attributes"])


# --- slow sweeps: every mode and dimension ----------------------------------------------------

@pytest.mark.slow
def test_noise_sweep_matches_cycles(tmp_path):
    cases, names = [], []
    for dim in ("1D", "2D", "3D", "4D"):
        for kind in ("FBM", "MULTIFRACTAL", "HYBRID_MULTIFRACTAL", "RIDGED_MULTIFRACTAL", "HETERO_TERRAIN"):
            cases.append(noise(dim, kind, Roughness=0.6, Lacunarity=2.3, Offset=0.8, Gain=1.2, Scale=1.5))
            names.append(f"noise {dim} {kind}")
        cases += [noise(dim, out="Color", Distortion=1.1), noise(dim, Detail=0.0, normalize=False),
                  noise(dim, Detail=4.0, Roughness=0.7)]
        names += [f"noise {dim} colour distorted", f"noise {dim} detail 0 unnormalized",
                  f"noise {dim} detail 4"]
    _check(cases, names, tmp_path, "noise_sweep")


@pytest.mark.slow
def test_voronoi_sweep_matches_cycles(tmp_path):
    cases, names = [], []
    for dim in ("1D", "2D", "3D", "4D"):
        for feat in ("F1", "F2", "SMOOTH_F1"):
            for metric in (("EUCLIDEAN",) if dim == "1D" else ("EUCLIDEAN", "MANHATTAN", "CHEBYCHEV", "MINKOWSKI")):
                cases.append(voronoi(dim, feat, metric, Exponent=1.5, Randomness=0.8))
                names.append(f"voronoi {dim} {feat} {metric}*")
        cases += [voronoi(dim, "DISTANCE_TO_EDGE"), voronoi(dim, "N_SPHERE_RADIUS", out="Radius"),
                  voronoi(dim, out="Color"), voronoi(dim, out="Position" if dim != "1D" else "W"),
                  voronoi(dim, "F1", Detail=2.5, Roughness=0.6, Scale=1.2, normalize=True),
                  voronoi(dim, "DISTANCE_TO_EDGE", Detail=1.7, Scale=1.5, normalize=True)]
        names += [f"voronoi {dim} edge*", f"voronoi {dim} radius*", f"voronoi {dim} colour*",
                  f"voronoi {dim} position*", f"voronoi {dim} fractal normalized*",
                  f"voronoi {dim} edge fractal*"]
    _check(cases, names, tmp_path, "voronoi_sweep")


@pytest.mark.slow
def test_other_textures_sweep_match_cycles(tmp_path):
    cases, names = [], []
    for dim in ("1D", "2D", "3D", "4D"):
        cases += [white_noise(dim), white_noise(dim, "Color")]
        names += [f"white {dim}", f"white {dim} colour"]
    for d in ("X", "Y", "Z", "DIAGONAL"):
        for prof in ("SIN", "SAW", "TRI"):
            cases.append(wave("BANDS", d, prof, **{"Phase Offset": 0.7}))
            names.append(f"wave bands {d} {prof}" + ("*" if prof == "SAW" else ""))
    for d in ("X", "Y", "Z", "SPHERICAL"):
        cases.append(wave("RINGS", d, "TRI", Distortion=3.0, Detail=3.5))
        names.append(f"wave rings {d} distorted")
    for depth in (0, 1, 2, 5, 10):
        cases.append(magic(depth, Distortion=0.9))
        names.append(f"magic {depth}")
    cases += [magic_exact(10, 2.9), magic_exact(7, 4.0, 3.0)]
    names += ["magic 10 chaotic exact", "magic 7 chaotic exact"]
    cases += [brick(), brick("Fac", Scale=1.0, **{"Mortar Size": 0.3}), brick(offset=0.3, offset_frequency=3, squash=1.5, squash_frequency=2,
                                           **{"Mortar Smooth": 0.0, "Brick Width": 0.7, "Row Height": 0.3})]
    names += ["brick*", "brick fac*", "brick sharp mortar*"]
    cases += [rgb_curves("EXTRAPOLATED"), rgb_curves("HORIZONTAL", wide=True), rgb_curves(fac=0.4),
              float_curve("HORIZONTAL"), vector_curves()]
    names += ["rgb curves", "rgb curves clamped", "rgb curves fac", "float curve clamped", "vector curves"]
    for domain in ("POINT", "CORNER"):
        for dtype in ("BYTE_COLOR", "FLOAT_COLOR"):
            cases.append(color_attribute(domain, dtype))
            names.append(f"colour {domain} {dtype}")
    cases += [color_attribute("CORNER", "FLOAT_COLOR", node_kind="ShaderNodeAttribute", out=o)
              for o in ("Color", "Vector", "Fac", "Alpha")]
    names += [f"attribute node {o}" for o in ("Color", "Vector", "Fac", "Alpha")]
    cases += [float_attribute(k, o) for k in ("FLOAT", "FLOAT2", "FLOAT_VECTOR") for o in ("Vector", "Fac")]
    names += [f"attribute {k} {o}" for k in ("FLOAT", "FLOAT2", "FLOAT_VECTOR") for o in ("Vector", "Fac")]
    cases += [float_attribute("FLOAT_VECTOR", "Color", "FACE")]
    names += ["attribute face domain*"]
    _check(cases, names, tmp_path, "other_sweep")


def _noise_bump(kind="FBM", strength=0.6):
    def case(nt, uv):
        tc = nt.nodes.new("ShaderNodeTexCoord")
        n = node(nt, "ShaderNodeTexNoise", {"Vector": tc.outputs["Object"], "Scale": 4.0, "Detail": 1.0},
                 noise_type=kind)
        return node(nt, "ShaderNodeBump", {"Height": n.outputs["Fac"], "Strength": strength,
                                           "Distance": 0.2}).outputs[0]
    return case


def _voronoi_bump(nt, uv):
    tc = nt.nodes.new("ShaderNodeTexCoord")
    v = node(nt, "ShaderNodeTexVoronoi", {"Vector": tc.outputs["Object"], "Scale": 3.0, "Smoothness": 1.0},
             feature="SMOOTH_F1")
    return node(nt, "ShaderNodeBump", {"Height": v.outputs["Distance"], "Strength": 1.0,
                                       "Distance": 0.4}).outputs[0]


def test_procedural_bump_matches_cycles(tmp_path):
    """Noise and smooth Voronoi heights through the Bump node (DRT evaluates the height sub-graph
    at two offset points, as Cycles; see test_shading_inputs): the normals agree."""
    cases = [_noise_bump(), _noise_bump("RIDGED_MULTIFRACTAL", 0.3), _voronoi_bump,
             lambda nt, uv: node(nt, "ShaderNodeNewGeometry").outputs["Normal"]]  # unbumped
    cycles, drt, res = P.render_tiles(cases, 2, tmp_path, shape="sphere")
    assert not res.warnings, res.warnings
    for k in range(len(cases)):
        if k < 3:  # the bump really tilts the normal
            assert np.abs(P.tile(cycles, k, 2) - P.tile(cycles, 3, 2)).max() > 0.03, k
        diff = np.abs(P.tile(cycles, k, 2) - P.tile(drt, k, 2)).max(axis=-1)
        assert int((diff > 3e-3).sum()) <= 6, (k, int((diff > 3e-3).sum()), float(diff.max()))
