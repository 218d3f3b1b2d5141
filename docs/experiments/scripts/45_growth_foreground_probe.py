"""Study 45 probe: the colour growth's foreground statistics without the sky-coloured pixels (``GROW_FOREGROUND``).

``grow_sky_by_colour`` adds a pixel near the mask when it fits the sky's colour model and is likelier under it
than under the local Gaussian of the non-sky pixels around it (``"all"``). Candidates: ``"exclude"`` (that
Gaussian without the non-sky pixels that fit the sky model) and ``"minority"`` (the same where those are under
half of the window's non-sky pixels). Scored as study 44 on the training crops (plain and lattice); ``--heldout``
scores sunrise's crops once. The candidates were a ``foreground=`` argument of ``grow_sky_by_colour`` (its
local Gaussian fitted to ``~sky & ~(maha < chi2)``), removed after the run because they changed no mask
(docs/experiments/45-growth-without-its-own-candidates.md); run today, every setting is today's.

    .venv/bin/python docs/experiments/scripts/45_growth_foreground_probe.py -o docs/experiments/results/45_training.json
    .venv/bin/python docs/experiments/scripts/45_growth_foreground_probe.py --heldout --only all --only CHOSEN -o docs/experiments/results/45_sunrise.json
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


SETTINGS = ("all", "exclude", "minority")


def masks(model, lin: torch.Tensor, settings) -> dict[str, np.ndarray]:
    """Per setting, the shipped mask with that ``GROW_FOREGROUND``."""
    out = {}
    for s in settings:
        ss.GROW_FOREGROUND = s
        out[s] = ss.sky_mask_full_resolution(model, lin)[0][0, 0].numpy()
    ss.GROW_FOREGROUND = "all"
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
