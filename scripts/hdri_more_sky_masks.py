"""Write the reviewed sky masks of ``physrelight/data/hdri_more`` (``pm_NAME_sky.png`` beside each map, white = sky).

``python scripts/hdri_more_sky_masks.py`` rewrites them all (deterministic: same maps, same bytes). Each outdoor map
starts from the shipped procedure (:func:`synth.panorama_sky.sky_mask_procedure`, tuned on the 1024 px maps) and
gets the rules below, each written after looking at the procedure's mask overlaid on the tone-mapped map (issue 43;
docs/experiments/58-prior-on-more-panoramas.md describes every mask). Rooms (``indoor`` in ``kinds.json``) get an
empty mask: no sky, as studio's. pm_bridge (a covered glass walkway) and any map in :data:`LEFT_OUT` get none.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from physrelight import data, envmap  # noqa: E402
from synth.panorama_sky import Correction, apply_corrections, mask_path, sky_mask_procedure, write_sky_mask  # noqa: E402

LEFT_OUT: dict[str, str] = {
    "pm_forest": "sky seen through a pine canopy at 512 px is texel-scale speckle mixed with needles; no rule tried "
                 "(the procedure, or bright non-green texels above 80 deg zenith) followed it: the left and right "
                 "thirds' sky was missed and mixed texels were called sky"}
"""Outdoor maps without a mask, and why."""


def fill_to_zenith(sky: np.ndarray) -> np.ndarray:
    """Every texel above a column's first sky texel is sky too: for an open sky with nothing overhead, where the
    procedure's brightness test drops the deep blue near the zenith (its level is set by the bright horizon)."""
    out = sky.copy()
    for c in np.flatnonzero(sky.any(0)):
        out[: int(np.argmax(sky[:, c])), c] = True
    return out


def fill_holes_above_horizon(sky: np.ndarray) -> np.ndarray:
    """Holes in the sky that do not reach the horizon row are sky: stars, a bird, a repaired texel (the sky is
    padded by a wrapped column on each side so a hole at the seam is a hole too)."""
    h, w = sky.shape
    half = sky[: h // 2]
    pad = np.pad(half, ((0, 1), (1, 1)), mode="wrap")
    pad[-1] = False  # the horizon row: a region touching it stays open
    filled = ndimage.binary_fill_holes(pad)[:-1, 1:-1]
    out = sky.copy()
    out[: h // 2] |= filled
    return out


def blue_above(env: np.ndarray, rows: tuple[int, int], cols: tuple[int, int], min_blue_over_red: float) -> np.ndarray:
    """Texels of the box whose blue/red is at least ``min_blue_over_red``: sky beside warm rock or brick."""
    box = np.zeros(env.shape[:2], dtype=bool)
    box[rows[0]: rows[1], np.arange(cols[0], cols[1]) % env.shape[1]] = True
    return box & (env[..., 2] >= min_blue_over_red * np.maximum(env[..., 0], 1e-6))


def upper_hemisphere(env: np.ndarray) -> np.ndarray:
    """Every texel above the horizon: zenith angle below 90 deg (row i at ``180 i / (H - 1)`` deg, DESIGN.md)."""
    h, w = env.shape[:2]
    zenith = 180.0 * np.arange(h) / (h - 1)
    return np.repeat((zenith < 90.0)[:, None], w, axis=1)


def pm_city(env: np.ndarray) -> np.ndarray:
    return sky_mask_procedure(env)  # overcast over towers: the procedure's mask follows every roofline


def pm_dawn(env: np.ndarray) -> np.ndarray:
    sky = fill_to_zenith(sky_mask_procedure(env))
    # blue sky low on the left, below a rise of the ridge, left out by the brightness test
    sky |= blue_above(env, (105, 127), (30, 120), 1.0)
    return fill_holes_above_horizon(sky)


def pm_night(env: np.ndarray) -> np.ndarray:
    return fill_holes_above_horizon(sky_mask_procedure(env))  # the stars' texels were cut out as too rough


def pm_sky(env: np.ndarray) -> np.ndarray:
    # clouds over a sea of cloud: everything above the horizon is sky; below it a reflecting haze, not sky
    return upper_hemisphere(env)


def pm_venice(env: np.ndarray) -> np.ndarray:
    sky = apply_corrections(env, sky_mask_procedure(env), [
        Correction(True, (85, 122), (170, 265), "the bright clouds round the low sun above the far shore, too rough "
                   "for the procedure; the trees below them are darker", min_luminance_of_level=0.3)])
    return fill_holes_above_horizon(sky)


RULES = {"pm_city": pm_city, "pm_dawn": pm_dawn, "pm_night": pm_night, "pm_sky": pm_sky,
         "pm_venice": pm_venice}


def reviewed_mask(name: str) -> np.ndarray | None:
    """The reviewed mask of the ``hdri_more`` map ``name``: ``(H, W)`` bool, or None where it has none."""
    kind = data.hdri_kind(name, collection="more")
    env = np.asarray(envmap.read(data.hdri(name, collection="more")), dtype=np.float64)
    if kind == "indoor":
        return np.zeros(env.shape[:2], dtype=bool)
    if kind != "outdoor" or name in LEFT_OUT:
        return None
    return RULES[name](env)


def main(argv: list[str] | None = None) -> int:
    names = argv if argv else list(data.hdri_names(collection="more"))
    for name in names:
        path = data.hdri(name, collection="more")
        sky = reviewed_mask(name)
        if sky is None:
            mask_path(path).unlink(missing_ok=True)
            print(f"{name}: no mask ({LEFT_OUT.get(name, data.hdri_kind(name, collection='more'))})")
            continue
        write_sky_mask(mask_path(path), sky)
        print(f"{mask_path(path).name}: {100 * sky.mean():.2f} % sky")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
