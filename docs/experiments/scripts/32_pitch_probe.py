"""Study 32 probe: estimate_pitch's percentile on bench --real's crops (training side; --heldout: sunrise, once).

    .venv/bin/python docs/experiments/scripts/32_pitch_probe.py -o docs/experiments/results/32_pitch_training.json
"""
from __future__ import annotations

import argparse
import json

import numpy as np
import torch

from learned import Relighter
from physrelight.horizon import estimate_pitch
from synth.panorama_crops import make_crops, shipped_panoramas

QUANTILES = (0.9, 0.95, 0.98, 1.0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true")
    ap.add_argument("--q", action="append", type=float, default=[])
    args = ap.parse_args()
    torch.set_num_threads(2)
    r = Relighter.load()
    group = "heldout" if args.heldout else "training"
    qs = args.q or list(QUANTILES)
    err: dict[str, list[float]] = {f"{q:g}": [] for q in qs}
    for pano in [p for p in shipped_panoramas() if p.group == group]:
        for c in make_crops(pano, 16, 0, fov_range=(45.0, 75.0), samples=4):
            seg, _ = r.photo_sky(c.linear())
            for q in qs:
                err[f"{q:g}"].append(estimate_pitch(seg[0, 0], c.K, quantile=q) - c.pitch_deg)
    out = {"group": group, "quantiles": {}}
    for k, v in err.items():
        a = np.asarray(v)
        out["quantiles"][k] = {"signed": float(a.mean()), "abs": float(np.abs(a).mean()), "n": len(a), "errors": v}
        print(f"q {k:>5}: signed {a.mean():6.2f}  abs {np.abs(a).mean():6.2f} deg  ({len(a)} crops)")
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
