"""Showcase: a product shot a Blender user would recognise, at 1280x720.

Real scanned and modelled meshes (the Stanford bunny in red plastic, Newell's teapot in copper,
Spot the cow with a checker texture on its UVs, Suzanne in brushed gold) on a wooden floor (an
image texture of planks, painted by the script and packed into the .blend) in front of a
backdrop, lit by a sun and a sky-blue world with a soft fill light; the camera focuses on the
bunny at f/2.8 (depth of field), and a ball rolls past in front (motion blur).

The two textured materials are matte (Specular IOR Level 0): with Blender's default 0.5, DRT's
simplified Principled specular layer (issue 11's Principled v2 part) makes the large wooden
floor 2-4 % darker than Cycles's, the only visible difference in the comparison picture.

Meshes come from ../shared/data/meshes (unmodified public test models, see its README); the
script bakes them into the .blend, so only building the scene needs them.

    python blend_scenes/showcase.py             # -> showcase.blend, showcase.npz
"""

import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402

FINISH = dict(resolution=(1280, 720), samples=128)
MESHES = os.path.join(C.REPO, "..", "shared", "data", "meshes")


def principled(name, color, metallic=0.0, roughness=0.5, specular=0.5):
    mat, nodes, out = C._new_material(name)
    n = nodes.new("ShaderNodeBsdfPrincipled")
    n.inputs["Base Color"].default_value = C._rgba(color)
    n.inputs["Metallic"].default_value = metallic
    n.inputs["Roughness"].default_value = roughness
    key = "Specular IOR Level" if "Specular IOR Level" in n.inputs else "Specular"
    n.inputs[key].default_value = specular
    mat.node_tree.links.new(n.outputs[0], out.inputs["Surface"])
    mat.diffuse_color = C._rgba(color)
    return mat


def import_obj(filename, name, height, location, rotation_z, material, smooth=True):
    """Import an OBJ (Y up, as the files are), scale it to ``height`` and stand it on the floor
    at ``location`` (x, y), turned by ``rotation_z`` radians."""
    path = os.path.normpath(os.path.join(MESHES, filename))
    if not os.path.exists(path):
        raise SystemExit(f"showcase needs {path} (the shared test meshes)")
    bpy.ops.object.select_all(action="DESELECT")
    bpy.ops.wm.obj_import(filepath=path, forward_axis="NEGATIVE_Z", up_axis="Y")
    obj = bpy.context.selected_objects[0]
    obj.name = obj.data.name = name
    # the importer turns Y-up into Blender's Z-up with an object rotation: bake it into the mesh
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    obj.data.materials.clear()
    obj.data.materials.append(material)
    obj.data.polygons.foreach_set("use_smooth", [smooth] * len(obj.data.polygons))
    # centre on the origin, base at z = 0, then scale: all in the mesh so the object is clean
    xs = [v.co.x for v in obj.data.vertices]
    ys = [v.co.y for v in obj.data.vertices]
    zs = [v.co.z for v in obj.data.vertices]
    cx, cy, z0 = (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2, min(zs)
    s = height / (max(zs) - z0)
    for v in obj.data.vertices:
        v.co.x, v.co.y, v.co.z = (v.co.x - cx) * s, (v.co.y - cy) * s, (v.co.z - z0) * s
    obj.data.update()
    obj.location = (location[0], location[1], 0.0)
    obj.rotation_euler = (0.0, 0.0, rotation_z)
    return obj


def plank_floor(name, size, repeats):
    """A ``size`` m square floor with UVs, its Principled base colour an image texture of
    planks (painted by textured.py's generator, packed into the .blend) repeated ``repeats``
    times each way through a Mapping node."""
    import textured

    mat, nodes, out = C._new_material(name)
    nt = mat.node_tree
    img = bpy.data.images.new("showcase_planks", 256, 256, alpha=False, float_buffer=False)
    img.pixels.foreach_set(textured.plank_pixels(256, 256, seed=11).reshape(-1).astype("float32"))
    img.pack()
    tc = nodes.new("ShaderNodeTexCoord")
    mp = nodes.new("ShaderNodeMapping")
    mp.inputs["Scale"].default_value = (repeats, repeats, 1.0)
    nt.links.new(tc.outputs["UV"], mp.inputs["Vector"])
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Linear"
    nt.links.new(mp.outputs[0], tex.inputs["Vector"])
    p = nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Roughness"].default_value = 0.35
    p.inputs["Specular IOR Level"].default_value = 0.0  # see the module docstring
    nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0.0, 0.0, 0.0))
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    obj.data.materials.append(mat)
    return obj


