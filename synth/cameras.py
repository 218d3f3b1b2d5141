"""Tourist-like camera collections around a procedural landmark, and Mitsuba sensors.

Cameras follow :mod:`physrelight.camera`: the camera frame has x right, y up, z towards
the viewer (it looks down -z), ``K`` acts on ``(x, -y, -z)``, pixel centres sit at
``(j + 0.5, i + 0.5)``, and ``world_to_camera`` maps world points into that frame.

:func:`sample_views` draws ``n_views`` views the way a photo collection of a landmark
looks: eye mostly at standing height (some from balconies or walls above), distance
1.2-4x the landmark's bounding radius (log-uniform), yaw over +-120 deg around the
landmark's front, horizontal field of view 35-75 deg (narrower when far: tourists zoom),
aimed at the landmark with jitter, a level horizon up to a small roll (sd 1 deg) and the
pitch kept within +-35 deg. Every view is ray cast (numpy, on a coarse 24 x 24 grid of
pixel centres) and kept only if at least 5 % of its rays see sky (miss everything), at
least 15 % first hit the landmark and at most 35 % hit props or trees; the eye never
stands inside the landmark, a prop or a tree. The landmark-coverage test is what shapes
the accepted distances: over 20 scenes they span 1.2-3.8 radii with a median of 1.7
(far views of flat or slender landmarks cover too little of the frame).

:func:`to_mitsuba_sensor` gives the matching Mitsuba ``perspective`` sensor dict.
Mitsuba's camera looks down its local +z with +y up and +x to the *left* of the image
(``look_at`` builds ``[left, up, dir]``), so its local frame is ours with x and z
negated::

    to_world = camera_to_world @ diag(-1, 1, -1, 1)

(verified in ``tests/synth/test_cameras.py``: every pixel's Mitsuba ray hits a point
that :func:`physrelight.camera.project` puts back on that pixel's centre).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from physrelight.camera import Camera, intrinsics_from_fov, look_at, scale_intrinsics

from .scene import SceneSpec

__all__ = [
    "MITSUBA_FLIP",
    "camera_rays",
    "cast_rays",
    "sample_views",
    "to_mitsuba_sensor",
    "view_coverage",
]

# Our camera frame -> Mitsuba's local camera frame (x left, y up, z forward).
MITSUBA_FLIP = np.diag([-1.0, 1.0, -1.0, 1.0])

_CHUNK = 64  # triangles per bounding box in the ray caster


# --------------------------------------------------------------------------------------
# Ray casting (numpy; trimesh's ray module needs rtree/embree, which we do not ship)
# --------------------------------------------------------------------------------------


@dataclass
class _Accel:
    v0: np.ndarray  # (M, 3)
    e1: np.ndarray  # (M, 3)
    e2: np.ndarray  # (M, 3)
    part: np.ndarray  # (M,) part index
    lo: np.ndarray  # (C, 3) chunk boxes
    hi: np.ndarray  # (C, 3)
    starts: np.ndarray  # (C + 1,) triangle ranges of the chunks
    key: tuple[int, ...]  # ids of the meshes it was built from


_ACCEL: "weakref.WeakKeyDictionary[SceneSpec, _Accel]" = weakref.WeakKeyDictionary()


def _accel(spec: SceneSpec) -> _Accel:
    """Triangles of the scene in chunks of consecutive faces with a box each (cached
    per scene; rebuilt if ``spec.parts`` was replaced)."""
    key = tuple(id(p.mesh) for p in spec.parts)
    acc = _ACCEL.get(spec)
    if acc is not None and acc.key == key:
        return acc
    tris, part, starts = [], [], [0]
    for k, p in enumerate(spec.parts):
        t = np.asarray(p.mesh.vertices, dtype=np.float64)[np.asarray(p.mesh.faces)]
        tris.append(t)
        part.append(np.full(len(t), k))
        # Chunks never span two parts; consecutive faces belong to one primitive, so
        # chunk boxes are tight.
        starts += list(range(starts[-1] + _CHUNK, starts[-1] + len(t), _CHUNK)) + [starts[-1] + len(t)]
    T = np.concatenate(tris)
    st = np.asarray(starts)
    lo = np.stack([T[a:b].reshape(-1, 3).min(axis=0) for a, b in zip(st[:-1], st[1:])])
    hi = np.stack([T[a:b].reshape(-1, 3).max(axis=0) for a, b in zip(st[:-1], st[1:])])
    acc = _Accel(T[:, 0], T[:, 1] - T[:, 0], T[:, 2] - T[:, 0], np.concatenate(part), lo, hi, st, key)
    _ACCEL[spec] = acc
    return acc


def cast_rays(spec: SceneSpec, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First hit of each ray with the scene's triangles (both sides count).

    Args:
        spec: the scene.
        origins, directions: ``(N, 3)`` world-space rays (directions need not be unit).

    Returns:
        ``t (N,)`` ray parameter of the first hit (inf on a miss) and ``part (N,)`` int
        index into ``spec.parts`` (-1 on a miss).
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if o.shape != d.shape:
        raise ValueError(f"origins {o.shape} and directions {d.shape} must have the same shape (N, 3)")
    if not (np.isfinite(o).all() and np.isfinite(d).all()):
        raise ValueError("origins and directions must be finite")
    acc = _accel(spec)
    n = len(o)
    best_t = np.full(n, np.inf)
    best_p = np.full(n, -1, dtype=np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(d == 0.0, np.copysign(1e300, d), 1.0 / d)
        t0 = (acc.lo[None] - o[:, None]) * inv[:, None]  # (N, C, 3) slab test
        t1 = (acc.hi[None] - o[:, None]) * inv[:, None]
    tmin = np.nan_to_num(np.minimum(t0, t1), nan=-np.inf).max(axis=2)
    tmax = np.nan_to_num(np.maximum(t0, t1), nan=np.inf).min(axis=2)
    hit_box = tmax >= np.maximum(tmin, 0.0)
    for c in np.argsort(np.where(hit_box, tmin, np.inf).min(axis=0)):  # near boxes first: more culling
        rays = np.nonzero(hit_box[:, c] & (tmin[:, c] < best_t))[0]
        if len(rays) == 0:
            continue
        a, b = acc.starts[c], acc.starts[c + 1]
        ro, rd = o[rays, None], d[rays, None]  # (k, 1, 3)
        v0, e1, e2 = acc.v0[None, a:b], acc.e1[None, a:b], acc.e2[None, a:b]
        # Moller-Trumbore, (k, m) pairs.
        p = np.cross(rd, e2)
        det = np.einsum("kmi,kmi->km", np.broadcast_to(e1, p.shape), p)
        ok = np.abs(det) > 1e-12
        inv_det = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = ro - v0
        u = np.einsum("kmi,kmi->km", s, p) * inv_det
        q = np.cross(s, e1)
        v = np.einsum("kmi,kmi->km", np.broadcast_to(rd, q.shape), q) * inv_det
        t = np.einsum("kmi,kmi->km", np.broadcast_to(e2, q.shape), q) * inv_det
        valid = ok & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 1e-9)
        t = np.where(valid, t, np.inf)
        j = np.argmin(t, axis=1)
        tj = t[np.arange(len(rays)), j]
        better = tj < best_t[rays]
        best_t[rays[better]] = tj[better]
        best_p[rays[better]] = acc.part[a + j[better]]
    return best_t, best_p


def camera_rays(camera: Camera, nx: int | None = None, ny: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World-space rays through pixel centres (of the image or of a coarser grid).

    Args:
        camera: a single (unbatched) camera.
        nx, ny: grid size; the rays pass through the centres of an ``ny x nx`` grid
            of equal cells covering the image (default: the camera's own pixels).

    Returns:
        origins ``(ny * nx, 3)`` (all the camera centre) and unit directions
        ``(ny * nx, 3)``, row-major (row i = image row from the top).
    """
    K, T = _single(camera)
    nx = camera.width if nx is None else int(nx)
    ny = camera.height if ny is None else int(ny)
    if nx < 1 or ny < 1:
        raise ValueError(f"grid size must be positive, got nx={nx}, ny={ny}")
    u = (np.arange(nx) + 0.5) * (camera.width / nx)
    v = (np.arange(ny) + 0.5) * (camera.height / ny)
    uu, vv = np.meshgrid(u, v)
    pix = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], axis=1)
    vis = pix @ np.linalg.inv(K).T  # vision frame (x right, y down, z forward), z = 1
    dirs_cam = vis * np.array([1.0, -1.0, -1.0])  # our camera frame
    R, t = T[:3, :3], T[:3, 3]
    dirs = dirs_cam @ R  # R^T d for each row
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    eye = -R.T @ t
    return np.tile(eye, (len(dirs), 1)), dirs


