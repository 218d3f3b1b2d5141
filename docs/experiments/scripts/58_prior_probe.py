"""Study 58: the lighting prior fitted on nine outdoor panoramas against the shipped one, on bench --quick's own
synthetic held-out scenes (rule 1 of docs/experiments/58-prior-on-more-panoramas.md).

    python docs/experiments/scripts/58_prior_probe.py fit -o docs/experiments/results/58_prior_more.npz
    python docs/experiments/scripts/58_prior_probe.py synthetic --candidate docs/experiments/results/58_prior_more.npz \
        -o docs/experiments/results/58_synthetic.json
    python docs/experiments/scripts/58_prior_probe.py real-training --candidate docs/experiments/results/58_prior_more.npz \
        -o docs/experiments/results/58_real_training.json

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


def real_training(candidate: Path, out: Path) -> None:
    """Rule 2: ``proposed``'s shading error on the training-side crops of ``bench --real --quick`` (the same crops:
    4 per panorama, seed 0, 45-75 deg, 4 x 4 rays), shipped prior against the candidate, as the bench computes it
    for its stability table (the decomposition ``relight_full_resolution`` makes, on the segmenter's mask). Only
    the training side: sunrise is not touched."""
    from learned import Relighter
    from learned.lighting import load_prior
    from learned.relighter import working_resolution
    from physrelight import envmap, sh
    from physrelight.stats import hierarchical_bootstrap
    from synth.panorama_crops import make_crops, shipped_panoramas
    from validation.bench.real import more_panoramas
    from validation.bench.real_metrics import SPHERE_NORMALS, shading_error

    torch.set_num_threads(1)
    shipped = Relighter.load()
    cand = copy.copy(shipped)
    cand.prior = load_prior(candidate)
    panos = [p for p in shipped_panoramas() + more_panoramas() if p.group == "training"]
    normals = sh.fibonacci_sphere(SPHERE_NORMALS)
    rows = []
    for pano in panos:
        truth_w = np.asarray(envmap.irradiance_reference(pano.env.astype(np.float64), normals))
        for c in make_crops(pano, 4, 0, fov_range=(45.0, 75.0), samples=4):
            if c.stratum != "sky":
                continue
            lin = c.linear()
            seg = shipped.photo_sky(lin)[0]
            small, small_sky = working_resolution(shipped.denoised(lin), seg, shipped.res)
            truth = truth_w * c.gain[None, :]
            cam_normals = normals @ c.rotation.T
            row = {"panorama": pano.name, "index": c.index}
            for label, r in (("shipped", shipped), ("candidate", cand)):
                L = r.decompose_linear(small.float(), small_sky.bool())["lighting"][0].double().numpy()
                row[label] = shading_error(np.asarray(sh.irradiance(L, cam_normals)), truth)
            rows.append(row)
            print(row, flush=True)
    groups = [r["panorama"] for r in rows]
    res = {"crops": rows}
    for label in ("shipped", "candidate"):
        mi = hierarchical_bootstrap([r[label] for r in rows], groups, samples=2000, seed=0)
        res[label] = {"mean": mi.mean, "lo": mi.lo, "hi": mi.hi}
    d = [r["candidate"] - r["shipped"] for r in rows]
    mi = hierarchical_bootstrap(d, groups, samples=2000, seed=0)
    res["difference"] = {"mean": mi.mean, "lo": mi.lo, "hi": mi.hi}
    print(json.dumps({k: v for k, v in res.items() if k != "crops"}))
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(res, indent=1))
    tmp.replace(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fit")
    f.add_argument("-o", "--output", type=Path, required=True)
    s = sub.add_parser("synthetic")
    s.add_argument("--candidate", type=Path, required=True)
    s.add_argument("-o", "--output", type=Path, required=True)
    t = sub.add_parser("real-training")
    t.add_argument("--candidate", type=Path, required=True)
    t.add_argument("-o", "--output", type=Path, required=True)
    args = ap.parse_args()
    if args.cmd == "fit":
        fit(args.output)
    elif args.cmd == "synthetic":
        synthetic(args.candidate, args.output)
    else:
        real_training(args.candidate, args.output)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
