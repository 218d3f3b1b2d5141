"""Study 36 probe: the source lighting's level from the photo's key (grey world, median foreground albedo 0.18),
on bench --real's crops (training panoramas; --heldout: sunrise, read once after the choice).

    .venv/bin/python docs/experiments/scripts/36_level_grey_world_probe.py -o docs/experiments/results/36_level_training.json
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from learned import Relighter
from physrelight.full_resolution import working_resolution
from physrelight import colour, image_model
from real_crop_scores import bench_crops, crop_panoramas
from validation.bench.real_metrics import level_stops

GREY = 0.18  # a light meter's middle grey, fixed before the run
LUM = torch.tensor(colour.LUMINANCE, dtype=torch.float64)


def grey_world_gain(small: torch.Tensor, fg: torch.Tensor, normals: torch.Tensor, L: torch.Tensor) -> float:
    """``g`` such that the foreground's median implied albedo under ``g L`` is :data:`GREY`."""
    s = image_model.shading(normals[None].double(), L[None].double())[0]  # (3, h, w)
    s_lum = torch.einsum("chw,c->hw", s, LUM)
    p_lum = torch.einsum("chw,c->hw", small[0].double(), LUM)
    ok = fg & (s_lum > 1e-6 * s_lum[fg].mean().clamp_min(1e-12))
    if int(ok.sum()) < 16:
        return 1.0
    return float(torch.median(p_lum[ok] / s_lum[ok])) / GREY


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(2)
    t0 = time.perf_counter()
    r = Relighter.load()
    group, panos = crop_panoramas(args.heldout)
    rows = []
    for pano, c in bench_crops(panos):
        lin = c.linear()
        seg, why = r.photo_sky(lin)
        source = c.lighting_sh(2) * c.gain[None, :]
        small, small_sky = working_resolution(lin, seg, r.res)  # what relight decomposes
        dec = r.decompose_linear(small, small_sky)
        L = dec["lighting"][0].double()
        g = grey_world_gain(small, ~small_sky[0, 0], dec["normals"][0], L)
        Ln = L.numpy()
        row = {"panorama": pano.name, "index": c.index, "true_sky": bool(c.sky.any()), "gain": g,
               "level_stops": {"decomposition": level_stops(Ln, source), "grey_world": level_stops(Ln * g, source),
                               "prior_mean": level_stops(np.asarray(r.prior.mean, dtype=np.float64).reshape(9, 3),
                                                         source)}}
        rows.append(row)
        print(pano.name, c.index, row["true_sky"], {k: round(v, 2) for k, v in row["level_stops"].items()}, flush=True)
    summary = {}
    for part, keep in (("with_sky", True), ("without_sky", False)):
        sel = [row for row in rows if row["true_sky"] == keep]
        summary[part] = {}
        for k in ("decomposition", "grey_world", "prior_mean"):
            a = np.array([row["level_stops"][k] for row in sel])
            if a.size:
                summary[part][k] = {"abs": float(np.abs(a).mean()), "signed": float(a.mean()), "n": int(a.size)}
                print(f"{part:>11} {k:>14}: mean |level| {np.abs(a).mean():.3f} stops, signed {a.mean():+.3f} ({a.size} crops)")
    with open(args.out, "w") as f:
        json.dump({"group": group, "grey": GREY, "summary": summary, "crops": rows,
                   "seconds": time.perf_counter() - t0}, f, indent=1)


if __name__ == "__main__":
    main()
