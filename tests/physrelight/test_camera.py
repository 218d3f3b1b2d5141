"""Specification of physrelight.camera, checked against an analytic ray-cast scene.

The scene (world frame, Y up): a square ground plane y = 0 (|x|, |z| <= 10), a unit
sphere resting on it at (0, 1, 0) and a box beside it. Its colour is a smooth
procedural function of the 3D world position, so it is view independent and a warp
from one view to another must reproduce the other view's image. Two cameras (different
positions, heights and yaw, 64x80 pixels, 60 degree horizontal FOV) are ray cast here
in numpy with their own pixel/ray maths: nothing in the fixtures calls the module
under test, so every comparison below is independent of it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight import camera as cam

H, W = 64, 80
FOV_X = 60.0
FX = (W / 2) / math.tan(math.radians(FOV_X) / 2)
K_NP = np.array([[FX, 0.0, W / 2], [0.0, FX, H / 2], [0.0, 0.0, 1.0]])

PLANE_HALF = 6.0
SPHERE_C = np.array([0.0, 1.0, 0.0])
SPHERE_R = 1.0
BOX_LO = np.array([0.9, 0.0, -2.2])
BOX_HI = np.array([2.1, 1.4, -1.0])
# Object ids: 0 = nothing (sky), 1 = plane, 2 = sphere, 10 + face = box face (face 0..5).


# ----------------------------------------------------------------------------------------
# Analytic scene (numpy, independent of physrelight.camera)
# ----------------------------------------------------------------------------------------


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)


def camera_pose(angle: float, height: float, dist: float, yaw_offset: float, target_y: float):
    """Camera on a circle around the Y axis; yaw/pitch built directly (no look_at).

    Returns eye (3,), camera-to-world rotation (3, 3), world_to_camera (4, 4).
    """
    eye = np.array([dist * math.sin(angle), height, dist * math.cos(angle)])
    pitch = -math.atan2(height - target_y, dist)
    R_c2w = rot_y(angle + yaw_offset) @ rot_x(pitch)  # camera looks down its -z
    T = np.eye(4)
    T[:3, :3] = R_c2w.T
    T[:3, 3] = -R_c2w.T @ eye
    return eye, R_c2w, T


def texture(X: np.ndarray) -> np.ndarray:
    """Smooth colour (N, 3) in [0.1, 0.9] as a function of world position (N, 3)."""
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    r = 0.5 + 0.4 * np.sin(1.5 * x + 0.7 * y + 0.4) * np.cos(1.2 * z - 0.5 * y)
    g = 0.5 + 0.4 * np.sin(1.1 * z + 2.1 * y + 0.8 * x)
    b = 0.5 + 0.4 * np.cos(1.4 * x - 0.9 * z + 1.1 * y)
    return np.stack([r, g, b], axis=-1)


def ray_cast(o: np.ndarray, d: np.ndarray):
    """First hit of rays o + t d (t > 0, d need not be unit).

    Returns t (N,) (inf on a miss), object id (N,), world normal (N, 3).
    """
    n_rays = d.shape[0]
    o = np.broadcast_to(o, d.shape)
    best_t = np.full(n_rays, np.inf)
    ids = np.zeros(n_rays, dtype=int)
    normals = np.zeros((n_rays, 3))
    eps = 1e-9

    # Ground plane y = 0, limited to a square.
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o[:, 1] / d[:, 1]
    X = o + t[:, None] * d
    hit = np.isfinite(t) & (t > eps) & (np.abs(X[:, 0]) <= PLANE_HALF) & (np.abs(X[:, 2]) <= PLANE_HALF)
    upd = hit & (t < best_t)
    best_t[upd], ids[upd], normals[upd] = t[upd], 1, (0.0, 1.0, 0.0)

    # Sphere.
    oc = o - SPHERE_C
    a = (d * d).sum(1)
    b = 2 * (d * oc).sum(1)
    c = (oc * oc).sum(1) - SPHERE_R**2
    disc = b * b - 4 * a * c
    sq = np.sqrt(np.maximum(disc, 0))
    t0, t1 = (-b - sq) / (2 * a), (-b + sq) / (2 * a)
    t = np.where(t0 > eps, t0, t1)
    upd = (disc > 0) & (t > eps) & (t < best_t)
    best_t[upd], ids[upd] = t[upd], 2
    normals[upd] = (o[upd] + t[upd, None] * d[upd] - SPHERE_C) / SPHERE_R

    # Axis-aligned box (slabs); the entering face gives the normal.
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (BOX_LO - o) / d
        tb = (BOX_HI - o) / d
    tmin, tmax = np.minimum(ta, tb), np.maximum(ta, tb)
    tmin = np.nan_to_num(tmin, nan=-np.inf)
    tmax = np.nan_to_num(tmax, nan=np.inf)
    t_near, axis = tmin.max(1), tmin.argmax(1)
    t_far = tmax.min(1)
    upd = (t_near <= t_far) & (t_near > eps) & (t_near < best_t)
    sign = -np.sign(d[np.arange(n_rays), axis])  # the entering face faces the ray origin
    best_t[upd] = t_near[upd]
    ids[upd] = 10 + 2 * axis[upd] + (sign[upd] > 0)
    nb = np.zeros((n_rays, 3))
    nb[np.arange(n_rays), axis] = sign
    normals[upd] = nb[upd]
    return best_t, ids, normals


def render(angle, height, dist, yaw_offset, target_y=0.7, scale=1):
    """Ray cast one view at (scale H, scale W). Depth is z-depth: rays are (a, b, -1) in the camera frame."""
    h, w, f = scale * H, scale * W, scale * FX
    eye, R_c2w, T = camera_pose(angle, height, dist, yaw_offset, target_y)
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    u, v = jj + 0.5, ii + 0.5
    d_cam = np.stack([(u - w / 2) / f, -(v - h / 2) / f, -np.ones_like(u)], -1).reshape(-1, 3)
    d_world = d_cam @ R_c2w.T
    t, ids, n_world = ray_cast(eye, d_world)
    hit = ids > 0
    X = eye + t[:, None] * d_world
    X[~hit] = 0.0
    img = np.where(hit[:, None], texture(X), 0.0)
    return dict(
        eye=eye,
        R_c2w=R_c2w,
        T=T,
        K=np.array([[f, 0.0, w / 2], [0.0, f, h / 2], [0.0, 0.0, 1.0]]),
        depth=np.where(hit, t, 0.0).reshape(h, w),  # t along (a, b, -1) is exactly -z_camera
        hit=hit.reshape(h, w),
        ids=ids.reshape(h, w),
        X=X.reshape(h, w, 3),
        n_cam=(n_world @ R_c2w).reshape(h, w, 3),  # R_w2c n = R_c2w^T n
        image=img.reshape(h, w, 3),
    )


def to_bchw(a: np.ndarray) -> np.ndarray:
    return a.transpose(2, 0, 1)[None] if a.ndim == 3 else a[None, None]


def project_np(T: np.ndarray, X: np.ndarray):
    """World points (N, 3) -> (u, v, z-depth) with the test's own pinhole maths."""
    pc = X @ T[:3, :3].T + T[:3, 3]
    depth = -pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = FX * pc[:, 0] / depth + K_NP[0, 2]
        v = -FX * pc[:, 1] / depth + K_NP[1, 2]
    return u, v, depth


