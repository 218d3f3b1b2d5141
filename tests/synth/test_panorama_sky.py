"""Specification of :mod:`synth.panorama_sky`: the sky-mask procedure on synthetic panoramas whose
sky is known texel by texel, and the shipped, reviewed masks pinned to procedure + corrections."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physrelight import envmap, metrics
from synth import panorama_sky as ps

DATA = Path(__file__).resolve().parents[2] / "physrelight" / "data"


def synthetic_panorama(height: int = 128, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A panorama with a known sky: a smooth blue sky with a sun glow over a textured ground, three
    textured buildings, a 1-texel pole, a canopy ring around a window of sky, and a sunlit white
    house below a dark roofline (bright, straddling the horizon: not sky). Returns (env, true sky)."""
    rng = np.random.default_rng(seed)
    w = 2 * height
    d = envmap.directions(height, w)
    zen = np.degrees(np.arccos(np.clip(d[..., 1], -1, 1)))
    col = np.arange(w)[None, :].repeat(height, 0)
    sun = np.array([0.5, 0.4, -0.77]) / np.linalg.norm([0.5, 0.4, -0.77])
    glow = 1.0 + 3.0 * np.maximum(0.0, d @ sun) ** 8 + 0.6 * (1 - np.abs(d[..., 1]))
    env = np.array([0.35, 0.55, 1.0]) * glow[..., None]
    sky = zen < 90.0

    def texture(mask: np.ndarray, level: float, sigma: float = 0.5) -> None:
        n = int(mask.sum())
        env[mask] = level * np.exp(rng.normal(0, sigma, size=(n, 1))) * np.array([0.9, 1.0, 0.8])

    texture(zen >= 90.0, 0.08)  # the ground
    for c0, c1, top in ((20, 50, 70.0), (90, 100, 60.0), (170, 220, 75.0)):  # buildings
        b = (col >= c0 * height // 128) & (col < c1 * height // 128) & (zen >= top) & (zen < 90)
        texture(b, 0.12)
        sky &= ~b
    pole = (col == 150 * height // 128) & (zen >= 40.0) & (zen < 90)
    env[pole] = 0.02
    sky &= ~pole
    # a canopy ring (foliage) around a window of sky at zenith 30-45 degrees
    ring = (col >= 230 * height // 128) & (col < 250 * height // 128) & (zen >= 22) & (zen < 55)
    window = (col >= 235 * height // 128) & (col < 245 * height // 128) & (zen >= 30) & (zen < 45)
    texture(ring & ~window, 0.15)
    sky &= ~(ring & ~window)
    # a sunlit white house below a dark roof, straddling the horizon
    roof = (col >= 107 * height // 128) & (col < 138 * height // 128) & (zen >= 70) & (zen < 100)
    house = (col >= 110 * height // 128) & (col < 135 * height // 128) & (zen >= 76) & (zen < 100)
    texture(roof, 0.05)  # the roof and the dark walls either side: the house is framed, as in courtyard.exr
    env[house] = 1.3 * np.median(env[sky], axis=0)
    sky &= ~(roof & (zen < 90))
    return env.astype(np.float32), sky


def test_01_procedure_finds_a_known_sky_texel_by_texel() -> None:
    env, truth = synthetic_panorama()
    got = ps.sky_mask_procedure(env)
    assert metrics.mask_iou(got, truth) > 0.98
    assert metrics.boundary_f(got, truth, tolerance=1.0) > 0.95


def test_02_thin_structures_stay_foreground_and_the_sky_round_them_is_sky() -> None:
    env, truth = synthetic_panorama()
    got = ps.sky_mask_procedure(env)
    h = env.shape[0]
    pole = (slice(int(0.3 * h), int(0.45 * h)), 150 * h // 128)
    assert not got[pole].any(), "the 1-texel pole was called sky"
    beside = (slice(int(0.3 * h), int(0.45 * h)), [150 * h // 128 - 1, 150 * h // 128 + 1])
    assert got[beside].all(), "the sky beside the pole (cut by the 3 x 3 smoothness test) was not grown back"


def test_03_sky_through_a_gap_is_sky_and_a_bright_wall_at_the_horizon_is_not() -> None:
    env, truth = synthetic_panorama()
    got = ps.sky_mask_procedure(env)
    h = env.shape[0]
    d = envmap.directions(h, 2 * h)
    zen = np.degrees(np.arccos(np.clip(d[..., 1], -1, 1)))
    col = np.arange(2 * h)[None, :].repeat(h, 0)
    window = (col >= 235 * h // 128) & (col < 245 * h // 128) & (zen >= 30) & (zen < 45)
    assert got[window].mean() > 0.9
    house = (col >= 110 * h // 128) & (col < 135 * h // 128) & (zen >= 76) & (zen < 100)
    assert not got[house].any()


def test_04_an_indoor_map_with_lamps_has_no_sky() -> None:
    rng = np.random.default_rng(3)
    env = (0.02 * np.exp(rng.normal(0, 0.3, size=(64, 128, 1))) * np.ones(3)).astype(np.float32)
    env[10:13, 20:23] = 50.0  # lamps: small, bright, smooth
    env[20:22, 90:93] = 30.0
    assert not ps.sky_mask_procedure(env).any()


@pytest.mark.parametrize("path", sorted((DATA / "hdri").glob("*.exr")) + sorted((DATA / "hdri_heldout").glob("*.exr")),
                         ids=lambda p: p.stem)
def test_05_shipped_masks_are_the_procedure_with_the_reviewed_corrections(path) -> None:
    """The PNGs beside the maps are what ``python -m synth.panorama_sky`` writes: regenerate them
    deliberately when the procedure or a correction changes."""
    env = envmap.read(path)
    shipped = ps.read_sky_mask(ps.mask_path(path), env.shape[:2])
    np.testing.assert_array_equal(shipped, ps.reviewed_sky_mask(path.stem, env))


def test_06_corrections_change_only_their_box_and_respect_their_conditions() -> None:
    env, truth = synthetic_panorama(64)
    sky = ps.sky_mask_procedure(env)
    c = ps.Correction(False, (5, 20), (120, 130), "test: clear a box that wraps past the seam")
    out = ps.apply_corrections(env, sky, [c])
    box = np.zeros_like(sky)
    box[5:20, list(range(120, 128)) + [0, 1]] = True
    assert not out[box].any() and (out[~box] == sky[~box]).all()
    bright_only = ps.Correction(True, (0, 64), (0, 128), "test: only texels above the sky level",
                                min_luminance_of_level=10.0)
    assert (ps.apply_corrections(env, sky, [bright_only]) == sky).all()


def test_07_bad_maps_are_refused() -> None:
    with pytest.raises(ValueError, match=r"2:1"):
        ps.sky_mask_procedure(np.ones((8, 8, 3), np.float32))
    bad = np.ones((8, 16, 3), np.float32)
    bad[1, 1, 0] = -1.0
    with pytest.raises(ValueError, match=r"negative"):
        ps.sky_mask_procedure(bad)
