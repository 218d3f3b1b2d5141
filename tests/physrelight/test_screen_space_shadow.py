"""Specification of :mod:`physrelight.screen_space_shadow`: sun visibility marched in a depth buffer.

The yardstick is an analytic scene made here in numpy: a box on a ground plane seen through a
pinhole camera, its depth and normals by exact ray casting, and the exact sun visibility by casting
a ray from every visible surface point towards the sun against the box (synth's convention: a
surface facing away from the sun counts as visible, attached shadow is shading's business).
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import torch

from physrelight.screen_space_shadow import sun_visibility

BOX_MIN = np.array([-1.0, 0.0, -1.0])
BOX_MAX = np.array([1.0, 2.0, 1.0])


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _camera(eye, target, res: int, fov_deg: float = 60.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(K (3, 3), R (3, 3) world->camera, eye (3,))`` of a pinhole looking from ``eye`` at ``target``."""
    eye = np.asarray(eye, dtype=np.float64)
    f = _unit(np.asarray(target) - eye)
    x = _unit(np.cross(f, [0.0, 1.0, 0.0]))
    y = np.cross(x, f)
    R = np.stack([x, y, -f])  # rows: camera x, y, z (z towards the viewer)
    fx = 0.5 * res / math.tan(math.radians(fov_deg) / 2)
    K = np.array([[fx, 0.0, res / 2], [0.0, fx, res / 2], [0.0, 0.0, 1.0]])
    return K, R, eye


def _box_hit(o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slab test of rays ``o (N, 3) + t d (N, 3)`` against the box: ``(t_near, t_far, axis of entry)``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1, t2 = (BOX_MIN - o) * inv, (BOX_MAX - o) * inv
    t1 = np.where(np.isnan(t1), -np.inf, t1)
    t2 = np.where(np.isnan(t2), np.inf, t2)
    lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
    return lo.max(1), hi.min(1), lo.argmax(1)


def box_scene(res: int, sun_world, eye=(5.0, 4.5, 9.0), target=(0.5, 0.3, 0.0)) -> dict[str, np.ndarray]:
    """Exact depth, normals (camera frame), object id and sun visibility of the box on the ground.

    Returns ``depth (H, W)`` z-depth (0 = sky), ``normal (H, W, 3)``, ``ids (H, W)`` (-1 sky, 0 ground,
    1 box), ``vis (H, W)`` exact visibility, ``K``, ``sun`` the camera-frame sun direction, ``up``.
    """
    K, R, eye = _camera(eye, target, res)
    s = _unit(sun_world)
    v, u = np.meshgrid(np.arange(res) + 0.5, np.arange(res) + 0.5, indexing="ij")
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], -(v - K[1, 2]) / K[1, 1], -np.ones_like(u)], -1).reshape(-1, 3)
    d = d_cam @ R  # world directions (R^T d_cam), with camera z-component -1: t is z-depth
    o = np.broadcast_to(eye, d.shape)
    t_ground = np.where(d[:, 1] < 0, -eye[1] / np.where(d[:, 1] < 0, d[:, 1], -1.0), np.inf)
    tn, tf, axis = _box_hit(o, d)
    box = (tn <= tf) & (tf > 0) & (tn > 0) & (tn < t_ground)
    t = np.where(box, tn, t_ground)
    ids = np.where(box, 1, np.where(np.isfinite(t_ground), 0, -1))
    n_world = np.zeros_like(d)
    n_world[ids == 0] = [0.0, 1.0, 0.0]
    bi = np.nonzero(box)[0]
    n_world[bi, axis[bi]] = -np.sign(d[bi, axis[bi]])
    hit = ids >= 0
    p = o + np.where(hit, t, 0.0)[:, None] * d
    # Exact visibility: a ray from the surface point (nudged off it) towards the sun against the box;
    # the ground cannot occlude a sun above the horizon; facing away = visible (synth's convention).
    tn2, tf2, _ = _box_hit(p + 1e-7 * n_world, np.broadcast_to(s, d.shape))
    blocked = (tn2 <= tf2) & (tf2 > 1e-9)
    facing = n_world @ s > 0
    vis = np.where(hit & facing & blocked, 0.0, 1.0)
    return {"depth": np.where(hit, t, 0.0).reshape(res, res), "normal": (n_world @ R.T).reshape(res, res, 3),
            "ids": ids.reshape(res, res), "vis": vis.reshape(res, res), "K": K, "sun": R @ s, "up": R[:, 1]}


