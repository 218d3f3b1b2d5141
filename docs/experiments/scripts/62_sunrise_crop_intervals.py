"""Study 62: paired intervals over sunrise's 16 ``--full`` crops from a ``52_clouds_probe.py --heldout`` JSON, and why
each segmenter's mask was refused on the crops where one was.

    .venv/bin/python docs/experiments/scripts/62_sunrise_crop_intervals.py PROBE.json shipped=S new=N -o OUT.json

Differences are ``new - shipped`` (the second NAME minus the first) with 95 % percentile-bootstrap intervals, crops
resampled (:func:`physrelight.stats.paired_bootstrap`, 2000 resamples, seed 0).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[3]))


def main() -> None:
    from learned.sky_segmentation import load_sky_segmenter, sky_mask_full_resolution
    from physrelight.stats import paired_bootstrap
    from real_crop_scores import bench_crops, crop_panoramas

    ap = argparse.ArgumentParser()
    ap.add_argument("probe")
    ap.add_argument("weights", nargs=2, help="NAME=PATH (before, after)")
    ap.add_argument("-o", "--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(1)
    crops = json.loads(Path(args.probe).read_text())["crops"]
    names = [w.split("=", 1)[0] for w in args.weights]
    out: dict = {"probe": args.probe}
    for key in ("iou_per_crop", "f_per_crop"):
        b, a = (np.asarray(crops[n][key]) for n in names)
        d = paired_bootstrap(a, b, groups=np.arange(len(a)), samples=2000, seed=0)
        out[key.split("_")[0]] = {names[0]: float(b.mean()), names[1]: float(a.mean()),
                                  f"{names[1]} - {names[0]}": {"diff": d.diff, "lo": d.lo, "hi": d.hi}}
    models = {w.split("=", 1)[0]: load_sky_segmenter(w.split("=", 1)[1]) for w in args.weights}
    _, panos = crop_panoramas(True)
    refused = []
    for i, (_, c) in enumerate(bench_crops(panos)):
        row = {"crop": i, "yaw_deg": round(c.yaw_deg, 1), "pitch_deg": round(c.pitch_deg, 1)}
        for n, m in models.items():
            sky, why = sky_mask_full_resolution(m, c.linear())
            row[n] = {"sky_fraction": float(sky.float().mean()), "refused": why[0]}
        if any(row[n]["refused"] for n in models):
            refused.append(row)
    out["refused"] = refused
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
