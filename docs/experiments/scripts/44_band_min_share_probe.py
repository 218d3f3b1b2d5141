"""Study 44 probe: the colour band's local statistics need enough sure pixels (``MIN_SURE_SHARE``).

``refine_sky_boundary`` decides each pixel within ``band`` of the upsampled sky boundary by the likelier of two
local diagonal Gaussians (log RGB), each from its side's sure pixels within ``4 band``. Where a side has only a
few sure pixels in that window (an object narrower than the band, its own colour all inside it), that side's
Gaussian comes from a handful of unrelated pixels and its variance sits at the floor: on rocket.jpg the whole
width of the rocket is then called sky in a band across its body. The candidate: below a share of the window,
the side's statistics over the whole photo stand in. Scored on the training panoramas' crops of
``bench --real --full`` (plain, as shipped: growth 0.1) and on study 40's lattice composites; ``--heldout``
scores sunrise's crops once for the chosen share and 0.

    .venv/bin/python docs/experiments/scripts/44_band_min_share_probe.py -o docs/experiments/results/44_training.json
    .venv/bin/python docs/experiments/scripts/44_band_min_share_probe.py --heldout --share 0 --share S -o docs/experiments/results/44_sunrise.json
"""
from __future__ import annotations

import argparse
import importlib
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_crop_scores import score_mask_variants  # noqa: E402

from learned import Relighter  # noqa: E402
from learned import sky_segmentation as ss  # noqa: E402

lattice = importlib.import_module("40_lattice_sky_probe")
SHARES = (0.0, 1 / 64, 1 / 32, 1 / 16, 1 / 8)


_GATE = ss._local_mean


def _prior_mean(w: torch.Tensor, v: torch.Tensor, r: int, min_share: float = 0.0) -> torch.Tensor:
    """Round 2's candidate: the side's whole-photo statistics as ``min_share`` pseudo-pixels (a share of the
    window), so the local statistics take over smoothly as the sure pixels fill the window."""
    from physrelight.guided_filter import box_filter

    if min_share <= 0:
        return _GATE(w, v, r, min_share)
    overall = (v * w).sum((2, 3), keepdim=True) / float(w.sum())
    return (box_filter(v * w, r) + min_share * overall) / (box_filter(w, r) + min_share)


def masks(model, lin: torch.Tensor, shares) -> dict[float, np.ndarray]:
    """Per share, the shipped mask with that share; a negative share ``-s`` is the round-2 prior of ``s``."""
    out = {}
    for s in shares:
        ss.MIN_SURE_SHARE, ss._local_mean = abs(s), (_prior_mean if s < 0 else _GATE)
        out[s] = ss.sky_mask_full_resolution(model, lin)[0][0, 0].numpy()
    ss.MIN_SURE_SHARE, ss._local_mean = 0.125, _GATE
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true")
    ap.add_argument("--share", type=float, action="append", default=[],
                    help="a gate share; -S for the round-2 prior of S pseudo-pixels (the first is the reference)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = Relighter.load().sky_segmenter
    settings = tuple(args.share) or SHARES
    out = score_mask_variants(lambda lin: masks(model, lin, settings), settings, args.heldout, lattice.composite)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
