"""Study 22: leave-one-panorama-out scores of sky-segmenter runs and of the full-resolution mask's settings.

For each fold NAME (a run trained with ``--real-exclude NAME``), the crops ``bench --real`` makes of
the training panorama NAME (seed 0, 16 crops) are scored with every inference variant: IoU and
boundary F (2 px) on crops with sky, fraction called sky on crops without. Never the held-out panorama.

    .venv/bin/python docs/experiments/scripts/22_sky_loo.py --fold city=runs/seg_loo_city ... \
        [--steps 500 1000] [--json OUT]
    (--fold shipped=learned/weights/sky_segmentation.safetensors scores a weights file on all folds)
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from learned import checkpoint as ckpt  # noqa: E402
from learned import sky_segmentation as ss  # noqa: E402
from physrelight import metrics  # noqa: E402
from synth.panorama_crops import TRAINING_DIR, load_panorama, make_crops  # noqa: E402

FOLDS = ("city", "courtyard", "forest")
VARIANTS = {  # name: keyword arguments of sky_mask_full_resolution
    "res128": {"res": 128},
    "res128_noband": {"res": 128, "band": 0},
    "res128_band1": {"res": 128, "band": 1},
    "res128_band4": {"res": 128, "band": 4},
    "res128_band6": {"res": 128, "band": 6},
    "native": {"res": None},
    "native_noband": {"res": None, "band": 0},
    "native_band1": {"res": None, "band": 1},
    "res192": {"res": 192},
    "res96": {"res": 96},
    "native_t04": {"res": None, "threshold": 0.4},
    "native_t06": {"res": None, "threshold": 0.6},
}


def load_model(spec: str, step: str | None) -> ss.SkySegmenter:
    """A weights file, or a run's checkpoint at ``step`` ("400"), or the mean of its checkpoints
    from A to B ("avg600-1200", :func:`learned.checkpoint._averaged_tensors`)."""
    p = Path(spec)
    if p.is_file():
        return ss.load_sky_segmenter(p)
    if step and step.startswith("avg"):
        a, b = (int(x) for x in step[3:].split("-"))
        sides = ckpt.checkpoints_between(p, a, b)
        tensors = ckpt._averaged_tensors(sides, "model.")
        side = sides[-1]
    else:
        side = ckpt.checkpoint_at(p, int(step)) if step else ckpt.latest_checkpoint(p)
        tensors, _ = ckpt.load_weights(side.with_suffix(".safetensors"))
    cfg = json.loads(side.read_text())["config"]
    m = ss.SkySegmenter(cfg["width"], cfg["depth"], cfg["res"])
    m.load_state_dict({k[10:]: v for k, v in tensors.items() if k.startswith("model.seg.")})
    return m.eval()


def crops_of(name: str):
    return make_crops(load_panorama(TRAINING_DIR / f"{name}.exr", "training"), 16, 0)


def score(model, crops, variants):
    out = {}
    for v, kw in variants.items():
        ious, fs, false = [], [], []
        for c in crops:
            m, _ = ss.sky_mask_full_resolution(model, c.linear(), **kw)
            m = m[0, 0].numpy()
            if c.stratum == "sky":
                ious.append(metrics.mask_iou(m, c.sky))
                fs.append(metrics.boundary_f(m, c.sky, 2.0))
            elif c.stratum == "no_sky":
                false.append(float(m.mean()))
        out[v] = {"iou": float(np.mean(ious)) if ious else None, "f": float(np.mean(fs)) if fs else None,
                  "false_sky": float(np.mean(false)) if false else None, "n_sky": len(ious), "n_no_sky": len(false)}
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--fold", action="append", required=True, help="NAME=RUN_OR_WEIGHTS")
    ap.add_argument("--steps", nargs="*", default=[None], help="400, avg600-1200, ...")
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS))
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    torch.set_num_threads(1)
    crops = {n: crops_of(n) for n in FOLDS}
    results = {}
    for spec in a.fold:
        name, path = spec.split("=", 1)
        targets = FOLDS if name not in FOLDS else (name,)
        for step in a.steps:
            model = load_model(path, step)
            for t in targets:
                r = score(model, crops[t], {v: VARIANTS[v] for v in a.variants})
                results[f"{name}@{step}:{t}"] = r
                for v, x in r.items():
                    print(f"{name}@{step} on {t:9s} {v:15s} iou {x['iou']:.3f} F {x['f']:.3f} "
                          f"false {x['false_sky'] if x['false_sky'] is None else round(x['false_sky'], 3)}", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1))
