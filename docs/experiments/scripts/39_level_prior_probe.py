"""Study 39 probe: the relit level on the estimated track, the lighting's shape blended with the grey world.

``Relighter.level_prior = beta`` divides the target's scale by ``g ** beta`` (``g``: the foreground's median
implied albedo over 0.18 with the estimated shape at the given source level). For each beta of the grid:

* synthetic (``DATA``): the bench's foreground l1 of ``proposed`` and ``quotient`` (estimated track) on the
  cross pairs as rendered and on the ``dark`` / ``noise_jpeg`` variants of each scene's first view, and the
  relit level (log2 of relit over target foreground mean luminance, linear);
* ``--real``: ``bench --real --full``'s crops of the training panoramas (``--heldout``: sunrise), crops with
  sky, self-relighting on the estimated track with the crop's level given, as ``bench --real`` (d): PSNR and
  l1 of ``proposed`` and ``quotient`` on the true foreground.

Each source photo is decomposed once; the decomposition does not depend on beta.

    .venv/bin/python docs/experiments/scripts/39_level_prior_probe.py data/val5 -o docs/experiments/results/39_level_val5.json
    .venv/bin/python docs/experiments/scripts/39_level_prior_probe.py --real -o docs/experiments/results/39_level_real_training.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from learned import Relighter  # noqa: E402
from physrelight import colour, io  # noqa: E402
from physrelight.stats import paired_bootstrap  # noqa: E402

GRID = (0.0, 0.25, 0.5, 0.75, 1.0)
METHODS = ("proposed", "quotient")
_LUM = torch.tensor(colour.LUMINANCE)


def _level(relit: torch.Tensor, target: torch.Tensor, fg: torch.Tensor) -> float:
    """log2 of the relit over the target foreground mean luminance (linear)."""
    lum = lambda x: (x[0] * _LUM[:, None, None]).sum(0)[fg[0, 0]].mean()  # noqa: E731
    return float(torch.log2(lum(relit).clamp_min(1e-9) / lum(target).clamp_min(1e-9)))


def synthetic(args: argparse.Namespace, r: Relighter, grid: tuple[float, ...]) -> dict:
    from validation.bench.data import load_dataset
    from validation.bench.protocols import cross_pairs
    from validation.bench.scores import score

    views = load_dataset(args.data, with_physical=False)
    first = sorted({v.name for v in views if v.view == 0})
    sets = {"as_rendered": cross_pairs(views),
            "dark": cross_pairs(views, ("dark",), first), "noise_jpeg": cross_pairs(views, ("noise_jpeg",), first)}
    out: dict = {"data": args.data, "pairs": {k: len(v) for k, v in sets.items()}, "settings": {}, "minus_0": {}}
    groups = {k: np.asarray([p.view.scene for p in v]) for k, v in sets.items()}
    rows: dict[float, dict] = {b: {} for b in grid}
    for name, pairs in sets.items():
        work: dict[tuple, dict] = {}
        preds = {(b, m): [] for b in grid for m in METHODS}
        levels = {(b, m): [] for b in grid for m in METHODS}
        T, M = [], []
        with torch.no_grad():
            for p in pairs:
                image = p.image()
                key = (p.view.name, p.source, p.variant)
                kw = dict(source_lighting=p.source_lighting(), working_res=min(image.shape[-2:]),
                          target_sun=p.sun_lighting(p.target), source_sun=p.sun_lighting(p.source))
                fg, tgt, tgt_lin = p.foreground(), p.target_display(), p.target_linear()
                for b in grid:
                    r.level_prior = b
                    for m in METHODS:
                        res = r.relight_full_resolution(image, p.sky(), p.target_lighting(), method=m,
                                                        decomposition=work.get(key), **kw)
                        work.setdefault(key, {k: res["working"][k] for k in
                                              ("albedo", "normals", "shadow", "lighting", "foreground")})
                        preds[(b, m)].append(torch.where(fg, p.display(res["relit"]), tgt))
                        levels[(b, m)].append(_level(res["relit"] * 2.0 ** p.eval_stops, tgt_lin, fg))
                T.append(tgt)
                M.append(fg)
                p.release()
        for (b, m), pr in preds.items():
            l1 = score(pr, T, M, which=("l1",))["l1"]
            lv = np.asarray(levels[(b, m)])
            rows[b][f"{m}:{name}"] = float(np.mean(l1))
            rows[b][f"{m}:{name}:level_mean"] = float(lv.mean())
            rows[b][f"{m}:{name}:level_sd"] = float(lv.std())
            rows[b][f"{m}:{name}:per_pair"] = [round(float(x), 5) for x in l1]
        print(f"{name} done ({time.time() - T0:.0f} s)", flush=True)
    for b in grid:
        out["settings"][str(b)] = rows[b]
        print(f"beta {b}: " + "  ".join(f"{k} {v:.4f}" for k, v in rows[b].items() if not k.endswith("per_pair")),
              flush=True)
    if 0.0 in rows:
        for b in grid:
            if b != 0.0:
                out["minus_0"][str(b)] = {
                    f"{m}:{name}": paired_bootstrap(rows[b][f"{m}:{name}:per_pair"], rows[0.0][f"{m}:{name}:per_pair"],
                                                    groups=groups[name], seed=0)._asdict()
                    for m in METHODS for name in sets}
    return out


def real(args: argparse.Namespace, r: Relighter, grid: tuple[float, ...]) -> dict:
    from real_crop_scores import bench_crops, crop_panoramas

    from validation.bench.methods import to_chw
    from validation.bench.scores import score

    group, panos = crop_panoramas(args.heldout)
    per = {(b, m): {"psnr": [], "l1": []} for b in grid for m in METHODS}
    names = []
    with torch.no_grad():
        for pano, crop in bench_crops(panos):
            if crop.stratum == "no_sky" or crop.sky.all():
                continue
            lin = crop.linear()
            fg = ~torch.from_numpy(crop.sky)[None, None]
            seg, _ = r.photo_sky(lin)
            source = torch.from_numpy(crop.lighting_sh(2) * crop.gain[None, :]).float()
            photo = to_chw(crop.display())
            dec = None
            for b in grid:
                r.level_prior = b
                for m in METHODS:
                    res = r.relight_full_resolution(lin, seg, source, source_lighting=source, method=m, decomposition=dec)
                    if dec is None:
                        dec = {k: res["working"][k] for k in ("albedo", "normals", "shadow", "lighting", "foreground")}
                    pred = torch.where(fg, colour.to_ldr(res["relit"].clamp_min(0)), photo)
                    s = score([pred], [photo], [fg], which=("l1", "psnr"))
                    per[(b, m)]["psnr"].append(min(float(s["psnr"][0]), 58.9))
                    per[(b, m)]["l1"].append(float(s["l1"][0]))
            names.append(f"{pano.name}_{crop.index}")
    out: dict = {"group": group, "crops": names, "settings": {}}
    for b in grid:
        row = {}
        for m in METHODS:
            row[f"{m}:psnr"] = float(np.mean(per[(b, m)]["psnr"]))
            row[f"{m}:l1"] = float(np.mean(per[(b, m)]["l1"]))
            row[f"{m}:per_crop_psnr"] = [round(x, 3) for x in per[(b, m)]["psnr"]]
        out["settings"][str(b)] = row
        print(f"beta {b}: " + "  ".join(f"{k} {v:.4f}" for k, v in row.items() if not k.startswith(tuple(
            f"{m}:per" for m in METHODS))), flush=True)
    return out


T0 = time.time()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("data", nargs="?")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--real", action="store_true", help="bench --real's crops instead of a synth folder")
    ap.add_argument("--heldout", action="store_true", help="with --real: sunrise (read once, after the choice)")
    ap.add_argument("--only", type=float, action="append", default=[], help="betas (default: the grid)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    r = Relighter.load()
    grid = tuple(args.only) or GRID
    out = real(args, r, grid) if args.real else synthetic(args, r, grid)
    out["seconds"] = round(time.time() - T0, 1)
    io.write_json(args.out, out)
    print(json.dumps({k: v for k, v in out.items() if k in ("seconds", "pairs")}))


if __name__ == "__main__":
    main()
