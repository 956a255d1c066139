"""Cost of material programs: render time of a scene whose every surface runs a 20-node texture
graph against the same scene with constant materials (issue 11's acceptance: < 2×).

    python benchmarks/texture_cost.py [--spp 32] [--resolution 160x120] [--procedural]

Builds, with bpy, the shipped blend_scenes/textured scene, gives every material a Principled
base colour from a chain of 20 texture/converter nodes (checker, gradient, image, ramp, mapping,
math, mix, hue/saturation, ...), exports it, and renders it on one thread with DRT: once as is,
once with the programs stripped (each lobe keeps its representative constant). Best of four
each, alternated, in process CPU time (wall time on the shared 2-vCPU machine mostly measured its
neighbours). Prints both times, the rays each traced and the ratio (also per ray: the constant
colours change path lengths); asserts nothing. ``--procedural``: the 20 nodes are
procedural textures instead (noise, Voronoi, wave, magic, brick, white noise, curves, ...);
``--scene X.npz``: a shipped scene as is against its programs stripped.

``--cycles SPP``: the same two scenes rendered by Cycles in this process (one render thread, SPP
samples, no denoising or adaptive sampling; the untextured twin unlinks the Base Color, so its
colour is the socket's constant), best of two each, alternated, in process CPU time: Cycles's
own cost of the same 20 nodes, the yardstick for DRT's ratio.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
for p in (REPO, os.path.join(REPO, "blend_scenes"), os.path.join(REPO, "tests")):
    sys.path.insert(0, p)


def twenty_node_chain(nt, img):
    """Base colour from 20 nodes; returns the colour socket."""
    from node_parity import mapping, node

    tc = nt.nodes.new("ShaderNodeTexCoord")                                              # 1
    m = mapping(nt, tc.outputs["UV"], scale=(3, 3, 1), rot=(0, 0, 0.2))                  # 2
    ck = node(nt, "ShaderNodeTexChecker", {"Vector": m, "Scale": 2.0})                    # 3
    gr = node(nt, "ShaderNodeTexGradient", {"Vector": tc.outputs["Generated"]})            # 4
    im = node(nt, "ShaderNodeTexImage", {"Vector": m}, image=img, interpolation="Linear")  # 5
    ramp = node(nt, "ShaderNodeValToRGB", {0: gr.outputs["Fac"]})                          # 6
    sep = node(nt, "ShaderNodeSeparateXYZ", {0: tc.outputs["UV"]})                         # 7
    a = node(nt, "ShaderNodeMath", {0: sep.outputs[0], 1: 6.0}, operation="MULTIPLY")      # 8
    b = node(nt, "ShaderNodeMath", {0: a.outputs[0]}, operation="SINE")                    # 9
    c = node(nt, "ShaderNodeMath", {0: b.outputs[0], 1: 0.5, 2: 0.5}, operation="MULTIPLY_ADD")  # 10
    mix1 = node(nt, "ShaderNodeMix", {"Factor": c.outputs[0]}, data_type="RGBA")          # 11
    socks = [s for s in mix1.inputs if s.enabled]
    nt.links.new(ck.outputs["Color"], socks[1])
    nt.links.new(im.outputs["Color"], socks[2])
    mix2 = node(nt, "ShaderNodeMix", {"Factor": 0.5}, data_type="RGBA", blend_type="MULTIPLY")  # 12
    socks = [s for s in mix2.inputs if s.enabled]
    nt.links.new([o for o in mix1.outputs if o.enabled][0], socks[1])
    nt.links.new(ramp.outputs["Color"], socks[2])
    hsv = node(nt, "ShaderNodeHueSaturation", {"Color": [o for o in mix2.outputs if o.enabled][0],
                                               "Saturation": 1.2})                         # 13
    gam = node(nt, "ShaderNodeGamma", {"Color": hsv.outputs[0], "Gamma": 1.1})             # 14
    bc = node(nt, "ShaderNodeBrightContrast", {"Color": gam.outputs[0], "Contrast": 0.1})  # 15
    inv = node(nt, "ShaderNodeInvert", {"Color": bc.outputs[0], "Fac": 0.1})               # 16
    mr = node(nt, "ShaderNodeMapRange", {"Value": sep.outputs[1], "To Min": 0.8})         # 17
    vm = node(nt, "ShaderNodeVectorMath", {0: inv.outputs[0], 3: 1.0}, operation="SCALE")  # 18
    nt.links.new(mr.outputs[0], vm.inputs[3])
    cl = node(nt, "ShaderNodeClamp", {"Value": mr.outputs[0]})                             # 19
    mix3 = node(nt, "ShaderNodeMix", {"Factor": cl.outputs[0]}, data_type="RGBA")          # 20
    socks = [s for s in mix3.inputs if s.enabled]
    nt.links.new(vm.outputs[0], socks[1])
    nt.links.new(inv.outputs[0], socks[2])
    return [o for o in mix3.outputs if o.enabled][0]


def twenty_procedural_nodes(nt, img=None):
    """Base colour from 20 procedural nodes (the issue's "20 texture nodes" as a procedural
    material is built: noise, Voronoi, wave, magic, brick, white noise, curves, ramps, maths)."""
    from node_parity import mapping, node

    tc = nt.nodes.new("ShaderNodeTexCoord")                                                        # 1
    m = mapping(nt, tc.outputs["Object"], scale=(2, 2, 2), rot=(0, 0, 0.3))                         # 2
    nz = node(nt, "ShaderNodeTexNoise", {"Vector": m, "Scale": 3.0, "Detail": 2.0})                 # 3
    vo = node(nt, "ShaderNodeTexVoronoi", {"Vector": m, "Scale": 4.0})                              # 4
    wv = node(nt, "ShaderNodeTexWave", {"Vector": nz.outputs["Color"], "Distortion": 2.0})          # 5
    mg = node(nt, "ShaderNodeTexMagic", {"Vector": m, "Scale": 2.0}, turbulence_depth=2)            # 6
    bk = node(nt, "ShaderNodeTexBrick", {"Vector": m, "Scale": 2.0})                                # 7
    fl = node(nt, "ShaderNodeVectorMath", {0: m, 3: 20.0}, operation="SCALE")                       # 8
    fl2 = node(nt, "ShaderNodeVectorMath", {0: fl.outputs[0]}, operation="FLOOR")                   # 9
    wn = node(nt, "ShaderNodeTexWhiteNoise", {"Vector": fl2.outputs[0]})                            # 10
    ramp = node(nt, "ShaderNodeValToRGB", {0: wv.outputs["Fac"]})                                   # 11
    mix1 = node(nt, "ShaderNodeMix", {"Factor": vo.outputs["Distance"]}, data_type="RGBA")          # 12
    socks = [s for s in mix1.inputs if s.enabled]
    nt.links.new(ramp.outputs["Color"], socks[1])
    nt.links.new(vo.outputs["Color"], socks[2])
    mix2 = node(nt, "ShaderNodeMix", {"Factor": 0.3}, data_type="RGBA", blend_type="OVERLAY")       # 13
    socks = [s for s in mix2.inputs if s.enabled]
    nt.links.new([o for o in mix1.outputs if o.enabled][0], socks[1])
    nt.links.new(mg.outputs["Color"], socks[2])
    mix3 = node(nt, "ShaderNodeMix", {"Factor": 0.4}, data_type="RGBA", blend_type="MULTIPLY")      # 14
    socks = [s for s in mix3.inputs if s.enabled]
    nt.links.new([o for o in mix2.outputs if o.enabled][0], socks[1])
    nt.links.new(bk.outputs["Color"], socks[2])
    curves = node(nt, "ShaderNodeRGBCurve", {"Color": [o for o in mix3.outputs if o.enabled][0]})  # 15
    fc = node(nt, "ShaderNodeFloatCurve", {"Value": wn.outputs["Value"]})                           # 16
    mr = node(nt, "ShaderNodeMapRange", {"Value": fc.outputs[0], "To Min": 0.8})                   # 17
    hsv = node(nt, "ShaderNodeHueSaturation", {"Color": curves.outputs[0], "Value": 1.1})          # 18
    mth = node(nt, "ShaderNodeMath", {0: mr.outputs[0], 1: nz.outputs["Fac"]}, operation="MULTIPLY")  # 19
    mix4 = node(nt, "ShaderNodeMix", {"Factor": mth.outputs[0]}, data_type="RGBA")                  # 20
    socks = [s for s in mix4.inputs if s.enabled]
    nt.links.new(hsv.outputs[0], socks[1])
    nt.links.new(curves.outputs[0], socks[2])
    return [o for o in mix4.outputs if o.enabled][0]


def build(spp, w, h, chain=None):
    import bpy
    import textured
    from addon.export import export_depsgraph

    scene = textured.build()
    from test_addon import ensure_registered

    ensure_registered()
    img = bpy.data.images["planks"]
    for mat in bpy.data.materials:
        p = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
        mat.node_tree.links.new((chain or twenty_node_chain)(mat.node_tree, img), p.inputs["Base Color"])
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = w, h, 100
    scene.drt.samples = spp
    res = export_depsgraph(bpy.context.evaluated_depsgraph_get())
    assert not res.warnings, res.warnings
    return res.header, res.arrays


def strip(header):
    h = copy.deepcopy(header)
    for m in h["materials"]:
        m.pop("program", None)
        m.pop("emission_reg", None)
        for lb in m["lobes"]:
            lb.pop("color_reg", None)
            lb.pop("roughness_reg", None)
    return h


def best_time(header, arrays, spp, runs=3):
    from drt.render import prepare, render
    from drt.scene import scene_from_dict

    scene = scene_from_dict(header, arrays)
    ctx = prepare(scene)
    render(scene, spp=1, threads=1, context=ctx)  # warm: kernels loaded
    best = float("inf")
    for _ in range(runs):
        # process CPU time: on a shared machine wall time mostly measures the neighbours
        t0 = time.process_time()
        film = render(scene, spp=spp, threads=1, context=ctx)
        best = min(best, time.process_time() - t0)
    return best, film.stats.rays


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--spp", type=int, default=32)
    p.add_argument("--resolution", default="160x120")
    p.add_argument("--procedural", action="store_true", help="20 procedural texture nodes instead")
    p.add_argument("--scene", help="instead: a scene file (.npz) as is vs its programs stripped")
    p.add_argument("--save", help="also write the built (textured) scene to this .npz (for --scene)")
    p.add_argument("--cycles", type=int, metavar="SPP", help="also time Cycles on both scenes at SPP samples")
    o = p.parse_args(argv)
    w, h = (int(x) for x in o.resolution.split("x"))
    if o.scene:
        from drt.scene_file import read_scene_arrays

        header, arrays = read_scene_arrays(o.scene)
        header["render"]["resolution"] = [w, h]
        report(header, arrays, o.spp, f"{o.scene} at {w}x{h}, {o.spp} spp, one thread")
        return 0
    header, arrays = build(o.spp, w, h, twenty_procedural_nodes if o.procedural else None)
    if o.save:
        from drt.scene_file import save_scene

        save_scene(o.save, header, arrays)
    n_ops = max(len(m["program"]["ops"]) for m in header["materials"] if "program" in m)
    kind = "procedural " if o.procedural else ""
    report(header, arrays, o.spp, f"{w}x{h} at {o.spp} spp, one thread; every material: 20 {kind}nodes "
                                  f"-> {n_ops} operations")
    if o.cycles:
        cycles_report(o.cycles)
    return 0


def cycles_report(spp):
    """Cycles on the scene ``build`` left in bpy, with and without the Base Color links."""
    import bpy

    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device, cy.samples, cy.use_adaptive_sampling, cy.use_denoising = "CPU", spp, False, False
    scene.render.threads_mode, scene.render.threads = "FIXED", 1
    links = []  # (tree, from socket, to socket) of every Principled's Base Color link
    for mat in bpy.data.materials:
        for ln in mat.node_tree.links:
            if ln.to_node.bl_idname == "ShaderNodeBsdfPrincipled" and ln.to_socket.name == "Base Color":
                links.append((mat.node_tree, ln.from_socket, ln.to_socket))

    def textured(on):
        for tree, a, b in links:
            if on:
                tree.links.new(a, b)
            else:
                for ln in list(b.links):
                    tree.links.remove(ln)

    def cpu_time():
        t0 = time.process_time()
        bpy.ops.render.render()
        return time.process_time() - t0

    times = {True: [], False: []}
    cpu_time()  # warm: kernels loaded, images cached
    for on in (True, False, True, False):
        textured(on)
        times[on].append(cpu_time())
    tex, plain = min(times[True]), min(times[False])
    print(f"Cycles, {spp} spp, one thread (CPU time of the whole render, sync included)")
    print(f"  constant materials : {plain:.3f} s")
    print(f"  textures           : {tex:.3f} s  ({tex / plain:.2f}x)")


def report(header, arrays, spp, title):
    """Both renders, alternated (textured, constant, textured, constant: the machine's load drifts),
    best of each. The stripped scene's constant colours are not the textures' average, so its
    paths differ in length: the rays each render traced are printed, and the ratio per ray too."""
    plain = strip(header)
    (t1, rays_t), (p1, rays_p) = best_time(header, arrays, spp, 2), best_time(plain, arrays, spp, 2)
    (t2, _), (p2, _) = best_time(header, arrays, spp, 2), best_time(plain, arrays, spp, 2)
    textured_t, plain_t = min(t1, t2), min(p1, p2)
    print(title)
    print(f"  constant materials : {plain_t:.3f} s  {rays_p} rays")
    print(f"  textures           : {textured_t:.3f} s  {rays_t} rays  ({textured_t / plain_t:.2f}x; per ray "
          f"{(textured_t / rays_t) / (plain_t / rays_p):.2f}x)")


if __name__ == "__main__":
    sys.exit(main())
