"""Study 37, after the adoption on synthetic data: what the denoise does to real photos.

For every ``bench --real --full`` crop of the training panoramas (seed 0, 16 each; the held-out sunrise is not
read), the noise level ``physrelight.denoise.noise_sigma`` reads off the 8-bit photo (mean over channels) against
the noise the photo model drew, and the l1 (display values) of the photo and of the denoised photo
(``DENOISE``) to the noise-free view (the crop's radiance, exposed and white-balanced like the photo, sRGB).
Writes a JSON and a PNG of the three crops the denoise changes most (photo left, denoised right, 3x).

    .venv/bin/python docs/experiments/scripts/37_denoise_real_crops.py -o docs/experiments/results/37_denoise_real_crops.json
    .venv/bin/python docs/experiments/scripts/37_denoise_real_crops.py --setting R:K:16 -o docs/experiments/results/37_denoise_real_crops_round2.json
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from learned.relight_options import DENOISE
from physrelight import colour, io
from physrelight.denoise import denoise, noise_sigma
from real_crop_scores import bench_crops, crop_panoramas


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--setting", default=None, help="RADIUS:STRENGTH:BLOCK (BLOCK 0: the whole photo); default: "
                                                    "round 1's, DENOISE with the whole-photo estimate")
    args = ap.parse_args()
    if args.setting is None:
        setting = (*DENOISE[:2], None)
    else:
        rad, k, blk = args.setting.split(":")
        setting = (int(rad), float(k), int(blk) or None)
    torch.set_num_threads(2)
    _, panos = crop_panoramas(False)
    rows, shown = [], []
    for _, c in bench_crops(panos):
        lin = c.linear()
        dn = colour.to_ldr(denoise(lin, *setting))[0].permute(1, 2, 0).numpy()
        photo = c.display()
        clean = colour.to_ldr(torch.from_numpy(c.radiance * c.gain.astype(np.float32)).permute(2, 0, 1)[None])
        clean = clean[0].permute(1, 2, 0).numpy()
        change = float(np.abs(dn - photo).mean())
        rows.append({"crop": c.name, "sigma_read": float(noise_sigma(lin, setting[2]).mean()),
                     "sigma_drawn": c.params.noise_sigma,
                     "l1_photo_to_clean": float(np.abs(photo - clean).mean()),
                     "l1_denoised_to_clean": float(np.abs(dn - clean).mean()), "l1_change": change})
        shown.append((change, photo, dn))
    summary = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k != "crop"}
    io.write_json(args.out, {"denoise": list(setting), "crops": rows, "mean": summary})
    print({k: round(v, 4) for k, v in summary.items()})
    shown.sort(key=lambda t: -t[0])
    strips = [np.concatenate([p, d], 1) for _, p, d in shown[:3]]
    w = max(s.shape[1] for s in strips)
    strips = [np.pad(s, ((0, 4), (0, w - s.shape[1]), (0, 0))) for s in strips]
    big = np.kron(np.concatenate(strips, 0), np.ones((3, 3, 1)))
    Image.fromarray((np.clip(big, 0, 1) * 255).round().astype(np.uint8)).save(Path(args.out).with_suffix(".png"))


if __name__ == "__main__":
    main()
