"""Degrade true depth into what multi-view stereo delivers (the paper's MegaDepth input).

MVS depth is what self-supervised training may use; the true depth is ground truth. Its
failure modes, each seeded: holes at depth discontinuities (matching fails at occlusion
boundaries), holes on thin structures (too few pixels to match), holes in textureless
regions (no photo-consistency signal), no depth on the sky, multiplicative noise and a
smooth low-frequency bias.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from physrelight import colour


@dataclass(frozen=True)
class MVSParams:
    """Knobs of the degradation (defaults give ~10-25 % holes on the foreground)."""

    edge_threshold: float = 0.05  # |second difference of 1/depth| / (1/depth) that marks an edge
    edge_dilation: int = 1  # pixels
    thin_radius: int = 1  # structures thinner than ~2r+1 pixels vanish
    texture_threshold: float = 0.004  # local std of albedo luminance below which matching may fail
    textureless_drop: float = 0.5  # fraction of textureless area lost (in blobs)
    noise: float = 0.005  # multiplicative per-pixel noise (std)
    bias: float = 0.01  # amplitude of a smooth multiplicative bias


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], scale: float) -> np.ndarray:
    """Unit-variance band-limited noise with correlation length ``scale`` pixels."""
    g = ndimage.gaussian_filter(rng.normal(size=shape), sigma=max(scale, 0.5), mode="wrap")
    return g / max(float(g.std()), 1e-12)


def degrade_depth(depth: np.ndarray, albedo: np.ndarray, rng: np.random.Generator,
                  params: MVSParams = MVSParams()) -> np.ndarray:
    """MVS-like depth ``float32 (H, W)``, 0 where missing.

    Args:
        depth: ``(H, W)`` true z-depth, 0 on the sky.
        albedo: ``(H, W, 3)`` (a proxy for the photo's texture, which drives matching).
        rng: seeded generator.
    """
    if depth.ndim != 2:
        raise ValueError(f"depth must have shape (H, W), got {depth.shape}")
    if albedo.shape != (*depth.shape, 3):
        raise ValueError(f"albedo must have shape {(*depth.shape, 3)}, got {albedo.shape}")
    valid = np.isfinite(depth) & (depth > 0)
    d = np.where(valid, depth, 0.0)

    # Depth discontinuities. Inverse depth is linear in the image on any plane, so its
    # second difference vanishes on smooth surfaces (even a grazing ground plane, whose
    # depth changes fast) and is large at occlusion boundaries.
    inv = np.where(valid, 1.0 / np.maximum(d, 1e-12), 0.0)
    jump = np.zeros(depth.shape, dtype=bool)
    for axis in (0, 1):
        prev, nxt = np.roll(inv, 1, axis=axis), np.roll(inv, -1, axis=axis)
        second = np.abs(prev - 2 * inv + nxt) / np.maximum(inv, 1e-12)
        both = valid & np.roll(valid, 1, axis=axis) & np.roll(valid, -1, axis=axis)
        edge = (second > params.edge_threshold) & both
        edge |= valid & ~(np.roll(valid, 1, axis=axis) & np.roll(valid, -1, axis=axis))  # next to sky
        edge &= ~_wrapped_border(depth.shape, axis)
        jump |= edge
    if params.edge_dilation:
        jump = ndimage.binary_dilation(jump, iterations=params.edge_dilation)

    # Thin structures: what a morphological opening removes.
    thin = np.zeros_like(valid)
    if params.thin_radius:
        opened = ndimage.binary_opening(valid, iterations=params.thin_radius)
        thin = valid & ~opened

    # Textureless regions lose depth in blobs.
    lum = albedo @ np.asarray(colour.LUMINANCE)
    mean = ndimage.uniform_filter(lum, 5)
    std = np.sqrt(np.maximum(ndimage.uniform_filter(lum**2, 5) - mean**2, 0.0))
    blobs = _smooth_noise(rng, depth.shape, max(depth.shape) / 16) > _gauss_quantile(1 - params.textureless_drop)
    textureless = (std < params.texture_threshold) & blobs

    keep = valid & ~jump & ~thin & ~textureless
    noisy = d * (1 + params.noise * rng.normal(size=depth.shape)) * (
        1 + params.bias * _smooth_noise(rng, depth.shape, max(depth.shape) / 4))
    return np.where(keep, noisy, 0.0).astype(np.float32)


def _wrapped_border(shape: tuple[int, int], axis: int) -> np.ndarray:
    """Mask of the first and last row/column, where np.roll wraps around (no real neighbour)."""
    m = np.zeros(shape, dtype=bool)
    if axis == 0:
        m[[0, -1], :] = True
    else:
        m[:, [0, -1]] = True
    return m


def _gauss_quantile(p: float) -> float:
    """Standard normal quantile (for the fraction of textureless area dropped)."""
    from statistics import NormalDist

    p = min(max(p, 1e-6), 1 - 1e-6)
    return NormalDist().inv_cdf(p)
