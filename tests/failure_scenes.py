"""Scenes where sampling strategies fail (issue 4), in two forms:

* *point setups* for `drt.estimators`: a LightSet, a MaterialTable and shading points, so a test
  can measure per-sample variance of each estimator exactly where it fails, in milliseconds;
* *render scenes* (header, arrays) for the whole renderer and the bench: the same situations
  seen through a camera.

Scenes: a small bright light over a diffuse floor; Veach's plates (four glossy plates of rising
roughness, four sphere lights of very different radii and equal power); a near-specular surface
reflecting a large light; a caustic (a glass sphere focusing a small light onto a diffuse floor);
a scene with easy and hard regions for adaptive sampling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drt.estimators import DirectLight, ShadingPoints
from drt.lights import LightSet
from drt.materials import MaterialTable
from scene_builders import add_material, add_mesh, base_header, look_at, quad, translation, uv_sphere

# Veach's plates: Blender roughness (GGX α = roughness²) of the four plates, sharpest first,
# and the radii of the four sphere lights (equal power, so radiance ∝ 1/r²)
PLATE_ROUGHNESS = (0.05, 0.1, 0.2, 0.35)
LIGHT_RADII = (0.03, 0.1, 0.3, 0.9)
LIGHT_X = (-3.75, -1.25, 1.25, 3.75)
LIGHT_POWER = 100.0


@dataclass
class PointSetup:
    """Lights, materials and shading points for `drt.estimators.DirectLight`."""

    lights: LightSet
    materials: MaterialTable
    points: ShadingPoints

    def direct(self, occluded=None) -> DirectLight:
        return DirectLight(self.lights, self.materials, occluded)


def _sphere_light(center, radius, power):
    return {"type": "POINT", "matrix_world": translation(*center), "color": [1, 1, 1],
            "power": power, "radius": radius, "soft_falloff": False}


def _materials(*lobes_list):
    return MaterialTable.from_scene([{"name": f"m{i}", "lobes": lobes, "emission": [0, 0, 0]}
                                     for i, lobes in enumerate(lobes_list)])


DIFFUSE = [{"type": "DIFFUSE", "color": [0.8, 0.8, 0.8]}]


def glossy(roughness):
    return [{"type": "GLOSSY", "color": [0.8, 0.8, 0.8], "roughness": roughness}]


# --------------------------------------------------------------------------- point setups


def small_light_points(radius=0.02, height=1.0, power=50.0, count=16) -> PointSetup:
    """A small bright sphere light above a diffuse floor; points spread under it."""
    lights = LightSet([_sphere_light((0, 0, height), radius, power)])
    x = np.linspace(-0.5, 0.5, count)
    p = np.stack([x, 0.3 * x[::-1], np.zeros(count)], axis=1)
    pts = ShadingPoints(p, (0, 0, 1), (0, 0, 1), 0)
    return PointSetup(lights, _materials(DIFFUSE), pts)


def veach_points(plate: int, distance=4.0, view_angle=math.radians(60)) -> PointSetup:
    """One of Veach's plates (index into PLATE_ROUGHNESS) under the four sphere lights.

    The plate is the plane z = 0 seen from direction wo at ``view_angle`` from its normal; the
    lights lie on a line across the mirror direction, ``distance`` away. There is one shading
    point per light, placed so its mirror direction aims at that light's centre: the plate's
    total variance covers all four reflections, as in Veach's image."""
    wo = np.array([0.0, -math.sin(view_angle), math.cos(view_angle)])
    mirror = np.array([0.0, math.sin(view_angle), math.cos(view_angle)])
    centres = [np.array([x, 0.0, 0.0]) + distance * mirror for x in LIGHT_X]
    lights = LightSet([_sphere_light(c, r, LIGHT_POWER) for c, r in zip(centres, LIGHT_RADII)])
    p = np.array([[x, 0.0, 0.0] for x in LIGHT_X])
    pts = ShadingPoints(p, (0, 0, 1), wo, 0)
    return PointSetup(lights, _materials(glossy(PLATE_ROUGHNESS[plate])), pts)


def near_specular_points(roughness=0.05, size=4.0, height=2.0, count=8) -> PointSetup:
    """A near-mirror surface (GGX α = roughness²) reflecting a large area light."""
    light = {"type": "AREA", "matrix_world": translation(0, 0, height), "color": [1, 1, 1],
             "power": 400.0, "shape": "SQUARE", "size": size}
    wo = np.array([0.0, -math.sin(0.3), math.cos(0.3)])
    x = np.linspace(-0.4, 0.4, count)
    p = np.stack([x, np.zeros(count), np.zeros(count)], axis=1)
    return PointSetup(LightSet([light]), _materials(glossy(roughness)), ShadingPoints(p, (0, 0, 1), wo, 0))


def many_lights_points(count=64, grid=8, spacing=1.0, height=0.5, seed=0, selection="DISTANCE") -> PointSetup:
    """A grid of ``grid``² small sphere lights of random power low over a diffuse floor: each
    shading point is lit mostly by its few nearest lights (the case for distance-aware
    selection)."""
    rng = np.random.default_rng(seed)
    xs = (np.arange(grid) - (grid - 1) / 2) * spacing
    lights = [_sphere_light((x, y, height), 0.05, float(p))
              for (x, y), p in zip(((x, y) for x in xs for y in xs), rng.uniform(5, 20, grid * grid))]
    p = np.concatenate([rng.uniform(xs[0], xs[-1], size=(count, 2)), np.zeros((count, 1))], axis=1)
    return PointSetup(LightSet(lights, selection=selection), _materials(DIFFUSE), ShadingPoints(p, (0, 0, 1), (0, 0, 1), 0))


