"""Every light type over a white floor, each lighting its own patch:
point (radius 0 and soft-falloff radius), spot (size, blend), sun (angle), area square,
rectangle with spread, disk, ellipse, and an emissive quad; world black.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common as C  # noqa: E402
import bpy  # noqa: E402

FINISH = dict(resolution=(160, 80), samples=16)


def build():
    scene = C.reset()
    C.quad("Floor", (0, 0, 0), (14.0, 6.0), C.diffuse("White", (0.8, 0.8, 0.8)))
    C.box("Occluder", (0.3, 0.3, 0.6), (0.0, 0.8, 0.3), C.diffuse("Grey", (0.5, 0.5, 0.5)))
    # Three posts sharing one mesh (linked duplicates), then the set instanced once more
    # through a collection instance: the exporter must store the post mesh once.
    posts = bpy.data.collections.new("Posts")
    scene.collection.children.link(posts)
    post = C.box("Post", (0.1, 0.1, 0.4), (-6.5, 1.5, 0.2), C.diffuse("PostMat", (0.7, 0.7, 0.2)))
    for i in range(3):
        o = post if i == 0 else bpy.data.objects.new(f"Post{i}", post.data)
        if i:
            o.location = (-6.5 + 0.4 * i, 1.5, 0.2)
        for c in list(o.users_collection):
            c.objects.unlink(o)
        posts.objects.link(o)
    inst = bpy.data.objects.new("PostsInstance", None)
    inst.instance_type = "COLLECTION"
    inst.instance_collection = posts
    inst.location = (0.0, 1.0, 0.0)
    scene.collection.objects.link(inst)
    h = 1.5
    C.light("Point", "POINT", (-5.5, 0, h), energy=60.0, shadow_soft_size=0.0)
    C.light("PointSoft", "POINT", (-4.0, 0, h), energy=60.0, shadow_soft_size=0.25,
            color=(1.0, 0.8, 0.6))
    C.light("Spot", "SPOT", (-2.5, 0, h), energy=150.0, spot_size=C.deg(60), spot_blend=0.3,
            shadow_soft_size=0.05)
    C.light("Square", "AREA", (-1.0, 0, h), shape="SQUARE", size=0.6, energy=40.0)
    C.light("RectSpread", "AREA", (0.5, 0, h), shape="RECTANGLE", size=0.8, size_y=0.3,
            spread=C.deg(60), energy=40.0, color=(0.6, 0.8, 1.0))
    C.light("Disk", "AREA", (2.0, 0, h), shape="DISK", size=0.6, energy=40.0)
    C.light("Ellipse", "AREA", (3.5, 0, h), shape="ELLIPSE", size=0.9, size_y=0.3, energy=40.0,
            rotation=(0, 0, C.deg(45)))
    C.quad("Emitter", (5.0, 0, h), 0.5, C.emission("Glow", (1.0, 0.9, 0.7), 15.0),
           rotation=(C.deg(180), 0, 0))
    C.light("Sun", "SUN", (0, 0, 10), rotation=(C.deg(50), 0, C.deg(-30)),
            energy=0.3, angle=C.deg(10), color=(0.8, 0.85, 1.0))
    C.camera((0.0, -9.0, 6.0), (0.0, 0.0, 0.0), lens=35.0)
    return scene


if __name__ == "__main__":
    C.finish(build(), "all_lights", **FINISH)
