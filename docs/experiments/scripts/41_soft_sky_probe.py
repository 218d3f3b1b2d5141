"""Study 41 probe: a soft sky edge for thin dark structures, scored as alpha (sky fraction) against the truth.

Candidate ``sky_alpha(sky, image, d)``: 1 on relight's mask; on the non-sky pixels within ``d`` px of it whose
chromaticity fits the smooth sky model (``learned.sky_segmentation.sky_colour_model``; brightness free, chi-square
2 dof at 0.99), ``clamp(lum(p) / lum(model(p)), 0, 1)``; 0 elsewhere. Truth: the panorama's sky coverage over each
crop pixel's sub-pixel rays (times one minus study 40's structures' coverage on the lattice set). Score: mean
absolute alpha error per sample, the hard mask (relight's, shipped) against each ``d``.

    .venv/bin/python docs/experiments/scripts/41_soft_sky_probe.py -o docs/experiments/results/41_soft_sky_training.json
    .venv/bin/python docs/experiments/scripts/41_soft_sky_probe.py --heldout --only 0 --only D -o docs/experiments/results/41_soft_sky_sunrise.json
"""
from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_crop_scores import bench_crops, crop_panoramas  # noqa: E402

from learned import Relighter  # noqa: E402
from learned import sky_segmentation as ss  # noqa: E402
from physrelight import colour, io, panorama  # noqa: E402
from physrelight.stats import paired_bootstrap  # noqa: E402

lattice = importlib.import_module("40_lattice_sky_probe")
GRID = (0, 1, 2, 3)
CHROMA_CHI2 = 9.21
_LUM = torch.tensor(colour.LUMINANCE, dtype=torch.float64)


def sky_alpha(sky: torch.Tensor, image: torch.Tensor, d: int) -> torch.Tensor:
    """``(H, W)`` float64 sky fraction: the candidate (``d`` = 0: the hard mask)."""
    alpha = sky[0, 0].to(torch.float64)
    if d == 0:
        return alpha
    model = ss.sky_colour_model(sky, image)
    if model is None:
        return alpha
    x, pred, sigma = model
    if float(sigma.max()) > ss.GROW_MAX_SPREAD:
        return alpha
    zone = (ss._dilate(sky, d) & ~sky)[0, 0]
    dev = x - pred
    chroma = dev - dev.mean(0, keepdim=True)
    fits = ((chroma / sigma[:, None, None]) ** 2).sum(0) < CHROMA_CHI2
    s_model = torch.exp(pred)
    lum = lambda v: torch.einsum("chw,c->hw", v, _LUM)  # noqa: E731
    t = (lum(image[0].to(torch.float64).clamp_min(0)) / lum(s_model)).clamp(0, 1)
    return torch.where(zone & fits, t, alpha)


def sky_coverage(crop) -> np.ndarray:
    """``(h, w)`` the panorama's sky coverage over the crop's sub-pixel rays."""
    m = torch.from_numpy(crop.panorama.sky.astype(np.float32))[..., None]
    return panorama.look_up(m, crop.rays)[..., 0].numpy().astype(np.float64)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="sunrise's own crops (read once, after the choice)")
    ap.add_argument("--only", type=int, action="append", default=[])
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = Relighter.load().sky_segmenter
    grid = tuple(args.only) or GRID
    group, panos = crop_panoramas(args.heldout)
    sets = {"plain": {}, "lattice": {}} if not args.heldout else {"plain": {}}
    t0 = time.time()
    for pano, crop in bench_crops(panos):
        if crop.sky.mean() < 0.01:
            continue
        cov = sky_coverage(crop)
        samples = [("plain", f"{pano.name}_{crop.index}", crop.linear(), cov)]
        if "lattice" in sets and crop.sky.mean() >= 0.10:
            for s in (0, 1):
                lin, _, a = lattice.composite(crop, s)
                samples.append(("lattice", f"{pano.name}_{crop.index}_{s}", lin, cov * (1 - a)))
        for which, name, lin, truth in samples:
            sky, _ = ss.sky_mask_full_resolution(model, lin)
            sets[which][name] = {d: float(np.abs(sky_alpha(sky, lin, d).numpy() - truth).mean()) for d in grid}
    out: dict = {"group": group, "seconds": round(time.time() - t0, 1), "sets": {}}
    for which, rows in sets.items():
        names = sorted(rows)
        crop_of = np.asarray(["_".join(n.split("_")[:2]) for n in names])
        res = {"samples": len(names)}
        for d in grid:
            err = np.asarray([rows[n][d] for n in names])
            res[str(d)] = {"mean_abs_alpha_error": float(err.mean()), "per_sample": [round(float(e), 6) for e in err]}
            if d != 0 and 0 in grid:
                diff = paired_bootstrap(err, [rows[n][0] for n in names], groups=crop_of, seed=0)
                res[str(d)]["minus_hard"] = diff._asdict()
                res[str(d)]["relative"] = float(diff.diff / np.mean([rows[n][0] for n in names]))
        out["sets"][which] = res
        for d in grid:
            r = res[str(d)]
            extra = (f"  minus hard {r['minus_hard']['diff']:+.5f} [{r['minus_hard']['lo']:+.5f}, "
                     f"{r['minus_hard']['hi']:+.5f}] ({100 * r['relative']:+.1f} %)") if "minus_hard" in r else ""
            print(f"{which:>8} d={d}: {r['mean_abs_alpha_error']:.5f}{extra}", flush=True)
    io.write_json(args.out, out)


if __name__ == "__main__":
    main()
