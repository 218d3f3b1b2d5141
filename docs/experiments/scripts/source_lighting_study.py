"""Study 23: the source-lighting estimate, before (the shipped ``map_relative`` step) and after
(:mod:`learned.source_lighting`), one switch at a time.

Usage (repository root, 1 thread):

    .venv/bin/python docs/experiments/scripts/source_lighting_study.py select   # data/val5 only: the grid
    .venv/bin/python docs/experiments/scripts/source_lighting_study.py report   # held-out sets, bench --real (b)

``select`` scores a grid of settings on the validation set ``data/val5`` (lighting shading error and
the estimated-track quotient relit l1 on its cross pairs) and writes
``docs/experiments/results/source_lighting_val5.json`` with the chosen setting (the lowest mean
shading error). ``report`` reads that choice and scores the shipped step, the chosen setting and the
setting with each switch flipped on ``data/heldout``, ``data/heldout3`` (lighting shading error, as
``learned.evaluate.shading_error``; quotient relit l1 on ``data/heldout``'s and ``data/heldout3``'s
cross pairs) and on ``bench --real --full`` section (b) crops (seed 0, 16 crops per panorama, the
segmenter's sky, working resolution; training panoramas and sunrise apart, studio apart), writing
``docs/experiments/results/source_lighting_report.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from learned import Relighter
from learned.data import SynthDataset, load_photo
from learned.evaluate import load_ground_truth, shading_error
from learned.objectives import decompose_and_solve
from learned.networks import repair_top_rows
from physrelight.full_resolution import working_resolution
from learned.source_lighting import SourceLightingConfig, solve_source_lighting

RESULTS = Path("docs/experiments/results")
NETWORK = "network"  # the shipped step: decompose_and_solve's map_relative lighting


def estimate(relighter: Relighter, out: dict, image: torch.Tensor, sky: torch.Tensor, K: torch.Tensor | None,
             cfg: SourceLightingConfig | str) -> torch.Tensor:
    """``(B, 9, 3)`` the source lighting by ``cfg`` (a config, or NETWORK) from a decomposition ``out``."""
    if cfg == NETWORK:
        return out["lighting"]
    return solve_source_lighting(image, out["albedo"], out["normals"], out["shadow"], out["foreground"],
                                 relighter.prior, sky=sky, K=K, config=cfg)


def synthetic(relighter: Relighter, root: str, configs: dict, quotient: bool = True) -> dict:
    """Per-config mean lighting shading error (true normals, foreground) and quotient relit l1 over cross pairs."""
    from validation.bench.data import load_dataset
    from validation.bench.protocols import cross_pairs, informative_pairs
    from validation.bench.scores import score

    ds = SynthDataset(root, split="all", mode="full")
    errs = {name: [] for name in configs}
    decomp: dict = {}
    t0 = time.perf_counter()
    for it in ds.items:
        p = load_photo(ds, it.scene, it.view, it.light, relighter.res)
        image, sky, K = p["image"][None], p["sky"][None], p["K"]
        with torch.no_grad():
            out = decompose_and_solve(relighter.inverse, image, sky, relighter.prior)
        gt = load_ground_truth(ds, it.scene, it.view, it.light, relighter.res)
        fg = ~sky[0] & (gt["normal"].norm(dim=0, keepdim=True) > 0.5)
        if int(fg.sum()) == 0:
            continue
        lights = {}
        errs.setdefault("prior_mean", []).append(shading_error(relighter.prior.mean.reshape(9, 3).double(),
                                                               gt["lighting"], gt["normal"], fg))
        for name, cfg in configs.items():
            L = estimate(relighter, out, image, sky, K, cfg)  # (1, 9, 3)
            lights[name] = L
            errs[name].append(shading_error(L[0], gt["lighting"], gt["normal"], fg))
        decomp[(it.scene, it.view, it.light)] = ({k: repair_top_rows(out[k]) for k in ("albedo", "normals", "shadow")}
                                                 | {"foreground": out["foreground"]}, lights)
    res = {name: {"shading_error": float(np.mean(v)), "photos": len(v)} for name, v in errs.items()}
    print(f"  {root}: lighting of {len(ds.items)} photos in {time.perf_counter() - t0:.0f} s", flush=True)
    if not quotient:
        return res
    views = load_dataset(root, with_physical=False)
    pairs, _ = informative_pairs(cross_pairs(views))
    preds = {name: [] for name in configs}
    targets, masks = [], []
    for pair in pairs:
        scene, view = pair.view.scene, pair.view.view
        layers, lights = decomp[(scene, view, pair.source)]
        fg, tgt = pair.foreground(), pair.target_display()
        targets.append(tgt)
        masks.append(fg)
        for name in configs:
            dec = layers | {"lighting": lights[name]}
            out = relighter.relight_linear(pair.image(), pair.sky(), pair.target_lighting(),
                                           source_lighting=pair.source_lighting(), method="quotient",
                                           decomposition=dec)
            preds[name].append(torch.where(fg, pair.display(out["relit"].float()), tgt))
        pair.release()
    for name in configs:
        res[name]["quotient_l1"] = float(score(preds[name], targets, masks, which=["l1"])["l1"].mean())
        res[name]["pairs"] = len(pairs)
    print(f"  {root}: {len(pairs)} quotient pairs in {time.perf_counter() - t0:.0f} s", flush=True)
    return res


def real_b(relighter: Relighter, configs: dict, crops_per_pano: int = 16, seed: int = 0) -> dict:
    """Section (b) of ``bench --real --full``: shading error on 256 sphere normals, per group."""
    from physrelight import camera, envmap, sh
    from synth.panorama_crops import make_crops, shipped_panoramas
    from validation.bench.real_metrics import SPHERE_NORMALS
    from validation.bench.real_metrics import shading_error as real_shading_error

    normals = sh.fibonacci_sphere(SPHERE_NORMALS)
    per: dict = {}
    t0 = time.perf_counter()
    for pano in shipped_panoramas():
        truth0 = np.asarray(envmap.irradiance_reference(pano.env.astype(np.float64), normals))
        for crop in make_crops(pano, crops_per_pano, seed, fov_range=(45.0, 75.0), samples=4):
            lin = crop.linear()
            seg, _ = relighter.photo_sky(lin)
            small, small_sky = working_resolution(lin, seg, relighter.res)
            h, w = lin.shape[-2:]
            sh_, sw_ = small.shape[-2:]
            K = torch.as_tensor(np.asarray(crop.K, dtype=np.float64)).clone()
            K[0] *= sw_ / w
            K[1] *= sh_ / h
            with torch.no_grad():
                out = decompose_and_solve(relighter.inverse, small, small_sky, relighter.prior)
            g = crop.gain
            truth = truth0 * g[None, :]
            cam_normals = normals @ crop.rotation.T
            group = "studio" if pano.name == "studio" else pano.group
            for name, cfg in configs.items():
                L = estimate(relighter, out, small, small_sky, K, cfg)[0].double().numpy()
                E = np.asarray(sh.irradiance(L, cam_normals))
                per.setdefault(group, {}).setdefault(name, []).append(real_shading_error(E, truth))
            prior_mean = np.asarray(relighter.prior.mean, dtype=np.float64).reshape(9, 3)
            per.setdefault(group, {}).setdefault("prior_mean", []).append(
                real_shading_error(np.asarray(sh.irradiance(prior_mean, cam_normals)), truth))
        print(f"  real: {pano.name} done at {time.perf_counter() - t0:.0f} s", flush=True)
    return {group: {name: {"shading_error": float(np.mean(v)), "crops": len(v)} for name, v in d.items()}
            for group, d in per.items()}


def grid(stage: int) -> dict:
    """Stage 1: noise x robust x sky settings; stage 2 (after stage 1 chose the largest noise, 2): larger
    noise constants, with and without dividing by the network's shadow; stage 3 (stage 2 chose 16, the
    largest again): larger still."""
    out: dict = {NETWORK: NETWORK}
    if stage == 1:
        for noise in (0.5, 1.0, 2.0):
            for robust in (False, True):
                base = SourceLightingConfig(noise=noise, robust=robust)
                out[f"n{noise}_r{int(robust)}_sky0"] = base
                for sky_noise, band in ((0.1, 1.0), (0.3, 1.0), (1.0, 1.0), (0.3, 3.0)):
                    out[f"n{noise}_r{int(robust)}_sky{sky_noise}_b{band}"] = base.but(sky=True, sky_noise=sky_noise,
                                                                                     band_scale=band)
        return out
    if stage == 3:  # stage 2 chose the largest noise again (16, no shadow division): go on until it turns
        for noise in (12.0, 24.0, 32.0, 64.0):
            base = SourceLightingConfig(noise=noise, robust=True, use_shadow=False)
            out[f"n{noise}_r1_s0_sky0"] = base
            out[f"n{noise}_r1_s0_sky0.3_b3.0"] = base.but(sky=True, sky_noise=0.3, band_scale=3.0)
        return out
    for noise in (2.0, 4.0, 8.0, 16.0):
        for shadow in (True, False):
            base = SourceLightingConfig(noise=noise, robust=True, use_shadow=shadow)
            out[f"n{noise}_r1_s{int(shadow)}_sky0"] = base
            for sky_noise, band in ((0.3, 1.0), (1.0, 1.0), (0.3, 3.0)):
                out[f"n{noise}_r1_s{int(shadow)}_sky{sky_noise}_b{band}"] = base.but(sky=True, sky_noise=sky_noise,
                                                                                    band_scale=band)
    return out


def switches(chosen: SourceLightingConfig) -> dict:
    """The shipped step, the chosen setting, and the chosen setting with each switch flipped."""
    out: dict = {NETWORK: NETWORK, "chosen": chosen,
                 "map_only": chosen.but(robust=False, sky=False),
                 "map_only_noise1": chosen.but(robust=False, sky=False, noise=1.0)}
    out["flip_robust"] = chosen.but(robust=not chosen.robust)
    # the sky switch at its best val5 setting next to the chosen noise (sky_noise 0.3, band_scale 3: stages 2-3)
    out["flip_sky"] = chosen.but(sky=False) if chosen.sky else chosen.but(sky=True, sky_noise=0.3, band_scale=3.0)
    out["flip_shadow"] = chosen.but(use_shadow=not chosen.use_shadow)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", choices=("select", "report"))
    ap.add_argument("--stage", type=int, default=1, choices=(1, 2, 3), help="select: which grid")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    relighter = Relighter.load()
    RESULTS.mkdir(parents=True, exist_ok=True)
    if args.part == "select":
        configs = grid(args.stage)
        res = synthetic(relighter, "data/val5", configs)
        doc = {"command": f"docs/experiments/scripts/source_lighting_study.py select --stage {args.stage}",
               "set": "data/val5", "criterion": "lowest mean lighting shading error over every stage's grid",
               "results": {n: {**res[n], "config": c if c == NETWORK else c.as_dict()} for n, c in configs.items()},
               "prior_mean": res["prior_mean"]}
        (RESULTS / f"source_lighting_val5_grid{args.stage}.json").write_text(json.dumps(doc, indent=1))
        pool = {}
        for f in sorted(RESULTS.glob("source_lighting_val5_grid*.json")):
            pool.update({n: r for n, r in json.loads(f.read_text())["results"].items() if n != NETWORK})
        best = min(pool, key=lambda n: pool[n]["shading_error"])
        choice = {"chosen": best, "chosen_config": pool[best]["config"], "val5": pool[best],
                  "network_val5": res[NETWORK], "grids": sorted(f.name for f in RESULTS.glob("source_lighting_val5_grid*"))}
        (RESULTS / "source_lighting_val5.json").write_text(json.dumps(choice, indent=1))
        print("chosen", best, pool[best], "network", res[NETWORK])
        return 0
    sel = json.loads((RESULTS / "source_lighting_val5.json").read_text())
    configs = switches(SourceLightingConfig(**sel["chosen_config"]))
    doc = {"command": "docs/experiments/scripts/source_lighting_study.py report", "chosen": sel["chosen_config"],
           "configs": {n: c if c == NETWORK else c.as_dict() for n, c in configs.items()}}
    for root in ("data/heldout", "data/heldout3"):
        doc[root] = synthetic(relighter, root, configs)
        (RESULTS / "source_lighting_report.json").write_text(json.dumps(doc, indent=1))
    doc["real_b"] = real_b(relighter, configs)
    (RESULTS / "source_lighting_report.json").write_text(json.dumps(doc, indent=1))
    print(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