VIEW_A = dict(angle=0.45, height=3.5, dist=6.0, yaw_offset=0.0)
VIEW_B = dict(angle=-0.25, height=4.2, dist=6.5, yaw_offset=0.12)


@pytest.fixture(scope="module")
def views():
    return render(**VIEW_A), render(**VIEW_B)


@pytest.fixture(scope="module")
def warp_b_from_a(views):
    """Warp view A into view B, plus analytic visibility of B's points from A."""
    a, b = views
    T_b2a = a["T"] @ np.linalg.inv(b["T"])
    depth_b = b["depth"].copy()
    depth_b[~b["hit"]] = np.nan  # B marks missing depth with NaN, A with 0
    warped, valid = cam.warp(to_bchw(a["image"]), to_bchw(depth_b), K_NP, K_NP, T_b2a, depth_src=to_bchw(a["depth"]))
    warped_no_occ, valid_no_occ = cam.warp(to_bchw(a["image"]), to_bchw(depth_b), K_NP, K_NP, T_b2a)

    X = b["X"].reshape(-1, 3)
    u, v, z = project_np(a["T"], X)
    inside = b["hit"].reshape(-1) & (z > 0) & (u >= 0) & (u <= W) & (v >= 0) & (v <= H)
    t_hit, _, _ = ray_cast(a["eye"], X - a["eye"])  # t = 1 at X itself
    visible = inside & (t_hit >= 1 - 1e-6)
    # Edge band: the 2x2 source pixels whose centres surround (u, v) (the bilinear
    # taps) do not all see the same surface piece, or some lie outside A's image.
    band = np.zeros(H * W, dtype=bool)
    for k in np.flatnonzero(inside):
        j0, i0 = int(math.floor(u[k] - 0.5)), int(math.floor(v[k] - 0.5))
        if j0 < 0 or i0 < 0 or j0 + 2 > W or i0 + 2 > H:
            band[k] = True
            continue
        win = a["ids"][i0 : i0 + 2, j0 : j0 + 2]
        band[k] = bool((win != win[0, 0]).any())
    rs = lambda m: m.reshape(H, W)  # noqa: E731
    return dict(
        warped=warped[0].transpose(1, 2, 0),
        valid=valid[0, 0],
        warped_no_occ=warped_no_occ[0].transpose(1, 2, 0),
        valid_no_occ=valid_no_occ[0, 0],
        inside=rs(inside),
        visible=rs(visible),
        band=rs(band),
    )


