"""Study 51 (measurement): how close must the source lighting be for real self-relighting to reach 30 dB?

For each ``bench --real --full`` crop with sky (seed 0, 16 per panorama), the source lighting handed to the
quotient is moved from the decomposition's estimate (its DC luminance set to the truth's, as the estimated track
has it) to the truth (the crop's camera-frame order-2 SH in the photo's units): ``L(a) = (1 - a) L_est + a L_true``.
Each is scored as ``bench --real`` (b) and (d) score it: the scale-invariant shading error on 256 sphere normals
against the panorama's exact irradiance, and the self-relighting PSNR of ``quotient`` on the known-source path
(relit = photo x S(n; L_true) / S(n; L(a)), the decomposition's normals) over the true foreground at full size.

    .venv/bin/python docs/experiments/scripts/51_self_relighting_vs_lighting_error.py [--heldout] -o OUT.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
import torch

sys.path.insert(0, "docs/experiments/scripts")
from real_crop_scores import bench_crops, crop_panoramas  # noqa: E402

from learned import Relighter  # noqa: E402
from physrelight import colour, envmap, metrics, sh  # noqa: E402
from validation.bench.real_metrics import PSNR_CAP, dc_luminance, shading_error  # noqa: E402

ALPHAS = (0.0, 0.25, 0.5, 0.75, 0.9, 0.95, 1.0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--heldout", action="store_true")
    ap.add_argument("-o", "--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(2)
    relighter = Relighter.load()
    group, panos = crop_panoramas(args.heldout)
    normals = sh.fibonacci_sphere(256)
    truths = {p.name: np.asarray(envmap.irradiance_reference(p.env.astype(np.float64), normals)) for p in panos}
    rows = []
    t0 = time.time()
    for pano, c in bench_crops(panos):
        if c.sky.mean() < 0.01:
            continue
        lin = c.linear()
        seg, _ = relighter.photo_sky(lin)
        g = c.gain
        L_true = c.lighting_sh(2) * g[None, :]
        src = torch.from_numpy(L_true).float()
        full = relighter.relight_full_resolution(lin, seg, src, source_lighting=src, method="quotient")
        dec = {k: full["working"][k] for k in ("albedo", "normals", "shadow", "lighting", "foreground")}
        L_est = full["working"]["lighting"][0].double().numpy()
        L_est = L_est * dc_luminance(L_true) / dc_luminance(L_est)
        fg = ~torch.from_numpy(c.sky)[None, None]
        photo = colour.to_ldr(lin.clamp_min(0))
        cam_normals = normals @ c.rotation.T
        truth = truths[pano.name] * g[None, :]
        row = {"crop": f"{pano.name}_{c.index}", "alpha": [], "shading_error": [], "psnr": []}
        for a in ALPHAS:
            L = (1 - a) * L_est + a * L_true
            relit = relighter.relight_full_resolution(lin, seg, src, source_lighting=torch.from_numpy(L).float(),
                                                      method="quotient", decomposition=dec, known_source=True)["relit"]
            out = colour.to_ldr(torch.where(fg, relit, lin).clamp_min(0))
            row["alpha"].append(a)
            row["shading_error"].append(shading_error(np.asarray(sh.irradiance(L, cam_normals)), truth))
            row["psnr"].append(min(float(metrics.psnr(out, photo, fg)), PSNR_CAP))
        rows.append(row)
        print(row["crop"], " ".join(f"a={a:.2f}: err {e:.3f} {p:5.2f} dB" for a, e, p in
                                    zip(row["alpha"], row["shading_error"], row["psnr"])), flush=True)
    err = np.array([r["shading_error"] for r in rows])
    psnr = np.array([r["psnr"] for r in rows])
    summary = {"group": group, "n": len(rows), "alphas": list(ALPHAS), "seconds": time.time() - t0,
               "mean_shading_error": err.mean(0).tolist(), "mean_psnr": psnr.mean(0).tolist(),
               "median_psnr": np.median(psnr, 0).tolist(), "share_at_30dB": (psnr >= 30).mean(0).tolist()}
    for a, e, p, m, s in zip(ALPHAS, summary["mean_shading_error"], summary["mean_psnr"], summary["median_psnr"],
                             summary["share_at_30dB"]):
        print(f"alpha {a:.2f}: shading error {e:.3f}, PSNR mean {p:.2f} median {m:.2f} dB, share >= 30 dB {s:.2f}")
    with open(args.out, "w") as f:
        json.dump({"summary": summary, "crops": rows}, f, indent=1)


if __name__ == "__main__":
    main()
