"""The sky of a real HDR panorama, texel by texel: the ground truth of ``bench --real``'s sky masks.

A sky mask of a view of a panorama is the view of the panorama's sky mask
(:func:`physrelight.panorama.view_mask`), so the mask is made once per panorama, at its
own resolution, by :func:`sky_mask_procedure`, then reviewed by eye and corrected where
the procedure fails (:data:`CORRECTIONS`; the shipped, reviewed masks are
``NAME_sky.png`` beside each map, white = sky).

The procedure uses three facts about an outdoor sky (docs/bench.md, "Real photos"):

1. **It is far brighter than the ground it lights.** The ground near the camera (zenith
   angle > 110 deg) has radiance ``albedo x E / pi``, a fraction of the sky's. A texel is
   *bright* when its luminance exceeds ``2 G`` (``G`` the ground's median) and ``S / 16``
   (``S`` the 95th percentile of the smooth upper texels, the sky's own level: a sunlit
   white wall can beat ``2 G``, rarely ``S / 16``).
2. **It is smooth.** The standard deviation of log luminance over 3 x 3 texels is below
   0.1 (clouds' interiors pass, foliage, facades and lattices do not).
3. **It is connected to the top.** Bright, smooth texels above the horizon are grouped
   into 8-connected components (wrapping in azimuth). Kept are those touching the zenith
   row, and the others (sky through foliage or a courtyard's opening) that lie at least
   90 % above 85 deg zenith angle, hold 10 texels or more and have a median luminance of at
   least ``S / 4`` or, when there is a sky touching the zenith, half its 10th percentile
   (sky through a gap is about as bright as the dimmer parts of the sky seen whole).

Then, at the panorama's resolution: the kept sky grows for 3 texels into adjacent texels
that are *bright* and at least half as bright as the sky texels next to them (the 3 x 3
smoothness test cut a 1-texel band at every edge; a gap of sky narrower than that between
two structures is recovered only 3 texels deep), not below 92 deg;
and enclosed non-sky holes of fewer than 2e-4 of the texels (cloud edges, the sun's disc,
specks) are filled. Kept components covering less than 0.5 % of the map are lamps or
windows, not a sky: the panorama then has none.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from physrelight import colour

__all__ = ["CORRECTIONS", "Correction", "apply_corrections", "mask_path", "read_sky_mask", "reviewed_sky_mask",
           "sky_mask_procedure", "write_sky_mask"]

GROUND_ZENITH_DEG = 110.0
UPPER_ZENITH_DEG = 80.0
HORIZON_DEG = 90.0
SECONDARY_ZENITH_DEG = 85.0
GROW_LIMIT_DEG = 92.0
ROUGHNESS = 0.1
GROUND_RATIO = 2.0
SKY_FRACTION = 1.0 / 16.0
SECONDARY_LEVEL = 0.25
SECONDARY_MIN_TEXELS = 10
GROW_TEXELS = 3
GROW_LEVEL = 0.5
HOLE_FRACTION = 2e-4
MIN_SKY_FRACTION = 5e-3


def _zenith_deg(height: int, width: int) -> np.ndarray:
    """``(H, W)`` zenith angle of each texel row (rows align-corners: row 0 = zenith)."""
    return np.repeat((180.0 * np.arange(height) / (height - 1))[:, None], width, axis=1)


def _roughness(log_y: np.ndarray) -> np.ndarray:
    """Standard deviation of ``log_y`` over 3 x 3 texels (wrapping in azimuth, edge rows repeated)."""
    from scipy import ndimage

    pad = np.pad(np.pad(log_y, ((1, 1), (0, 0)), mode="edge"), ((0, 0), (1, 1)), mode="wrap")
    m = ndimage.uniform_filter(pad, 3)
    m2 = ndimage.uniform_filter(pad * pad, 3)
    return np.sqrt(np.maximum(m2 - m * m, 0.0))[1:-1, 1:-1]


def _components(mask: np.ndarray) -> np.ndarray:
    """8-connected component labels of ``(H, W)`` bool, the first and last columns adjacent (azimuth wraps)."""
    from scipy import ndimage

    lab, n = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    parent = np.arange(n + 1)

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    h = mask.shape[0]
    for i in range(h):
        a = lab[i, -1]
        if not a:
            continue
        for k in (i - 1, i, i + 1):
            if 0 <= k < h and lab[k, 0]:
                ra, rb = find(a), find(int(lab[k, 0]))
                if ra != rb:
                    parent[ra] = rb
    roots = np.array([find(a) for a in range(n + 1)])
    return roots[lab]


def _neighbour_mean(y: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Mean of ``y`` over the ``mask`` texels of each 3 x 3 neighbourhood (wrapping in azimuth; inf where none)."""
    from scipy import ndimage

    def box(x: np.ndarray) -> np.ndarray:
        pad = np.pad(np.pad(x, ((1, 1), (0, 0))), ((0, 0), (1, 1)), mode="wrap")
        return ndimage.uniform_filter(pad, 3, mode="constant")[1:-1, 1:-1]

    m = mask.astype(np.float64)
    count = box(m)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, box(y * m) / count, np.inf)