# ----------------------------------------------------------------------------------------
# Pixels, intrinsics, projection
# ----------------------------------------------------------------------------------------


def test_01_pixel_grid_holds_pixel_centres_u_right_v_down():
    g = cam.pixel_grid(3, 4, dtype=torch.float64)
    assert g.shape == (2, 3, 4)
    assert torch.equal(g[0, 2], torch.tensor([0.5, 1.5, 2.5, 3.5], dtype=torch.float64))  # u = column + 0.5
    assert torch.equal(g[1, :, 3], torch.tensor([0.5, 1.5, 2.5], dtype=torch.float64))  # v = row + 0.5


def test_02_intrinsics_from_fov_matches_pinhole_with_centred_principal_point():
    K = cam.intrinsics_from_fov(FOV_X, W, H)
    assert isinstance(K, np.ndarray) and K.shape == (3, 3)
    np.testing.assert_allclose(K, K_NP, rtol=1e-12)
    # The image's left and right edges are at +-fov/2 from the optical axis.
    half = math.degrees(math.atan((W - K[0, 2]) / K[0, 0]))
    assert half == pytest.approx(FOV_X / 2, abs=1e-9)
    Kb = cam.intrinsics(torch.tensor([100.0, 200.0]), 150.0, 40.0, 32.0)
    assert isinstance(Kb, torch.Tensor) and Kb.shape == (2, 3, 3)
    assert Kb[1].tolist() == [[200.0, 0.0, 40.0], [0.0, 150.0, 32.0], [0.0, 0.0, 1.0]]


def test_03_project_inverts_backproject_and_depth_is_minus_z():
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 20.0, size=(2, 1, 7, 9))
    K = np.stack([cam.intrinsics(50.0, 60.0, 4.0, 3.7), cam.intrinsics(80.0, 70.0, 5.1, 3.2)])
    P = cam.backproject(depth, K)
    assert P.shape == (2, 3, 7, 9)
    np.testing.assert_allclose(-P[:, 2:3], depth, rtol=1e-12)  # z-depth = -z_camera
    uv, z = cam.project(P, K)
    jj, ii = np.meshgrid(np.arange(9), np.arange(7))
    np.testing.assert_allclose(uv[:, 0], np.broadcast_to(jj + 0.5, (2, 7, 9)), atol=1e-10)  # pixel centres
    np.testing.assert_allclose(uv[:, 1], np.broadcast_to(ii + 0.5, (2, 7, 9)), atol=1e-10)
    np.testing.assert_allclose(z, depth, rtol=1e-12)


def test_04_backproject_recovers_the_ray_cast_surface_points(views):
    _, b = views
    P = cam.backproject(to_bchw(b["depth"]), K_NP)[0].transpose(1, 2, 0)
    X_cam = b["X"] @ b["T"][:3, :3].T + b["T"][:3, 3]
    np.testing.assert_allclose(P[b["hit"]], X_cam[b["hit"]], atol=1e-9)
    assert np.all(P[~b["hit"]] == 0)  # missing depth -> the origin
    # A point right of and above the camera projects right of / above the centre.
    uv, z = cam.project(np.array([[[1.0], [1.0], [-4.0]]]), K_NP)
    assert uv[0, 0, 0] > W / 2 and uv[0, 1, 0] < H / 2 and z[0, 0, 0] == 4.0


# ----------------------------------------------------------------------------------------
# Extrinsics
# ----------------------------------------------------------------------------------------


def test_05_look_at_puts_target_on_the_optical_axis_at_the_image_centre(views):
    a, _ = views
    target = np.array([0.0, 0.7, 0.0])  # the point camera A was aimed at
    T = cam.look_at(a["eye"], target)
    assert isinstance(T, np.ndarray) and T.shape == (4, 4)
    np.testing.assert_allclose(T, a["T"], atol=1e-12)  # same as yaw/pitch with no roll
    pc = T[:3, :3] @ target + T[:3, 3]
    dist = np.linalg.norm(target - a["eye"])
    np.testing.assert_allclose(pc, [0.0, 0.0, -dist], atol=1e-12)  # in front = negative z
    uv, z = cam.project(pc.reshape(1, 3, 1), K_NP)
    np.testing.assert_allclose(uv[0, :, 0], [W / 2, H / 2], atol=1e-9)
    assert z[0, 0, 0] == pytest.approx(dist, rel=1e-12) and z[0, 0, 0] > 0
    np.testing.assert_allclose(-T[:3, :3].T @ T[:3, 3], a["eye"], atol=1e-12)  # camera centre
    np.testing.assert_allclose(cam.transform_points(T, a["eye"]), 0.0, atol=1e-12)  # eye -> origin
    # World up stays "up" on screen: a point above the target has v < H/2.
    uv_up, _ = cam.project((T[:3, :3] @ (target + [0, 0.5, 0]) + T[:3, 3]).reshape(1, 3, 1), K_NP)
    assert uv_up[0, 1, 0] < H / 2


