"""A box on a plane under a known sun, path-traced by Mitsuba 3: the reference photos of the shadow and shading cues
(physrelight.sun_from_shadows) and of their combination with the sky (physrelight.sun_estimate).

The camera stands ``eye_height`` above the ground at the origin, level (``relight``'s camera: yaw, pitch), its
pixels exactly :func:`physrelight.panorama.view_intrinsics`'s (``synth.cameras.to_mitsuba_sensor``). Normals and
the sky mask are the pixel centres' (``synth.render.render_geometry``), camera frame, as the decomposition gives."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest


@dataclass
class BoxPhoto:
    image: np.ndarray  # (H, W, 3) linear radiance
    sky_mask: np.ndarray  # (H, W) bool
    normals: np.ndarray  # (3, H, W) camera frame
    K: np.ndarray
    world_to_camera: np.ndarray  # (4, 4)
    sun: np.ndarray | None  # (3,) towards the sun, world frame


def render_box(sun_elevation: float | None, sun_azimuth: float | None, *, yaw: float = 0.0, pitch: float = -20.0,
               eye_height: float = 3.0, distance: float = 8.0, box_yaw: float = 45.0, size=(0.6, 0.6, 0.6),
               sky: str = "constant", turbidity: float = 3.0, width: int = 320, height: int = 240, fov: float = 60.0,
               spp: int = 16, seed: int = 0) -> BoxPhoto:
    """A grey plane with a box ``size`` (half extents x, y, z) standing on it ``distance`` ahead of the camera,
    turned ``box_yaw`` degrees from the camera's heading. ``sky="constant"``: a uniform bluish sky plus a
    directional sun (none when ``sun_elevation`` is None); ``sky="sunsky"``: Mitsuba's Hosek-Wilkie ``sunsky``
    (sky and sun) at ``turbidity``; ``sky="overcast"``: the CIE overcast sky as an environment map, no sun."""
    pytest.importorskip("mitsuba", reason="Mitsuba 3 renders the reference photos (pip install mitsuba)")
    from synth.backend import load_mitsuba

    mi = load_mitsuba()
    from physrelight.camera import Camera, look_at
    from physrelight.envmap import direction_from_angles
    from physrelight.panorama import view_intrinsics
    from synth import render
    from synth.cameras import to_mitsuba_sensor
    from synth.lighting import _sunsky_dict

    y, p = math.radians(yaw), math.radians(pitch)
    eye = np.array([0.0, eye_height, 0.0])
    fwd = np.array([math.sin(y) * math.cos(p), math.sin(p), -math.cos(y) * math.cos(p)])
    T = np.asarray(look_at(eye, eye + fwd, np.array([0.0, 1.0, 0.0])), dtype=np.float64)
    K = view_intrinsics(fov, width, height)
    cam = Camera(K=K, world_to_camera=T, width=width, height=height)
    at = distance * np.array([math.sin(y), 0.0, -math.cos(y)])
    hx, hy, hz = size
    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": 4},
             "sensor": to_mitsuba_sensor(cam, spp, mi, seed),
             "ground": {"type": "rectangle",
                        "to_world": mi.ScalarTransform4f().scale([200, 1, 200]).rotate([1, 0, 0], -90),
                        "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.35, 0.35, 0.35]}}},
             "box": {"type": "cube",
                     "to_world": mi.ScalarTransform4f().translate([at[0], hy, at[2]]).rotate([0, 1, 0], yaw + box_yaw)
                     .scale([hx, hy, hz]),
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.4]}}}}
    s = None if sun_elevation is None else direction_from_angles(sun_elevation, sun_azimuth)
    if sky == "sunsky":
        scene["sky"] = _sunsky_dict(mi, s, turbidity, 0.3)
    elif sky == "overcast":  # the CIE overcast sky (zenith 0.5), no sun
        from physrelight.envmap import directions
        from physrelight.sky_model import overcast_sky

        d = directions(64, 128).astype(np.float64)
        env = 0.5 * np.where(d[..., 1:2] > 0, overcast_sky(d)[..., None], 1.0 / 3.0) * np.ones(3)
        scene["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(env.astype(np.float32)))}
    else:
        scene["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.24, 0.27, 0.33]}}
        if s is not None:
            scene["sun"] = {"type": "directional", "direction": (-s).tolist(),
                            "irradiance": {"type": "rgb", "value": [3.0, 3.0, 2.7]}}
    loaded = mi.load_dict(scene)
    img = np.asarray(mi.render(loaded, spp=spp, seed=seed), dtype=np.float64)
    g = render.render_geometry(loaded, 0, cam, 1, seed)
    return BoxPhoto(image=img, sky_mask=np.asarray(g.sky_mask, bool), normals=np.moveaxis(g.normal, -1, 0).astype(np.float64),
                    K=K, world_to_camera=T, sun=s)


def azimuth_error(a: float, b: float) -> float:
    """Absolute difference of two azimuths, degrees in [0, 180]."""
    return abs((a - b + 180.0) % 360.0 - 180.0)