def _dilate_wrapped(mask: np.ndarray) -> np.ndarray:
    from scipy import ndimage

    pad = np.pad(mask, ((0, 0), (1, 1)), mode="wrap")
    return ndimage.binary_dilation(pad, structure=np.ones((3, 3), dtype=bool))[:, 1:-1]


def sky_mask_procedure(env: np.ndarray) -> np.ndarray:
    """The sky of a lat-long HDR panorama by the procedure of the module doc.

    Args:
        env: ``(H, 2H, 3)`` linear radiance, world frame, row 0 = zenith (checked).

    Returns:
        ``(H, 2H)`` bool, True on sky texels.
    """
    import torch

    from physrelight import envmap

    e = np.asarray(env, dtype=np.float64)
    envmap.check_envmap(torch.from_numpy(e), "env")
    h, w = e.shape[:2]
    zen = _zenith_deg(h, w)
    y = e @ np.asarray(colour.LUMINANCE)
    rough = _roughness(np.log(np.maximum(y, 1e-6)))
    smooth = rough < ROUGHNESS
    ground = float(np.median(y[zen > GROUND_ZENITH_DEG]))
    upper = smooth & (zen < UPPER_ZENITH_DEG)
    level = float(np.percentile(y[upper], 95)) if upper.any() else float(y.max())
    bright = y > max(GROUND_RATIO * ground, SKY_FRACTION * level)
    core = bright & smooth & (zen < HORIZON_DEG)
    labels = _components(core)
    top = np.unique(labels[0][labels[0] > 0]).tolist()
    main = np.isin(labels, top)
    # Sky seen through gaps is as bright as the dimmest part of the sky seen whole.
    secondary = min(SECONDARY_LEVEL * level, 0.5 * float(np.percentile(y[main], 10))) if main.any() \
        else SECONDARY_LEVEL * level
    keep = list(top)
    for c in np.unique(labels[labels > 0]).tolist():
        sel = labels == c
        if c not in top and int(sel.sum()) >= SECONDARY_MIN_TEXELS \
                and float(np.mean(zen[sel] < SECONDARY_ZENITH_DEG)) >= 0.9 and float(np.median(y[sel])) >= secondary:
            keep.append(c)
    sky = np.isin(labels, keep)
    if sky.mean() < MIN_SKY_FRACTION:  # a few lamps or windows, not a sky: an indoor or covered place
        return np.zeros_like(sky)
    for _ in range(GROW_TEXELS):
        sky |= _dilate_wrapped(sky) & (y >= GROW_LEVEL * _neighbour_mean(y, sky)) & bright & (zen < GROW_LIMIT_DEG)
    holes = _components(~sky)
    sizes = np.bincount(holes.ravel())
    touches_bottom = set(np.unique(holes[zen > GROW_LIMIT_DEG]).tolist())
    small = [c for c in np.unique(holes[holes > 0]).tolist()
             if sizes[c] < HOLE_FRACTION * h * w and c not in touches_bottom]
    return sky | np.isin(holes, small)


# ----------------------------------------------------------------------------- reviewed masks


@dataclass(frozen=True)
class Correction:
    """One hand correction of the procedure, in panorama coordinates.

    Attributes:
        label: ``True`` (make sky) or ``False`` (make not sky).
        rows, cols: the half-open texel box ``[r0, r1) x [c0, c1)`` it applies to (columns may wrap: c1 > W).
        why: what the procedure got wrong there, seen by eye.
        min_luminance_of_level: only texels brighter than this fraction of the sky level ``S``
            change (so a box need not trace a silhouette); 0: no condition.
        max_blue_over_green: only texels whose blue/green ratio is below this change (trees and
            fields are warmer than a blue sky); None: no condition.
    """

    label: bool
    rows: tuple[int, int]
    cols: tuple[int, int]
    why: str
    min_luminance_of_level: float = 0.0
    max_blue_over_green: float | None = None


