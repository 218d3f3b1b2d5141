"""Study 34 probe: the camera's pitch from the sky (estimate_pitch), from the vertical vanishing point
(pitch_from_verticals), and both (estimate_camera_pitch), on bench --real's crops (seed 0, 16 per panorama).

    .venv/bin/python docs/experiments/scripts/34_pitch_verticals_probe.py -o docs/experiments/results/34_training.json
    .venv/bin/python docs/experiments/scripts/34_pitch_verticals_probe.py --heldout -o docs/experiments/results/34_heldout.json
"""
from __future__ import annotations

import argparse
import json

import numpy as np
import torch

from learned import Relighter
from physrelight.horizon import SKY_BOUND_MARGIN_DEG, estimate_pitch, pitch_from_verticals
from real_crop_scores import bench_crops, crop_panoramas

MARGINS = (0.0, 2.0, 5.0, float("inf"))  # inf: the vanishing point whenever it has one


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(2)
    r = Relighter.load()
    group, panos = crop_panoramas(args.heldout)
    rows = []
    for pano, c in bench_crops(panos):
        lin = c.linear()
        seg, _ = r.photo_sky(lin)
        rows.append({"panorama": pano.name, "index": c.index, "true": c.pitch_deg,
                     "sky": estimate_pitch(seg[0, 0], c.K), "verticals": pitch_from_verticals(lin, c.K)})
    t = np.array([x["true"] for x in rows])
    s = np.array([x["sky"] for x in rows])
    v = np.array([np.nan if x["verticals"] is None else x["verticals"] for x in rows])
    out = {"group": group, "crops": rows, "mean_abs_error_deg": {"sky": float(np.mean(np.abs(s - t))),
                                                                 "verticals": float(np.nanmean(np.abs(v - t)))}}
    for m in MARGINS:
        comb = np.where(np.isfinite(v) & (v >= s - m), v, s)
        out["mean_abs_error_deg"][f"combined_margin_{m:g}"] = float(np.mean(np.abs(comb - t)))
    out["shipped_margin"] = SKY_BOUND_MARGIN_DEG
    print(json.dumps(out["mean_abs_error_deg"], indent=1))
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
