"""Study 37 probe: the photo denoised before relighting (``Relighter.denoise``), on the bench's pairs.

For each setting of the grid (off, or RADIUS:STRENGTH of :func:`physrelight.denoise.denoise`), the bench's
foreground l1 of ``proposed`` (estimated track, the default) and ``quotient_known`` (known track) on the
cross pairs of DATA as rendered and on the ``dark`` and ``noise_jpeg`` variants of each scene's first view
(as ``bench`` makes them). The decomposition of each source photo is computed once per setting and reused
for both targets and both methods.

    .venv/bin/python docs/experiments/scripts/37_denoise_probe.py data/val5 -o docs/experiments/results/37_denoise_val5.json
    .venv/bin/python docs/experiments/scripts/37_denoise_probe.py data/heldout --only off --only 2:3 -o docs/experiments/results/37_denoise_heldout.json
    .venv/bin/python docs/experiments/scripts/37_denoise_probe.py data/val5 --round 2 -o docs/experiments/results/37_denoise_val5_round2.json
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from learned import Relighter
from physrelight import io
from physrelight.denoise import FLOOR_BLOCK
from physrelight.stats import paired_bootstrap
from validation.bench.data import load_dataset
from validation.bench.protocols import cross_pairs
from validation.bench.scores import score

GRID = ("off", "1:1", "1:2", "1:3", "2:1", "2:2", "2:3")
GRID_2 = ("off", "1:3", "1:4", "1:6", "2:3", "2:4", "2:6")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("data")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--only", action="append", default=[], help="settings (default: the grid)")
    ap.add_argument("--round", type=int, default=1, choices=(1, 2),
                    help="1: the noise read over the whole photo and round 1's grid; 2: the noise floor, round 2's grid")
    args = ap.parse_args()
    torch.set_num_threads(2)
    t0 = time.time()
    views = load_dataset(args.data, with_physical=False)
    first = sorted({v.name for v in views if v.view == 0})
    sets = {"as_rendered": cross_pairs(views),
            "dark": cross_pairs(views, ("dark",), first), "noise_jpeg": cross_pairs(views, ("noise_jpeg",), first)}
    r = Relighter.load()
    out = {"data": args.data, "pairs": {k: len(v) for k, v in sets.items()}, "settings": {}, "minus_off": {}}
    groups = {k: np.asarray([p.view.scene for p in v]) for k, v in sets.items()}
    block = None if args.round == 1 else FLOOR_BLOCK
    for setting in args.only or (GRID if args.round == 1 else GRID_2):
        r.denoise = None if setting == "off" else (int(setting.split(":")[0]), float(setting.split(":")[1]), block)
        row = {}
        for name, pairs in sets.items():
            work: dict[tuple, dict] = {}
            preds = {"proposed": [], "quotient_known": []}
            T, M = [], []
            with torch.no_grad():
                for p in pairs:
                    image = p.image()
                    key = (p.view.name, p.source, p.variant)
                    kw = dict(source_lighting=p.source_lighting(), working_res=min(image.shape[-2:]),
                              target_sun=p.sun_lighting(p.target))
                    res = r.relight_full_resolution(image, p.sky(), p.target_lighting(), method="proposed",
                                                    decomposition=work.get(key), **kw)
                    work.setdefault(key, {k: res["working"][k] for k in ("albedo", "normals", "shadow", "lighting",
                                                                         "foreground")})
                    known = r.relight_full_resolution(image, p.sky(), p.target_lighting(), method="quotient",
                                                      known_source=True, source_sun=p.sun_lighting(p.source),
                                                      decomposition=work[key], **kw)
                    fg, tgt = p.foreground(), p.target_display()
                    preds["proposed"].append(torch.where(fg, p.display(res["relit"]), tgt))
                    preds["quotient_known"].append(torch.where(fg, p.display(known["relit"]), tgt))
                    T.append(tgt)
                    M.append(fg)
            for m, pr in preds.items():
                l1 = score(pr, T, M, which=("l1",))["l1"]
                row[f"{m}:{name}"] = float(np.mean(l1))
                row[f"{m}:{name}:per_pair"] = [round(float(x), 5) for x in l1]
        row["proposed:mean_of_sets"] = float(np.mean([row[f"proposed:{k}"] for k in sets]))
        out["settings"][setting] = row
        print(f"{setting:>4}: " + "  ".join(f"{k} {v:.4f}" for k, v in row.items() if not k.endswith("per_pair")) +
              f"  ({time.time() - t0:.0f} s)", flush=True)
    if "off" in out["settings"]:  # each setting minus off, paired per pair, scenes resampled
        off = out["settings"]["off"]
        for setting, row in out["settings"].items():
            if setting != "off":
                out["minus_off"][setting] = {
                    f"{m}:{name}": paired_bootstrap(row[f"{m}:{name}:per_pair"], off[f"{m}:{name}:per_pair"],
                                                    groups=groups[name], seed=0)._asdict()
                    for m in ("proposed", "quotient_known") for name in sets}
    out["seconds"] = round(time.time() - t0, 1)
    io.write_json(args.out, out)


if __name__ == "__main__":
    main()
