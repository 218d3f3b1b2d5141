"""Study 29: a quotient-based neural renderer against the quotient method, with the bench's pairs and l1.

``proposed`` is the bench's method as ``bench`` builds it (:func:`validation.bench.methods.build_methods`)
with the candidate renderer loaded (``Relighter.load(renderer=...)``); ``quotient`` is the bench's
(estimated track, the sun by its exact cosine). Also reported, not part of the rule: ``proposed_sun``
(the renderer given the quotient image with the sun's exact cosine, as ``quotient`` has it).

    .venv/bin/python docs/experiments/scripts/29_quotient_renderer_bench.py DATA RENDERER -o OUT.json   (1 thread)
    ... --known: the known track instead: ``proposed_known`` (the renderer's gain on the quotient image
    that divides by the given source lighting) against the bench's ``quotient_known``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from learned import Relighter
from physrelight import io
from physrelight.stats import paired_bootstrap
from validation.bench.data import load_dataset
from validation.bench.methods import build_methods
from validation.bench.protocols import cross_pairs
from real_crop_scores import bench_l1


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("data")
    ap.add_argument("renderer")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--known", action="store_true", help="score the known track (proposed_known vs quotient_known)")
    ap.add_argument("--gain-ratio", action="store_true",
                    help="also score proposed_ratio: the renderer's gain for the target over its gain for the source")
    args = ap.parse_args()
    torch.set_num_threads(1)
    t0 = time.time()
    views = load_dataset(args.data, with_physical=False)
    pairs = cross_pairs(views)
    r = Relighter.load(renderer=args.renderer)
    ms = build_methods(r)

    def proposed_sun(p):
        image = p.image()
        return r.relight_full_resolution(image, p.sky(), p.target_lighting(), source_lighting=p.source_lighting(),
                                         method="proposed", working_res=min(image.shape[-2:]),
                                         target_sun=p.sun_lighting(p.target))["relit"]

    def proposed_known(p):
        image = p.image()
        return r.relight_full_resolution(image, p.sky(), p.target_lighting(), source_lighting=p.source_lighting(),
                                         method="proposed", working_res=min(image.shape[-2:]), known_source=True,
                                         target_sun=p.sun_lighting(p.target),
                                         source_sun=p.sun_lighting(p.source))["relit"]

    def ratio(fn):
        def call(p):
            r.renderer_gain_ratio = True
            try:
                return fn(p)
            finally:
                r.renderer_gain_ratio = False
        return call

    if args.known:
        methods = {"proposed_known": proposed_known, "quotient_known": ms["quotient_known"]}
        if args.gain_ratio:
            methods["proposed_known_ratio"] = ratio(proposed_known)
    elif args.gain_ratio:
        methods = {"proposed": ms["proposed"], "quotient": ms["quotient"], "proposed_ratio": ratio(ms["proposed"])}
    else:
        methods = {"proposed": ms["proposed"], "quotient": ms["quotient"], "proposed_sun": proposed_sun}
    l1 = bench_l1(methods, pairs)
    groups = np.asarray([p.view.scene for p in pairs])
    out = {"data": args.data, "renderer": args.renderer, "pairs": len(pairs),
           "l1": {k: float(v.mean()) for k, v in l1.items()}}
    if args.gain_ratio and not args.known:
        for other in ("proposed", "quotient"):
            out[f"proposed_ratio_minus_{other}"] = paired_bootstrap(l1["proposed_ratio"], l1[other], groups=groups,
                                                                   seed=0)._asdict()
    elif args.known:
        if args.gain_ratio:
            out["proposed_known_ratio_minus_quotient_known"] = paired_bootstrap(
                l1["proposed_known_ratio"], l1["quotient_known"], groups=groups, seed=0)._asdict()
        out["proposed_known_minus_quotient_known"] = paired_bootstrap(l1["proposed_known"], l1["quotient_known"],
                                                                      groups=groups, seed=0)._asdict()
    if not args.known and not args.gain_ratio:
        out["proposed_minus_quotient"] = paired_bootstrap(l1["proposed"], l1["quotient"], groups=groups,
                                                          seed=0)._asdict()
        out["proposed_sun_minus_quotient"] = paired_bootstrap(l1["proposed_sun"], l1["quotient"], groups=groups,
                                                              seed=0)._asdict()
    out["seconds"] = round(time.time() - t0, 1)
    io.write_json(args.out, out)
    print(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
