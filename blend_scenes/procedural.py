"""Procedural materials (issue 11, phase 2): a brick floor (Brick texture), a marble sphere
(Noise with distortion feeding Wave bands, through a Color Ramp), a wooden cube (Wave rings
distorted by Noise, shaped by RGB Curves), a cell sphere (Voronoi F1 colour darkened by the
Voronoi distance to edge through a Float Curve), a vertex-painted cube (Color Attribute, corner
domain, byte colours) and a hetero-terrain Noise with White Noise speckles on a back wall, under a
sun and a dim world. docs/materials.md.

Every Principled BSDF has Specular IOR Level 0 (matte), as in textured.py: the scene measures
the texture nodes, not DRT's still simplified Principled specular layer.
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

import bpy  # noqa: E402

FINISH = dict(resolution=(128, 96), samples=16)


def _material(name):
    mat, nodes, out = C._new_material(name)
    p = nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Specular IOR Level"].default_value = 0.0
    p.inputs["Roughness"].default_value = 0.6
    mat.node_tree.links.new(p.outputs[0], out.inputs["Surface"])
    return mat, mat.node_tree, p


def _node(nt, kind, inputs=None, **props):
    n = nt.nodes.new(kind)
    for k, v in props.items():
        setattr(n, k, v)
    for key, v in (inputs or {}).items():
        sock = n.inputs[key]
        if isinstance(v, bpy.types.NodeSocket):
            nt.links.new(v, sock)
        else:
            sock.default_value = v
    return n


def brick_material():
    mat, nt, p = _material("Bricks")
    tc = _node(nt, "ShaderNodeTexCoord")
    b = _node(nt, "ShaderNodeTexBrick", {"Vector": tc.outputs["Object"], "Scale": 1.2,
                                         "Color1": (0.55, 0.18, 0.1, 1), "Color2": (0.75, 0.4, 0.25, 1),
                                         "Mortar": (0.6, 0.6, 0.55, 1), "Mortar Size": 0.03,
                                         "Mortar Smooth": 0.4, "Bias": 0.0},
              offset=0.5, offset_frequency=2, squash=1.0, squash_frequency=2)
    nt.links.new(b.outputs["Color"], p.inputs["Base Color"])
    return mat


def marble_material():
    mat, nt, p = _material("Marble")
    tc = _node(nt, "ShaderNodeTexCoord")
    n = _node(nt, "ShaderNodeTexNoise", {"Vector": tc.outputs["Object"], "Scale": 2.0, "Detail": 6.0,
                                         "Roughness": 0.55, "Distortion": 0.4}, noise_type="FBM")
    w = _node(nt, "ShaderNodeTexWave", {"Vector": n.outputs["Color"], "Scale": 1.3, "Distortion": 6.0,
                                        "Detail": 3.0}, wave_type="BANDS", bands_direction="DIAGONAL")
    ramp = _node(nt, "ShaderNodeValToRGB", {"Fac": w.outputs["Fac"]})
    els = ramp.color_ramp.elements
    els[0].position, els[0].color = 0.0, (0.25, 0.27, 0.33, 1.0)
    els[1].position, els[1].color = 0.6, (0.92, 0.9, 0.86, 1.0)
    nt.links.new(ramp.outputs["Color"], p.inputs["Base Color"])
    return mat


def wood_material():
    mat, nt, p = _material("Wood")
    tc = _node(nt, "ShaderNodeTexCoord")
    n = _node(nt, "ShaderNodeTexNoise", {"Vector": tc.outputs["Object"], "Scale": 3.0, "Detail": 2.0},
              noise_dimensions="3D")
    mix = _node(nt, "ShaderNodeMix", data_type="VECTOR")
    socks = [s for s in mix.inputs if s.enabled]
    socks[0].default_value = 0.15
    nt.links.new(tc.outputs["Object"], socks[1])
    nt.links.new(n.outputs["Color"], socks[2])
    w = _node(nt, "ShaderNodeTexWave", {"Vector": [o for o in mix.outputs if o.enabled][0], "Scale": 1.5,
                                        "Distortion": 1.0, "Detail": 2.0},
              wave_type="RINGS", rings_direction="Z", wave_profile="SAW")
    col = _node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="MIX")
    cs = [s for s in col.inputs if s.enabled]
    nt.links.new(w.outputs["Fac"], cs[0])
    cs[1].default_value = (0.45, 0.25, 0.1, 1)
    cs[2].default_value = (0.2, 0.09, 0.03, 1)
    curves = _node(nt, "ShaderNodeRGBCurve", {"Color": [o for o in col.outputs if o.enabled][0], "Fac": 1.0})
    c = curves.mapping.curves[3]
    c.points[0].location = (0.0, 0.05)
    c.points.new(0.3, 0.45)
    c.points[-1].location = (1.0, 0.9)
    curves.mapping.update()
    nt.links.new(curves.outputs["Color"], p.inputs["Base Color"])
    return mat


def cells_material():
    mat, nt, p = _material("Cells")
    tc = _node(nt, "ShaderNodeTexCoord")
    v = _node(nt, "ShaderNodeTexVoronoi", {"Vector": tc.outputs["Object"], "Scale": 4.0},
              feature="F1", voronoi_dimensions="3D")
    e = _node(nt, "ShaderNodeTexVoronoi", {"Vector": tc.outputs["Object"], "Scale": 4.0},
              feature="DISTANCE_TO_EDGE", voronoi_dimensions="3D")
    fc = _node(nt, "ShaderNodeFloatCurve", {"Value": e.outputs["Distance"], "Factor": 1.0})
    pts = fc.mapping.curves[0].points
    pts[0].location = (0.0, 0.1)
    pts[1].location = (0.12, 1.0)
    fc.mapping.update()
    mul = _node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="MULTIPLY")
    ms = [s for s in mul.inputs if s.enabled]
    ms[0].default_value = 1.0
    nt.links.new(v.outputs["Color"], ms[1])
    nt.links.new(fc.outputs[0], ms[2])
    nt.links.new([o for o in mul.outputs if o.enabled][0], p.inputs["Base Color"])
    return mat


def painted_material():
    mat, nt, p = _material("Painted")
    ca = _node(nt, "ShaderNodeVertexColor", layer_name="Paint")
    nt.links.new(ca.outputs["Color"], p.inputs["Base Color"])
    return mat


def wall_material():
    mat, nt, p = _material("Terrain")
    tc = _node(nt, "ShaderNodeTexCoord")
    n = _node(nt, "ShaderNodeTexNoise", {"Vector": tc.outputs["Generated"], "Scale": 4.0, "Detail": 5.0,
                                         "Roughness": 0.5, "Offset": 0.6, "Lacunarity": 2.2},
              noise_type="HETERO_TERRAIN")
    # 41, not 40: Generated is exactly 0.5 across the flat wall, and 0.5·40 = 20 sits on a cell
    # boundary, where Cycles's float32 attribute interpolation lands on either side of floor()
    # from sample to sample (speckles of two cell layers, blended) — rounding noise no renderer
    # is meant to reproduce, and 46 % of DRT's converged error against Cycles (docs/materials.md)
    q = _node(nt, "ShaderNodeVectorMath", {0: tc.outputs["Generated"], 3: 41.0}, operation="SCALE")
    fl = _node(nt, "ShaderNodeVectorMath", {0: q.outputs[0]}, operation="FLOOR")
    wn = _node(nt, "ShaderNodeTexWhiteNoise", {"Vector": fl.outputs[0]}, noise_dimensions="3D")
    speck = _node(nt, "ShaderNodeMath", {0: wn.outputs["Value"], 1: 0.9}, operation="GREATER_THAN")
    ramp = _node(nt, "ShaderNodeValToRGB", {"Fac": n.outputs["Fac"]})
    els = ramp.color_ramp.elements
    els[0].position, els[0].color = 0.1, (0.1, 0.2, 0.08, 1.0)
    els[1].position, els[1].color = 1.2 / 2, (0.7, 0.65, 0.45, 1.0)
    mix = _node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="SCREEN")
    ms = [s for s in mix.inputs if s.enabled]
    nt.links.new(speck.outputs[0], ms[0])
    nt.links.new(ramp.outputs["Color"], ms[1])
    ms[2].default_value = (0.9, 0.9, 0.95, 1)
    nt.links.new([o for o in mix.outputs if o.enabled][0], p.inputs["Base Color"])
    return mat


def paint(mesh, seed=3):
    """A corner-domain byte colour attribute "Paint" with a colour per face corner."""
    attr = mesh.color_attributes.new("Paint", "BYTE_COLOR", "CORNER")
    rng = np.random.default_rng(seed)
    vals = np.ones((len(attr.data), 4), np.float32)
    vals[:, :3] = rng.uniform(0.05, 0.9, (len(attr.data), 3))
    attr.data.foreach_set("color", vals.ravel())


def build():
    scene = C.reset()
    C.set_world(scene.world, (0.35, 0.4, 0.5), 0.4)
    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0, 0, 0))
    floor = bpy.context.object
    floor.name = "Floor"
    floor.data.materials.append(brick_material())
    bpy.ops.mesh.primitive_plane_add(size=6.0, location=(0, 2.5, 2.0), rotation=(C.deg(90), 0, 0))
    wall = bpy.context.object
    wall.name = "Wall"
    wall.data.materials.append(wall_material())
    C.uv_sphere("Marble", 0.6, (-1.4, 0.3, 0.6), marble_material(), segments=48, rings=24)
    C.uv_sphere("Cells", 0.5, (0.3, 0.9, 0.5), cells_material(), segments=48, rings=24)
    bpy.ops.mesh.primitive_cube_add(size=0.9, location=(1.5, -0.1, 0.45), rotation=(0, 0, C.deg(25)))
    cube = bpy.context.object
    cube.name = "Wood"
    cube.data.materials.append(wood_material())
    bpy.ops.mesh.primitive_cube_add(size=0.6, location=(-0.3, -0.9, 0.3), rotation=(0, 0, C.deg(-20)))
    painted = bpy.context.object
    painted.name = "Painted"
    paint(painted.data)
    painted.data.materials.append(painted_material())
    C.light("Sun", "SUN", (0, 0, 5), rotation=(C.deg(40), C.deg(15), C.deg(30)), energy=3.0)
    C.camera((0.0, -5.0, 2.6), (0.0, 0.4, 0.6), lens=38.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "procedural", **FINISH)
