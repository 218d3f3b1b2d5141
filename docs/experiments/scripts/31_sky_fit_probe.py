"""Study 31 probe: the sky fitted to a target's SH (physrelight.sky_model.fit_sky) against SkyGAN, as bench --real (c).

Each crop with sky of bench --real --full (seed 0) is relit to its targets_for panoramas other than sunrise,
with the quotient foreground, the segmenter's mask and relight's estimated pitch; the relit sky's PSNR and l1
in sRGB over the true sky against the target through the true camera. Selection uses the training crops only;
--heldout scores sunrise's crops (relit to the training panoramas) instead, once, for the chosen setting.

    .venv/bin/python docs/experiments/scripts/31_sky_fit_probe.py -o docs/experiments/results/31_sky_fit_training.json
    .venv/bin/python docs/experiments/scripts/31_sky_fit_probe.py --heldout --exponent 8 -o ...
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from learned import Relighter
from physrelight.horizon import estimate_pitch
from physrelight.sky_view import fitted_sky
from learned.sky_gan import smooth_sky
from physrelight import colour, metrics, panorama, sh
from synth.panorama_crops import make_crops, shipped_panoramas
from validation.bench.real_metrics import dc_luminance, targets_for

EXPONENTS = (32.0, 16.0, 8.0, 4.0, 2.0)


def _display(x: torch.Tensor) -> torch.Tensor:
    return colour.to_ldr(x.clamp_min(0.0))


def at_level(sky: torch.Tensor, reference: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """``sky (1, 3, H, W)`` scaled per channel so its mean over ``mask`` is ``reference``'s there."""
    m = mask.expand_as(sky)
    a = (sky * m).sum((2, 3)) / m.sum((2, 3)).clamp_min(1)
    b = (reference * m).sum((2, 3)) / m.sum((2, 3)).clamp_min(1)
    return sky * (b / a.clamp_min(1e-12))[..., None, None]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="score sunrise's crops instead of the training side")
    ap.add_argument("--exponent", action="append", type=float, default=[], help="glow exponents (default: the grid)")
    ap.add_argument("--round3", action="store_true", help="round 3: fit2 at SkyGAN's level, and SkyGAN smoothed")
    args = ap.parse_args()
    torch.set_num_threads(2)
    r = Relighter.load()
    panos = shipped_panoramas()
    group = "heldout" if args.heldout else "training"
    exps = args.exponent or list(EXPONENTS)
    sources = ["skygan"] + ([f"fit{e:g}" for e in exps] if not args.round3 else ["fit_gan_level", "gan_smooth"])
    rows: dict[str, dict[str, list[float]]] = {s: {"psnr": [], "l1": []} for s in sources}
    pairs = []
    t0 = time.time()
    for pano in [p for p in panos if p.group == group]:
        for crop in make_crops(pano, 16, 0, fov_range=(45.0, 75.0), samples=4):
            if crop.stratum == "no_sky":
                continue
            h, w = crop.size
            lin = crop.linear()
            true_sky = torch.from_numpy(crop.sky)[None, None]
            seg, _ = r.photo_sky(lin)
            estimated = panorama.level_camera(crop.yaw_deg, estimate_pitch(seg[0, 0], crop.K))
            source = crop.lighting_sh(2) * crop.gain[None, :]
            dec = None
            for tgt in targets_for(pano, panos, 3, crop.index):
                if tgt.group == "heldout":
                    continue  # the held-out panorama chooses nothing, not even as a target
                L_t = np.asarray(sh.rotate(tgt.sh(2), crop.rotation))
                k = dc_luminance(source) / dc_luminance(L_t)
                res = r.relight_full_resolution(lin, seg, torch.from_numpy(L_t * k).float(),
                                                source_lighting=torch.from_numpy(source).float(), method="quotient",
                                                decomposition=dec)
                dec = {q: res["working"][q] for q in ("albedo", "normals", "shadow", "lighting", "foreground")}
                relit = res["relit"]
                truth = _display(torch.from_numpy(crop.view_of(tgt.env) * k).permute(2, 0, 1)[None].float())
                skies = {"skygan": r.paint_sky(relit, seg, res["working"], res["working_sky"], seed=0)}
                if args.round3:
                    fit = fitted_sky(tgt.sh(2) * k, crop.K, estimated, h, w, glow_exponent=2.0).permute(2, 0, 1)[None]
                    skies["fit_gan_level"] = torch.where(seg, at_level(fit, skies["skygan"], seg), relit)
                    skies["gan_smooth"] = torch.where(seg, smooth_sky(skies["skygan"], seg), relit)
                for e in ([] if args.round3 else exps):
                    fit = fitted_sky(tgt.sh(2) * k, crop.K, estimated, h, w, glow_exponent=e)
                    skies[f"fit{e:g}"] = torch.where(seg, fit.permute(2, 0, 1)[None], relit)
                for s_, img in skies.items():
                    rows[s_]["psnr"].append(min(float(metrics.psnr(_display(img), truth, true_sky)), 58.9))
                    rows[s_]["l1"].append(float(metrics.l1(_display(img), truth, true_sky)))
                pairs.append([pano.name, crop.index, tgt.name])
        print(f"{pano.name}: {time.time() - t0:.0f} s", flush=True)
    out = {"group": group, "pairs": pairs, "sources": {}}
    for s_, v in rows.items():
        out["sources"][s_] = {"psnr": float(np.mean(v["psnr"])), "l1": float(np.mean(v["l1"])), "n": len(v["psnr"]),
                              "per_pair_psnr": v["psnr"], "per_pair_l1": v["l1"]}
        print(f"{s_:>8}: PSNR {np.mean(v['psnr']):.3f} dB  l1 {np.mean(v['l1']):.4f}  ({len(v['psnr'])} pairs)")
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
