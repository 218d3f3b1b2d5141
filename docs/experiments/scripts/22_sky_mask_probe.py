"""Study 22: where the real-photo sky mask fails, on the training-side panoramas only.

Scores the stages of ``learned.sky_segmentation.sky_mask_full_resolution`` on the crops
``bench --real`` makes of the training panoramas (city, courtyard, forest; studio for false sky),
seed 0, 16 crops each: never the held-out panorama.

    .venv/bin/python docs/experiments/scripts/22_sky_mask_probe.py --weights W [--json OUT] [--panels DIR]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from learned import sky_segmentation as ss  # noqa: E402
from physrelight.full_resolution import resize_short_side  # noqa: E402
from physrelight import io, metrics  # noqa: E402
from synth.panorama_crops import TRAINING_DIR, load_panorama, make_crops  # noqa: E402

TRAINING = ("city", "courtyard", "forest", "studio")


def training_crops(names=TRAINING, n=16, seed=0):
    out = {}
    for name in names:
        p = load_panorama(TRAINING_DIR / f"{name}.exr", "indoor" if name == "studio" else "training")
        out[name] = make_crops(p, n, seed)
    return out


def stages(model, lin, res):
    """Masks of each stage at full size: raw (bilinear prob > .5), plausible, guided, refined (= shipped)."""
    from physrelight.guided_filter import guided_upsample

    h, w = lin.shape[-2:]
    small = resize_short_side(lin, res) if res else lin
    with torch.no_grad():
        prob = torch.sigmoid(model(small))
    up = lambda x: F.interpolate(x[None, None].float(), size=(h, w), mode="bilinear", align_corners=False)[0, 0]
    raw = up(prob[0, 0]) > 0.5
    kept, why = ss.plausible_sky(prob[0, 0] > 0.5, small[0])
    plaus = up(prob[0, 0] * kept) > 0.5
    out = {"raw": raw, "plausible": plaus}
    if kept.any():
        lum = (lin * lin.new_tensor(ss._LUMA)[None, :, None, None]).sum(1, keepdim=True)
        guide = torch.log(lum.clamp_min(1e-3))
        g = guided_upsample(guide, (prob[0, 0] * kept)[None, None], eps=1e-2) > 0.5
        band = max(1, ss.BAND_WORKING_PIXELS * round(h / small.shape[-2]))
        out["guided"] = g[0, 0]
        out["refined"] = ss.refine_sky_boundary(g, lin, band)[0, 0]
    else:
        out["guided"] = out["refined"] = torch.zeros(h, w, dtype=torch.bool)
    return out, why


def score(model, crops, res, panels=None):
    rows = {}
    for name, cs in crops.items():
        per = []
        for c in cs:
            lin = c.linear()
            m, why = stages(model, lin, res)
            rec = {"index": c.index, "stratum": c.stratum, "sky_fraction": float(c.sky.mean()), "why": why}
            for k, v in m.items():
                v = v.numpy()
                rec[k] = {"iou": metrics.mask_iou(v, c.sky), "f": metrics.boundary_f(v, c.sky, 2.0),
                          "called": float(v.mean())}
            per.append(rec)
            if panels is not None:
                img = c.display()
                cols = [img] + [np.repeat(m[k].numpy()[..., None], 3, -1).astype(np.float32) for k in
                                ("raw", "refined")] + [np.repeat(c.sky[..., None], 3, -1).astype(np.float32)]
                Path(panels).mkdir(parents=True, exist_ok=True)
                io.write_png(Path(panels) / f"{name}_{c.index:02d}.png", np.concatenate(cols, 1))
        rows[name] = per
    return rows


def summary(rows, stage="refined"):
    out = {}
    for name, per in rows.items():
        sky = [r for r in per if r["stratum"] == "sky"]
        nos = [r for r in per if r["stratum"] == "no_sky"]
        out[name] = {"n_sky": len(sky),
                     "iou": float(np.mean([r[stage]["iou"] for r in sky])) if sky else None,
                     "f": float(np.mean([r[stage]["f"] for r in sky])) if sky else None,
                     "false_sky": float(np.mean([r[stage]["called"] for r in nos])) if nos else None}
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--weights", default="learned/weights/sky_segmentation.safetensors")
    ap.add_argument("--res", type=int, nargs="+", default=[64, 128])
    ap.add_argument("--json", default=None)
    ap.add_argument("--panels", default=None)
    a = ap.parse_args()
    torch.set_num_threads(1)
    model = ss.load_sky_segmenter(a.weights)
    crops = training_crops()
    res_all = {}
    for r in a.res:
        rows = score(model, crops, r, a.panels if r == a.res[-1] else None)
        res_all[str(r)] = {"crops": rows, "summary": {s: summary(rows, s) for s in ("raw", "plausible", "guided",
                                                                                   "refined")}}
        for s in ("raw", "plausible", "guided", "refined"):
            print(r, s, json.dumps({k: {kk: (round(vv, 3) if isinstance(vv, float) else vv) for kk, vv in v.items()}
                                    for k, v in res_all[str(r)]["summary"][s].items()}))
    if a.json:
        Path(a.json).write_text(json.dumps(res_all, indent=1))
