"""Study 52: segmenters compared through the shipped full-resolution sky mask.

    .venv/bin/python docs/experiments/scripts/52_clouds_probe.py NAME=WEIGHTS [NAME=WEIGHTS ...] -o OUT.json [--heldout]

For each segmenter: the training panoramas' ``bench --real --full`` crops (IoU / boundary F over the crops
with sky, the fraction called sky on those without; with ``--heldout`` the sunrise crops instead), the indoor
studio's crops (fraction called sky), ``data/val5``'s synthetic IoU at 64 px, scikit-image's indoor photos
(refused or not) and rocket.jpg (the share of its cloud band, rows 360-399, called sky; the mask written as
PNG beside OUT).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_crop_scores import bench_crops, crop_panoramas, score_sky_masks, setting_summary  # noqa: E402


def main() -> None:
    from PIL import Image
    import skimage.data

    from learned.sky_segmentation import load_sky_segmenter, sky_mask_full_resolution
    from learned.train_sky import evaluate_segmentation
    from physrelight import colour, io
    from synth.panorama_crops import shipped_panoramas

    ap = argparse.ArgumentParser()
    ap.add_argument("weights", nargs="+", help="NAME=PATH")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="the sunrise crops (read once, after the rule's choice)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    models = {}
    for item in args.weights:
        name, path = item.split("=", 1)
        models[name] = load_sky_segmenter(path)
    names = list(models)

    def masks_of(lin: torch.Tensor) -> dict[str, tuple[torch.Tensor, str]]:
        out = {}
        for n, m in models.items():
            sky, why = sky_mask_full_resolution(m, lin)
            out[n] = (sky, why[0])
        return out

    t0 = time.time()
    group, panos = crop_panoramas(args.heldout)
    rows = score_sky_masks(panos, names, masks_of)
    result: dict = {"group": group, "crops": {n: {**setting_summary(rows[n]), "iou_per_crop": rows[n]["iou"],
                                                  "f_per_crop": rows[n]["f"]} for n in names}}
    if not args.heldout:
        studio = [p for p in shipped_panoramas() if p.group == "indoor"]
        called = {n: [] for n in names}
        for _, c in bench_crops(studio):
            for n, (sky, _) in masks_of(c.linear()).items():
                called[n].append(float(sky.float().mean()))
        result["studio_called_sky"] = {n: float(np.mean(v)) for n, v in called.items()}
        result["val5_iou"] = {n: evaluate_segmentation(m, "data/val5", "all", 64)["network"]["iou_mean"]
                              for n, m in models.items()}
        photos = {"astronaut": skimage.data.astronaut(), "coffee": skimage.data.coffee(),
                  "chelsea": skimage.data.chelsea(), "motorcycle": skimage.data.stereo_motorcycle()[0],
                  "rocket": skimage.data.rocket()}
        result["photos"] = {}
        for pname, img in photos.items():
            lin = colour.from_ldr(torch.from_numpy(img).permute(2, 0, 1).float()[None] / 255.0)
            for n, (sky, why) in masks_of(lin).items():
                m = sky[0, 0].numpy()
                entry = {"sky_fraction": float(m.mean()), "refused": why}
                if pname == "rocket":
                    entry["cloud_band_sky"] = float(m[360:400].mean())
                    Image.fromarray((m * 255).astype(np.uint8)).save(Path(args.out).with_name(f"52_rocket_{n}.png"))
                result["photos"].setdefault(pname, {})[n] = entry
    result["seconds"] = time.time() - t0
    io.write_json(args.out, result)
    for n in names:
        c = result["crops"][n]
        print(f"{n}: IoU {c['iou']:.4f} F {c['boundary_f']:.4f} no-sky called {c['no_sky_called']} "
              f"refused {c['refused_with_sky']}/{c['crops_with_sky']}")
    for k in ("studio_called_sky", "val5_iou"):
        if k in result:
            print(k, {n: round(v, 4) for n, v in result[k].items()})
    for pname, per in result.get("photos", {}).items():
        print(pname, {n: (round(e["sky_fraction"], 3), e.get("cloud_band_sky"), bool(e["refused"])) for n, e in per.items()})


if __name__ == "__main__":
    main()
