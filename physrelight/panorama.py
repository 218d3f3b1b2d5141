"""Pinhole views of a lat-long panorama: real photos with known lighting, and the exact sky of a target.

A panorama (an environment map, :mod:`physrelight.envmap`) is the radiance arriving at one
point from every direction. A pinhole camera at that point sees, through pixel ``(u, v)``,
the radiance along the pixel's ray: the map looked up in the ray's world direction. So a
view of a real HDR panorama is a real photo whose lighting is exactly known (the whole map,
turned into the camera frame), and a view of a *target* panorama through a photo's camera
is that target's sky as the photo would show it.

Conventions:

* camera frame, pixel coordinates and ``K``: :mod:`physrelight.camera` (x right, y up, the
  camera looks down -z; pixel centres at ``(j + 0.5, i + 0.5)``);
* world frame Y up; :func:`level_camera`'s yaw turns from world -Z towards +X (clockwise
  seen from above, like ``relight --sun``'s azimuth), its pitch lifts the view above the
  horizon, roll is 0 (a level horizon).

Antialiasing: a pixel is the mean of ``samples x samples`` sub-pixel rays on a regular
grid, each a bilinear lookup of the map (:func:`physrelight.envmap.sample`, Mitsuba's
interpolant): a box filter of the pixel's footprint. :func:`native_width` gives the widest
view whose every pixel covers at least one texel, so a view never invents detail the
panorama does not have.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import torch

from physrelight import envmap
from physrelight._checks import Array, check_finite, check_rotation, to_tensor
from physrelight.camera import intrinsics_from_fov, look_at
from physrelight.parallel import even_strips, thread_map

__all__ = ["INTERPOLATIONS", "MAX_FOV_DEG", "camera_rays", "level_camera", "look_up", "native_width", "pixel_rays",
           "texel_magnification", "view", "view_intrinsics", "view_mask"]

MAX_FOV_DEG = 179.0
"""Widest horizontal field of view a pinhole view may have (180 deg is a plane at infinity)."""


def level_camera(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """``(4, 4)`` world-to-camera transform of a level camera at the origin.

    Args:
        yaw_deg: viewing direction's azimuth: 0 looks along world -Z, 90 along +X.
        pitch_deg: elevation of the viewing direction, in (-90, 90); positive looks up.

    Returns:
        float64 rigid transform (zero translation; :func:`physrelight.camera.look_at` with up = +Y).
    """
    if not (math.isfinite(yaw_deg) and math.isfinite(pitch_deg)) or not -90.0 < pitch_deg < 90.0:
        raise ValueError(f"yaw must be finite and pitch in (-90, 90) degrees, got yaw={yaw_deg}, pitch={pitch_deg}")
    y, p = math.radians(yaw_deg), math.radians(pitch_deg)
    forward = np.array([math.sin(y) * math.cos(p), math.sin(p), -math.cos(y) * math.cos(p)])
    return np.asarray(look_at(np.zeros(3), forward, np.array([0.0, 1.0, 0.0])))


def native_width(fov_x_deg: float, height_over_width: float, panorama_width: int) -> int:
    """The widest view (pixels) of a ``panorama_width``-wide map whose every pixel covers a texel.

    A pinhole pixel at angle ``alpha`` off the axis subtends the solid angle
    ``cos(alpha)^3 / f^2`` (``f`` the focal length in pixels): smallest in the corners. A
    texel at the equator subtends ``(2 pi / W)^2``. Equating the two in the corner gives
    ``width = W tan(fov / 2) cos(alpha_corner)^1.5 / pi``, rounded down: every pixel then
    averages at least one texel, so the view is never upsampled past the panorama.

    Args:
        fov_x_deg: horizontal field of view, in (0, :data:`MAX_FOV_DEG`].
        height_over_width: the view's aspect, height / width (0.75 for 4:3 landscape).
        panorama_width: the map's width W in texels.
    """
    _check_fov(fov_x_deg)
    if not (math.isfinite(height_over_width) and height_over_width > 0):
        raise ValueError(f"height_over_width must be a positive number, got {height_over_width}")
    if panorama_width < 4:
        raise ValueError(f"panorama_width must be at least 4 texels, got {panorama_width}")
    t = math.tan(math.radians(fov_x_deg) / 2.0)
    cos_corner = 1.0 / math.sqrt(1.0 + t * t * (1.0 + height_over_width**2))
    return max(1, int(panorama_width * t * cos_corner**1.5 / math.pi))


def _check_fov(fov_x_deg: float) -> None:
    if not (math.isfinite(fov_x_deg) and 0.0 < fov_x_deg <= MAX_FOV_DEG):
        raise ValueError(f"a pinhole view's field of view must lie in (0, {MAX_FOV_DEG:g}] degrees, got {fov_x_deg}")


def _rotation(world_to_camera: Array) -> torch.Tensor:
    r, _ = to_tensor(world_to_camera, "world_to_camera", torch.float64)
    if r.shape == (4, 4):
        r = r[:3, :3]
    if r.shape != (3, 3):
        raise ValueError(f"world_to_camera must have shape (4, 4) or (3, 3), got {tuple(r.shape)}")
    check_finite(r, "world_to_camera")
    check_rotation(r, "world_to_camera")
    return r


def _check_size(height: int, width: int, samples: int) -> None:
    for name, v in (("height", height), ("width", width), ("samples", samples)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be a positive integer, got {v!r}")


def camera_rays(K: Array, world_to_camera: Array, height: int, width: int, samples: int = 1,
                rows: slice | None = None) -> torch.Tensor:
    """World directions of a pinhole camera's sub-pixel rays.

    Args:
        K: ``(3, 3)`` intrinsics (:mod:`physrelight.camera`).
        world_to_camera: ``(4, 4)`` or ``(3, 3)``; only the rotation is used (a panorama is at infinity).
        height, width: image size.
        samples: rays per pixel along each axis, on the regular grid ``(k + 0.5) / samples``.
        rows: only these image rows (None: all).

    Returns:
        torch float64 ``(h, width, samples**2, 3)`` unit directions, world frame (``h`` rows).
    """
    _check_size(height, width, samples)
    Kt, _ = to_tensor(K, "K", torch.float64)
    if Kt.shape != (3, 3):
        raise ValueError(f"K must have shape (3, 3), got {tuple(Kt.shape)}")
    check_finite(Kt, "K")
    R = _rotation(world_to_camera)
    i = torch.arange(height, dtype=torch.float64)[rows if rows is not None else slice(None)]
    j = torch.arange(width, dtype=torch.float64)
    s = (torch.arange(samples, dtype=torch.float64) + 0.5) / samples
    v = (i[:, None, None, None] + s[None, None, :, None]).expand(-1, width, samples, samples)
    u = (j[None, :, None, None] + s[None, None, None, :]).expand(len(i), -1, samples, samples)
    uv1 = torch.stack([u, v, torch.ones_like(u)], dim=-1).reshape(len(i), width, samples * samples, 3)
    vision = uv1 @ torch.linalg.inv(Kt).T  # x right, y down, z forward
    cam = vision * torch.tensor([1.0, -1.0, -1.0], dtype=torch.float64)  # our camera frame
    world = cam @ R  # R^T d for row vectors
    return world / torch.linalg.vector_norm(world, dim=-1, keepdim=True)


INTERPOLATIONS = ("bilinear", "bspline")
"""How :func:`look_up` reconstructs a map between texels: :func:`physrelight.envmap.sample` (bilinear, Mitsuba's) or
:func:`physrelight.envmap.sample_bspline` (smooth, for views that magnify the map)."""


def texel_magnification(K: Array, panorama_width: int) -> float:
    """Pixels per texel at the centre of a view with intrinsics ``K (3, 3)`` of a ``panorama_width``-wide map: the
    focal length (pixels per radian there) times a texel's width at the equator (``2 pi / W`` radians). Above 1 the
    view magnifies the map. It is a typical value, not a bound: off the axis a pinhole's pixels subtend less (more
    pixels per texel), towards the poles a texel narrows (fewer). A view at :func:`native_width` is under 1 here."""
    f = float(np.asarray(K, dtype=np.float64)[0, 0])
    return f * 2.0 * math.pi / float(panorama_width)


def view(env: Array, K: Array, world_to_camera: Array, height: int, width: int, samples: int = 4,
         chunk_rays: int = 1 << 20, interpolation: str = "bilinear") -> Array:
    """The panorama as a pinhole camera at its centre sees it: linear radiance per pixel.

    Args:
        env: ``(He, We, 3)`` lat-long map (world frame; :func:`physrelight.envmap.check_envmap`).
        K: ``(3, 3)`` intrinsics of the view; world_to_camera: ``(4, 4)`` or ``(3, 3)``.
        height, width: the view's size in pixels.
        samples: sub-pixel rays per axis (``samples**2`` per pixel). 4 and 8 agree within 1 %
            (relative l1) on the shipped panoramas at :func:`native_width`.
        chunk_rays: rays looked up at once (memory bound).
        interpolation: one of :data:`INTERPOLATIONS` (:func:`look_up`).

    Returns:
        ``(height, width, 3)`` radiance, the type of ``env`` (float64 for numpy input).
    """
    e, restore = to_tensor(env, "env")
    envmap.check_envmap(e, "env")
    _check_size(height, width, samples)
    if interpolation == "bspline" and samples == 1 and e.dtype == torch.float32 and e.device.type == "cpu":
        return restore(_bspline_view(e, K, world_to_camera, height, width))
    rows_per_chunk = max(1, chunk_rays // (width * samples * samples))

    def chunk(r0: int) -> torch.Tensor:
        d = camera_rays(K, world_to_camera, height, width, samples, slice(r0, min(height, r0 + rows_per_chunk)))
        return look_up(e, d, interpolation)

    # the chunks are independent: on torch's threads (physrelight.parallel), the same pixels as one after another
    return restore(torch.cat(thread_map(chunk, range(0, height, rows_per_chunk)), dim=0))


@numba.njit(inline="always")
def _pixel_ray(k: np.ndarray, R: np.ndarray, u: float, v: float) -> tuple[float, float, float]:  # pragma: no cover
    """The unit world direction through image point ``(u, v)`` (pixel units) of a camera with inverse intrinsics
    ``k (3, 3)`` and world-to-camera rotation ``R (3, 3)``: :func:`camera_rays`' arithmetic per ray (its matrix
    products may round the last bit differently)."""
    c0 = u * k[0, 0] + v * k[0, 1] + k[0, 2]
    c1 = -(u * k[1, 0] + v * k[1, 1] + k[1, 2])  # vision (x right, y down, z forward) to our camera frame
    c2 = -(u * k[2, 0] + v * k[2, 1] + k[2, 2])
    d0 = c0 * R[0, 0] + c1 * R[1, 0] + c2 * R[2, 0]  # R^T d
    d1 = c0 * R[0, 1] + c1 * R[1, 1] + c2 * R[2, 1]
    d2 = c0 * R[0, 2] + c1 * R[1, 2] + c2 * R[2, 2]
    n = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return d0 / n, d1 / n, d2 / n


@numba.njit(nogil=True, cache=True)
def _pixel_rays_loop(k: np.ndarray, R: np.ndarray, i0: int, out: np.ndarray) -> None:  # pragma: no cover
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j, 0], out[i, j, 1], out[i, j, 2] = _pixel_ray(k, R, j + 0.5, i0 + i + 0.5)


def _loop_camera(K: Array, world_to_camera: Array) -> tuple[np.ndarray, np.ndarray]:
    """The checked camera as the compiled loops take it: the inverse intrinsics and the world-to-camera rotation,
    ``(3, 3)`` float64 each, contiguous."""
    Kt, _ = to_tensor(K, "K", torch.float64)
    if Kt.shape != (3, 3):
        raise ValueError(f"K must have shape (3, 3), got {tuple(Kt.shape)}")
    check_finite(Kt, "K")
    return (np.ascontiguousarray(torch.linalg.inv(Kt).numpy()),
            np.ascontiguousarray(_rotation(world_to_camera).numpy()))


def pixel_rays(K: Array, world_to_camera: Array, height: int, width: int, rows: slice | None = None) -> torch.Tensor:
    """``(h, width, 3)`` float64 unit world directions through the pixel centres of rows ``rows`` (None: all) of a
    ``height x width`` pinhole camera: :func:`camera_rays` with one ray per pixel, as one compiled loop (a
    12-megapixel image: 0.15 s against 5 s). Equal to it within the last bit (the matrix products round differently)."""
    _check_size(height, width, 1)
    k_inv, r = _loop_camera(K, world_to_camera)
    i0, i1, _ = (rows or slice(None)).indices(height)
    out = np.empty((max(0, i1 - i0), width, 3), dtype=np.float64)
    _pixel_rays_loop(k_inv, r, i0, out)
    return torch.from_numpy(out)


def _bspline_view(env: torch.Tensor, K: Array, world_to_camera: Array, height: int, width: int) -> torch.Tensor:
    """:func:`view` of a float32 map by the cubic B-spline, one ray per pixel, as one compiled loop per strip of rows
    (:func:`_bspline_view_rows`) on torch's threads: the work of :func:`camera_rays` and
    :func:`physrelight.envmap.sample_bspline` without their full-size intermediates (a 12-megapixel sky: 1.2 s against
    2.3 s, one thread, 2-core AMD EPYC). The texel coordinates and weights are float64 where the torch path rounds the
    rays to float32 first; beside a pole, where ``acos`` magnifies a direction's last bit, that path's lookup was
    up to 0.3 relative off and this one stays with the float64 evaluation (``tests/physrelight/test_panorama.py``
    08)."""
    k_inv, r = _loop_camera(K, world_to_camera)
    e = env.contiguous().numpy()
    means = env.double().mean(dim=1)  # the pole rows' means, as sample_bspline takes them
    north = ((5 * means[0] + means[1]) / 6).numpy()
    south = ((5 * means[-1] + means[-2]) / 6).numpy()
    out = np.empty((height, width, 3), dtype=np.float32)
    n = max(1, torch.get_num_threads())
    thread_map(lambda s: _bspline_view_rows(e, k_inv, r, north, south, out, s[0], s[1]),
               even_strips(height, 4 * n if n > 1 else 1))
    return torch.from_numpy(out)


@numba.njit(nogil=True, cache=True)
def _bspline_view_rows(env: np.ndarray, k_inv: np.ndarray, R: np.ndarray, north: np.ndarray, south: np.ndarray,
                       out: np.ndarray, i0: int, i1: int) -> None:  # pragma: no cover
    """Rows ``i0 <= i < i1`` of a pinhole view (``k_inv`` the inverse intrinsics, ``R`` world-to-camera, both float64)
    of ``env (H, W, 3)`` float32 by the cubic B-spline into ``out (h, w, 3)`` float32: per pixel the ray of
    :func:`camera_rays`, then :func:`physrelight.envmap.sample_bspline`'s texel coordinates, weights and sum, in
    float64; a ray at a pole takes the pole's ``north``/``south (3,)`` value."""
    he, we = env.shape[0], env.shape[1]
    w = out.shape[1]
    wx = np.empty(4)
    wy = np.empty(4)
    for i in range(i0, i1):
        v = i + 0.5
        for j in range(w):
            d0, d1, d2 = _pixel_ray(k_inv, R, j + 0.5, v)
            if abs(d1) >= 1.0 - 1e-12:  # a pole: the pole rows' means (sample_bspline's _at_poles)
                pole = north if d1 > 0 else south
                out[i, j, 0], out[i, j, 1], out[i, j, 2] = pole[0], pole[1], pole[2]
                continue
            uu = math.atan2(d0, -d2) / (2.0 * math.pi)
            uu = uu - math.floor(uu)
            x = uu * we - 0.5
            y = math.acos(min(max(d1, -1.0), 1.0)) / math.pi * (he - 1)
            ix, iy = math.floor(x), math.floor(y)
            _bspline_weights(x - ix, wx)
            _bspline_weights(y - iy, wy)
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            for a in range(4):
                row = min(max(iy + a - 1, 0), he - 1)
                for b in range(4):
                    col = (ix + b - 1) % we
                    wab = wy[a] * wx[b]
                    s0 += wab * env[row, col, 0]
                    s1 += wab * env[row, col, 1]
                    s2 += wab * env[row, col, 2]
            out[i, j, 0], out[i, j, 1], out[i, j, 2] = s0, s1, s2


