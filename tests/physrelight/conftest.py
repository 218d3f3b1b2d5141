"""Shared fixtures: the real outdoor HDRIs that ship with the package, and seeded maps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physrelight import envmap, sh

HDRI_DIR = Path(__file__).resolve().parents[2] / "physrelight" / "data" / "hdri"
HDRI_NAMES = ("city", "courtyard", "forest", "studio")


@pytest.fixture(scope="session")
def hdris() -> dict[str, np.ndarray]:
    """The four shared CC0 maps at full resolution (1024 x 512), float32."""
    return {name: envmap.read(HDRI_DIR / f"{name}.exr") for name in HDRI_NAMES}


def band_limited_map(coeffs: np.ndarray, height: int) -> np.ndarray:
    """Sample the SH expansion ``coeffs (K, 3)`` at the texels of an ``(height, 2 height)`` map."""
    order = sh.order_of(coeffs.shape[0])
    d = envmap.directions(height, 2 * height)
    return sh.basis(d, order) @ coeffs


def positive_coeffs(order: int, seed: int) -> np.ndarray:
    """Random SH coefficients ``(K, 3)`` whose expansion is positive everywhere.

    Band norms are kept below the bound for non-negative functions and L00 is raised
    until the sampled minimum is positive with margin.
    """
    rng = np.random.default_rng(seed)
    c = rng.normal(size=((order + 1) ** 2, 3)) * 0.3
    d = sh.fibonacci_sphere(4000)
    y = sh.basis(d, order)
    low = (y[:, 1:] @ c[1:]).min(axis=0)
    c[0] = (-low + 0.5) / y[0, 0]
    return c
