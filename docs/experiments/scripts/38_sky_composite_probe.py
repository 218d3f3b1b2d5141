"""Study 38 probe: the new sky composited with the boundary's mixed pixels un-mixed (physrelight.sky_composite).

Ground truth: for a crop of panorama A and another panorama B (scaled to A's DC luminance, as bench --real
scales targets), the panorama A' = A with its sky texels (A's reviewed sky mask) replaced by B's is seen
through the crop's own camera with the crop's 4 x 4 sub-pixel rays: a boundary pixel then mixes A's land and
B's sky as a camera would. The method gets the crop's 8-bit photo, a sky mask and B through the same camera
(the sky source "target" with the true camera, so only the compositing differs) and keeps the land as it is
(relit = photo): sky replacement alone. Scores in display values (sRGB of the photo's exposure): l1 over the
pixels within 2 px of the true boundary ("band"), and over the whole image.

    .venv/bin/python docs/experiments/scripts/38_sky_composite_probe.py -o docs/experiments/results/38_composite_training.json
    .venv/bin/python docs/experiments/scripts/38_sky_composite_probe.py --heldout --only 0 --only BAND -o ...
"""
from __future__ import annotations

import argparse
import importlib
import time

import numpy as np
import torch
import torch.nn.functional as F

from learned import Relighter
from learned import sky_segmentation as ss
from physrelight import colour, io
from physrelight.stats import paired_bootstrap
from real_crop_scores import bench_crops, crop_panoramas

# the candidate, kept beside this probe (study 38 did not adopt it into physrelight)
composite_sky = importlib.import_module("38_sky_composite").composite_sky
GRID = ("0", "1", "2", "3")


def _near(mask: np.ndarray, r: int) -> np.ndarray:
    m = torch.from_numpy(mask)[None, None].float()
    grow = F.max_pool2d(m, 2 * r + 1, stride=1, padding=r) > 0.5
    shrink = F.max_pool2d(1 - m, 2 * r + 1, stride=1, padding=r) > 0.5
    return (grow & shrink)[0, 0].numpy()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="sunrise's crops, composited with the training skies")
    ap.add_argument("--only", action="append", default=[], help="band widths (default: the grid)")
    args = ap.parse_args()
    torch.set_num_threads(2)
    t0 = time.time()
    grid = args.only or list(GRID)
    model = Relighter.load().sky_segmenter
    group, panos = crop_panoramas(args.heldout)
    _, skies = crop_panoramas(False)  # the new skies always come from the training panoramas
    lum = np.asarray(colour.LUMINANCE)
    rows = {f"{m}:{g}": {"band": [], "whole": []} for m in ("relight_mask", "true_mask") for g in grid}
    names = []
    for pano, c in bench_crops(panos):
        if c.sky.mean() < 0.01:
            continue
        lin = c.linear()
        masks = {"relight_mask": ss.sky_mask_full_resolution(model, lin)[0],
                 "true_mask": torch.from_numpy(c.sky)[None, None]}
        band_px = _near(c.sky, 2)
        gain = c.gain.astype(np.float32)
        for other in skies:
            if other.name == pano.name:
                continue
            s = float(pano.sh(2)[0] @ lum) / float(other.sh(2)[0] @ lum)
            comp = np.where(pano.sky[..., None], other.env * s, pano.env).astype(np.float32)
            truth = colour.to_ldr(torch.from_numpy(c.view_of(comp) * gain)).numpy()
            new_sky = torch.from_numpy(c.view_of(other.env * s) * gain).permute(2, 0, 1)[None]
            names.append(f"{c.name}<-{other.name}")
            for m, sky in masks.items():
                for g in grid:
                    out = composite_sky(lin, lin, sky, new_sky, int(g))
                    disp = colour.to_ldr(out.clamp_min(0))[0].permute(1, 2, 0).numpy()
                    err = np.abs(disp - truth).mean(-1)
                    rows[f"{m}:{g}"]["band"].append(float(err[band_px].mean()))
                    rows[f"{m}:{g}"]["whole"].append(float(err.mean()))
    groups = np.asarray([n.split("<-")[0] for n in names])  # the source crop: its pairs share its photo and mask
    out = {"group": group, "pairs": len(names), "pair_names": names, "settings": {}, "minus_hard": {}}
    for k, r in rows.items():
        out["settings"][k] = {"band_l1": float(np.mean(r["band"])), "whole_l1": float(np.mean(r["whole"])),
                              "band_per_pair": [round(v, 5) for v in r["band"]]}
        print(f"{k:>16}: band l1 {np.mean(r['band']):.4f}  whole l1 {np.mean(r['whole']):.5f}", flush=True)
    for m in ("relight_mask", "true_mask"):
        if "0" in grid:
            for g in grid:
                if g != "0":
                    out["minus_hard"][f"{m}:{g}"] = {
                        w: paired_bootstrap(rows[f"{m}:{g}"][w], rows[f"{m}:0"][w], groups=groups, seed=0)._asdict()
                        for w in ("band", "whole")}
    out["seconds"] = round(time.time() - t0, 1)
    io.write_json(args.out, out)
    print(f"{len(names)} pairs, {out['seconds']} s")


if __name__ == "__main__":
    main()
