"""Quality vs network width vs inference time (the inverse network; docs/experiments/16-width.md).

For each width: train (or reuse) ``runs/width_W`` for ``--steps`` steps with the shipped
run's settings, read its validation metrics at that step, and time ``Relighter``-style
decomposition (network + lighting solve) of a 256x256 image (median of 5 after a warm-up)
with ``--time-threads`` torch threads. Runs already at ``--steps`` are reused; ``--extra W=RUN`` adds a run
trained elsewhere (e.g. the shipped width-12 run, read at the same step).

    .venv/bin/python scripts/learned_width_chart.py --data data/train --widths 4 8 16 \
        --extra 12=runs/inverse_w12 --steps 1000 --out docs/experiments/results/learned_width
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import time
from pathlib import Path

import torch


def val_at(run: Path, step: int) -> dict[str, float]:
    with (run / "val.csv").open() as f:
        for row in csv.DictReader(f):
            if int(row["step"]) == step:
                return {k: float(v) for k, v in row.items() if k != "step"}
    raise ValueError(f"{run} has no validation row at step {step}")


def inference_seconds(width: int, depth: int = 3, size: int = 256, threads: int = 2) -> float:
    from learned.lighting import load_prior
    from learned.networks import InverseNet
    from learned.objectives import decompose_and_solve

    torch.set_num_threads(threads)
    torch.manual_seed(0)
    net = InverseNet(width, depth).eval()
    prior = load_prior()
    image = torch.rand(1, 3, size, size) * 0.8 + 0.1
    sky = torch.zeros(1, 1, size, size, dtype=torch.bool)
    sky[..., : size // 4, :] = True
    times = []
    with torch.no_grad():
        for i in range(6):
            t = time.perf_counter()
            decompose_and_solve(net, image, sky, prior)
            if i:
                times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--widths", type=int, nargs="*", default=[4, 8, 16])
    ap.add_argument("--extra", nargs="*", default=[], help="W=RUN: a run of width W trained elsewhere")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--threads", type=int, default=1, help="training threads")
    ap.add_argument("--time-threads", type=int, default=2,
                    help="torch threads for the inference timing (2 = the 2-core machine; use 1 when it is shared: "
                         "two threads on two busy cores were 10-30x slower)")
    ap.add_argument("--out", default="docs/experiments/results/learned_width")
    args = ap.parse_args()

    from learned.networks import InverseNet, count_parameters
    from learned.train import TrainConfig, train

    runs: dict[int, Path] = {}
    for w in args.widths:
        run = Path("runs") / f"width_{w}"
        train(TrainConfig(stage="inverse", data=args.data, out=str(run), width=w, steps=args.steps, batch=4,
                          val_every=250, val_images=96, ckpt_every=250, threads=args.threads, seed=0,
                          progress=False))
        runs[w] = run
    for item in args.extra:
        w, _, run = item.partition("=")
        runs[int(w)] = Path(run)

    table = []
    for w in sorted(runs):
        m = val_at(runs[w], args.steps)
        table.append({"width": w, "parameters": count_parameters(InverseNet(w)),
                      "seconds_256": inference_seconds(w, threads=args.time_threads), **m})
        print(json.dumps(table[-1]))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps({"steps": args.steps, "time_threads": args.time_threads, "rows": table},
                                                  indent=1) + "\n")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    secs = [r["seconds_256"] * 1000 for r in table]
    for ax, key, base, label in (
            (axes[0], "normal_mae_deg", "baseline_normal_mae_deg", "normal MAE (deg)"),
            (axes[1], "albedo_si_mse", "baseline_albedo_si_mse", "albedo si-MSE"),
            (axes[2], "shadow_ap", "baseline_shadow_ap", "shadow AP")):
        ax.plot(secs, [r[key] for r in table], "o-")
        for r, s in zip(table, secs):
            ax.annotate(f"w={r['width']}\n{r['parameters'] / 1e3:.0f}k", (s, r[key]), fontsize=8,
                        xytext=(4, 4), textcoords="offset points")
        ax.axhline(table[0][base], color="grey", ls="--", label="trivial baseline")
        ax.set_xlabel(f"inference ms / 256x256 image ({args.time_threads} thread(s))")
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    fig.suptitle(f"inverse network: held-out quality after {args.steps} steps vs width vs inference time")
    fig.tight_layout()
    fig.savefig(out.with_suffix(".png"), dpi=110)
    print(f"wrote {out.with_suffix('.png')} and {out.with_suffix('.json')}")


if __name__ == "__main__":
    main()
