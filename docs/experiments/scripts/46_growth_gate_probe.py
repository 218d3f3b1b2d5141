"""Study 46 probe: the colour growth's gate (``GROW_CHI2``).

``grow_sky_by_colour`` grows a pixel near the mask when its squared Mahalanobis distance to the smooth sky
model is under ``chi2`` (and it is likelier sky than foreground, a test study 45 found never binding). The gate
is applied inside the shipped pipeline by wrapping the growth; scored as study 44 on the training crops (plain
and lattice); ``--heldout`` scores sunrise's crops once.

    .venv/bin/python docs/experiments/scripts/46_growth_gate_probe.py -o docs/experiments/results/46_training.json
    .venv/bin/python docs/experiments/scripts/46_growth_gate_probe.py --heldout --only 11.34 --only CHOSEN -o docs/experiments/results/46_sunrise.json
"""
from __future__ import annotations

import argparse
import functools
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


SETTINGS = ("11.34", "16.27", "21.11", "30")
_GROW = ss.grow_sky_by_colour


def masks(model, lin: torch.Tensor, settings) -> dict[str, np.ndarray]:
    """Per setting, the shipped mask with that gate."""
    out = {}
    for s in settings:
        ss.grow_sky_by_colour = functools.partial(_GROW, chi2=float(s))
        out[s] = ss.sky_mask_full_resolution(model, lin)[0][0, 0].numpy()
    ss.grow_sky_by_colour = _GROW
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true")
    ap.add_argument("--only", action="append", default=[], help="settings (the first is the reference)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = Relighter.load().sky_segmenter
    settings = tuple(args.only) or SETTINGS
    out = score_mask_variants(lambda lin: masks(model, lin, settings), settings, args.heldout, lattice.composite)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