def test_06_relative_pose_composes_and_invert_rigid_inverts(views):
    a, b = views
    rel = cam.relative_pose(a["T"], b["T"])
    np.testing.assert_allclose(rel @ a["T"], b["T"], atol=1e-12)
    np.testing.assert_allclose(cam.invert_rigid(a["T"]), np.linalg.inv(a["T"]), atol=1e-12)
    # Batched, torch in -> torch out; transform_points agrees with the matrix product.
    Ta = torch.from_numpy(np.stack([a["T"], b["T"]]))
    Tb = torch.from_numpy(np.stack([b["T"], a["T"]]))
    relb = cam.relative_pose(Ta, Tb)
    assert isinstance(relb, torch.Tensor) and relb.shape == (2, 4, 4)
    assert torch.allclose(relb @ Ta, Tb, atol=1e-12)
    pts = torch.randn(2, 5, 3, dtype=torch.float64)
    out = cam.transform_points(relb, pts)
    want = torch.einsum("bij,bnj->bni", relb[:, :3, :3], pts) + relb[:, None, :3, 3]
    assert torch.allclose(out, want, atol=1e-12)
    # A camera-a point and its world point agree with camera b's view of the world point.
    X = b["X"][b["hit"]][:10]
    p_a = X @ a["T"][:3, :3].T + a["T"][:3, 3]
    p_b = X @ b["T"][:3, :3].T + b["T"][:3, 3]
    np.testing.assert_allclose(cam.transform_points(rel, p_a), p_b, atol=1e-10)


# ----------------------------------------------------------------------------------------
# Warping
# ----------------------------------------------------------------------------------------


def test_07_warp_uses_pixel_centres_identity_and_integer_shifts_are_exact():
    rng = np.random.default_rng(1)
    img = rng.uniform(size=(1, 3, 12, 16))
    depth = np.full((1, 1, 12, 16), 5.0)
    K = cam.intrinsics(40.0, 40.0, 8.0, 6.0)
    out, valid = cam.warp(img, depth, K, K, np.eye(4), depth_src=depth)
    assert valid.dtype == bool and valid.all()
    np.testing.assert_allclose(out, img, atol=1e-12)
    # Source camera moved by +tx: a fronto-parallel plane at depth 5 shifts by
    # fx tx / 5 = 2 pixels to the left in the source, so dst column j reads src column j - 2.
    T = np.eye(4)
    T[0, 3] = -0.25  # dst -> src: x_src = x_dst - 0.25  (src camera is 0.25 to the right)
    out, valid = cam.warp(img, depth, K, K, T, depth_src=depth)
    np.testing.assert_allclose(out[..., 2:], img[..., :-2], atol=1e-12)
    assert valid[..., 2:].all()
    # Half a pixel: the bilinear average of two neighbours.
    T[0, 3] = -0.0625
    out, _ = cam.warp(img, depth, K, K, T)
    np.testing.assert_allclose(out[..., 1:], 0.5 * (img[..., 1:] + img[..., :-1]), atol=1e-12)


def test_08_warp_of_view_a_reproduces_view_b_on_valid_pixels(views, warp_b_from_a):
    _, b = views
    w = warp_b_from_a
    valid = w["valid"]
    assert valid.sum() > 0.5 * b["hit"].sum()  # most of B is seen by A
    err = np.abs(w["warped"] - b["image"]).max(-1)  # colours span [0.1, 0.9]
    core = valid & ~w["band"]
    # Bilinear interpolation of a smooth texture: largest on the far ground, which A sees
    # at a grazing angle (~0.5 world units per pixel). At A's silhouettes the occlusion
    # test rejects most mixed samples; a few blends of two surfaces within rel_tol in
    # depth remain.
    assert err[core].max() < 0.05, err[core].max()
    assert err[valid].mean() < 0.006, err[valid].mean()
    assert np.percentile(err[valid], 99) < 0.04
    assert (err[valid] > 0.05).mean() < 0.005
    assert np.all(w["warped"][~valid] == 0)


def test_09_occlusion_test_matches_analytic_visibility_away_from_edges(views, warp_b_from_a):
    _, b = views
    w = warp_b_from_a
    valid, visible, band, inside = w["valid"], w["visible"], w["band"], w["inside"]
    assert band.sum() < 0.1 * b["hit"].sum()  # the excused band is a thin rim (6% here)
    assert np.array_equal(valid[~band], visible[~band])
    # Pixels A cannot see (plane behind the sphere / box) but which land inside A's image.
    occluded = inside & ~visible & ~band
    assert occluded.sum() > 100
    assert not valid[occluded].any()
    # Without depth_src only the geometric tests apply: they are valid there, and A's
    # colour at those places is the occluder's, far from B's: the test is needed.
    assert np.array_equal(w["valid_no_occ"], inside)
    err = np.abs(w["warped_no_occ"] - b["image"]).max(-1)
    assert err[occluded].mean() > 0.1
    # Points of B outside A's view are invalid.
    assert not valid[b["hit"] & ~inside].any()


