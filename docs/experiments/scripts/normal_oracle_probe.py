"""What can the inverse network's normals reach at all? A supervised upper bound (docs/experiments/07-normal-upper-bound-and-mvs-coverage.md).

A diagnostic, **not a self-supervised result**: the inverse network's architecture
(:class:`learned.networks.InverseNet`, the shipped UNet) is trained on the ground-truth normals of a
synth dataset's training split (``1 - cos`` on the foreground, left-right mirror augmentation, Adam),
nothing else, and its normals are read on held-out scenes with ``train evaluate``'s own code
(:func:`learned.evaluate.evaluate`; the albedo, shadow and lighting slots are filled by the shipped
network, whose figures are not the probe's). Nothing it trains is saved or shipped.

If the supervised network, at the same resolution, width and data, lands far below the
self-supervised one, the self-supervised signal (not capacity or resolution) is what holds the
normals back; if it lands near it, a bigger network or a higher resolution is the lever. Prints JSON
(and writes it to ``--json``): held-out normal MAE and its breakdown at each ``--eval-every`` step, and the
same on ``--train-images`` training photos (``train_`` prefixed: how well it fits what it saw).

    .venv/bin/python docs/experiments/scripts/normal_oracle_probe.py --data data/train640 --heldout data/heldout --width 12 \\
        --steps 24000 --eval-every 4000 --threads 1 --json docs/experiments/results/learned_normal_oracle_w12.json
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from learned.data import load_photo
from learned.evaluate import evaluate
from learned.lighting import WEIGHTS_DIR, load_prior
from learned.networks import InverseNet, mirror_averaged
from learned.objectives import decompose_and_solve
from learned.networks import load_inverse
from synth.dataset import SynthDataset, to_chw

NORMAL_KEYS = ("normal_mae_deg", "normal_median_deg", "normal_mae_deg_mvs", "normal_mae_deg_no_mvs",
               "normal_mae_deg_up", "normal_mae_deg_not_up", "baseline_normal_mae_deg")


def load_split(root: str, res: int, max_scenes: int | None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Training split's photos ``(N, 3, res, res)``, true normals ``(N, 3, res, res)`` and foreground
    masks ``(N, 1, res, res)`` (not sky, valid normal)."""
    ds = SynthDataset(root, split="train", mode="full")
    scenes = set(ds.scenes[:max_scenes]) if max_scenes else set(ds.scenes)
    items = [it for it in ds.items if it.scene in scenes]
    if not items:
        raise ValueError(f"{root!r} has no training photos")
    images, normals, masks = [], [], []
    for it in tqdm(items, desc="load", unit="photo"):
        p = load_photo(ds, it.scene, it.view, it.light, res)
        n = to_chw(ds.load(it.scene, it.view, it.light, keys=("normal",))["normal"])
        if n.shape[-1] != res:
            n = F.interpolate(n[None], size=(res, res), mode="nearest")[0]
        images.append(p["image"])
        normals.append(n)
        masks.append(~p["sky"] & (n.norm(dim=0, keepdim=True) > 0.5))
    return torch.stack(images), F.normalize(torch.stack(normals), dim=1), torch.stack(masks)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, help="synth dataset to train on (its training split)")
    ap.add_argument("--heldout", required=True, help="synth dataset to read the normals on (split all)")
    ap.add_argument("--width", type=int, default=12)
    ap.add_argument("--depth", type=int, default=3)
    ap.add_argument("--steps", type=int, default=8000)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--eval-every", type=int, default=2000)
    ap.add_argument("--scenes", type=int, default=None, help="use the first N training scenes only")
    ap.add_argument("--train-images", type=int, default=96,
                    help="also read the normals on this many training photos (evenly spread): the fit, against the "
                         "held-out generalisation")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--json", default=None, help="also write the result here (atomically)")
    args = ap.parse_args()
    for name in ("width", "depth", "steps", "batch", "eval_every", "res", "threads", "train_images"):
        if getattr(args, name) < 1:
            raise SystemExit(f"error: --{name.replace('_', '-')} must be >= 1")
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    images, normals, masks = load_split(args.data, args.res, args.scenes)
    net = InverseNet(width=args.width, depth=args.depth)
    opt = torch.optim.Adam(net.parameters(), lr=args.lr)
    shipped, prior = load_inverse(WEIGHTS_DIR / "inverse.safetensors").eval(), load_prior()
    rng = np.random.default_rng(args.seed)
    flip_x = torch.tensor([-1.0, 1.0, 1.0])[None, :, None, None]
    curve, seconds = [], 0.0

    def decompose(image: torch.Tensor, sky: torch.Tensor) -> dict[str, torch.Tensor]:
        out = decompose_and_solve(shipped, image, sky, prior)
        out["normals"] = mirror_averaged(net, image)["normals"]  # the shipped inference's averaging
        return out

    for step in tqdm(range(1, args.steps + 1), desc="oracle", unit="step"):
        t0 = time.perf_counter()
        net.train()
        idx = torch.from_numpy(rng.integers(0, len(images), args.batch))
        x, n, m = images[idx], normals[idx], masks[idx].float()
        flip = torch.from_numpy(rng.random(args.batch) < 0.5)[:, None, None, None]
        x = torch.where(flip, x.flip(-1), x)
        n = torch.where(flip, n.flip(-1) * flip_x, n)
        m = torch.where(flip, m.flip(-1), m)
        cos = (net(x)["normals"] * n).sum(1, keepdim=True)
        loss = ((1.0 - cos) * m).sum() / m.sum().clamp_min(1.0)
        opt.zero_grad()
        loss.backward()
        opt.step()
        seconds += time.perf_counter() - t0
        if step % args.eval_every == 0 or step == args.steps:
            net.eval()
            metrics = evaluate(decompose, args.heldout, "all", args.res, prior)
            fit = evaluate(decompose, args.data, "train", args.res, prior, max_images=args.train_images)
            curve.append({"step": step, "train_seconds": round(seconds, 1), "loss": float(loss),
                          **{k: metrics[k] for k in NORMAL_KEYS},
                          **{f"train_{k}": fit[k] for k in NORMAL_KEYS if k != "baseline_normal_mae_deg"}})
            tqdm.write(json.dumps(curve[-1]))
    result = {"probe": "supervised normals (ground truth), not self-supervised", "data": args.data,
              "heldout": args.heldout, "train_photos": len(images), "width": args.width, "depth": args.depth,
              "parameters": sum(p.numel() for p in net.parameters()), "batch": args.batch, "lr": args.lr,
              "seed": args.seed, "threads": args.threads, "curve": curve}
    text = json.dumps(result, indent=1)
    print(text)
    if args.json:
        tmp = f"{args.json}.tmp"
        with open(tmp, "w") as f:
            f.write(text + "\n")
        os.replace(tmp, args.json)
    return 0


if __name__ == "__main__":
    try:
        raise SystemExit(main())
    except ValueError as e:  # a bad dataset path or content: one line, not a traceback
        raise SystemExit(f"error: {e}")
