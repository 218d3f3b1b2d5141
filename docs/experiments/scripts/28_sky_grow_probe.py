"""Study 28 probe: growing the sky mask by a smooth sky-colour model, on real crops.

Scores relight's full-resolution sky mask (learned.sky_segmentation.sky_mask_full_resolution, shipped
128 px / band 6 / gauss) for a grid of ``grow`` reaches (fraction of the short side) on the crops of
bench --real --full (seed 0, 16 crops per panorama, fov 45-75, 4 samples). Selection uses the training
side only (city, courtyard, forest: IoU and boundary F on crops with sky; sky fraction called on crops
without); sunrise (held out) is scored only with --heldout, once, after the choice.

    .venv/bin/python docs/experiments/scripts/28_sky_grow_probe.py --round 1 -o docs/experiments/results/28_sky_grow_training.json
    .venv/bin/python docs/experiments/scripts/28_sky_grow_probe.py -o docs/experiments/results/28_sky_grow_training_round2.json
    .venv/bin/python docs/experiments/scripts/28_sky_grow_probe.py --round 3 -o docs/experiments/results/28_sky_grow_training_round3.json
    .venv/bin/python docs/experiments/scripts/28_sky_grow_probe.py --heldout --only 0 --only REACH:ORDER:1 -o ...
"""
from __future__ import annotations

import argparse
import json
import time

import torch

from learned import Relighter
from learned import sky_segmentation as ss
from real_crop_scores import crop_panoramas, score_sky_masks, setting_summary


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="score sunrise instead of the training side")
    ap.add_argument("--only", action="append", default=[], help="REACH or REACH:ORDER:CLAMP[:MAX_SPREAD] (default: the grid)")
    ap.add_argument("--round", type=int, default=2, help="1: unclamped degree 2 (round 1's grid); 2: round 2's grid; 3: round 3's (gated by the spread)")
    args = ap.parse_args()
    torch.set_num_threads(2)
    model = Relighter.load().sky_segmenter
    group, panos = crop_panoramas(args.heldout)
    if args.round == 1:
        default = [f"{r}:2:0" for r in ("0", "0.05", "0.1", "0.2", "1.0")]
    elif args.round == 2:
        default = ["0:2:1"] + [f"{r}:{o}:1" for r in ("0.05", "0.1", "0.2", "1.0") for o in (1, 2)]
    else:
        default = ["0:2:1"] + [f"{r}:2:1:{s}" for r in ("0.05", "0.1", "0.2") for s in ("0.05", "0.1", "0.2")]
    grid = [g if ":" in g else f"{g}:2:1" for g in args.only] or default

    def masks_of(lin: torch.Tensor) -> dict[str, tuple[torch.Tensor, str]]:
        base, why = ss.sky_mask_full_resolution(model, lin, grow=0.0)
        out = {}
        for g in grid:
            reach, order, clamp, *spread = g.split(":")
            # growth is the mask's last step, so it is applied here to the shipped mask
            r_px = int(round(float(reach) * min(lin.shape[-2:])))
            out[g] = (ss.grow_sky_by_colour(base, lin, r_px, order=int(order), clamp=bool(int(clamp)),
                                            max_spread=float(spread[0]) if spread else None), why[0])
        return out

    t0 = time.time()
    rows = score_sky_masks(panos, grid, masks_of)
    out = {"group": group, "panoramas": [p.name for p in panos], "seconds": round(time.time() - t0, 1), "settings": {}}
    for k, row in rows.items():
        out["settings"][k] = s = {**setting_summary(row), "iou_per_crop": [round(v, 4) for v in row["iou"]]}
        print(f"reach:order:clamp {k:>10}: IoU {s['iou']:.4f}  F {s['boundary_f']:.4f}  no-sky called {s['no_sky_called']}  "
              f"refused {s['refused_with_sky']}/{s['crops_with_sky']}")
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