@numba.njit(inline="always")
def _bspline_weights(t: float, ws: np.ndarray) -> None:  # pragma: no cover
    """:func:`physrelight.envmap._bspline_weights` of ``t`` in [0, 1) into ``ws (4,)``."""
    t2 = t * t
    t3 = t2 * t
    s = 1.0 - t
    ws[0] = s * s * s / 6.0
    ws[1] = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0
    ws[2] = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0
    ws[3] = t3 / 6.0


def look_up(env: torch.Tensor, rays: torch.Tensor, interpolation: str = "bilinear") -> torch.Tensor:
    """Box-filtered lookup: ``env (He, We, C)`` torch map, ``rays (h, w, S, 3)`` world directions
    (:func:`camera_rays`) -> ``(h, w, C)``, the mean of the lookups of each pixel's ``S`` rays, bilinear
    (:func:`physrelight.envmap.sample`) or cubic B-spline (:func:`physrelight.envmap.sample_bspline`).

    For several maps seen through one camera (a photo, its sky mask, targets), make the rays
    once. ``C`` is 3 (a map) or 1 (a mask); no checks beyond the samplers'."""
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
    if env.ndim == 3 and env.shape[-1] == 1:
        return look_up(env.expand(-1, -1, 3).contiguous(), rays, interpolation)[..., :1]
    sampler = envmap.sample_bspline if interpolation == "bspline" else envmap.sample
    return sampler(env, rays.to(env.dtype)).mean(dim=-2)