# --------------------------------------------------------------------------- render scenes


def small_light_scene(width=32, height=32, spp=16):
    """A diffuse floor under a small, bright sphere light, seen from above."""
    h = base_header(width, height, spp, camera={"type": "PERSP", "matrix_world": look_at((0, -3, 2.5), (0, 0, 0)),
                                                "lens": 35.0})
    a = {}
    add_mesh(h, a, "floor", *quad((0, 0, 0), (3, 0, 0), (0, 3, 0)), material=add_material(h, "floor", DIFFUSE))
    h["lights"].append(_sphere_light((0, 0, 1.0), 0.02, 50.0))
    return h, a


def veach_scene(width=64, height=48, spp=16):
    """Veach's plates: four glossy plates (roughness rising toward the camera) reflecting four
    equal-power sphere lights of radii 0.03 .. 0.9, plus a dim fill light."""
    cam_pos, target = np.array([0.0, -9.0, 4.5]), np.array([0.0, 0.0, 0.6])
    h = base_header(width, height, spp, camera={"type": "PERSP", "matrix_world": look_at(cam_pos, target), "lens": 40.0},
                    max_bounces=0)
    a = {}
    light_y, light_z = 4.0, 3.0
    for k, rough in enumerate(PLATE_ROUGHNESS):
        m = add_material(h, f"plate{k}", glossy(rough))
        y = -1.6 + 1.05 * k
        z = 0.25 * k
        centre = np.array([0.0, y, z])
        # tilt each plate so the camera sees the lights mirrored in it (normal = half vector)
        to_cam = cam_pos - centre
        to_light = np.array([0.0, light_y, light_z]) - centre
        normal = to_cam / np.linalg.norm(to_cam) + to_light / np.linalg.norm(to_light)
        normal /= np.linalg.norm(normal)
        u = np.array([4.5, 0.0, 0.0])
        v = np.cross(normal, u / np.linalg.norm(u)) * 0.42
        add_mesh(h, a, f"plate{k}", *quad(centre, u, v), material=m)
    for x, r in zip(LIGHT_X, LIGHT_RADII):
        h["lights"].append(dict(_sphere_light((x, light_y, light_z), r, LIGHT_POWER), visible_camera=True))
    h["lights"].append({"type": "POINT", "matrix_world": translation(0, -6, 6), "color": [1, 1, 1],
                        "power": 50.0, "radius": 0.0})
    return h, a


def caustic_scene(width=24, height=24, spp=64, clamp_indirect=0.0):
    """A clear glass ball focusing a small sphere light onto a diffuse floor: the caustic is
    reachable only by paths floor → glass → glass → light found by BSDF sampling (fireflies)."""
    h = base_header(width, height, spp, camera={"type": "PERSP", "matrix_world": look_at((0, -2.2, 2.2), (0, 0, 0)),
                                                "lens": 40.0},
                    clamp_indirect=clamp_indirect, max_bounces=4)
    a = {}
    add_mesh(h, a, "floor", *quad((0, 0, 0), (3, 0, 0), (0, 3, 0)), material=add_material(h, "floor", DIFFUSE))
    glass = add_material(h, "glass", [{"type": "GLASS", "color": [1, 1, 1], "roughness": 0.0, "ior": 1.5}])
    pos, tri, nrm = uv_sphere(0.35, center=(0, 0, 0.55), rings=24, segments=48)
    add_mesh(h, a, "ball", pos, tri, material=glass, normals=nrm)
    # the light is off to the side so the caustic lands beside the ball, in view (x ≈ 0.55)
    h["lights"].append(_sphere_light((-1.5, 0.0, 2.0), 0.05, 200.0))
    return h, a


def mixed_scene(width=32, height=32, spp=64):
    """Easy and hard regions side by side (for adaptive sampling): the left half of the image
    sees a diffuse floor lit evenly by a big overhead area light (low variance); the right half
    sees a rough glossy floor reflecting a small sphere light, with soft shadows of a post."""
    h = base_header(width, height, spp, camera={"type": "PERSP", "matrix_world": look_at((0, -3, 3), (0, 0, 0)),
                                                "lens": 35.0}, max_bounces=0)
    a = {}
    d = add_material(h, "matte", DIFFUSE)
    g = add_material(h, "glossy", glossy(0.25))
    add_mesh(h, a, "left", *quad((-1, 0, 0), (1, 0, 0), (0, 2, 0)), material=d)
    add_mesh(h, a, "right", *quad((1, 0, 0), (1, 0, 0), (0, 2, 0)), material=g)
    h["lights"].append({"type": "AREA", "matrix_world": translation(-1, 0, 3), "color": [1, 1, 1],
                        "power": 300.0, "shape": "SQUARE", "size": 3.0})
    h["lights"].append(_sphere_light((1.2, 1.2, 0.8), 0.15, 40.0))
    return h, a
