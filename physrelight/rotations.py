"""Rotation matrices ``(3, 3)`` used to turn lighting, environment maps and cameras.

All rotations act on column vectors, ``x' = R x``, in a right-handed frame.
"""

from __future__ import annotations

import math

import numpy as np


def axis_angle(axis: np.ndarray | list[float], angle_deg: float) -> np.ndarray:
    """Rotation by ``angle_deg`` degrees about ``axis`` (right-hand rule), ``(3, 3)`` float64."""
    a = np.asarray(axis, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"axis must be a finite (3,) vector, got {a!r}")
    norm = np.linalg.norm(a)
    if norm < 1e-12:
        raise ValueError("axis must not be the zero vector")
    if not math.isfinite(angle_deg):
        raise ValueError(f"angle must be finite, got {angle_deg}")
    x, y, z = a / norm
    t = math.radians(angle_deg)
    c, s = math.cos(t), math.sin(t)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def about_y(angle_deg: float) -> np.ndarray:
    """Rotation about the world's vertical axis (+Y up): turns lighting in azimuth."""
    return axis_angle([0.0, 1.0, 0.0], angle_deg)


def about_y_many(angles_deg: np.ndarray) -> np.ndarray:
    """:func:`about_y` for every angle of ``angles_deg (N,)`` at once: ``(N, 3, 3)`` float64."""
    t = np.radians(np.asarray(angles_deg, dtype=np.float64))
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError(f"angles must be a finite (N,) array, got shape {t.shape}")
    c, s = np.cos(t), np.sin(t)
    zero, one = np.zeros_like(t), np.ones_like(t)
    return np.stack([np.stack([c, zero, s], -1), np.stack([zero, one, zero], -1), np.stack([-s, zero, c], -1)], -2)


def random_rotation(seed: int) -> np.ndarray:
    """A rotation drawn uniformly from SO(3) (Haar measure) with a seeded generator."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
