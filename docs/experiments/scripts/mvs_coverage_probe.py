"""How much of the foreground gets an MVS normal, and how good it is, at each rendering resolution (docs/experiments/07-normal-upper-bound-and-mvs-coverage.md).

For each synth dataset given (the same scenes rendered at different ``--res``), over all its photos: the share
of foreground pixels (not sky, valid true normal) with MVS-like depth, the share with a central-difference MVS
normal (:func:`physrelight.camera.normals_from_depth`, ``max_rel_jump=0.1``, as the training's normal term and
``train evaluate``'s MVS split use), and that normal's angular error against the true normal (``train
evaluate``'s angle). Prints JSON.

With ``--pool-to N`` the MVS normals are computed at the dataset's resolution and then area-pooled to N px
(:func:`learned.data.pooled_mvs_normals`, what ``train inverse --mvs-pooled`` trains on: a pixel keeps the
renormalised mean of its valid sub-pixel normals, if at least half of them are valid), and are
compared on N-px pixels with the true normals and sky resized as ``train evaluate`` resizes them (nearest).

    .venv/bin/python docs/experiments/scripts/mvs_coverage_probe.py data/res64_probe data/res128_probe data/res256_probe
    .venv/bin/python docs/experiments/scripts/mvs_coverage_probe.py --pool-to 64 data/res128_probe
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch
import torch.nn.functional as F

from learned.data import pooled_mvs_normals
from learned.evaluate import _angle_map_deg
from synth.dataset import SynthDataset, to_chw


def coverage(root: str, pool_to: int | None = None) -> dict[str, float]:
    """MVS coverage and normal error of one dataset (all splits), optionally pooled to ``pool_to`` px."""
    ds = SynthDataset(root, split="all", mode="full")
    if not ds.items:
        raise ValueError(f"{root!r} has no photos")
    if ds.mvs_scale != 1:  # its depth, normals and K would be at different resolutions
        raise ValueError(f"{root!r} was written with --mvs-scale {ds.mvs_scale}; this probe reads sets without it")
    res = int(ds.config["res"])
    out_res = pool_to or res
    foreground = with_depth = with_normal = 0
    errors = []
    for it in ds.items:
        d = ds.load(it.scene, it.view, it.light, keys=("mvs_depth", "K", "normal", "sky_mask"))
        depth, normal = to_chw(d["mvs_depth"]), to_chw(d["normal"])
        sky = to_chw(d["sky_mask"].astype(np.float32))
        # The training loader's own normals (at out_res == res: those of the depth itself).
        mvs, ok = pooled_mvs_normals(depth, torch.from_numpy(d["K"]).float(), out_res)
        if out_res != res:
            depth, normal, sky = (F.interpolate(x[None], size=(out_res, out_res), mode="nearest")[0]
                                  for x in (depth, normal, sky))
        fg = ~(sky > 0.5) & (normal.norm(dim=0, keepdim=True) > 0.5)
        m = fg & ok
        foreground += int(fg.sum())
        with_depth += int((fg & (depth > 0)).sum())
        with_normal += int(m.sum())
        errors.append(_angle_map_deg(mvs, normal)[m].numpy())
    e = np.concatenate(errors)
    return {"res": res, "pooled_to": pool_to, "photos": len(ds.items), "foreground_pixels": foreground,
            "with_mvs_depth": with_depth / foreground, "with_mvs_normal": with_normal / foreground,
            "mvs_normal_mae_deg": float(e.mean()), "mvs_normal_median_deg": float(np.median(e))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("data", nargs="+", help="synth dataset folders")
    ap.add_argument("--pool-to", type=int, default=None, metavar="N",
                    help="compute the MVS normals at the dataset's resolution, then area-pool them to N px")
    args = ap.parse_args()
    print(json.dumps({root: coverage(root, args.pool_to) for root in args.data}, indent=1))
    return 0


if __name__ == "__main__":
    try:
        raise SystemExit(main())
    except ValueError as e:
        raise SystemExit(f"error: {e}")
