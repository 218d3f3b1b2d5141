"""Study 27: what limits the known-source quotient (``quotient_known``), term by term.

``quotient_known`` relights the photo linearised with the sRGB inverse by the ratio of the target to the
given source shading, on the decomposition's normals, without cast shadows. Against path tracing it sits
at l1 0.0739 on ``bench --full`` while ``oracle_sh_shadow`` sits at 0.0420. Each variant below replaces one
estimated or nuisance input by its truth, cumulatively, on the cross-relighting pairs of a synth folder
(the bench's pairs, targets and l1: :func:`validation.bench.scores.score` on display values):

``bench``            the bench's ``quotient_known`` (:class:`validation.bench.methods.Learned`), as is;
``true_curve``       the photo linearised with its own response curve (``photo_params["curve"]``)
                     instead of the sRGB inverse; noise, JPEG, 8-bit and clipping stay;
``clean``            the photo replaced by the path-traced radiance in the photo's linear units (no curve,
                     noise, JPEG, quantisation or clipping); the decomposition still runs on it;
``clean_normals``    ``clean`` with the true normals (``physrelight.quotient.quotient_relight`` itself, the
                     sun by its exact cosine as ``Learned`` does);
``clean_shadows``    ``clean_normals`` with the true sun visibility in the denominator and the numerator;
``curve_normals``    ``true_curve`` with the true normals (what the curve leaves once normals are exact).

Each variant's l1 is split by the source photo's response curve. Run (1 thread):
``.venv/bin/python docs/experiments/scripts/27_known_track_budget.py --data data/heldout
-o docs/experiments/results/27_known_track_budget_heldout.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from learned import Relighter
from physrelight import colour
from physrelight.quotient import quotient_relight
from physrelight.stats import paired_bootstrap
from validation.bench.data import load_dataset
from validation.bench.methods import Learned, to_chw
from validation.bench.protocols import Pair, cross_pairs
from validation.bench.scores import score

VARIANTS = ("bench", "true_curve", "clean", "clean_normals", "clean_shadows", "curve_normals")


def _with_image(pair: Pair, image: torch.Tensor) -> Pair:
    """A copy of ``pair`` whose :meth:`Pair.image` is ``image`` (1, 3, H, W)."""
    q = Pair(pair.view, pair.source, pair.target, pair.protocol, pair.variant, pair.photo, pair.gain, pair.eval_stops)
    q._cache["image"] = image
    return q


def true_curve_image(pair: Pair) -> torch.Tensor:
    curve = pair.view.photo_params[pair.source]["curve"]
    t = to_chw(pair.photo).clamp(0.0, 1.0)
    if curve == "filmic":  # the curve's range ends at 1.0143: 1.0 is inside it
        t = t.clamp_max(1.0)
    return colour.from_ldr(t, curve)


def clean_image(pair: Pair) -> torch.Tensor:
    return to_chw(pair.view.radiance[pair.source] * pair.gain[None, None, :]).clamp_min(0.0)


def true_normals_relit(pair: Pair, image: torch.Tensor, shadows: bool) -> torch.Tensor:
    v, sky = pair.view, pair.sky()
    kw = {}
    if shadows:
        kw = {"source_shadow": to_chw(v.shadow[pair.source]), "target_shadow": to_chw(v.shadow[pair.target])}
    relit = quotient_relight(image, to_chw(v.normal), pair.source_lighting(), pair.target_lighting(), mask=~sky,
                             source_sun=pair.sun_lighting(pair.source), target_sun=pair.sun_lighting(pair.target),
                             sun_cosine=True, **kw)
    return torch.where(sky, image, relit.clamp_min(0.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data/heldout")
    ap.add_argument("-o", "--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    relighter = Relighter.load()
    known = Learned(relighter, "quotient", known_source=True, sun=True, name="quotient_known")
    views = load_dataset(args.data, with_physical=False)
    pairs = cross_pairs(views)
    preds = {k: [] for k in VARIANTS}
    targets, masks, scenes, curves = [], [], [], []
    with torch.no_grad():
        for i, p in enumerate(pairs):
            fg, tgt = p.foreground(), p.target_display()

            def put(name: str, relit: torch.Tensor) -> None:
                preds[name].append(torch.where(fg, p.display(relit.float()), tgt))

            put("bench", known(p))
            tc = true_curve_image(p)
            put("true_curve", known(_with_image(p, tc)))
            clean = clean_image(p)
            put("clean", known(_with_image(p, clean)))
            put("clean_normals", true_normals_relit(p, clean, shadows=False))
            put("clean_shadows", true_normals_relit(p, clean, shadows=True))
            put("curve_normals", true_normals_relit(p, tc, shadows=False))
            targets.append(tgt)
            masks.append(fg)
            scenes.append(p.view.scene)
            curves.append(p.view.photo_params[p.source]["curve"])
            if i % 100 == 0:
                print(f"{i}/{len(pairs)} pairs, {time.perf_counter() - t0:.0f} s", flush=True)
    l1 = {k: score(x, targets, masks, which=("l1",))["l1"] for k, x in preds.items()}
    curves_a, groups = np.asarray(curves), np.asarray(scenes)
    out = {"data": args.data, "pairs": len(pairs), "scenes": len(set(scenes)),
           "curve_counts": {c: int((curves_a == c).sum()) for c in sorted(set(curves))},
           "mean_l1": {k: float(x.mean()) for k, x in l1.items()},
           "by_curve": {k: {c: float(x[curves_a == c].mean()) for c in sorted(set(curves))} for k, x in l1.items()},
           "vs_bench": {k: paired_bootstrap(x, l1["bench"], groups=groups, seed=0)._asdict()
                        for k, x in l1.items() if k != "bench"},
           "seconds": time.perf_counter() - t0}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1, default=float) + "\n")
    print(json.dumps({k: out[k] for k in ("mean_l1", "by_curve", "curve_counts")}, indent=1))


if __name__ == "__main__":
    main()
