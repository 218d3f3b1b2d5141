"""Study 53 probe: the shipped sky mask less its detached pieces of sky under a thick run of land.

    .venv/bin/python docs/experiments/scripts/53_sky_under_land_probe.py -o docs/experiments/results/53_training.json
    .venv/bin/python docs/experiments/scripts/53_sky_under_land_probe.py --heldout --only 0 --only CHOSEN -o docs/experiments/results/53_sunrise.json
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

SETTINGS = ("0", "0.02", "0.03", "0.05", "0.1")


def drop_sky_under_land(mask: np.ndarray, frac: float) -> np.ndarray:
    """``mask (H, W)`` bool less its components that do not touch the top row and whose columns have, in the
    median, a run of non-sky of at least ``frac * H`` pixels right above their topmost pixel."""
    if frac <= 0:
        return mask
    h, w = mask.shape
    lab = ss.label_components(torch.from_numpy(mask)).numpy()
    top = set(lab[0][lab[0] > 0].tolist())
    run = np.zeros((h, w), int)  # non-sky pixels directly above each pixel
    cur = np.zeros(w, int)
    for y in range(h):
        run[y] = cur
        cur = np.where(mask[y], 0, cur + 1)
    out = mask.copy()
    for c in np.unique(lab[lab > 0]):
        if c in top:
            continue
        sel = lab == c
        first = np.where(sel.any(0), sel.argmax(0), -1)  # topmost row of the component per column
        cols = np.nonzero(first >= 0)[0]
        if np.median(run[first[cols], cols]) >= frac * h:
            out &= ~sel
    return out


def masks(model, lin: torch.Tensor, settings) -> dict[str, np.ndarray]:
    shipped = ss.sky_mask_full_resolution(model, lin)[0][0, 0].numpy()
    return {s: drop_sky_under_land(shipped, float(s)) for s in settings}


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
