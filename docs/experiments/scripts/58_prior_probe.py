"""Study 58: the lighting prior fitted on nine outdoor panoramas against the shipped one, on bench --quick's own
synthetic held-out scenes (rule 1 of docs/experiments/58-prior-on-more-panoramas.md).

    python docs/experiments/scripts/58_prior_probe.py fit -o docs/experiments/results/58_prior_more.npz
    python docs/experiments/scripts/58_prior_probe.py synthetic --candidate docs/experiments/results/58_prior_more.npz \
        -o docs/experiments/results/58_synthetic.json

``fit`` fits the candidate (``fit_outdoor_prior(hdris="more")``) and checks that the shipped recipe
(``hdris="shipped"``) reproduces the shipped prior. ``synthetic`` renders bench --quick's scenes once, makes its
pairs (cross-relighting with the dark and noise+JPEG variants, and the time-lapse), relights every pair with
``proposed`` and ``quotient`` (the estimated track) with the shipped pipeline and with the same pipeline holding the
candidate prior, and writes each method's mean l1 per prior and the per-scene paired difference (candidate minus
shipped) with its 95 % scene-bootstrap interval (2000 resamples of the scenes, seed 0). One torch thread.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))


def fit(out: Path) -> None:
    from learned.lighting import PRIOR_PATH, fit_outdoor_prior, load_prior

    t0 = time.perf_counter()
    shipped = load_prior(PRIOR_PATH)
    again = fit_outdoor_prior(path=None)
    for name in ("mean", "components", "scale"):
        a, b = np.asarray(getattr(shipped, name)), np.asarray(getattr(again, name))
        print(f"shipped recipe reproduces the shipped prior's {name}: max |diff| {np.abs(a - b).max():.3g}")
    cand = fit_outdoor_prior(hdris="more", path=out)
    print(f"candidate written to {out} ({time.perf_counter() - t0:.0f} s); mean's DC luminance shipped "
          f"{np.asarray(shipped.mean).reshape(9, 3)[0].mean():.4f}, candidate "
          f"{np.asarray(cand.mean).reshape(9, 3)[0].mean():.4f}")


def synthetic(candidate: Path, out: Path, bootstrap: int = 2000) -> None:
    from learned import Relighter
    from learned.lighting import load_prior
    from validation.bench.methods import build_methods
    from validation.bench.protocols import VARIANTS, cross_pairs, informative_pairs, timelapse_pairs
    from validation.bench.run import QUICK, evaluate, gather_views

    torch.set_num_threads(1)
    shipped = Relighter.load()
    cand = copy.copy(shipped)
    cand.prior = load_prior(candidate)
    views, info = gather_views(QUICK, None, print)
    variant_views = [v.name for v in views if v.view == 0 and v.group != "timelapse"][: QUICK.variant_views]
    cross, _ = informative_pairs(cross_pairs(views, VARIANTS, variant_views))
    tl, _ = informative_pairs(timelapse_pairs(views))
    pairs = cross + tl
    scenes = np.array([p.view.scene for p in pairs])
    result: dict = {"pairs": len(pairs), "scenes": sorted(set(scenes.tolist())), "candidate": str(candidate),
                    "methods": {}}
    for m in ("proposed", "quotient"):
        l1 = {}
        for label, r in (("shipped", shipped), ("candidate", cand)):
            t0 = time.perf_counter()
            l1[label] = evaluate(m, build_methods(r)[m], pairs).values["l1"]
            print(f"{m} with the {label} prior: l1 {l1[label].mean():.5f} ({time.perf_counter() - t0:.0f} s)")
        d = l1["candidate"] - l1["shipped"]
        names = sorted(set(scenes.tolist()))
        per_scene = np.array([d[scenes == s].mean() for s in names])
        rng = np.random.default_rng(0)
        boot = per_scene[rng.integers(0, len(per_scene), (bootstrap, len(per_scene)))].mean(1)
        result["methods"][m] = {
            "l1_shipped": float(l1["shipped"].mean()), "l1_candidate": float(l1["candidate"].mean()),
            "pair_mean_diff": float(d.mean()), "pairs_better": int((d < 0).sum()),
            "scene_mean_diff": float(per_scene.mean()), "scene_diff_interval": [float(np.percentile(boot, 2.5)),
                                                                              float(np.percentile(boot, 97.5))],
            "scenes_better": int((per_scene < 0).sum()), "per_scene_diff": dict(zip(names, per_scene.tolist()))}
        print(json.dumps(result["methods"][m]))
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fit")
    f.add_argument("-o", "--output", type=Path, required=True)
    s = sub.add_parser("synthetic")
    s.add_argument("--candidate", type=Path, required=True)
    s.add_argument("-o", "--output", type=Path, required=True)
    args = ap.parse_args()
    if args.cmd == "fit":
        fit(args.output)
    else:
        synthetic(args.candidate, args.output)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
