"""Study 26 probe: the sky mask's colour band and working resolution on real crops.

Scores relight's full-resolution sky mask (learned.sky_segmentation.sky_mask_full_resolution) on the
crops of bench --real --full (seed 0, 16 crops per panorama) for a grid of (working res, colour band,
refinement). Selection uses the training side only (city, courtyard, forest crops with sky: IoU and
boundary F; their no-sky crops: sky called); sunrise (held out) is scored only with --heldout, once,
for the setting chosen without it.

    .venv/bin/python docs/experiments/scripts/26_sky_band_probe.py -o docs/experiments/results/26_sky_band_training.json
    .venv/bin/python docs/experiments/scripts/26_sky_band_probe.py --heldout --only RES:BAND:REFINE -o ...
"""
from __future__ import annotations

import argparse
import json

import torch

from learned import Relighter
from learned import sky_segmentation as ss
from real_crop_scores import crop_panoramas, score_sky_masks, setting_summary


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="score sunrise instead of the training side")
    ap.add_argument("--only", action="append", default=[], help="RES:BAND:REFINE settings (default: the grid)")
    args = ap.parse_args()
    torch.set_num_threads(2)
    model = Relighter.load().sky_segmenter
    group, panos = crop_panoramas(args.heldout)
    grid = args.only or [":".join((res, band, refine)) for res in ("64", "128") for band in ("0", "1", "2", "3", "4", "6")
                         for refine in (("local",) if band == "0" else ss.REFINEMENTS)]

    def masks_of(lin: torch.Tensor) -> dict[str, tuple[torch.Tensor, str]]:
        out = {}
        for g in grid:
            res, band, refine = g.split(":")
            sky, why = ss.sky_mask_full_resolution(model, lin, res=int(res), band=int(band), refine=refine)
            out[g] = (sky, why[0])
        return out

    rows = score_sky_masks(panos, grid, masks_of)
    out = {"group": group, "panoramas": [p.name for p in panos], "settings": {}}
    for k, row in rows.items():
        out["settings"][k] = s = setting_summary(row)
        print(f"{k:>16}: IoU {s['iou']:.3f}  F {s['boundary_f']:.3f}  no-sky called {s['no_sky_called']}  "
              f"refused {s['refused_with_sky']}/{s['crops_with_sky']}")
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