def test_10_warp_dtype_and_type_round_trip():
    img = torch.rand(2, 3, 6, 7)
    depth = torch.full((2, 1, 5, 4), 3.0)
    K = cam.intrinsics_from_fov(50.0, 7, 6)  # numpy K with torch images is fine
    out, valid = cam.warp(img, depth, K, K, torch.eye(4))
    assert out.dtype == torch.float32 and out.shape == (2, 3, 5, 4) and valid.dtype == torch.bool
    out_np, valid_np = cam.warp(img.numpy(), depth.numpy(), K, K, np.eye(4))
    assert out_np.dtype == np.float32 and valid_np.dtype == np.bool_


# ----------------------------------------------------------------------------------------
# Normals from depth
# ----------------------------------------------------------------------------------------


def _interior(ids: np.ndarray) -> np.ndarray:
    """Pixels whose 5-point stencil lies on one smooth surface piece (not at image border)."""
    inner = np.zeros_like(ids, dtype=bool)
    c = ids[1:-1, 1:-1]
    same = (c > 0) & (ids[:-2, 1:-1] == c) & (ids[2:, 1:-1] == c) & (ids[1:-1, :-2] == c) & (ids[1:-1, 2:] == c)
    inner[1:-1, 1:-1] = same
    return inner


def _view_cosine(v) -> np.ndarray:
    """cos of the angle between the analytic normal and the direction to the camera."""
    P = v["X"] @ v["T"][:3, :3].T + v["T"][:3, 3]
    return (v["n_cam"] * -P / np.maximum(np.linalg.norm(P, axis=-1, keepdims=True), 1e-300)).sum(-1)


def _normal_errors_deg(v):
    n, valid = cam.normals_from_depth(to_bchw(v["depth"]), v["K"])
    n, valid = n[0].transpose(1, 2, 0), valid[0, 0]
    ang = np.degrees(np.arccos(np.clip((n * v["n_cam"]).sum(-1), -1, 1)))
    return n, valid, ang


@pytest.mark.parametrize("which", [0, 1])
def test_11_normals_from_depth_match_analytic_normals(views, which):
    v = views[which]
    n, valid, ang = _normal_errors_deg(v)
    inner = _interior(v["ids"])
    assert valid[inner].all()
    flat = inner & ((v["ids"] == 1) | (v["ids"] >= 10))
    sphere = inner & (v["ids"] == 2)
    frontal = sphere & (_view_cosine(v) > 0.6)
    assert ang[flat].max() < 1e-4, ang[flat].max()  # central differences are exact on planes
    # On the sphere (radius ~11 px) the error is second order, largest at grazing view
    # (the stencil's points are spread unevenly along the surface there).
    assert ang[frontal].max() < 1.5 and ang[frontal].mean() < 0.5, (ang[frontal].max(), ang[frontal].mean())
    assert ang[sphere].max() < 10.0 and ang[sphere].mean() < 1.5, (ang[sphere].max(), ang[sphere].mean())
    np.testing.assert_allclose(np.linalg.norm(n[valid], axis=-1), 1.0, atol=1e-12)
    P = v["X"] @ v["T"][:3, :3].T + v["T"][:3, 3]
    assert np.all((n[valid] * -P[valid]).sum(-1) > 0)  # faces the camera


def test_12_normals_from_depth_converge_at_second_order():
    errs = []
    for scale in (1, 2):
        v = render(**VIEW_B, scale=scale)
        _, _, ang = _normal_errors_deg(v)
        frontal = _interior(v["ids"]) & (v["ids"] == 2) & (_view_cosine(v) > 0.6)
        errs.append(ang[frontal].mean())
    assert errs[0] / errs[1] > 3.0, errs  # halving the pixel pitch divides the error by ~4


