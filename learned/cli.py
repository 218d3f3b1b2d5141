"""``physrelight train ...``: the first stage's training, evaluation and weight export.

Sub-subcommands (heavy imports stay inside the handlers):

* ``train inverse --data DIR --out RUN``: the self-supervised inverse rendering network;
* ``train shadow --data DIR --out RUN --inverse RUN_OR_WEIGHTS``: ShadowNet on the
  inverse network's normals, lighting and shadows;
* ``train evaluate --data DIR [--split all] [--weights DIR]``: held-out metrics of shipped
  (or exported) weights next to the trivial baselines, as JSON;
* ``train export --inverse RUN --shadow RUN --dest DIR``: weights-only safetensors for
  :meth:`learned.Relighter.load`.

Re-running ``train inverse``/``train shadow`` with the same ``--out`` resumes from the
latest checkpoint. Under ``torchrun --nproc_per_node N`` the loops run distributed (gloo).
"""

from __future__ import annotations

import argparse
import json

from physrelight.cli import positive_int


def _config(args: argparse.Namespace, stage: str):
    from .objectives import LossWeights
    from .train import TrainConfig

    weights = LossWeights().as_dict()
    for item in args.loss_weight or []:
        name, _, value = item.partition("=")
        if name not in weights:
            raise ValueError(f"unknown loss weight {name!r}; known: {sorted(weights)}")
        weights[name] = float(value)
    return TrainConfig(stage=stage, data=args.data, out=args.out, val_data=args.val_data, val_split=args.val_split,
                       train_split=args.train_split,
                       width=args.width, depth=args.depth, res=args.res, batch=args.batch, steps=args.steps,
                       lr=args.lr, seed=args.seed, val_every=args.val_every, val_images=args.val_images,
                       ckpt_every=args.ckpt_every, log_every=args.log_every, threads=args.threads,
                       prior=args.prior, inverse=getattr(args, "inverse", None), weights=weights,
                       progress=not args.quiet)


def _train_inverse(args: argparse.Namespace) -> int:
    from .train import train

    result = train(_config(args, "inverse"))
    print(json.dumps(result, indent=1))
    return 0


def _train_shadow(args: argparse.Namespace) -> int:
    from .train import train

    result = train(_config(args, "shadow"))
    print(json.dumps(result, indent=1))
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    import torch

    from .evaluate import evaluate
    from .relighter import Relighter

    torch.set_num_threads(args.threads)
    r = Relighter.load(args.weights)

    def decompose(image: torch.Tensor, sky: torch.Tensor) -> dict:
        return r.decompose_linear(image, sky)

    metrics = evaluate(decompose, args.data, args.split, r.res, r.prior, args.max_images,
                       shadow_fn=lambda out: r.shadow_net(out["normals"], out["lighting"]))
    text = json.dumps(metrics, indent=1)
    print(text)
    if args.json:
        from pathlib import Path

        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(text + "\n")
    return 0


def _export(args: argparse.Namespace) -> int:
    from pathlib import Path

    from . import checkpoint as ckpt

    dest = Path(args.dest)
    for kind, run in (("inverse", args.inverse), ("shadow", args.shadow)):
        side = ckpt.latest_checkpoint(run)
        if side is None:
            raise ValueError(f"no checkpoint in {run!r}")
        path = ckpt.export_weights(side, dest / f"{kind}.safetensors", kind)
        print(f"{kind}: {side} -> {path} ({path.stat().st_size / 1e6:.2f} MB)")
    return 0


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, help="synth dataset folder (trains on its 'train' split)")
    p.add_argument("--out", required=True, help="run folder (re-run to resume)")
    p.add_argument("--val-data", default=None, help="dataset for validation (default: --data)")
    p.add_argument("--val-split", default="val", help="split validated on (default: val)")
    p.add_argument("--train-split", default="train", help="split trained on (default: train)")
    p.add_argument("--width", type=positive_int, default=16, help="UNet width (default: 16)")
    p.add_argument("--depth", type=positive_int, default=3, help="UNet levels (default: 3)")
    p.add_argument("--res", type=positive_int, default=64, help="training resolution (default: 64)")
    p.add_argument("--batch", type=positive_int, default=4, help="photo pairs per step and process (default: 4)")
    p.add_argument("--steps", type=positive_int, default=2000)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--val-every", type=positive_int, default=250)
    p.add_argument("--val-images", type=positive_int, default=96, help="held-out photos per validation")
    p.add_argument("--ckpt-every", type=positive_int, default=250)
    p.add_argument("--log-every", type=positive_int, default=10)
    p.add_argument("--threads", type=positive_int, default=2, help="torch CPU threads per process (default: 2)")
    p.add_argument("--prior", default=None, help="lighting prior .npz (default: the shipped one)")
    p.add_argument("--loss-weight", action="append", metavar="NAME=VALUE",
                   help="override a loss weight (appearance, albedo, normal, cross, prior, shadow)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``train`` with ``inverse``, ``shadow``, ``evaluate`` and ``export``."""
    p = sub.add_parser("train", help="train the inverse rendering network and ShadowNet (self-supervised)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    tsub = p.add_subparsers(dest="stage", required=True, metavar="STAGE")

    inv = tsub.add_parser("inverse", help="self-supervised inverse rendering network")
    _common(inv)
    inv.set_defaults(handler=_train_inverse)

    sh = tsub.add_parser("shadow", help="ShadowNet on a trained inverse network")
    _common(sh)
    sh.add_argument("--inverse", required=True, help="inverse run folder or exported weights")
    sh.set_defaults(handler=_train_shadow)

    ev = tsub.add_parser("evaluate", help="held-out metrics of weights vs trivial baselines")
    ev.add_argument("--data", required=True, help="synth dataset folder with ground truth")
    ev.add_argument("--split", default="all", help="split to evaluate (default: all)")
    ev.add_argument("--weights", default=None, help="weights folder (default: the shipped ones)")
    ev.add_argument("--max-images", type=positive_int, default=None)
    ev.add_argument("--threads", type=positive_int, default=2)
    ev.add_argument("--json", default=None, help="also write the metrics here")
    ev.set_defaults(handler=_evaluate)

    ex = tsub.add_parser("export", help="write weights-only safetensors for Relighter.load")
    ex.add_argument("--inverse", required=True, help="inverse run folder")
    ex.add_argument("--shadow", required=True, help="shadow run folder")
    ex.add_argument("--dest", default="learned/weights", help="destination folder (default: learned/weights)")
    ex.set_defaults(handler=_export)