def _tensors(scene: dict[str, np.ndarray]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    depth = torch.from_numpy(scene["depth"])[None, None]
    normals = torch.from_numpy(scene["normal"]).permute(2, 0, 1)[None]
    return depth, torch.from_numpy(scene["K"]), torch.from_numpy(scene["sun"])[None], normals


def _band(*maps: np.ndarray) -> np.ndarray:
    """``(H, W)`` True within one pixel (3 x 3) of a change in any of ``maps``."""
    out = np.zeros(maps[0].shape, dtype=bool)
    for m in maps:
        p = np.pad(m, 1, mode="edge")
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                out |= p[1 + di:1 + di + m.shape[0], 1 + dj:1 + dj + m.shape[1]] != m
    return out


def _agreement(scene: dict[str, np.ndarray], vis: torch.Tensor) -> tuple[float, int]:
    """Share of surface pixels outside the 1-pixel band of object and shadow edges where the
    screen-space visibility equals the exact one, and how many pixels that is."""
    keep = (scene["ids"] >= 0) & ~_band(scene["ids"], scene["vis"])
    got = vis[0, 0].numpy() > 0.5
    return float((got[keep] == (scene["vis"][keep] > 0.5)).mean()), int(keep.sum())


EYE = (3.0, 3.2, 5.0)  # close enough that the box and its shadow fill a good part of the frame


def test_01_box_on_a_plane_matches_exact_ray_cast_visibility_away_from_edges() -> None:
    """Screen-space visibility vs exact ray casting, box on a plane, 128 px, 64 steps, thickness 0.1.

    Measured (outside the 1-pixel band of object and shadow edges): sun (-0.5, 0.7, -0.5) (shadow
    falls towards the camera, in full view) 99.74 % of 14729 pixels, shadow IoU 0.976; sun
    (-0.3, 0.4, 0.8) (behind the camera's side) 99.99 %. The two failure modes of a depth buffer, not
    asserted here: a ray that passes behind the box without meeting a face the camera sees (sun
    (0.6, 0.5, -0.8): 99.35 %, missed shadow) and a ray that passes behind it within the thickness
    (sun (-0.8, 0.6, 0.1): 99.34 %, false shadow on the ground behind the box).
    """
    for sun, floor in (((-0.5, 0.7, -0.5), 0.99), ((-0.3, 0.4, 0.8), 0.99)):
        scene = box_scene(128, sun, eye=EYE)
        depth, K, s, normals = _tensors(scene)
        assert ((scene["vis"] < 0.5) & (scene["ids"] >= 0)).mean() > 0.03  # a shadow in view to get right
        vis = sun_visibility(depth, K, s, normals=normals, steps=64, thickness=0.1)
        agree, count = _agreement(scene, vis)
        assert count > 10000
        assert agree >= floor, (sun, agree)
        keep = (scene["ids"] >= 0) & ~_band(scene["ids"], scene["vis"])
        got, exact = vis[0, 0].numpy() < 0.5, scene["vis"] < 0.5
        iou = (got & exact & keep).sum() / ((got | exact) & keep).sum()
        assert iou >= 0.95, (sun, iou)


def test_02_depth_is_needed_only_up_to_scale() -> None:
    scene = box_scene(64, (-0.5, 0.7, -0.5), eye=EYE)
    depth, K, s, normals = _tensors(scene)
    ref = sun_visibility(depth, K, s, normals=normals)
    assert (ref < 0.5).any()
    for k in (1e-3, 0.37, 5.0, 1e4):
        assert torch.equal(sun_visibility(depth * k, K, s, normals=normals), ref), k


def test_03_sun_along_the_optical_axis_and_below_the_horizon() -> None:
    """Measured at 96 px: back light (0, 0.8, -1) in the camera frame, 99.33 % of 8084 pixels with a
    long shadow (23 % of the surface) towards the camera; sun straight behind the camera, 100 %
    (every shadow hidden behind its caster, none invented)."""
    # Away from the camera (back light: rays converge towards their vanishing point) and straight
    # towards it (rays diverge from the principal point): both still match ray casting.
    _, R, _ = _camera(EYE, (0.5, 0.3, 0.0), 96)
    for sun_cam in (_unit((0.0, 0.8, -1.0)), np.array([0.0, 0.0, 1.0])):
        sun_world = R.T @ sun_cam
        assert sun_world[1] > 0.05  # above the horizon: the exact reference has no ground occlusion
        scene = box_scene(96, sun_world, eye=EYE)
        depth, K, s, normals = _tensors(scene)
        vis = sun_visibility(depth, K, s, normals=normals)
        assert torch.isfinite(vis).all() and ((vis == 0) | (vis == 1)).all()
        agree, _ = _agreement(scene, vis)
        assert agree >= 0.99, (sun_cam, agree)
    # Exactly along the axis: the pixel at the principal point has no screen ray and is unoccluded.
    depth = torch.full((1, 1, 4, 4), 3.0)
    K = torch.tensor([[4.0, 0.0, 2.0], [0.0, 4.0, 2.0], [0.0, 0.0, 1.0]])
    assert torch.equal(sun_visibility(depth, K, torch.tensor([[0.0, 0.0, 1.0]])), torch.ones_like(depth))
    scene = box_scene(64, (-0.5, -0.2, -0.5), eye=EYE)
    depth, K, s, normals = _tensors(scene)
    up = torch.from_numpy(scene["up"])
    vis = sun_visibility(depth, K, s, normals=normals, up=up)
    assert torch.equal(vis[depth > 0], torch.zeros(int((depth > 0).sum()), dtype=vis.dtype))
    assert torch.equal(vis[depth == 0], torch.ones(int((depth == 0).sum()), dtype=vis.dtype))


def test_04_bad_inputs_raise_value_errors_naming_the_shape() -> None:
    depth = torch.ones(2, 1, 8, 8)
    K = torch.eye(3)
    d = torch.tensor([[0.0, 1.0, 0.0]]).expand(2, 3)
    with pytest.raises(ValueError, match=r"depth must have shape \(B, 1, H, W\), got \(2, 8, 8\)"):
        sun_visibility(depth[:, 0], K, d)
    with pytest.raises(ValueError, match=r"K must have shape \(3, 3\) or \(2, 3, 3\), got \(3, 3, 3\)"):
        sun_visibility(depth, torch.eye(3).expand(3, 3, 3), d)
    with pytest.raises(ValueError, match=r"sun_direction must have shape \(3,\) or \(2, 3\), got \(2, 2\)"):
        sun_visibility(depth, K, d[:, :2])
    with pytest.raises(ValueError, match=r"mask must be a bool tensor of shape \(2, 1, 8, 8\)"):
        sun_visibility(depth, K, d, mask=torch.ones(2, 1, 4, 8, dtype=torch.bool))
    with pytest.raises(ValueError, match=r"normals must have shape \(2, 3, 8, 8\), got \(2, 3, 8, 7\)"):
        sun_visibility(depth, K, d, normals=torch.ones(2, 3, 8, 7))
    with pytest.raises(ValueError, match="sun_direction must be finite and non-zero"):
        sun_visibility(depth, K, torch.zeros(2, 3))
    with pytest.raises(ValueError, match="thickness"):
        sun_visibility(depth, K, d, thickness=1.5)


def test_05_mask_removes_casters_and_speed_is_reported() -> None:
    """Masked-out pixels neither cast nor receive; 256 x 256 at 64 steps on 1 thread took ~0.1 s
    here (2 shared cores); the bound below is loose, for a loaded machine."""
    scene = box_scene(64, (-0.5, 0.7, -0.5), eye=EYE)
    depth, K, s, normals = _tensors(scene)
    ground = torch.from_numpy(scene["ids"] == 0)[None, None]
    assert torch.equal(sun_visibility(depth, K, s, normals=normals, mask=ground), torch.ones_like(depth))
    scene = box_scene(256, (-0.5, 0.7, -0.5), eye=EYE)
    depth, K, s, normals = (t.float() for t in _tensors(scene))
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        sun_visibility(depth, K, s, normals=normals)
        t0 = time.perf_counter()
        sun_visibility(depth, K, s, normals=normals)
        assert time.perf_counter() - t0 < 2.0
    finally:
        torch.set_num_threads(threads)
