"""Study 59: two sky segmenters compared, paired, with scene-bootstrap intervals.

    # the synthetic held-out set (64 px, every photo; IoU per photo, whole scenes resampled)
    .venv/bin/python docs/experiments/scripts/59_segmenter_compare.py synthetic --data data/heldout \
        shipped=learned/weights/sky_segmentation.safetensors new=runs/s59_real.safetensors -o OUT.json
    # two `bench --real` runs (the same level and seed), crop by crop: sunrise (crops resampled), the training
    # side (panoramas resampled), the rooms and studio (share called sky)
    .venv/bin/python docs/experiments/scripts/59_segmenter_compare.py real --before A/real.json --after B/real.json -o OUT.json
    # rocket.jpg through relight's full-resolution mask: one PNG per segmenter and a side-by-side panel
    .venv/bin/python docs/experiments/scripts/59_segmenter_compare.py rocket shipped=... new=... -o PANEL.png

Differences are ``after - before`` (``new - shipped``) with 95 % percentile-bootstrap intervals
(:func:`physrelight.stats.paired_bootstrap`, 2000 resamples, seed 0).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))


def _models(items: list[str]) -> dict[str, torch.nn.Module]:
    from learned.sky_segmentation import load_sky_segmenter

    out = {}
    for item in items:
        if "=" not in item:
            raise SystemExit(f"59_segmenter_compare: give NAME=WEIGHTS, got {item!r}")
        name, path = item.split("=", 1)
        out[name] = load_sky_segmenter(path)
    return out


def _diff(a: np.ndarray, b: np.ndarray, groups: np.ndarray) -> dict[str, float]:
    from physrelight.stats import paired_bootstrap

    d = paired_bootstrap(a, b, groups=groups, samples=2000, seed=0)
    return {"diff": d.diff, "lo": d.lo, "hi": d.hi, "groups": d.groups}


def synthetic(args: argparse.Namespace) -> dict:
    from learned.sky_segmentation import segment_sky
    from learned.train_sky import SkyData, _iou

    models = _models(args.weights)
    data = SkyData(args.data, "all", 64, lighting=False)
    scenes = np.asarray([s for s, _, _ in data.items])
    iou = {}
    for name, m in models.items():
        per = _iou(segment_sky(m.eval(), data.image), data.sky)
        iou[name] = np.nan_to_num(per, nan=1.0)  # a photo without sky, called without sky, is right
    names = list(models)
    out = {"data": args.data, "photos": len(data), "scenes": int(len(set(scenes))),
           "iou_mean": {n: float(v.mean()) for n, v in iou.items()}}
    if len(names) == 2:
        out["difference"] = {f"{names[1]} - {names[0]}": _diff(iou[names[1]], iou[names[0]], scenes)}
    return out


def real(args: argparse.Namespace) -> dict:
    before = json.loads(Path(args.before).read_text())
    after = json.loads(Path(args.after).read_text())
    key = lambda c: (c["panorama"], c["index"])  # noqa: E731
    a_by = {key(c): c for c in after["crops"]}
    if set(a_by) != {key(c) for c in before["crops"]}:
        raise SystemExit("59_segmenter_compare: the two runs did not score the same crops (level, seed, panoramas)")
    out: dict = {"before": args.before, "after": args.after, "level": before["level"]["name"]}
    for group in ("heldout", "training", "indoor"):
        cs = [c for c in before["crops"] if c["group"] == group]
        sky = [c for c in cs if c["stratum"] == "sky"]
        nosky = [c for c in cs if c["stratum"] == "no_sky"]
        # one panorama on the held-out side: its crops are the units; elsewhere whole panoramas
        unit = (lambda c: f"{c['panorama']}/{c['index']}") if group == "heldout" else (lambda c: c["panorama"])
        entry: dict = {"crops": len(cs), "sky_crops": len(sky), "no_sky_crops": len(nosky)}
        for metric, pool in (("iou", sky), ("boundary_f", sky), ("sky_called", nosky)):
            if not pool:
                continue
            b = np.asarray([c["segmentation"]["segmenter"][metric] for c in pool])
            a = np.asarray([a_by[key(c)]["segmentation"]["segmenter"][metric] for c in pool])
            g = np.asarray([unit(c) for c in pool])
            entry[metric] = {"before": float(b.mean()), "after": float(a.mean()), "after - before": _diff(a, b, g)}
        if sky:
            entry["declined_with_sky"] = {"before": int(sum(bool(c["no_sky_reason"]) for c in sky)),
                                          "after": int(sum(bool(a_by[key(c)]["no_sky_reason"]) for c in sky))}
        per_pano = {}
        for p in sorted({c["panorama"] for c in cs}):
            pc = [c for c in cs if c["panorama"] == p]
            ps = [c for c in pc if c["stratum"] == "sky"]
            row = {}
            if ps:
                row["iou"] = [float(np.mean([c["segmentation"]["segmenter"]["iou"] for c in ps])),
                              float(np.mean([a_by[key(c)]["segmentation"]["segmenter"]["iou"] for c in ps]))]
            pn = [c for c in pc if c["stratum"] == "no_sky"]
            if pn:
                row["sky_called"] = [float(np.mean([c["segmentation"]["segmenter"]["sky_called"] for c in pn])),
                                     float(np.mean([a_by[key(c)]["segmentation"]["segmenter"]["sky_called"]
                                                    for c in pn]))]
                row["crops_called_sky"] = [int(sum(c["segmentation"]["segmenter"]["sky_called"] > 0 for c in pn)),
                                           int(sum(a_by[key(c)]["segmentation"]["segmenter"]["sky_called"] > 0
                                                   for c in pn))]
            per_pano[p] = row
        entry["per_panorama (before, after)"] = per_pano
        out[group] = entry
    return out


def rocket(args: argparse.Namespace) -> dict:
    import skimage.data
    from PIL import Image

    from learned.sky_segmentation import sky_mask_full_resolution
    from physrelight import colour

    models = _models(args.weights)
    img = skimage.data.rocket()
    lin = colour.from_ldr(torch.from_numpy(img).permute(2, 0, 1).float()[None] / 255.0)
    tiles, out = [img], {}
    for name, m in models.items():
        sky, why = sky_mask_full_resolution(m, lin)
        mask = sky[0, 0].numpy()
        out[name] = {"sky_fraction": float(mask.mean()), "cloud_band_sky": float(mask[360:400].mean()),
                     "refused": why[0]}
        # the photo with its non-sky darkened: what relight keeps and what it repaints
        shown = img.astype(np.float32)
        shown[~mask] *= 0.35
        tiles.append(shown.astype(np.uint8))
    gap = np.full((img.shape[0], 8, 3), 255, np.uint8)
    panel = np.concatenate([t for tile in tiles for t in (tile, gap)][:-1], axis=1)
    Image.fromarray(panel).save(args.out)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    s = sub.add_parser("synthetic")
    s.add_argument("weights", nargs="+")
    s.add_argument("--data", default="data/heldout")
    s.add_argument("-o", "--out", required=True)
    r = sub.add_parser("real")
    r.add_argument("--before", required=True)
    r.add_argument("--after", required=True)
    r.add_argument("-o", "--out", required=True)
    k = sub.add_parser("rocket")
    k.add_argument("weights", nargs="+")
    k.add_argument("-o", "--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(1)
    result = {"synthetic": synthetic, "real": real, "rocket": rocket}[args.what](args)
    text = json.dumps(result, indent=1)
    if args.what != "rocket":
        Path(args.out).write_text(text + "\n")
    else:
        Path(args.out).with_suffix(".json").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