CORRECTIONS: dict[str, tuple[Correction, ...]] = {
    "city": (
        Correction(False, (180, 262), (140, 232), "the sunlit beige facade left of the glass towers, as bright as the "
                   "overcast sky's dimmer parts and smooth between its windows, was kept as sky through a gap"),
    ),
    "courtyard": (
        Correction(False, (208, 262), (300, 405), "the sunlit white house beyond the carport, brighter than much of the "
                   "sky and smooth, was kept as sky through the opening"),
        Correction(False, (224, 246), (395, 428), "a sunlit strip of the garage wall below its roof"),
    ),
    "forest": (
        Correction(True, (100, 240), (430, 700), "the sky glowing round the sun through thin branches is rough at the "
                   "texel scale and was left out; its bright texels are sky, the leaves' silhouettes not",
                   min_luminance_of_level=0.5),
    ),
    "sunrise": (
        Correction(False, (240, 262), (0, 300), "the misty field and the distant trees in haze left of the sun are as "
                   "bright and smooth as the sky above them and were taken for it"),
        Correction(False, (222, 246), (128, 196), "a clump of trees in the haze, taken for sky",
                   max_blue_over_green=1.2),
        Correction(False, (210, 236), (290, 380), "the sunlit top of the orange tree, grown into by the sky's "
                   "3-texel refinement", max_blue_over_green=1.2),
        Correction(False, (244, 262), (960, 1024), "the hazy field at the right end, below the treeline"),
    ),
}
"""Reviewed corrections per shipped panorama (name -> corrections), each seen by eye on the
panorama and on its views (docs/bench.md, "Real photos"). studio's mask (no sky: indoor) needed none."""


def apply_corrections(env: np.ndarray, sky: np.ndarray, corrections: Sequence[Correction]) -> np.ndarray:
    """``sky`` with ``corrections`` applied in order (a new array)."""
    out = np.array(sky, dtype=bool)
    h, w = out.shape
    e = np.asarray(env, dtype=np.float64)
    y = e @ np.asarray(colour.LUMINANCE)
    zen = _zenith_deg(h, w)
    upper = (_roughness(np.log(np.maximum(y, 1e-6))) < ROUGHNESS) & (zen < UPPER_ZENITH_DEG)
    level = float(np.percentile(y[upper], 95)) if upper.any() else float(y.max())
    for c in corrections:
        r0, r1 = c.rows
        cols = np.arange(c.cols[0], c.cols[1]) % w
        box = np.zeros_like(out)
        box[r0:r1, cols] = True
        if c.min_luminance_of_level > 0:
            box &= y > c.min_luminance_of_level * level
        if c.max_blue_over_green is not None:
            box &= e[..., 2] < c.max_blue_over_green * e[..., 1]
        out[box] = c.label
    return out


def mask_path(panorama_path: str | os.PathLike) -> Path:
    """Where a panorama's reviewed sky mask lives: ``NAME_sky.png`` beside ``NAME.exr``."""
    p = Path(panorama_path)
    return p.with_name(f"{p.stem}_sky.png")


def read_sky_mask(path: str | os.PathLike, shape: tuple[int, int]) -> np.ndarray:
    """A sky mask PNG (white = sky) as ``(H, W)`` bool, checked against the panorama's ``shape``."""
    from physrelight import io

    m = io.read_mask(path)
    if m.shape != tuple(shape):
        raise ValueError(f"sky mask {str(path)!r} is {m.shape[1]}x{m.shape[0]}, its panorama {shape[1]}x{shape[0]}")
    return m


def write_sky_mask(path: str | os.PathLike, sky: np.ndarray) -> None:
    """Write ``(H, W)`` bool as an 8-bit PNG, white = sky (atomically)."""
    from physrelight import io

    io.write_png(path, np.asarray(sky, dtype=np.float32)[..., None])


def reviewed_sky_mask(name: str, env: np.ndarray) -> np.ndarray:
    """The procedure's mask of the shipped panorama ``name`` with its reviewed :data:`CORRECTIONS`."""
    return apply_corrections(env, sky_mask_procedure(env), CORRECTIONS.get(name, ()))


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m synth.panorama_sky MAP.exr ...``: write each map's reviewed mask beside it (``NAME_sky.png``)."""
    import sys

    from physrelight import envmap

    paths = list(sys.argv[1:] if argv is None else argv)
    if not paths:
        print("usage: python -m synth.panorama_sky MAP.exr [MAP.exr ...]", file=sys.stderr)
        return 2
    for p in paths:
        sky = reviewed_sky_mask(Path(p).stem, envmap.read(p))
        write_sky_mask(mask_path(p), sky)
        print(f"{mask_path(p)}: {100 * sky.mean():.2f} % sky")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