def checker_material(name, color1, color2, scale):
    """Principled base colour from a Checker texture on the mesh's UVs."""
    mat, nodes, out = C._new_material(name)
    nt = mat.node_tree
    tc = nodes.new("ShaderNodeTexCoord")
    chk = nodes.new("ShaderNodeTexChecker")
    chk.inputs["Color1"].default_value = C._rgba(color1)
    chk.inputs["Color2"].default_value = C._rgba(color2)
    chk.inputs["Scale"].default_value = scale
    nt.links.new(tc.outputs["UV"], chk.inputs["Vector"])
    p = nodes.new("ShaderNodeBsdfPrincipled")
    p.inputs["Roughness"].default_value = 0.4
    p.inputs["Specular IOR Level"].default_value = 0.0  # see the module docstring
    nt.links.new(chk.outputs["Color"], p.inputs["Base Color"])
    nt.links.new(p.outputs[0], out.inputs["Surface"])
    return mat


def build():
    scene = C.reset()
    bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"
    C.set_world(scene.world, (0.45, 0.6, 0.85), 0.45)
    plank_floor("Floor", 16.0, 8.0)
    # a backdrop wall behind the products
    C.quad("Backdrop", (0.0, 3.0, 2.5), (16.0, 5.0), C.diffuse("Backdrop", (0.55, 0.58, 0.62)),
           rotation=(C.deg(90), 0, 0))

    import_obj("stanford-bunny.obj", "Bunny", 1.0, (0.0, 0.6), C.deg(-25),
               principled("RedPlastic", (0.7, 0.06, 0.04), roughness=0.25))
    import_obj("teapot.obj", "Teapot", 0.75, (-1.6, 1.4), C.deg(-30),
               principled("Copper", (0.95, 0.64, 0.54), metallic=1.0, roughness=0.2))
    import_obj("spot.obj", "Spot", 0.9, (1.7, 1.5), C.deg(-60),
               checker_material("SpotChecker", (0.85, 0.85, 0.82), (0.12, 0.12, 0.14), 8.0))
    import_obj("suzanne.obj", "Suzanne", 0.6, (-0.9, -0.6), C.deg(25),
               principled("Gold", (1.0, 0.77, 0.34), metallic=1.0, roughness=0.35))

    # a ball rolling across the foreground: motion blur at the rendered frame
    ball = C.uv_sphere("Ball", 0.22, (0.9, -0.9, 0.22), principled("BlueRubber", (0.08, 0.2, 0.65), roughness=0.6),
                       segments=48, rings=24)
    for frame, x in ((1, 0.3), (11, 2.3)):
        ball.location.x = x
        ball.keyframe_insert("location", index=0, frame=frame)
        ball.rotation_euler.y = (x - 0.3) / 0.22
        ball.keyframe_insert("rotation_euler", index=1, frame=frame)
    C.make_linear(ball)

    C.light("Sun", "SUN", (0, 0, 10), rotation=(C.deg(50), C.deg(0), C.deg(-35)),
            energy=3.5, angle=C.deg(3))
    C.light("Fill", "AREA", (-3.0, -3.5, 3.0), rotation=(C.deg(55), 0, C.deg(-40)),
            shape="DISK", size=3.0, energy=250.0)

    cam = C.camera((0.6, -5.2, 1.5), (0.0, 0.8, 0.45), lens=50.0)
    focus = bpy.data.objects.new("Focus", None)
    scene.collection.objects.link(focus)
    focus.location = (0.0, 0.6, 0.45)
    dof = cam.data.dof
    dof.use_dof = True
    dof.focus_object = focus
    dof.aperture_fstop = 2.8

    scene.frame_start, scene.frame_end = 1, 11
    scene.frame_set(6)
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = 0.5
    scene.render.motion_blur_position = "CENTER"
    return scene


if __name__ == "__main__":
    C.finish(build(), "showcase", **FINISH)