def view_coverage(spec: SceneSpec, camera: Camera, probe: int = 24) -> dict[str, float]:
    """What a ``probe x probe`` grid of rays through the image sees first.

    Returns:
        fractions of the rays ``{"sky", "landmark", "prop", "tree", "ground"}`` (sum 1;
        sky = the ray misses everything).
    """
    o, d = camera_rays(camera, probe, probe)
    _, part = cast_rays(spec, o, d)
    roles = np.array([p.role for p in spec.parts] + ["sky"])
    first = roles[part]  # part == -1 picks the trailing "sky"
    return {r: float(np.mean(first == r)) for r in ("sky", "landmark", "prop", "tree", "ground")}


def _single(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    K = camera.K.detach().cpu().numpy().astype(np.float64)
    T = camera.world_to_camera.detach().cpu().numpy().astype(np.float64)
    if K.shape != (3, 3) or T.shape != (4, 4):
        raise ValueError(f"expected a single camera (K (3, 3), world_to_camera (4, 4)), got {K.shape}, {T.shape}")
    return K, T


# --------------------------------------------------------------------------------------
# Sampling
# --------------------------------------------------------------------------------------


def _rotate_about(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues rotation of ``v`` about the unit ``axis``."""
    c, s = math.cos(angle), math.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * (axis @ v) * (1.0 - c)


def _eye_blocked(spec: SceneSpec, eye: np.ndarray) -> bool:
    """True when the eye is inside (or within a small margin of) the landmark, a prop or a tree."""
    lo, hi = spec.landmark_bounds
    if np.all(eye > lo - 1.0) and np.all(eye < hi + 1.0):
        return True
    for x, z, r, top in spec.obstacles:
        if math.hypot(eye[0] - x, eye[2] - z) < r + 0.75 and eye[1] < top + 0.5:
            return True
    return False


def sample_views(
    spec: SceneSpec,
    n_views: int,
    seed: int,
    width: int,
    height: int,
    *,
    fov_range: tuple[float, float] = (35.0, 75.0),
    distance_range: tuple[float, float] = (1.2, 4.0),
    yaw_range_deg: float = 120.0,
    elevated_fraction: float = 0.25,
    min_sky: float = 0.05,
    min_landmark: float = 0.15,
    max_occluded: float = 0.35,
    probe: int = 24,
    max_attempts: int = 200,
) -> list[Camera]:
    """A tourist-like photo collection of the scene's landmark.

    Args:
        spec: the scene (:func:`synth.scene.generate_scene`).
        n_views: number of views V >= 1.
        seed: non-negative integer; the views depend on it and on ``spec.seed``, and
            the same pair gives the same cameras.
        width, height: image size in pixels.
        fov_range: horizontal field of view range ``(f0, f1)`` in degrees: uniform in
            ``[f0, f1 - 0.7 (f1 - f0) u]`` where ``u`` in [0, 1] is the view's position
            in the log-distance range (far views zoom in).
        distance_range: horizontal eye distance from the landmark centre, in units of
            ``spec.landmark_radius`` (log-uniform: near views are as common as far ones).
        yaw_range_deg: views come from within +- this angle of the landmark's front.
        elevated_fraction: share of views taken from above standing height (3 m up to
            the landmark's height, at most 30 m); the others are at 1.4-1.9 m.
        min_sky, min_landmark: acceptance thresholds on the ray-cast fractions.
        max_occluded: at most this fraction of the rays may first hit props or trees
            (a tree in the foreground is fine, a view filled by one is not).
        probe: ray grid size for the acceptance test (``probe x probe`` rays).
        max_attempts: candidate views tried per view; after each tenth of them the
            distance and lens ranges shrink by 25 % towards
            ``(distance_range[0], fov_range[0])``. When none passes, the candidate
            closest to the thresholds is taken if it reaches at least half of each
            (and passes ``max_occluded``): a slender landmark that covers 13 % of the
            frame at best is still a view of it, and one hard scene must not stop a
            dataset of hundreds.

    Returns:
        ``n_views`` single :class:`physrelight.camera.Camera` s (float64, centred
        principal point, square pixels).

    Raises:
        ValueError: bad arguments, or no view within ``max_attempts`` reaching even half
            of the thresholds (the message gives the best fractions seen).
    """
    for name, val, lo_ in (("n_views", n_views, 1), ("width", width, 1), ("height", height, 1),
                           ("probe", probe, 2), ("max_attempts", max_attempts, 1)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < lo_:
            raise ValueError(f"{name} must be an integer >= {lo_}, got {val!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    f0, f1 = fov_range
    d0, d1 = distance_range
    if not 0.0 < f0 <= f1 < 180.0:
        raise ValueError(f"fov_range must satisfy 0 < lo <= hi < 180 degrees, got {fov_range}")
    if not 0.0 < d0 <= d1:
        raise ValueError(f"distance_range must satisfy 0 < lo <= hi, got {distance_range}")
    if not (0.0 <= min_sky < 1.0 and 0.0 <= min_landmark < 1.0 and min_sky + min_landmark <= 1.0):
        raise ValueError(f"min_sky={min_sky} and min_landmark={min_landmark} must be fractions summing to <= 1")
    if not 0.0 <= elevated_fraction <= 1.0:
        raise ValueError(f"elevated_fraction must lie in [0, 1], got {elevated_fraction}")

    rng = np.random.default_rng([int(seed), int(spec.seed)])
    lo, hi = spec.landmark_bounds
    center = spec.landmark_center
    radius = spec.landmark_radius
    ext = hi - lo
    max_pitch = math.radians(35.0)
    cams: list[Camera] = []
    for k in range(n_views):
        best, best_cam = (-1.0, -1.0), None
        for attempt in range(max_attempts):
            yaw = spec.front_yaw + math.radians(rng.uniform(-yaw_range_deg, yaw_range_deg))
            # Slender landmarks (a column, a thin tower) rarely cover 15 % of a wide or
            # distant frame: after each failed tenth of the attempts, draw distance and
            # lens from a range shrunk towards the near end and the narrow lens (easy
            # landmarks are accepted within the first few attempts, unaffected).
            reach = 0.75 ** (10 * attempt // max_attempts)
            u = rng.uniform(0.0, 1.0)
            dist = radius * d0 * (d1 / d0) ** (u * reach)  # log-uniform
            if rng.random() < elevated_fraction:
                eye_h = rng.uniform(3.0, max(4.0, min(ext[1], 30.0)))
            else:
                eye_h = rng.uniform(1.4, 1.9)
            # Far from the landmark a tourist zooms in: the widest lens allowed shrinks
            # linearly in log-distance to 30 % of the way from f0 to f1 at the far end.
            fov = rng.uniform(f0, f0 + (f1 - f0) * reach * (1.0 - 0.7 * u))
            target = np.array([
                center[0] + rng.normal(0.0, 0.12 * ext[0]),
                lo[1] + rng.uniform(0.2, 0.6) * ext[1],
                center[2] + rng.normal(0.0, 0.12 * ext[2]),
            ])
            roll = math.radians(float(np.clip(rng.normal(0.0, 1.0), -3.0, 3.0)))
            eye = np.array([center[0] + dist * math.sin(yaw), eye_h, center[2] + dist * math.cos(yaw)])
            if _eye_blocked(spec, eye):
                continue
            hd = math.hypot(*(target - eye)[[0, 2]])
            dy = float(np.clip(target[1] - eye[1], -math.tan(max_pitch) * hd, math.tan(max_pitch) * hd))
            target[1] = eye[1] + dy  # a tourist tilts the camera, but not to the zenith
            fwd = (target - eye) / np.linalg.norm(target - eye)
            up = _rotate_about(np.array([0.0, 1.0, 0.0]), fwd, roll)
            T = look_at(eye, target, up)
            K = intrinsics_from_fov(float(fov), int(width), int(height))
            cam = Camera(K=K, world_to_camera=T, width=int(width), height=int(height))
            cov = view_coverage(spec, cam, probe)
            sky, lm = cov["sky"], cov["landmark"]
            clear = cov["prop"] + cov["tree"] <= max_occluded
            if sky >= min_sky and lm >= min_landmark and clear:
                cams.append(cam)
                break
            if clear and min(sky - min_sky, lm - min_landmark) > min(best[0] - min_sky, best[1] - min_landmark):
                best, best_cam = (sky, lm), cam
        else:
            if best_cam is not None and best[0] >= 0.5 * min_sky and best[1] >= 0.5 * min_landmark:
                cams.append(best_cam)
                continue
            raise ValueError(
                f"no view {k} of scene seed {spec.seed} ({spec.landmark_type}) reached sky >= {min_sky} and "
                f"landmark >= {min_landmark} in {max_attempts} attempts, nor half of them (best unoccluded view: "
                f"sky {best[0]:.3f}, landmark {best[1]:.3f}); widen distance_range/fov_range or lower the thresholds"
            )
    return cams


def scaled_camera(camera: Camera, scale: int) -> Camera:
    """The same camera with ``scale`` times the pixels on each side (:func:`physrelight.camera.scale_intrinsics`:
    pixel ``(u, v)`` of ``camera`` covers pixels ``[scale u, scale (u + 1))`` of the result)."""
    if isinstance(scale, bool) or not isinstance(scale, (int, np.integer)) or scale < 1:
        raise ValueError(f"scale must be an integer >= 1, got {scale!r}")
    K, T = _single(camera)
    return Camera(K=scale_intrinsics(K, int(scale)), world_to_camera=T, width=int(camera.width) * int(scale),
                  height=int(camera.height) * int(scale))


# --------------------------------------------------------------------------------------
# Mitsuba
# --------------------------------------------------------------------------------------


def to_mitsuba_sensor(camera: Camera, spp: int, mi: ModuleType, seed: int = 0) -> dict[str, Any]:
    """Mitsuba ``perspective`` sensor dict matching ``camera`` exactly.

    Film ``hdrfilm`` (RGB, ``width x height``) with a box reconstruction filter (each
    sample lands in its own pixel only), sampler ``independent`` with ``spp`` samples
    and ``seed``. ``fov`` is the horizontal one (``fov_axis='x'``) from ``K``.

    Args:
        camera: single camera with square pixels, no skew and a centred principal point
            (what :func:`sample_views` makes).
        spp: samples per pixel >= 1.
        mi: the Mitsuba module from :func:`synth.backend.load_mitsuba`.
        seed: sampler seed.

    Raises:
        ValueError: batched camera, non-square pixels, skew or an off-centre principal point.
    """
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise ValueError(f"spp must be an integer >= 1, got {spp!r}")
    K, T = _single(camera)
    W, H = camera.width, camera.height
    fx, fy, cx, cy, skew = K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]
    if abs(fx - fy) > 1e-6 * fx:
        raise ValueError(f"Mitsuba's perspective sensor needs square pixels (fx == fy), got fx={fx}, fy={fy}")
    if abs(skew) > 1e-9:
        raise ValueError(f"Mitsuba's perspective sensor has no skew, got K[0, 1]={skew}")
    if abs(cx - W / 2) > 1e-6 or abs(cy - H / 2) > 1e-6:
        raise ValueError(f"principal point must be the image centre ({W / 2}, {H / 2}), got ({cx}, {cy})")
    fov_x = math.degrees(2.0 * math.atan(0.5 * W / fx))
    cam_to_world = np.linalg.inv(T)
    to_world = cam_to_world @ MITSUBA_FLIP
    return {
        "type": "perspective",
        "fov": fov_x,
        "fov_axis": "x",
        "to_world": mi.ScalarTransform4f(to_world.tolist()),
        "near_clip": 0.01,
        "far_clip": 1.0e5,
        "film": {
            "type": "hdrfilm",
            "width": int(W),
            "height": int(H),
            "pixel_format": "rgb",
            "rfilter": {"type": "box"},
        },
        "sampler": {"type": "independent", "sample_count": int(spp), "seed": int(seed)},
    }
