"""Study 30 probe: the sky mask from the segmenter's mean probability at several working sizes.

Scores relight's full-resolution sky mask (learned.sky_segmentation.sky_mask_full_resolution, band and
refinement as shipped) on the crops of bench --real --full (seed 0, 16 crops per panorama) for a grid of
working sizes. Selection uses the training side only; sunrise (held out) is scored only with --heldout,
once, for the setting chosen without it.

    .venv/bin/python docs/experiments/scripts/30_multi_scale_sky_probe.py -o docs/experiments/results/30_multi_scale_training.json
    .venv/bin/python docs/experiments/scripts/30_multi_scale_sky_probe.py --heldout --only 128 --only 64+128 -o ...
"""
from __future__ import annotations

import argparse
import json

import torch

from learned import Relighter
from learned import sky_segmentation as ss
from real_crop_scores import crop_panoramas, score_sky_masks, setting_summary

GRID = ("128", "64", "96", "64+128", "96+128", "64+96+128", "128+192")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="score sunrise instead of the training side")
    ap.add_argument("--only", action="append", default=[], help="working sizes joined by '+' (default: the grid)")
    args = ap.parse_args()
    torch.set_num_threads(2)
    model = Relighter.load().sky_segmenter
    group, panos = crop_panoramas(args.heldout)
    grid = args.only or list(GRID)

    def masks_of(lin: torch.Tensor) -> dict[str, tuple[torch.Tensor, str]]:
        out = {}
        for g in grid:
            sizes = tuple(int(s) for s in g.split("+"))
            sky, why = ss.sky_mask_full_resolution(model, lin, res=sizes if len(sizes) > 1 else sizes[0])
            out[g] = (sky, why[0])
        return out

    rows = score_sky_masks(panos, grid, masks_of)
    out = {"group": group, "panoramas": [p.name for p in panos], "settings": {}}
    for k, row in rows.items():
        s = setting_summary(row)
        out["settings"][k] = s = {**s, "mean_iou_f": (s["iou"] + s["boundary_f"]) / 2,
                                  "per_crop_iou": row["iou"], "per_crop_f": row["f"]}
        print(f"{k:>12}: IoU {s['iou']:.4f}  F {s['boundary_f']:.4f}  mean {s['mean_iou_f']:.4f}  "
              f"no-sky called {s['no_sky_called']}  refused {s['refused_with_sky']}/{s['crops_with_sky']}")
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