def test_13_normals_valid_mask_is_false_wherever_the_stencil_misses_depth(views):
    _, b = views
    depth = b["depth"].copy()
    depth[~b["hit"]] = np.inf
    holes = [(40, 20), (50, 60), (33, 45)]
    for i, j in holes:
        depth[i, j] = 0.0 if i != 33 else np.nan
    n, valid = cam.normals_from_depth(to_bchw(depth), K_NP)
    valid = valid[0, 0]
    ok = np.isfinite(depth) & (depth > 0)
    stencil = np.zeros_like(ok)
    stencil[1:-1, 1:-1] = ok[1:-1, 1:-1] & ok[:-2, 1:-1] & ok[2:, 1:-1] & ok[1:-1, :-2] & ok[1:-1, 2:]
    assert np.array_equal(valid, stencil & valid)  # never valid without a full stencil
    for i, j in holes:
        assert not valid[i - 1 : i + 2, j].any() and not valid[i, j - 1 : j + 2].any()
    assert not valid[0].any() and not valid[-1].any() and not valid[:, 0].any() and not valid[:, -1].any()
    assert np.all(n[0][:, ~valid] == 0)
    # Depth-jump masking removes stencils straddling a silhouette, keeps smooth ones.
    _, valid_j = cam.normals_from_depth(to_bchw(depth), K_NP, max_rel_jump=0.2)
    valid_j = valid_j[0, 0]
    c = depth[1:-1, 1:-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        nbs = (depth[:-2, 1:-1], depth[2:, 1:-1], depth[1:-1, :-2], depth[1:-1, 2:])
        step = np.max([np.abs(nb - c) / c for nb in nbs], 0)
    step = np.pad(step, 1, constant_values=np.inf)
    assert not valid_j[stencil & (step > 0.2)].any() and (stencil & (step > 0.2)).sum() > 20
    assert np.array_equal(valid_j[stencil & (step <= 0.2)], valid[stencil & (step <= 0.2)])


# ----------------------------------------------------------------------------------------
# Differentiability
# ----------------------------------------------------------------------------------------


def test_14_gradcheck_backproject_and_warp_in_float64():
    torch.manual_seed(0)
    depth = (2.0 + torch.rand(1, 1, 4, 5, dtype=torch.float64)).requires_grad_()
    f = torch.tensor([6.0, 5.0, 2.5, 2.0], dtype=torch.float64, requires_grad=True)  # fx, fy, cx, cy
    assert torch.autograd.gradcheck(lambda d, f: cam.backproject(d, cam.intrinsics(*f)), (depth, f))
    img = torch.rand(2, 2, 5, 6, dtype=torch.float64, requires_grad=True)
    depth_dst = 3.0 + torch.rand(2, 1, 4, 5, dtype=torch.float64)
    Kd = cam.intrinsics(6.0, 6.0, 2.5, 2.0)
    Ks = cam.intrinsics(7.0, 7.0, 3.0, 2.5)
    c, s = math.cos(0.1), math.sin(0.1)
    T = torch.tensor([[c, 0, s, 0.1], [0, 1, 0, -0.05], [-s, 0, c, 0.2], [0, 0, 0, 1]], dtype=torch.float64)
    out, valid = cam.warp(img, depth_dst, Kd, Ks, T)
    assert valid.any() and not valid.all()
    assert torch.autograd.gradcheck(lambda im: cam.warp(im, depth_dst, Kd, Ks, T)[0], (img,))
    # Gradients reach the destination depth too, and stay finite with missing depth.
    dd = depth_dst.clone()
    dd[0, 0, 1, 1] = float("nan")
    dd.requires_grad_()
    cam.warp(img, dd, Kd, Ks, T)[0].sum().backward()
    assert torch.isfinite(dd.grad).all() and dd.grad.abs().sum() > 0
    d2 = torch.full((1, 1, 5, 5), 4.0, dtype=torch.float64)
    d2[0, 0, 2, 3] = 0.0
    d2.requires_grad_()
    cam.normals_from_depth(d2, Kd)[0].sum().backward()
    assert torch.isfinite(d2.grad).all()


# ----------------------------------------------------------------------------------------
# Bad input
# ----------------------------------------------------------------------------------------

_D = np.full((1, 1, 4, 5), 2.0)
_K = K_NP
_S = np.diag([2.0, 2.0, 2.0, 1.0])  # scaling, not rigid
_M = np.diag([1.0, 1.0, -1.0, 1.0])  # mirror, not proper
_P = np.eye(4)
_P[3, 0] = 0.1  # projective last row


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: cam.backproject(np.full((4, 5), 2.0), _K), r"depth must be a \(B, C, H, W\)"),
        (lambda: cam.backproject(np.full((1, 2, 4, 5), 2.0), _K), "depth must have 1 channel"),
        (lambda: cam.backproject(-_D, _K), "z-depth >= 0"),
        (lambda: cam.backproject(_D, np.eye(4)), r"K must have shape \(3, 3\)"),
        (lambda: cam.backproject(_D, np.diag([5.0, -5.0, 1.0])), "positive focal"),
        (lambda: cam.backproject(_D, np.array([[5.0, 0, 1], [0, 5, 1], [0, 0, np.nan]])), "non-finite"),
        (lambda: cam.backproject(_D, np.array([[5.0, 0, 1], [0, 5, 1], [0, 1, 1]])), "last row"),
        (lambda: cam.backproject(_D, np.stack([_K] * 3)), "batch size 3"),
        (lambda: cam.intrinsics(-1.0, 1.0, 0.0, 0.0), "fx must be a positive"),
        (lambda: cam.intrinsics_from_fov(180.0, 8, 8), r"\(0, 180\)"),
        (lambda: cam.intrinsics_from_fov(60.0, 0, 8), "width must be a positive integer"),
        (lambda: cam.invert_rigid(_S), "not a rigid transform"),
        (lambda: cam.invert_rigid(_M), "not a rigid transform"),
        (lambda: cam.invert_rigid(_P), "last row"),
        (lambda: cam.invert_rigid(np.eye(3)), r"shape \(4, 4\)"),
        (lambda: cam.relative_pose(np.eye(4), np.full((4, 4), np.nan)), "non-finite"),
        (lambda: cam.transform_points(np.eye(4), np.zeros((5, 2))), r"points must have shape \(\.\.\., 3\)"),
        (lambda: cam.look_at([0, 0, 1.0], [0, 0, 1.0]), "coincide"),
        (lambda: cam.look_at([0, 5.0, 0], [0, 0, 0.0]), "parallel"),
        (lambda: cam.project(np.zeros((1, 2, 3)), _K), r"points must have shape \(B, 3"),
        (lambda: cam.normals_from_depth(np.full((1, 1, 2, 5), 1.0), _K), "at least 3x3"),
        (lambda: cam.normals_from_depth(np.full((1, 1, 4, 5), 1.0), _K, stencil="sobel"), "stencil must be"),
        (lambda: cam.warp(np.full((1, 3, 4, 5), np.nan), _D, _K, _K, np.eye(4)), "image_src holds"),
        (lambda: cam.warp(np.zeros((1, 3, 4, 5)), _D, _K, _K, _S), "dst_to_src is not a rigid"),
        (lambda: cam.warp(np.zeros((1, 3, 4, 5)), _D, _K, _K, np.eye(4), rel_tol=0.0), "rel_tol"),
        (lambda: cam.warp(np.zeros((2, 3, 4, 5)), _D, _K, _K, np.eye(4)), "batch size"),
        (lambda: cam.warp(np.zeros((1, 3, 4, 5)), _D, _K, _K, np.eye(4), depth_src=np.ones((1, 1, 3, 5))), "depth_src"),
    ],
)
def test_15_bad_input_raises_value_error_naming_the_problem(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_16_camera_bundle_shortens_call_sites(views):
    a, b = views
    ca = cam.Camera.look_at(a["eye"], [0.0, 0.7, 0.0], FOV_X, W, H)
    cb = cam.Camera(K=K_NP, world_to_camera=b["T"], width=W, height=H)
    assert isinstance(ca.K, torch.Tensor) and ca.K.shape == (3, 3)
    np.testing.assert_allclose(ca.center.numpy(), a["eye"], atol=1e-12)
    np.testing.assert_allclose(cb.pose_to(ca).numpy(), a["T"] @ np.linalg.inv(b["T"]), atol=1e-12)
    with pytest.raises(ValueError, match="not a rigid"):
        cam.Camera(K=K_NP, world_to_camera=_S, width=W, height=H)


# ----------------------------------------------------------------------------------------
# One-sided normals (more pixels next to holes, edges and the border)
# ----------------------------------------------------------------------------------------


def _holed_depth(v) -> np.ndarray:
    """View depth with the background missing and a few holes punched into surfaces."""
    depth = v["depth"].copy()
    depth[~v["hit"]] = np.inf
    for i, j in [(40, 20), (50, 60), (33, 45), (20, 30), (60, 10)]:
        depth[i - 1 : i + 2, j - 1 : j + 2] = 0.0
    depth[45, 70:72] = np.nan
    return depth


def _same_surface_or_missing(ids: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Pixels whose every in-image 4-neighbour is missing or on the pixel's own surface."""
    ok = np.isfinite(depth) & (depth > 0)
    out = ok & (ids > 0)
    pad_ids = np.pad(ids, 1, constant_values=-1)
    pad_ok = np.pad(ok, 1, constant_values=False)
    h, w = ids.shape
    for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        nb_ids = pad_ids[1 + di : 1 + di + h, 1 + dj : 1 + dj + w]
        nb_ok = pad_ok[1 + di : 1 + di + h, 1 + dj : 1 + dj + w]
        out &= ~nb_ok | (nb_ids == ids)
    return out


def test_17_one_sided_normals_extend_the_central_ones_and_stay_exact_on_planes(views):
    _, b = views
    depth = _holed_depth(b)
    n0, v0 = cam.normals_from_depth(to_bchw(depth), K_NP)
    n1, v1 = cam.normals_from_depth(to_bchw(depth), K_NP, stencil="one_sided")
    n0, v0, n1, v1 = n0[0].transpose(1, 2, 0), v0[0, 0], n1[0].transpose(1, 2, 0), v1[0, 0]
    # Where the central stencil works, the one-sided one is the central one.
    assert np.array_equal(v0 & v1, v0)
    np.testing.assert_allclose(n1[v0], n0[v0], atol=1e-12)
    extra = v1 & ~v0
    assert extra.sum() > 100  # next to the holes, the silhouettes and on the image border
    border = np.ones_like(extra)
    border[1:-1, 1:-1] = False
    assert (extra & border).sum() > 10  # the central stencil never reaches the border
    ang = np.degrees(np.arccos(np.clip((n1 * b["n_cam"]).sum(-1), -1, 1)))
    planar = (b["ids"] == 1) | (b["ids"] >= 10)
    clean = extra & planar & _same_surface_or_missing(b["ids"], depth)
    assert clean.sum() > 50 and ang[clean].max() < 1e-4, (clean.sum(), ang[clean].max())  # still exact on planes
    # On the sphere the fallback is first order: worse than central, still close.
    sphere = extra & (b["ids"] == 2) & _same_surface_or_missing(b["ids"], depth) & (_view_cosine(b) > 0.6)
    assert sphere.sum() > 5 and ang[sphere].mean() < 5.0, (sphere.sum(), ang[sphere].mean())
    np.testing.assert_allclose(np.linalg.norm(n1[v1], axis=-1), 1.0, atol=1e-12)
    assert np.all(n1[~v1] == 0)
    P = b["X"] @ b["T"][:3, :3].T + b["T"][:3, 3]
    assert np.all((n1[v1] * -P[v1]).sum(-1) > 0)  # faces the camera


def test_18_one_sided_normals_need_a_usable_neighbour_per_axis_and_skip_jumps(views):
    _, b = views
    depth = _holed_depth(b)
    ok = np.isfinite(depth) & (depth > 0)
    _, v1 = cam.normals_from_depth(to_bchw(depth), K_NP, stencil="one_sided")
    v1 = v1[0, 0]
    pad = np.pad(ok, 1, constant_values=False)
    has_v = pad[:-2, 1:-1] | pad[2:, 1:-1]
    has_u = pad[1:-1, :-2] | pad[1:-1, 2:]
    assert np.array_equal(v1, ok & has_v & has_u)  # exactly: no degenerate stencil on this scene
    isolated = depth.copy()
    isolated[30, 39] = isolated[30, 41] = 0.0  # (30, 40) keeps its vertical neighbours only
    _, vi = cam.normals_from_depth(to_bchw(isolated), K_NP, stencil="one_sided")
    assert ok[30, 40] and not vi[0, 0, 30, 40]
    # With a jump threshold a side across a silhouette is not used: the pixel keeps its
    # other side and, on a plane whose other neighbours are its own, its exact normal.
    nj, vj = cam.normals_from_depth(to_bchw(depth), K_NP, max_rel_jump=0.2, stencil="one_sided")
    _, vc = cam.normals_from_depth(to_bchw(depth), K_NP, max_rel_jump=0.2)
    nj, vj, vc = nj[0].transpose(1, 2, 0), vj[0, 0], vc[0, 0]
    ang = np.degrees(np.arccos(np.clip((nj * b["n_cam"]).sum(-1), -1, 1)))
    d = np.where(ok, depth, np.nan)
    pd, pids = np.pad(d, 1, constant_values=np.nan), np.pad(b["ids"], 1, constant_values=-1)
    clean = vj & ~vc & ((b["ids"] == 1) | (b["ids"] >= 10))
    h, w = d.shape
    for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        nd, nid = pd[1 + di : 1 + di + h, 1 + dj : 1 + dj + w], pids[1 + di : 1 + di + h, 1 + dj : 1 + dj + w]
        with np.errstate(invalid="ignore"):
            jump = np.abs(nd - d) > 0.2 * np.fmin(nd, d)
        clean &= ~np.isfinite(nd) | (nid == b["ids"]) | jump
    assert clean.sum() > 20 and ang[clean].max() < 1e-4, (clean.sum(), ang[clean].max())


def test_19_scaled_intrinsics_project_to_the_scaled_pixel_coordinates() -> None:
    """Resizing an image by s maps (u, v) -> (s u, s v) (corners at 0): the same point projects there
    through ``scale_intrinsics(K, s)``, for numpy and torch, single and batched, and ``K`` is untouched."""
    K = np.array([[50.0, 0.3, 31.0], [0.0, 48.0, 33.0], [0.0, 0.0, 1.0]])
    points = torch.tensor([[[0.2, -0.4, 1.1], [0.1, 0.3, -0.2], [-2.0, -3.0, -4.0]]], dtype=torch.float64)
    uv, _ = cam.project(points, torch.from_numpy(K))
    for s in (2, 0.5, 3.0):
        for k in (K, torch.from_numpy(K), torch.from_numpy(np.stack([K, K]))):
            before = torch.as_tensor(k).clone()
            scaled = cam.scale_intrinsics(k, s)
            assert type(scaled) is type(k) and tuple(scaled.shape) == tuple(k.shape)
            assert torch.equal(torch.as_tensor(k), before)
            k1 = torch.as_tensor(scaled).reshape(-1, 3, 3)[:1]
            uv_s, _ = cam.project(points, k1)
            torch.testing.assert_close(uv_s, s * uv, rtol=0, atol=1e-12)
    for bad in (0, -1.0, float("nan"), True):
        with pytest.raises(ValueError, match="scale"):
            cam.scale_intrinsics(K, bad)
    with pytest.raises(ValueError, match="shape"):
        cam.scale_intrinsics(np.eye(4), 2)
