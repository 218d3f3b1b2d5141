"""How much of the foreground gets an MVS normal, and how good it is, at each rendering resolution (docs/learned.md).

For each synth dataset given (the same scenes rendered at different ``--res``), over all its photos: the share
of foreground pixels (not sky, valid true normal) with MVS-like depth, the share with a central-difference MVS
normal (:func:`physrelight.camera.normals_from_depth`, ``max_rel_jump=0.1``, as the training's normal term and
``train evaluate``'s MVS split use), and that normal's angular error against the true normal. Prints JSON.

With ``--pool-to N`` the MVS normals are computed at the dataset's resolution and then area-pooled to N px (a
pixel keeps the renormalised mean of its valid sub-pixel normals, if at least half of them are valid), and are
compared on N-px pixels with the true normals and sky resized as ``train evaluate`` resizes them (nearest).

    .venv/bin/python scripts/mvs_coverage_probe.py data/res64_probe data/res128_probe data/res256_probe
    .venv/bin/python scripts/mvs_coverage_probe.py --pool-to 64 data/res128_probe
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch
import torch.nn.functional as F

from physrelight import camera
from synth.dataset import SynthDataset, to_chw


def coverage(root: str, pool_to: int | None = None) -> dict[str, float]:
    """MVS coverage and normal error of one dataset (all splits), optionally pooled to ``pool_to`` px."""
    ds = SynthDataset(root, split="all", mode="full")
    if not ds.items:
        raise ValueError(f"{root!r} has no photos")
    res = int(ds.config["res"])
    if pool_to is not None and (pool_to < 1 or res % pool_to):
        raise ValueError(f"--pool-to must divide the dataset's resolution {res}, got {pool_to}")
    k = res // pool_to if pool_to else 1
    foreground = with_depth = with_normal = 0
    errors = []
    for it in ds.items:
        d = ds.load(it.scene, it.view, it.light, keys=("mvs_depth", "K", "normal", "sky_mask"))
        depth, normal = to_chw(d["mvs_depth"]), to_chw(d["normal"])
        sky = to_chw(d["sky_mask"].astype(np.float32))
        mvs, ok = camera.normals_from_depth(depth[None], torch.from_numpy(d["K"]).float()[None], max_rel_jump=0.1)
        if k > 1:  # mean of the valid sub-pixel normals; valid where at least half are
            mvs = F.normalize(F.avg_pool2d(mvs * ok, k), dim=1)
            ok = F.avg_pool2d(ok.float(), k) >= 0.5
            size = (pool_to, pool_to)
            depth = F.interpolate(depth[None], size=size, mode="nearest")[0]
            normal = F.interpolate(normal[None], size=size, mode="nearest")[0]
            sky = F.interpolate(sky[None], size=size, mode="nearest")[0]
        fg = ~(sky > 0.5) & (normal.norm(dim=0, keepdim=True) > 0.5)
        m = fg & ok[0]
        foreground += int(fg.sum())
        with_depth += int((fg & (depth > 0)).sum())
        with_normal += int(m.sum())
        cos = (mvs[0] * torch.nn.functional.normalize(normal, dim=0)).sum(0, keepdim=True).clamp(-1, 1)
        errors.append(torch.rad2deg(torch.acos(cos))[m].numpy())
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
