"""Probe: does a graded sun-shadow score (mean of binary visibilities over several thicknesses) rank
shadow pixels better than one binary visibility? (issue 26, study 25)

A binary score has a two-point precision-recall curve, which caps its AP. Averaging the visibility over
thicknesses {0.05, 0.1, 0.2, 0.3} grades each pixel by how far in front of its ray the occluder is. AP
(positive class ``shadow.exr < 0.5``, foreground pixels of every photo pooled, as ``learned/evaluate.py``)
on data/val5 first; the held-out sets only if it helps there (``--heldout``).

Run: ``.venv/bin/python docs/experiments/scripts/screen_space_shadow_graded_probe.py --heldout
--out docs/experiments/results/screen_space_shadow_graded.json``
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from screen_space_shadow_study import Photos  # noqa: E402

from learned import Relighter  # noqa: E402
from learned.evaluate import average_precision  # noqa: E402

THICKNESSES = (0.05, 0.1, 0.2, 0.3)
# The study's val5 choices by AP: (steps, thickness, min_cos).
SINGLE = {"true_depth": (64, 0.2, 0.05), "est_normals_depth": (64, 0.1, 0.003)}


def aps(P: Photos) -> dict:
    scores = {f"{s}_{k}": [] for s in SINGLE for k in ("single", "graded")}
    labels = []
    for v in P.views:
        fg = P.view(v)["fg"][0, 0]
        for light in range(v.num_lights):
            labels.append(v.shadow[light][fg.numpy()] < 0.5)
            for src, (steps, th, mc) in SINGLE.items():
                single = P.visibility(v, light, src, (steps, th, mc), light)
                graded = torch.stack([P.visibility(v, light, src, (steps, t, mc), light) for t in THICKNESSES]).mean(0)
                scores[f"{src}_single"].append((1 - single[0, 0][fg]).numpy())
                scores[f"{src}_graded"].append((1 - graded[0, 0][fg]).numpy())
    y = np.concatenate(labels)
    return {"chance": float(y.mean()), **{k: average_precision(np.concatenate(s), y) for k, s in scores.items()}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--heldout", action="store_true")
    ap.add_argument("--out", default=None, help="also write the figures to this JSON")
    args = ap.parse_args()
    torch.set_num_threads(1)
    relighter = Relighter.load()
    roots = ["data/val5"] + (["data/heldout", "data/heldout3"] if args.heldout else [])
    out = {"thicknesses": list(THICKNESSES), "single": {k: list(v) for k, v in SINGLE.items()}}
    with torch.no_grad():
        for root in roots:
            out[root] = aps(Photos(root, relighter))
            print(root, {k: round(v, 3) for k, v in out[root].items()}, flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
