"""Probe: does a *softened* estimated-depth sun shadow help the relit l1? (issue 26, shadows from geometry)

The visibility from depth integrated from the decomposition's normals is right only part of the
time, and a wrong hard shadow costs more l1 than a missing one. This blends it towards no shadow,
``v_a = 1 - a (1 - v)``, applied to the sun's light only in source and target (the known-source
quotient as in ``screen_space_shadow_study.py``), chooses ``a`` on data/val5 by relit l1 and reports
it on the held-out sets. The setting (steps, thickness, min_cos) is the one the study chose by l1
on data/val5 for the estimated depth, read from its JSON.

Run: ``.venv/bin/python docs/experiments/scripts/screen_space_shadow_blend_probe.py
--study docs/experiments/results/screen_space_shadow.json --out docs/experiments/results/screen_space_shadow_blend.json``
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
from physrelight.quotient import quotient_relight  # noqa: E402
from physrelight.stats import paired_bootstrap  # noqa: E402
from validation.bench.protocols import cross_pairs  # noqa: E402
from validation.bench.scores import score  # noqa: E402

ALPHAS = (0.0, 0.25, 0.5, 0.75, 1.0)


def blended_l1(P: Photos, setting: tuple) -> dict:
    pairs = cross_pairs(P.views)
    preds = {a: [] for a in ALPHAS}
    targets, masks, scenes = [], [], []
    for p in pairs:
        v, ph = p.view, P.photo(p.view, p.source)
        image, sky = p.image(), p.sky()
        Ls, Lt = p.source_lighting(), p.target_lighting()
        sun_s = torch.from_numpy((v.sun_sh[p.source] * p.gain[None, :]).astype(np.float32))[None]
        sun_t = torch.from_numpy((v.sun_sh[p.target] * p.gain[None, :]).astype(np.float32))[None]
        vs = P.visibility(v, p.source, "est_normals_depth", setting, p.source).float()
        vt = P.visibility(v, p.target, "est_normals_depth", setting, p.source).float()
        fg, tgt = p.foreground(), p.target_display()
        for a in ALPHAS:
            relit = quotient_relight(image, ph["normals"].float(), Ls, Lt, mask=~sky, source_shadow=1 - a * (1 - vs),
                                     target_shadow=1 - a * (1 - vt), source_sun=sun_s, target_sun=sun_t)
            relit = torch.where(sky, image, relit.clamp_min(0.0))
            preds[a].append(torch.where(fg, p.display(relit), tgt))
        targets.append(tgt)
        masks.append(fg)
        scenes.append(v.scene)
    l1 = {a: score(x, targets, masks)["l1"] for a, x in preds.items()}
    return {"mean_l1": {str(a): float(np.mean(x)) for a, x in l1.items()},
            "vs_no_shadow": {str(a): paired_bootstrap(x, l1[0.0], groups=np.asarray(scenes), seed=0)._asdict()
                             for a, x in l1.items() if a != 0.0}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--study", default="docs/experiments/results/screen_space_shadow.json")
    ap.add_argument("--setting", default=None, help="steps/thickness/min_cos (default: the study's l1 choice)")
    ap.add_argument("--val", default="data/val5")
    ap.add_argument("--heldout", nargs="+", default=["data/heldout", "data/heldout3"])
    ap.add_argument("--out", default="docs/experiments/results/screen_space_shadow_blend.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    if args.setting:
        a, b, c = args.setting.split("/")
        setting = (int(a), float(b), float(c))
    else:
        setting = tuple(json.loads(Path(args.study).read_text())["val"]["by_l1"]["est_normals_depth"])
    relighter = Relighter.load()
    with torch.no_grad():
        val = blended_l1(Photos(args.val, relighter), setting)
        best = min(ALPHAS, key=lambda a: val["mean_l1"][str(a)])
        print("val", val["mean_l1"], "chosen", best, flush=True)
        out = {"setting": list(setting), "val": val, "chosen_alpha": best, "heldout": {}}
        for root in args.heldout:
            out["heldout"][root] = blended_l1(Photos(root, relighter), setting)
            print(root, out["heldout"][root]["mean_l1"], flush=True)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
