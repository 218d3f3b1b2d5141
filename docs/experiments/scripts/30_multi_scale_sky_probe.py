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
import time

import numpy as np
import torch

from learned import Relighter
from learned import sky_segmentation as ss
from physrelight import metrics
from synth.panorama_crops import make_crops, shipped_panoramas

GRID = ("128", "64", "96", "64+128", "96+128", "64+96+128", "128+192")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="score sunrise instead of the training side")
    ap.add_argument("--only", action="append", default=[], help="working sizes joined by '+' (default: the grid)")
    args = ap.parse_args()
    torch.set_num_threads(2)
    model = Relighter.load().sky_segmenter
    group = "heldout" if args.heldout else "training"
    panos = [p for p in shipped_panoramas() if p.group == group]
    grid = args.only or list(GRID)
    rows = {g: {"iou": [], "f": [], "no_sky_called": [], "refused_with_sky": 0} for g in grid}
    t0 = time.time()
    for pano in panos:
        for c in make_crops(pano, 16, 0, fov_range=(45.0, 75.0), samples=4):
            lin = c.linear()
            has_sky = c.sky.mean() >= 0.01
            for g in grid:
                sizes = tuple(int(s) for s in g.split("+"))
                sky, why = ss.sky_mask_full_resolution(model, lin, res=sizes if len(sizes) > 1 else sizes[0])
                m = sky[0, 0].numpy()
                row = rows[g]
                if has_sky:
                    row["iou"].append(metrics.mask_iou(m, c.sky))
                    row["f"].append(metrics.boundary_f(m, c.sky, 2.0))
                    row["refused_with_sky"] += bool(why[0])
                else:
                    row["no_sky_called"].append(float(m.mean()))
        print(f"{pano.name}: {time.time() - t0:.0f} s", flush=True)
    out = {"group": group, "panoramas": [p.name for p in panos], "settings": {}}
    for k, row in rows.items():
        out["settings"][k] = {"iou": float(np.mean(row["iou"])), "boundary_f": float(np.mean(row["f"])),
                              "mean_iou_f": float((np.mean(row["iou"]) + np.mean(row["f"])) / 2),
                              "no_sky_called": float(np.mean(row["no_sky_called"])) if row["no_sky_called"] else None,
                              "refused_with_sky": row["refused_with_sky"], "crops_with_sky": len(row["iou"]),
                              "per_crop_iou": row["iou"], "per_crop_f": row["f"]}
        s = out["settings"][k]
        print(f"{k:>12}: IoU {s['iou']:.4f}  F {s['boundary_f']:.4f}  mean {s['mean_iou_f']:.4f}  "
              f"no-sky called {s['no_sky_called']}  refused {s['refused_with_sky']}/{s['crops_with_sky']}")
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
