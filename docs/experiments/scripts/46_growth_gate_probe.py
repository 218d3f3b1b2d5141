"""Study 46 probe: the colour growth's gate (``GROW_CHI2``).

``grow_sky_by_colour`` grows a pixel near the mask when its squared Mahalanobis distance to the smooth sky
model is under ``chi2`` (and it is likelier sky than foreground, a test study 45 found never binding). The gate
is applied inside the shipped pipeline by wrapping the growth; scored as study 44 on the training crops (plain
and lattice); ``--heldout`` scores sunrise's crops once.

    .venv/bin/python docs/experiments/scripts/46_growth_gate_probe.py -o docs/experiments/results/46_training.json
    .venv/bin/python docs/experiments/scripts/46_growth_gate_probe.py --heldout --only 11.34 --only CHOSEN -o docs/experiments/results/46_sunrise.json
"""
from __future__ import annotations

import argparse
import functools
import importlib
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_crop_scores import bench_crops, crop_panoramas  # noqa: E402

from learned import Relighter  # noqa: E402
from learned import sky_segmentation as ss  # noqa: E402
from physrelight import metrics  # noqa: E402
from physrelight.stats import paired_bootstrap  # noqa: E402

lattice = importlib.import_module("40_lattice_sky_probe")


SETTINGS = ("11.34", "16.27", "21.11", "30")
_GROW = ss.grow_sky_by_colour


def masks(model, lin: torch.Tensor, settings) -> dict[str, np.ndarray]:
    """Per setting, the shipped mask with that gate."""
    out = {}
    for s in settings:
        ss.grow_sky_by_colour = functools.partial(_GROW, chi2=float(s))
        out[s] = ss.sky_mask_full_resolution(model, lin)[0][0, 0].numpy()
    ss.grow_sky_by_colour = _GROW
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
    group, panos = crop_panoramas(args.heldout)
    sets = {"plain": {s: [] for s in settings}, "lattice": {s: [] for s in settings}}
    no_sky = {s: [] for s in settings}
    groups = {"plain": [], "lattice": []}
    t0 = time.time()
    for pano, crop in bench_crops(panos):
        lin = crop.linear()
        if crop.sky.mean() < 0.01:
            for s, m in masks(model, lin, settings).items():
                no_sky[s].append(float(m.mean()))
            continue
        for s, m in masks(model, lin, settings).items():
            sets["plain"][s].append((metrics.mask_iou(m, crop.sky) + metrics.boundary_f(m, crop.sky, 2.0)) / 2)
        groups["plain"].append(f"{pano.name}_{crop.index}")
        if not args.heldout and crop.sky.mean() >= 0.10:
            for seed in (0, 1):
                comp, truth, _ = lattice.composite(crop, seed)
                for s, m in masks(model, comp, settings).items():
                    sets["lattice"][s].append((metrics.mask_iou(m, truth) + metrics.boundary_f(m, truth, 2.0)) / 2)
                groups["lattice"].append(f"{pano.name}_{crop.index}")
    out = {"group": group, "seconds": time.time() - t0, "settings": list(settings)}
    for name, rows in sets.items():
        if not groups[name]:
            continue
        base = np.asarray(rows[settings[0]])
        out[name] = {}
        for s in settings:
            v = np.asarray(rows[s])
            entry = {"mean_iou_f": float(v.mean()), "n": int(v.size)}
            if s != settings[0]:
                entry["minus_first"] = paired_bootstrap(v, base, groups=np.asarray(groups[name]), seed=0)._asdict()
            out[name][str(s)] = entry
            print(f"{name:8s} {s:9s}: mean IoU/F {v.mean():.4f}"
                  + (f"  {entry['minus_first']['diff']:+.4f} [{entry['minus_first']['lo']:+.4f}, "
                     f"{entry['minus_first']['hi']:+.4f}]" if s != settings[0] else ""), flush=True)
    out["no_sky_called"] = {str(s): float(np.mean(v)) if v else None for s, v in no_sky.items()}
    print("sky called on crops without sky:", {k: round(v, 4) for k, v in out["no_sky_called"].items() if v is not None})
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
