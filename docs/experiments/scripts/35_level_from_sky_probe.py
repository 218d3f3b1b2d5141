"""Study 35 probe: the source lighting's level from the photo's own sky pixels, on bench --real's crops
(training panoramas; --heldout: sunrise, read once after the choice).

    .venv/bin/python docs/experiments/scripts/35_level_from_sky_probe.py -o docs/experiments/results/35_level_training.json
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from learned import Relighter
from physrelight.full_resolution import working_resolution
from physrelight.horizon import estimate_pitch
from learned.source_lighting import camera_directions, sky_observations
from physrelight import colour, panorama, sh
from physrelight.sky_model import fit_sky, sky_view
from real_crop_scores import bench_crops, crop_panoramas
from validation.bench.real_metrics import level_stops

CANDIDATES = ("decomposition", "sh", "fit")
MIN_SKY_PIXELS = 16
LUM = np.asarray(colour.LUMINANCE, dtype=np.float64)


def sky_gains(L: np.ndarray, lin: torch.Tensor, seg: torch.Tensor, K: np.ndarray, pitch: float) -> dict[str, float]:
    """``g`` of each candidate for one crop: the median of photo / model luminance over the usable sky pixels."""
    d_cam, r = sky_observations(lin[0], seg[0], torch.as_tensor(K))
    if d_cam.shape[0] < MIN_SKY_PIXELS:
        return {c: 1.0 for c in CANDIDATES}
    photo = r.numpy() @ LUM
    model_sh = np.clip(np.asarray(sh.basis(d_cam, 2)) @ L, 0, None) @ LUM
    R = panorama.level_camera(0.0, pitch)[:3, :3]  # world -> camera
    fit = fit_sky(np.asarray(sh.rotate(L, R.T)))
    world = d_cam.numpy() @ R  # d_w = R^T d_c
    model_fit = sky_view(fit, torch.from_numpy(world)[:, None, None, :])[:, 0].numpy() @ LUM
    out = {"decomposition": 1.0}
    for name, m in (("sh", model_sh), ("fit", model_fit)):
        ok = m > 1e-9
        out[name] = float(np.median(photo[ok] / m[ok])) if ok.sum() >= MIN_SKY_PIXELS else 1.0
    return out


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
        if not c.sky.any():
            continue
        lin = c.linear()
        seg, why = r.photo_sky(lin)
        source = c.lighting_sh(2) * c.gain[None, :]
        small, small_sky = working_resolution(lin, seg, r.res)  # what relight decomposes
        dec = r.decompose_linear(small, small_sky)
        L = dec["lighting"][0].double().numpy()
        pitch = estimate_pitch(seg[0, 0], c.K)
        gains = sky_gains(L, lin, seg, c.K, pitch) if not why else {k: 1.0 for k in CANDIDATES}
        row = {"panorama": pano.name, "index": c.index, "no_sky_reason": why, "gains": gains,
               "level_stops": {k: level_stops(L * g, source) for k, g in gains.items()}}
        row["level_stops"]["prior_mean"] = level_stops(np.asarray(r.prior.mean, dtype=np.float64).reshape(9, 3), source)
        rows.append(row)
        print(pano.name, c.index, {k: round(v, 2) for k, v in row["level_stops"].items()}, flush=True)
    summary = {}
    for k in (*CANDIDATES, "prior_mean"):
        a = np.array([row["level_stops"][k] for row in rows])
        summary[k] = {"abs": float(np.abs(a).mean()), "signed": float(a.mean()), "n": int(a.size)}
        print(f"{k:>14}: mean |level| {np.abs(a).mean():.3f} stops, signed {a.mean():+.3f} ({a.size} crops)")
    with open(args.out, "w") as f:
        json.dump({"group": group, "summary": summary, "crops": rows, "seconds": time.perf_counter() - t0}, f, indent=1)


if __name__ == "__main__":
    main()
