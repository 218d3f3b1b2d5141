"""Study 27: the shipped ratio filter (``Relighter(ratio_radius=3)``) against the raw ratio (``ratio_radius=0``), both tracks.

The bench's ``quotient`` (estimated track) and ``quotient_known`` (known track), built by
:func:`validation.bench.methods.build_methods`, scored on the cross pairs of a synth folder (the bench's l1).
Run: ``.venv/bin/python docs/experiments/scripts/27_ratio_filter_tracks.py data/val5`` (1 thread).
"""

from __future__ import annotations

import json
import sys

import numpy as np
import torch

from learned import Relighter
from physrelight.stats import paired_bootstrap
from validation.bench.data import load_dataset
from validation.bench.methods import build_methods
from validation.bench.protocols import cross_pairs
from validation.bench.scores import score

torch.set_num_threads(1)
views = load_dataset(sys.argv[1], with_physical=False)
pairs = cross_pairs(views)
methods = {r: build_methods(Relighter.load(ratio_radius=r)) for r in (0, 3)}
out = {"data": sys.argv[1], "pairs": len(pairs)}
with torch.no_grad():
    for name in ("quotient", "quotient_known"):
        l1 = {}
        for r, ms in methods.items():
            preds, T, M = [], [], []
            for p in pairs:
                fg, tgt = p.foreground(), p.target_display()
                preds.append(torch.where(fg, p.display(ms[name](p)), tgt))
                T.append(tgt)
                M.append(fg)
            l1[r] = score(preds, T, M, which=("l1",))["l1"]
        d = paired_bootstrap(l1[3], l1[0], groups=np.asarray([p.view.scene for p in pairs]), seed=0)
        out[name] = {"radius_0": float(l1[0].mean()), "radius_3": float(l1[3].mean()), "diff": d._asdict()}
print(json.dumps(out, indent=1, default=float))
