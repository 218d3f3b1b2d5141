"""Study 33 probe: the quotient for an SH target without a sun, with the sun fit_sky finds, and with the true sun.

    .venv/bin/python docs/experiments/scripts/33_fitted_sun_probe.py data/val5 -o docs/experiments/results/33_val5.json
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from learned import Relighter
from physrelight import io, sh
from physrelight.sky_model import fit_sky
from physrelight.stats import paired_bootstrap
from synth.dataset import SynthDataset
from validation.bench.data import load_dataset
from validation.bench.protocols import cross_pairs
from real_crop_scores import bench_l1


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("data")
    ap.add_argument("-o", "--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(2)
    t0 = time.time()
    views = load_dataset(args.data, with_physical=False)
    ds = SynthDataset(args.data, split="all", mode="full")
    w2c = {(s, v): np.asarray(view["world_to_camera"], dtype=np.float64)[:3, :3]
           for s in ds.scenes for v, view in enumerate(ds.record(s)["views"])}
    pairs = cross_pairs(views)
    r = Relighter.load()
    fits: dict[tuple[str, int, int], torch.Tensor] = {}

    def fitted(p) -> torch.Tensor:
        key = (p.view.scene, p.view.view, p.target)
        if key not in fits:
            R = w2c[(p.view.scene, p.view.view)]
            cam = p.target_lighting()[0].double().numpy()
            fit = fit_sky(np.asarray(sh.rotate(cam, R.T)))  # camera -> world
            sun_w = np.asarray(sh.project_sun(fit.sun_direction, fit.weights[0], order=2))
            fits[key] = torch.from_numpy(np.asarray(sh.rotate(sun_w, R))).float()[None]
        return fits[key]

    def relight(p, sun):
        image = p.image()
        kw = {} if sun is None else {"target_sun": sun}
        return r.relight_full_resolution(image, p.sky(), p.target_lighting(), source_lighting=p.source_lighting(),
                                         method="quotient", working_res=min(image.shape[-2:]), **kw)["relit"]

    methods = {"sh_only": lambda p: relight(p, None), "fitted_sun": lambda p: relight(p, fitted(p)),
               "true_sun": lambda p: relight(p, p.sun_lighting(p.target))}
    l1 = bench_l1(methods, pairs, progress=lambda name, v: print(f"{name}: {float(v.mean()):.5f} "
                                                                f"({time.time() - t0:.0f} s)", flush=True))
    groups = np.asarray([p.view.scene for p in pairs])
    out = {"data": args.data, "pairs": len(pairs), "l1": {k: float(v.mean()) for k, v in l1.items()},
           "fitted_sun_minus_sh_only": paired_bootstrap(l1["fitted_sun"], l1["sh_only"], groups=groups, seed=0)._asdict(),
           "true_sun_minus_sh_only": paired_bootstrap(l1["true_sun"], l1["sh_only"], groups=groups, seed=0)._asdict(),
           "fitted_sun_minus_true_sun": paired_bootstrap(l1["fitted_sun"], l1["true_sun"], groups=groups,
                                                         seed=0)._asdict(),
           "seconds": round(time.time() - t0, 1)}
    io.write_json(args.out, out)
    print(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