def view_mask(mask: Array, K: Array, world_to_camera: Array, height: int, width: int, samples: int = 4) -> Array:
    """Fraction of each pixel of a view covered by a panorama mask.

    Args:
        mask: ``(He, We)`` bool or float in [0, 1] on the panorama's texels (e.g. its sky).
        K, world_to_camera, height, width, samples: as for :func:`view`.

    Returns:
        ``(height, width)`` coverage in [0, 1] (threshold at 0.5 for a mask of the view), type of ``mask``.
    """
    m, restore = to_tensor(mask, "mask")
    if m.ndim != 2:
        raise ValueError(f"mask must have shape (H, W), got {tuple(m.shape)}")
    cover = view(m[..., None].expand(-1, -1, 3).contiguous(), K, world_to_camera, height, width, samples)
    return restore(cover[..., 0].clamp(0.0, 1.0))  # bilinear weights sum to 1: clamp only rounding


def view_intrinsics(fov_x_deg: float, width: int, height: int) -> np.ndarray:
    """``(3, 3)`` intrinsics of a view with horizontal field of view ``fov_x_deg`` (checked against :data:`MAX_FOV_DEG`)."""
    _check_fov(fov_x_deg)
    return np.asarray(intrinsics_from_fov(float(fov_x_deg), width, height), dtype=np.float64)

