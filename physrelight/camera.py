"""Pinhole cameras, back-projection, normals from depth and depth-based view warping.

The machinery behind the multi-view self-supervised losses (albedo consistency across
views, cross-rendering, normal supervision from multi-view-stereo depth).

Conventions (fixed here; every other module that talks about cameras uses them)
---------------------------------------------------------------------------------

Camera frame (DESIGN.md)
    x right, y up, z towards the viewer: the camera looks down -z (OpenGL style).
    A surface facing the camera has normal +z.

World frame
    Y up (Mitsuba's env-map default). :func:`look_at` takes its ``up`` in this frame.

Pixel coordinates
    Continuous ``(u, v)``: u to the right, v down, the image's top-left *corner* at
    ``(0, 0)`` and its bottom-right corner at ``(W, H)``. The centre of pixel
    (row i, column j) is ``(u, v) = (j + 0.5, i + 0.5)`` (Mitsuba's film does the
    same). ``torch.nn.functional.grid_sample(..., align_corners=False)`` with
    ``x = 2u/W - 1, y = 2v/H - 1`` samples exactly this convention (tested).

Intrinsics ``K`` (3x3, or (B, 3, 3) one per batch item)
    ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` acts on the *vision* frame
    (x right, y down, z forward), which is ``(x, -y, -z)`` of our camera frame::

        [u, v, 1]^T  ~  K @ [x, -y, -z]^T        (u = fx x / (-z) + s (-y) / (-z) + cx, ...)

    so the y and z flips live here, not in K: fx, fy must be positive and the last
    row must be (0, 0, 1). The skew ``s`` is allowed (0 in everything we build).

Depth
    z-depth, positive in front of the camera: ``depth = -z_camera`` (not the distance
    along the ray). Missing depth is stored as 0 or as a non-finite value (NaN/inf);
    :func:`valid_depth` gives the mask. A *negative* finite depth is an error (it is
    what one gets by passing camera z instead of depth).

Extrinsics
    ``world_to_camera``: a 4x4 rigid transform (proper rotation + translation, last row
    (0, 0, 0, 1)) mapping world points into our camera frame:
    ``p_cam = R p_world + t``. The camera centre in the world is ``-R^T t``.
    ``relative_pose(T_a, T_b) = T_b @ T_a^-1`` maps camera a's frame into camera b's
    frame, so ``T_b = relative_pose(T_a, T_b) @ T_a``. Its rotation block is the
    rotation that carries directions in camera a's frame (normals, SH lighting) into
    camera b's frame.

Arrays
    Public functions accept numpy arrays or torch tensors (lists/scalars count as
    numpy) and give results back as the type of their main argument (named in each
    docstring); secondary arrays (K, transforms) are cast to its dtype and device.
    numpy inputs are computed in float64. Boolean masks come back as torch bool or
    numpy bool. Computations are batched torch and differentiable (masks excepted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from ._checks import Array, check_finite, check_image, check_rotation, to_tensor

__all__ = [
    "Camera",
    "backproject",
    "intrinsics",
    "intrinsics_from_fov",
    "scale_intrinsics",
    "invert_rigid",
    "look_at",
    "normals_from_depth",
    "pixel_grid",
    "project",
    "relative_pose",
    "transform_points",
    "valid_depth",
    "warp",
]

# Our camera frame -> vision frame (x right, y down, z forward) is a sign flip of y and z.
_FLIP = (1.0, -1.0, -1.0)
# |z-depth| below this is treated as "at the camera centre" when dividing (keeps u, v finite).
_EPS_DEPTH = 1e-8


# --------------------------------------------------------------------------------------
# Input checks (private: the public ones live in _checks.py)
# --------------------------------------------------------------------------------------


def _is_torch(x: Any) -> bool:
    return isinstance(x, torch.Tensor)


def _mask_out(mask: torch.Tensor, torch_in: bool) -> Array:
    """Give a bool mask back as torch or numpy bool (``restore`` would cast it to float)."""
    return mask if torch_in else mask.detach().cpu().numpy()


def _to_tensor_keep_shape(x: Array, name: str) -> tuple[torch.Tensor, Any]:
    """``to_tensor`` that keeps 0-d shapes (``np.ascontiguousarray`` turns scalars into (1,))."""
    t, restore = to_tensor(x, name)
    if not _is_torch(x):
        t = t.reshape(np.shape(x))
    return t, restore


def _check_K(K: Array, name: str, like: torch.Tensor, batch: int | None) -> torch.Tensor:
    """Validate intrinsics and return them as ``(B', 3, 3)`` on ``like``'s dtype/device.

    ``B'`` is 1 for a single ``(3, 3)`` matrix (broadcasts over the batch).
    """
    Kt, _ = to_tensor(K, name)
    if not (Kt.ndim in (2, 3) and Kt.shape[-2:] == (3, 3)):
        raise ValueError(f"{name} must have shape (3, 3) or (B, 3, 3), got {tuple(Kt.shape)}")
    check_finite(Kt, name)
    Kt = Kt.to(dtype=like.dtype, device=like.device)
    if Kt.ndim == 2:
        Kt = Kt.unsqueeze(0)
    if batch is not None and Kt.shape[0] not in (1, batch):
        raise ValueError(f"{name} has batch size {Kt.shape[0]}, expected 1 or {batch}")
    Kd = Kt.detach()
    if bool((Kd[:, 0, 0] <= 0).any()) or bool((Kd[:, 1, 1] <= 0).any()):
        raise ValueError(
            f"{name} must have positive focal lengths fx = K[0, 0] and fy = K[1, 1], got "
            f"fx = {Kd[:, 0, 0].tolist()}, fy = {Kd[:, 1, 1].tolist()} (K acts on the vision "
            "frame (x, -y, -z): do not put the y/z flip into K)"
        )
    bottom = torch.tensor([0.0, 0.0, 1.0], dtype=Kd.dtype, device=Kd.device)
    if float((Kd[:, 2, :] - bottom).abs().amax()) > 1e-6 or float(Kd[:, 1, 0].abs().amax()) > 1e-6:
        raise ValueError(f"{name} must be upper triangular with last row (0, 0, 1), got {Kd.tolist()}")
    return Kt


def _check_rigid(T: torch.Tensor, name: str) -> None:
    """Raise unless ``T`` is ``(..., 4, 4)`` rigid: rotation block, last row (0, 0, 0, 1)."""
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise ValueError(f"{name} must have shape (4, 4) or (B, 4, 4), got {tuple(T.shape)}")
    check_finite(T, name)
    last = T.detach()[..., 3, :]
    want = torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=T.dtype, device=T.device)
    if float((last - want).abs().amax()) > 1e-6:
        raise ValueError(f"{name} must be a rigid transform with last row (0, 0, 0, 1), got {last.tolist()}")
    try:
        check_rotation(T[..., :3, :3], name=f"{name}[:3, :3]")
    except ValueError as e:
        raise ValueError(f"{name} is not a rigid transform (rotation + translation): {e}") from None


def _check_T(T: Array, name: str, like: torch.Tensor, batch: int | None) -> torch.Tensor:
    """Validate a rigid transform and return it as ``(B', 4, 4)`` on ``like``'s dtype/device."""
    Tt, _ = to_tensor(T, name)
    if Tt.ndim not in (2, 3):
        raise ValueError(f"{name} must have shape (4, 4) or (B, 4, 4), got {tuple(Tt.shape)}")
    _check_rigid(Tt, name)
    Tt = Tt.to(dtype=like.dtype, device=like.device)
    if Tt.ndim == 2:
        Tt = Tt.unsqueeze(0)
    if batch is not None and Tt.shape[0] not in (1, batch):
        raise ValueError(f"{name} has batch size {Tt.shape[0]}, expected 1 or {batch}")
    return Tt


def _check_depth(depth: torch.Tensor, name: str) -> None:
    """Depth is ``(B, 1, H, W)``, non-negative where finite (NaN/inf/0 mean missing)."""
    check_image(depth, name, channels=1)
    d = depth.detach()
    neg = torch.isfinite(d) & (d < 0)
    if bool(neg.any()):
        raise ValueError(
            f"{name} must be z-depth >= 0 (depth = -z_camera; 0 or non-finite = missing): found "
            f"{int(neg.sum())} negative value(s), min {float(d[neg].min()):.4g}"
        )


def _check_positive_size(height: int, width: int) -> None:
    for n, v in (("height", height), ("width", width)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
            raise ValueError(f"{n} must be a positive integer, got {v!r}")


# --------------------------------------------------------------------------------------
# Intrinsics
# --------------------------------------------------------------------------------------


def intrinsics(fx: Array, fy: Array, cx: Array, cy: Array) -> Array:
    """Pinhole intrinsics ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (no skew).

    Args:
        fx, fy: focal lengths in pixels, > 0: scalars or ``(B,)``.
        cx, cy: principal point in pixel coordinates (image centre = ``(W/2, H/2)``):
            scalars or ``(B,)``.

    Returns:
        ``(3, 3)`` for scalar inputs, ``(B, 3, 3)`` otherwise; type follows ``fx``.

    Raises:
        ValueError: non-finite values, non-positive focal length, shapes that do not
            broadcast to a scalar or ``(B,)``.
    """
    fxt, restore = _to_tensor_keep_shape(fx, "fx")
    parts = [fxt]
    for v, n in ((fy, "fy"), (cx, "cx"), (cy, "cy")):
        parts.append(_to_tensor_keep_shape(v, n)[0].to(dtype=fxt.dtype, device=fxt.device))
    for t, n in zip(parts, ("fx", "fy", "cx", "cy")):
        check_finite(t, n)
        if t.ndim > 1:
            raise ValueError(f"{n} must be a scalar or have shape (B,), got {tuple(t.shape)}")
    for t, n in zip(parts[:2], ("fx", "fy")):
        if bool((t.detach() <= 0).any()):
            raise ValueError(f"{n} must be a positive focal length in pixels, got {t.detach().tolist()}")
    try:
        fx_, fy_, cx_, cy_ = torch.broadcast_tensors(*parts)
    except RuntimeError as e:
        raise ValueError(f"fx, fy, cx, cy must broadcast to one shape: {e}") from None
    zero, one = torch.zeros_like(fx_), torch.ones_like(fx_)
    K = torch.stack(
        [torch.stack([fx_, zero, cx_], -1), torch.stack([zero, fy_, cy_], -1), torch.stack([zero, zero, one], -1)],
        -2,
    )
    return restore(K)


def intrinsics_from_fov(fov_x_deg: Array, width: int, height: int) -> Array:
    """Square-pixel intrinsics from a horizontal field of view (Mitsuba ``fov_axis='x'``).

    ``fx = fy = (W / 2) / tan(fov_x / 2)``, principal point at the image centre
    ``(cx, cy) = (W / 2, H / 2)``.

    Args:
        fov_x_deg: horizontal field of view in degrees, in (0, 180): scalar or ``(B,)``.
        width, height: image size in pixels.

    Returns:
        ``(3, 3)`` or ``(B, 3, 3)``; type follows ``fov_x_deg`` (a Python float gives numpy).
    """
    _check_positive_size(height, width)
    fov, restore = _to_tensor_keep_shape(fov_x_deg, "fov_x_deg")
    check_finite(fov, "fov_x_deg")
    if fov.ndim > 1:
        raise ValueError(f"fov_x_deg must be a scalar or have shape (B,), got {tuple(fov.shape)}")
    if bool(((fov.detach() <= 0) | (fov.detach() >= 180)).any()):
        raise ValueError(f"fov_x_deg must lie in (0, 180) degrees, got {fov.detach().tolist()}")
    f = (width / 2.0) / torch.tan(torch.deg2rad(fov) / 2.0)
    cx = torch.full_like(f, width / 2.0)
    cy = torch.full_like(f, height / 2.0)
    return restore(intrinsics(f, f, cx, cy))


def scale_intrinsics(K: Array, scale: float) -> Array:
    """Intrinsics of the same camera with its image resized by ``scale`` on both axes.

    With the top-left corner at ``(0, 0)`` a resize maps ``(u, v) -> (scale u, scale v)``, so
    ``fx, fy, skew, cx, cy`` all scale: ``K[..., :2, :] * scale``.

    Args:
        K: ``(3, 3)`` or ``(B, 3, 3)``, numpy or torch.
        scale: new size / old size, > 0 (e.g. 2 for an image twice as large).

    Returns:
        A scaled copy of the same type and shape; ``K`` is not modified.
    """
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)) \
            or not math.isfinite(scale) or scale <= 0:
        raise ValueError(f"scale must be a finite number > 0, got {scale!r}")
    out = K.clone() if isinstance(K, torch.Tensor) else np.array(K, dtype=np.float64)
    if out.shape[-2:] != (3, 3):
        raise ValueError(f"K must have shape (3, 3) or (B, 3, 3), got {tuple(out.shape)}")
    out[..., :2, :] *= scale
    return out


# --------------------------------------------------------------------------------------
# Extrinsics
# --------------------------------------------------------------------------------------


def look_at(eye: Array, target: Array, up: Array = (0.0, 1.0, 0.0)) -> Array:
    """World-to-camera transform of a camera at ``eye`` looking at ``target``.

    The camera's -z axis points from ``eye`` to ``target``; its +y axis is the part of
    ``up`` (world frame, Y up by default) orthogonal to the viewing direction; +x
    completes a right-handed frame (x = y cross z, "right" on screen).

    Args:
        eye, target: ``(3,)`` or ``(B, 3)`` world points (type follows ``eye``).
        up: ``(3,)`` or ``(B, 3)`` world up direction, need not be unit.

    Returns:
        ``(4, 4)`` or ``(B, 4, 4)`` rigid ``world_to_camera``.

    Raises:
        ValueError: wrong shapes, non-finite values, ``eye == target``, or ``up``
            parallel to the viewing direction.
    """
    e, restore = to_tensor(eye, "eye")
    t = to_tensor(target, "target")[0].to(dtype=e.dtype, device=e.device)
    u = to_tensor(up, "up")[0].to(dtype=e.dtype, device=e.device)
    for x, n in ((e, "eye"), (t, "target"), (u, "up")):
        if x.ndim not in (1, 2) or x.shape[-1] != 3:
            raise ValueError(f"{n} must have shape (3,) or (B, 3), got {tuple(x.shape)}")
        check_finite(x, n)
    try:
        e, t, u = torch.broadcast_tensors(e, t, u)
    except RuntimeError as err:
        raise ValueError(f"eye, target, up must broadcast to one shape: {err}") from None
    back = e - t  # camera +z points back towards the viewer
    dist = back.norm(dim=-1, keepdim=True)
    if bool((dist.detach() <= 1e-12).any()):
        raise ValueError("look_at: eye and target coincide, the viewing direction is undefined")
    z = back / dist
    x = torch.linalg.cross(u, z, dim=-1)
    xn = x.norm(dim=-1, keepdim=True)
    if bool((xn.detach() <= 1e-9 * u.detach().norm(dim=-1, keepdim=True).clamp_min(1e-300)).any()):
        raise ValueError("look_at: up is parallel to the viewing direction (or zero); pick another up")
    x = x / xn
    y = torch.linalg.cross(z, x, dim=-1)
    R = torch.stack([x, y, z], dim=-2)  # rows = camera axes in world coords = world->camera rotation
    tr = -(R @ e.unsqueeze(-1)).squeeze(-1)
    return restore(_compose(R, tr))


def _compose(R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """``(..., 3, 3)``, ``(..., 3)`` -> ``(..., 4, 4)`` homogeneous transform."""
    top = torch.cat([R, t.unsqueeze(-1)], dim=-1)
    bottom = torch.zeros_like(top[..., :1, :])
    bottom[..., 0, 3] = 1.0
    return torch.cat([top, bottom], dim=-2)


def _invert(T: torch.Tensor) -> torch.Tensor:
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    Rt = R.transpose(-1, -2)
    return _compose(Rt, -(Rt @ t.unsqueeze(-1)).squeeze(-1))


def invert_rigid(T: Array) -> Array:
    """Inverse of a rigid transform, ``[R, t]^-1 = [R^T, -R^T t]`` (exact, no matrix inverse).

    Args:
        T: ``(4, 4)`` or ``(B, 4, 4)`` rigid transform (type follows ``T``).

    Returns:
        Same shape as ``T``.

    Raises:
        ValueError: wrong shape, non-finite, not rigid (non-orthonormal/reflection
            rotation block, last row not (0, 0, 0, 1)).
    """
    Tt, restore = to_tensor(T, "T")
    _check_rigid(Tt, "T")
    return restore(_invert(Tt))


def relative_pose(T_a: Array, T_b: Array) -> Array:
    """Transform from camera a's frame to camera b's frame: ``T_b @ T_a^-1``.

    Args:
        T_a, T_b: ``world_to_camera`` of cameras a and b, ``(4, 4)`` or ``(B, 4, 4)``
            (broadcast; type follows ``T_a``).

    Returns:
        ``(4, 4)`` or ``(B, 4, 4)`` with ``T_b = relative_pose(T_a, T_b) @ T_a``.
        Its ``[:3, :3]`` block rotates camera-a directions (normals, lighting) into
        camera b's frame.
    """
    Ta, restore = to_tensor(T_a, "T_a")
    _check_rigid(Ta, "T_a")
    Tb = to_tensor(T_b, "T_b")[0]
    _check_rigid(Tb, "T_b")
    Tb = Tb.to(dtype=Ta.dtype, device=Ta.device)
    return restore(Tb @ _invert(Ta))


def transform_points(T: Array, points: Array) -> Array:
    """Apply a rigid transform to points: ``R p + t``.

    Args:
        T: ``(4, 4)``, or ``(B, 4, 4)`` one per batch item.
        points: ``(..., 3)``; with a batched ``T`` the leading dimension must be ``B``
            (or 1): ``(B, ..., 3)``, and a single ``(3,)`` point gives ``(B, 3)``.
            Type follows ``points``.

    Returns:
        Transformed points, shape of ``points`` (batch-broadcast with ``T``).
    """
    p, restore = to_tensor(points, "points")
    if p.ndim == 0 or p.shape[-1] != 3:
        raise ValueError(f"points must have shape (..., 3), got {tuple(p.shape)}")
    check_finite(p, "points")
    Tt, _ = to_tensor(T, "T")
    if Tt.ndim not in (2, 3):
        raise ValueError(f"T must have shape (4, 4) or (B, 4, 4), got {tuple(Tt.shape)}")
    _check_rigid(Tt, "T")
    Tt = Tt.to(dtype=p.dtype, device=p.device)
    R, t = Tt[..., :3, :3], Tt[..., :3, 3]
    if Tt.ndim == 3:
        if p.ndim == 1:
            p = p.unsqueeze(0)  # one point, many transforms -> (B, 3)
        if p.shape[0] not in (1, Tt.shape[0]) and Tt.shape[0] != 1:
            raise ValueError(
                f"with T of shape {tuple(Tt.shape)}, points must be (B, ..., 3) with B = {Tt.shape[0]}, "
                f"got {tuple(p.shape)}"
            )
        # View R, t as (B, 1, ..., 1, 3, 3) so they broadcast over the middle dims.
        mid = (1,) * (p.ndim - 2)
        R = R.reshape(R.shape[0], *mid, 3, 3)
        t = t.reshape(t.shape[0], *mid, 3)
    out = (R @ p.unsqueeze(-1)).squeeze(-1) + t
    return restore(out)


def _transform_image_points(T: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
    """``T (B', 4, 4)``, points ``(B, 3, H, W)`` -> ``(B, 3, H, W)`` (internal, no checks)."""
    B = p.shape[0]
    flat = p.reshape(B, 3, -1)
    out = T[:, :3, :3] @ flat + T[:, :3, 3:]
    return out.reshape(p.shape)


# --------------------------------------------------------------------------------------
# Pixels <-> camera-frame points
# --------------------------------------------------------------------------------------


def pixel_grid(
    height: int, width: int, dtype: torch.dtype = torch.float32, device: torch.device | str | None = None
) -> torch.Tensor:
    """Pixel-centre coordinates ``(u, v)`` of an image, as a two-channel image.

    Args:
        height, width: image size H, W.

    Returns:
        torch ``(2, H, W)``: channel 0 is ``u = j + 0.5`` (column j), channel 1 is
        ``v = i + 0.5`` (row i). Broadcasts against ``(B, 2, H, W)``.
    """
    _check_positive_size(height, width)
    v = torch.arange(height, dtype=dtype, device=device) + 0.5
    u = torch.arange(width, dtype=dtype, device=device) + 0.5
    vv, uu = torch.meshgrid(v, u, indexing="ij")
    return torch.stack([uu, vv], dim=0)


def valid_depth(depth: Array) -> Array:
    """Mask of usable depth: finite and > 0.

    Args:
        depth: ``(B, 1, H, W)`` z-depth.

    Returns:
        ``(B, 1, H, W)`` bool (torch or numpy, following ``depth``).
    """
    d, _ = to_tensor(depth, "depth")
    _check_depth(d, "depth")
    return _mask_out(_valid(d), _is_torch(depth))


def _valid(d: torch.Tensor) -> torch.Tensor:
    return torch.isfinite(d) & (d > 0)


def _backproject(d: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Internal: depth ``(B, 1, H, W)`` (already checked), ``K (B', 3, 3)`` -> ``(B, 3, H, W)``."""
    B, _, H, W = d.shape
    d = torch.where(_valid(d), d, torch.zeros_like(d))  # missing -> the origin, no NaN in grads
    uv1 = torch.cat(
        [pixel_grid(H, W, dtype=d.dtype, device=d.device), torch.ones(1, H, W, dtype=d.dtype, device=d.device)]
    ).reshape(1, 3, H * W)
    rays = torch.linalg.inv(K) @ uv1  # vision frame, third component 1 because K's last row is (0, 0, 1)
    flip = torch.tensor(_FLIP, dtype=d.dtype, device=d.device).reshape(1, 3, 1)
    pts = rays * flip * d.reshape(B, 1, H * W)
    return pts.reshape(B, 3, H, W)


def backproject(depth: Array, K: Array) -> Array:
    """Camera-frame 3D points seen at every pixel centre.

    ``p = depth * (x, -y, -z)`` of ``K^-1 [u, v, 1]`` with ``(u, v) = (j + 0.5, i + 0.5)``,
    so ``-p_z = depth``.

    Args:
        depth: ``(B, 1, H, W)`` z-depth (0 / non-finite = missing). Main argument.
        K: ``(3, 3)`` or ``(B, 3, 3)`` intrinsics.

    Returns:
        ``(B, 3, H, W)`` points in our camera frame; pixels with missing depth give
        ``(0, 0, 0)`` (mask them with :func:`valid_depth`).
    """
    d, restore = to_tensor(depth, "depth")
    _check_depth(d, "depth")
    Kt = _check_K(K, "K", d, d.shape[0])
    return restore(_backproject(d, Kt))


def _project(p: torch.Tensor, K: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Internal: points ``(B, 3, *)`` -> uv ``(B, 2, *)``, depth ``(B, 1, *)``."""
    B = p.shape[0]
    flat = p.reshape(B, 3, -1)
    flip = torch.tensor(_FLIP, dtype=p.dtype, device=p.device).reshape(1, 3, 1)
    q = K @ (flat * flip)
    z = q[:, 2:3]  # = -p_z, since K's last row is (0, 0, 1)
    z_safe = torch.where(z.abs() > _EPS_DEPTH, z, torch.full_like(z, _EPS_DEPTH))
    uv = q[:, :2] / z_safe
    return uv.reshape(B, 2, *p.shape[2:]), z.reshape(B, 1, *p.shape[2:])


def project(points: Array, K: Array) -> tuple[Array, Array]:
    """Project camera-frame points to pixel coordinates.

    Args:
        points: ``(B, 3, *)`` points in our camera frame, e.g. ``(B, 3, H, W)`` from
            :func:`backproject` or ``(B, 3, N)``. Main argument.
        K: ``(3, 3)`` or ``(B, 3, 3)`` intrinsics.

    Returns:
        ``uv``: ``(B, 2, *)`` continuous pixel coordinates (u right, v down, pixel
        centres at half-integers). Only meaningful where ``depth > 0``: points behind
        the camera are projected through the centre (mirrored), and ``|depth| < 1e-8``
        is divided by 1e-8 to stay finite.
        ``depth``: ``(B, 1, *)`` z-depth ``-z`` (negative behind the camera).
    """
    p, restore = to_tensor(points, "points")
    if p.ndim < 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (B, 3, ...), got {tuple(p.shape)}")
    check_finite(p, "points")
    Kt = _check_K(K, "K", p, p.shape[0])
    uv, z = _project(p, Kt)
    return restore(uv), restore(z)


# --------------------------------------------------------------------------------------
# Normals from depth
# --------------------------------------------------------------------------------------


def normals_from_depth(
    depth: Array, K: Array, max_rel_jump: float | None = None, stencil: str = "central"
) -> tuple[Array, Array]:
    """Surface normals in the camera frame from a depth map, by finite differences.

    At pixel (i, j) the back-projected points of the 4-neighbour stencil give
    ``n = (P[i+1, j] - P[i-1, j]) x (P[i, j+1] - P[i, j-1])`` (v down x u right, which
    faces the camera), normalised and flipped where needed so that ``n . (-P[i, j]) > 0``.
    Central differences are exact on planes and second-order accurate on smooth
    surfaces; across a depth discontinuity they give a wrong (but finite) normal:
    mask those with ``max_rel_jump`` or your own edge mask.

    ``stencil="one_sided"`` keeps the central difference wherever it is usable and,
    per image axis, falls back to the one usable side (``P[i, j+1] - P[i, j]`` or
    ``P[i, j] - P[i, j-1]``) where the other neighbour is missing, off the image or
    across a jump. Still exact on planes, first-order on curved surfaces there; it gives
    normals next to holes, depth edges and the image border, which the central stencil
    leaves out (on the synthetic MVS-like depth: 62 % of the foreground instead of 49 %).

    Args:
        depth: ``(B, 1, H, W)`` z-depth (0 / non-finite = missing). Main argument.
        K: ``(3, 3)`` or ``(B, 3, 3)`` intrinsics.
        max_rel_jump: if given, a neighbour whose depth differs from the centre's by more
            than ``max_rel_jump * depth`` is not used (a crude depth-edge detector; note
            that a plane seen at a grazing angle has large relative steps too). With the
            central stencil one such neighbour invalidates the pixel; the one-sided
            stencil measures the step against the nearer of the two depths.
        stencil: ``"central"`` (default) or ``"one_sided"`` (see above).

    Returns:
        ``normals``: ``(B, 3, H, W)`` unit normals, camera frame, where valid; the zero
        vector where not (so an unmasked use shows up instead of looking plausible).
        ``valid``: ``(B, 1, H, W)`` bool. Central: False on the one-pixel image border
        (the stencil leaves the image), where any of the 5 stencil depths is missing,
        where the cross product degenerates (|n| <= 1e-9 |dP/du| |dP/dv|), or at jumps.
        One-sided: False where the centre's depth is missing, where an axis has no usable
        neighbour, or where the cross product degenerates.
    """
    d, restore = to_tensor(depth, "depth")
    _check_depth(d, "depth")
    if max_rel_jump is not None and not (math.isfinite(max_rel_jump) and max_rel_jump > 0):
        raise ValueError(f"max_rel_jump must be a positive finite number or None, got {max_rel_jump!r}")
    if stencil not in ("central", "one_sided"):
        raise ValueError(f"stencil must be 'central' or 'one_sided', got {stencil!r}")
    B, _, H, W = d.shape
    if H < 3 or W < 3:
        raise ValueError(f"depth must be at least 3x3 for central differences, got {H}x{W}")
    Kt = _check_K(K, "K", d, B)
    P = _backproject(d, Kt)
    ok = _valid(d)
    if stencil == "one_sided":
        normals, valid = _normals_one_sided(d, P, ok, max_rel_jump)
        return restore(normals), _mask_out(valid, _is_torch(depth))

    c = (slice(None), slice(None), slice(1, -1), slice(1, -1))
    du = P[..., 1:-1, 2:] - P[..., 1:-1, :-2]  # along u (right)
    dv = P[..., 2:, 1:-1] - P[..., :-2, 1:-1]  # along v (down)
    n = torch.linalg.cross(dv, du, dim=1)
    nn_ = n.norm(dim=1, keepdim=True)
    scale = du.norm(dim=1, keepdim=True) * dv.norm(dim=1, keepdim=True)
    good = ok[c] & ok[..., 1:-1, 2:] & ok[..., 1:-1, :-2] & ok[..., 2:, 1:-1] & ok[..., :-2, 1:-1]
    good = good & (nn_.detach() > 1e-9 * scale.detach()) & (scale.detach() > 0)
    if max_rel_jump is not None:
        dc = d[c]
        for nb in (d[..., 1:-1, 2:], d[..., 1:-1, :-2], d[..., 2:, 1:-1], d[..., :-2, 1:-1]):
            with torch.no_grad():
                jump = (nb - dc).abs() > max_rel_jump * dc
            good = good & ~torch.nan_to_num(jump, nan=True)
    # Normalise only where good (avoids 0/0 and NaN gradients), then face the camera.
    n = torch.where(good, n / torch.where(good, nn_, torch.ones_like(nn_)), torch.zeros_like(n))
    facing = (n * -P[c]).sum(dim=1, keepdim=True)
    n = torch.where(facing < 0, -n, n)

    normals = F.pad(n, (1, 1, 1, 1))
    valid = F.pad(good, (1, 1, 1, 1), value=False)
    return restore(normals), _mask_out(valid, _is_torch(depth))


def _side_differences(d: torch.Tensor, P: torch.Tensor, ok: torch.Tensor, max_rel_jump: float | None,
                      dim: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Internal: the difference of ``P (B, 3, H, W)`` along ``dim`` (2 = v, 3 = u) from the usable sides.

    Central where both neighbours are usable, else the one usable side; ``(B, 3, H, W)``
    and where any side was usable ``(B, 1, H, W)`` bool.
    """
    n = d.shape[dim]
    step = P.narrow(dim, 1, n - 1) - P.narrow(dim, 0, n - 1)  # P[k + 1] - P[k], at k
    d0, d1 = d.narrow(dim, 0, n - 1), d.narrow(dim, 1, n - 1)
    usable = ok.narrow(dim, 0, n - 1) & ok.narrow(dim, 1, n - 1)
    if max_rel_jump is not None:
        with torch.no_grad():
            usable = usable & ~torch.nan_to_num((d1 - d0).abs() > max_rel_jump * torch.minimum(d0, d1), nan=True)
    pad_after = [0, 0] * (3 - dim) + [0, 1]  # F.pad lists the last dimension first
    pad_before = [0, 0] * (3 - dim) + [1, 0]
    fwd, fwd_ok = F.pad(step, pad_after), F.pad(usable, pad_after, value=False)  # forward side at k
    bwd, bwd_ok = F.pad(step, pad_before), F.pad(usable, pad_before, value=False)  # backward side at k
    diff = torch.where(fwd_ok & bwd_ok, fwd + bwd, torch.where(fwd_ok, fwd, bwd))
    return diff, fwd_ok | bwd_ok


def _normals_one_sided(d: torch.Tensor, P: torch.Tensor, ok: torch.Tensor,
                       max_rel_jump: float | None) -> tuple[torch.Tensor, torch.Tensor]:
    """Internal: :func:`normals_from_depth` with ``stencil="one_sided"`` on checked tensors."""
    dv, ok_v = _side_differences(d, P, ok, max_rel_jump, 2)
    du, ok_u = _side_differences(d, P, ok, max_rel_jump, 3)
    n = torch.linalg.cross(dv, du, dim=1)
    nn_ = n.norm(dim=1, keepdim=True)
    scale = du.norm(dim=1, keepdim=True) * dv.norm(dim=1, keepdim=True)
    good = ok & ok_v & ok_u & (nn_.detach() > 1e-9 * scale.detach()) & (scale.detach() > 0)
    n = torch.where(good, n / torch.where(good, nn_, torch.ones_like(nn_)), torch.zeros_like(n))
    n = torch.where((n * -P).sum(dim=1, keepdim=True) < 0, -n, n)
    return n, good


# --------------------------------------------------------------------------------------
# Warping
# --------------------------------------------------------------------------------------


def _uv_to_grid(uv: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """``(B, 2, H, W)`` pixel coords -> ``(B, H, W, 2)`` grid for ``grid_sample(align_corners=False)``.

    With align_corners=False, -1 and +1 are the outer edges of the border pixels, so
    pixel j's centre (u = j + 0.5) maps to x = 2 (j + 0.5) / W - 1: exactly x = 2u/W - 1.
    """
    x = 2.0 * uv[:, 0] / width - 1.0
    y = 2.0 * uv[:, 1] / height - 1.0
    return torch.stack([x, y], dim=-1)


def warp(
    image_src: Array,
    depth_dst: Array,
    K_dst: Array,
    K_src: Array,
    dst_to_src: Array,
    depth_src: Array | None = None,
    rel_tol: float = 0.01,
) -> tuple[Array, Array]:
    """Resample a source view into a destination view using the destination's depth.

    For every destination pixel centre: back-project with ``depth_dst`` and ``K_dst``,
    move the point into the source camera with ``dst_to_src``, project with ``K_src``,
    and sample ``image_src`` bilinearly there (``grid_sample``, ``align_corners=False``,
    border padding: the half-pixel rim outside the outermost pixel centres repeats the
    edge pixel).

    A destination pixel is valid when
      * its depth is valid (finite, > 0),
      * the point is in front of the source camera (source z-depth > 0),
      * it projects inside the source image rectangle ``0 <= u <= W_src, 0 <= v <= H_src``,
      * (only if ``depth_src`` is given) it is not occluded in the source view:
        ``|z - depth_src(u, v)| <= rel_tol * z`` where ``z`` is the point's source
        z-depth. ``depth_src(u, v)`` is interpolated bilinearly in *inverse* depth,
        which is exact for planes (1/depth is affine in (u, v) on a plane), so the
        test holds on ground planes seen at grazing angles where nearest-neighbour
        depth would be off by several percent. Missing source depth counts as inverse
        depth 0 (infinitely far), and across depth edges the interpolated value falls
        between the two surfaces, so points within about one source pixel of a depth
        edge or of missing depth mostly fail the test: the mask is conservative there.
        (Rarely a blend of a foreground and a background tap matches a surface seen
        at a grazing angle by coincidence; the sample is then a colour blend.)

    Invalid pixels of ``warped`` are set to 0. ``warped`` is differentiable w.r.t.
    ``image_src``, ``depth_dst``, the intrinsics and the pose (the mask is not).

    Args:
        image_src: ``(B, C, H_src, W_src)`` source image. Main argument.
        depth_dst: ``(B, 1, H, W)`` destination z-depth (0 / non-finite = missing).
        K_dst: ``(3, 3)`` or ``(B, 3, 3)`` destination intrinsics.
        K_src: ``(3, 3)`` or ``(B, 3, 3)`` source intrinsics.
        dst_to_src: ``(4, 4)`` or ``(B, 4, 4)`` rigid transform from the destination
            camera frame to the source camera frame, i.e.
            ``relative_pose(world_to_camera_dst, world_to_camera_src)``.
        depth_src: optional ``(B, 1, H_src, W_src)`` source z-depth for the occlusion test.
        rel_tol: relative depth tolerance of the occlusion test, > 0.

    Returns:
        ``warped``: ``(B, C, H, W)`` source image seen from the destination camera.
        ``valid``: ``(B, 1, H, W)`` bool.
    """
    img, restore = to_tensor(image_src, "image_src")
    check_image(img, "image_src")
    check_finite(img, "image_src")
    B, _, Hs, Ws = img.shape
    dd = to_tensor(depth_dst, "depth_dst")[0].to(dtype=img.dtype, device=img.device)
    _check_depth(dd, "depth_dst")
    if dd.shape[0] != B:
        raise ValueError(f"depth_dst {tuple(dd.shape)} and image_src {tuple(img.shape)} must share batch size")
    Kd = _check_K(K_dst, "K_dst", img, B)
    Ks = _check_K(K_src, "K_src", img, B)
    T = _check_T(dst_to_src, "dst_to_src", img, B)
    if not (isinstance(rel_tol, (int, float)) and math.isfinite(rel_tol) and rel_tol > 0):
        raise ValueError(f"rel_tol must be a positive finite number, got {rel_tol!r}")
    ds = None
    if depth_src is not None:
        ds = to_tensor(depth_src, "depth_src")[0].to(dtype=img.dtype, device=img.device)
        _check_depth(ds, "depth_src")
        if ds.shape[0] != B or ds.shape[-2:] != (Hs, Ws):
            raise ValueError(
                f"depth_src {tuple(ds.shape)} must match image_src {tuple(img.shape)} in batch size and (H, W)"
            )

    p_src = _transform_image_points(T, _backproject(dd, Kd))
    uv, z = _project(p_src, Ks)
    u, v = uv[:, :1], uv[:, 1:]
    with torch.no_grad():
        valid = _valid(dd) & (z > _EPS_DEPTH) & (u >= 0) & (u <= Ws) & (v >= 0) & (v <= Hs)
    # Park invalid coordinates at (u, v) = (0, 0): keeps the grid finite and in range.
    grid = _uv_to_grid(torch.where(valid, uv, torch.zeros_like(uv)), Hs, Ws)
    warped = F.grid_sample(img, grid, mode="bilinear", padding_mode="border", align_corners=False)

    if ds is not None:
        with torch.no_grad():
            ok_s = _valid(ds)
            inv = torch.where(ok_s, 1.0 / torch.where(ok_s, ds, torch.ones_like(ds)), torch.zeros_like(ds))
            inv_at = F.grid_sample(inv, grid.detach(), mode="bilinear", padding_mode="border", align_corners=False)
            tiny = torch.finfo(inv_at.dtype).tiny
            d_at = torch.where(inv_at > 0, 1.0 / inv_at.clamp_min(tiny), torch.zeros_like(inv_at))
            valid = valid & ((z.detach() - d_at).abs() <= rel_tol * z.detach())

    warped = torch.where(valid, warped, torch.zeros_like(warped))
    return restore(warped), _mask_out(valid, _is_torch(image_src))


# --------------------------------------------------------------------------------------
# Camera bundle
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera: intrinsics, pose and image size, stored as torch tensors.

    Attributes:
        K: ``(3, 3)`` or ``(B, 3, 3)`` intrinsics (see the module docstring).
        world_to_camera: ``(4, 4)`` or ``(B, 4, 4)`` rigid transform.
        width, height: image size in pixels.

    numpy inputs are converted to float64 tensors on construction.
    """

    K: torch.Tensor
    world_to_camera: torch.Tensor
    width: int
    height: int

    def __post_init__(self) -> None:
        _check_positive_size(self.height, self.width)
        T, _ = to_tensor(self.world_to_camera, "world_to_camera")
        if T.ndim not in (2, 3):
            raise ValueError(f"world_to_camera must have shape (4, 4) or (B, 4, 4), got {tuple(T.shape)}")
        _check_rigid(T, "world_to_camera")
        K = _check_K(self.K, "K", T, None)
        if to_tensor(self.K, "K")[0].ndim == 2:
            K = K[0]
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "world_to_camera", T)

    @classmethod
    def look_at(
        cls,
        eye: Array,
        target: Array,
        fov_x_deg: float,
        width: int,
        height: int,
        up: Array = (0.0, 1.0, 0.0),
    ) -> "Camera":
        """Camera at ``eye`` looking at ``target`` with a horizontal FOV and centred principal point."""
        T, _ = to_tensor(look_at(eye, target, up), "world_to_camera")
        K = to_tensor(intrinsics_from_fov(fov_x_deg, width, height), "K")[0].to(T.dtype)
        return cls(K=K, world_to_camera=T, width=width, height=height)

    @property
    def center(self) -> torch.Tensor:
        """``(3,)`` or ``(B, 3)`` camera centre in world coordinates, ``-R^T t``."""
        return _invert(self.world_to_camera)[..., :3, 3]

    def pose_to(self, other: "Camera") -> torch.Tensor:
        """``(4, 4)`` or ``(B, 4, 4)`` transform from this camera's frame to ``other``'s.

        E.g. ``warp(img_src, depth_dst, dst.K, src.K, dst.pose_to(src), depth_src)``.
        """
        return relative_pose(self.world_to_camera, other.world_to_camera)
