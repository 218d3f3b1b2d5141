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
import time

import numpy as np
import torch

from learned import Relighter
from learned import sky_segmentation as ss
from physrelight import metrics
from synth.panorama_crops import make_crops, shipped_panoramas


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="score sunrise instead of the training side")
    ap.add_argument("--only", action="append", default=[], help="RES:BAND:REFINE settings (default: the grid)")
    args = ap.parse_args()
    torch.set_num_threads(2)
    r = Relighter.load()
    model = r.sky_segmenter
    group = "heldout" if args.heldout else "training"
    panos = [p for p in shipped_panoramas() if p.group == group]
    grid = [tuple(s.split(":")) for s in args.only] or [
        (res, band, refine) for res in ("64", "128") for band in ("0", "1", "2", "3", "4", "6")
        for refine in (("local",) if band == "0" else ss.REFINEMENTS)]
    rows = {":".join(g): {"iou": [], "f": [], "no_sky_called": [], "refused_with_sky": 0} for g in grid}
    t0 = time.time()
    for pano in panos:
        for c in make_crops(pano, 16, 0, fov_range=(45.0, 75.0), samples=4):
            lin = c.linear()
            has_sky = c.sky.mean() >= 0.01
            for g in grid:
                res, band, refine = int(g[0]), int(g[1]), g[2]
                sky, why = ss.sky_mask_full_resolution(model, lin, res=res, band=band, refine=refine)
                m = sky[0, 0].numpy()
                row = rows[":".join(g)]
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
                              "no_sky_called": float(np.mean(row["no_sky_called"])) if row["no_sky_called"] else None,
                              "refused_with_sky": row["refused_with_sky"], "crops_with_sky": len(row["iou"])}
        s = out["settings"][k]
        print(f"{k:>16}: IoU {s['iou']:.3f}  F {s['boundary_f']:.3f}  no-sky called {s['no_sky_called']}  "
              f"refused {s['refused_with_sky']}/{s['crops_with_sky']}")
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
