"""Smoke test of the inverse-network training on a device: the loss falls, nothing is NaN, a resumed
run continues the same run, and how many steps a second it makes. Run through ``scripts/gpu_smoke.sh``.

Three runs of ``learned.train`` on a synth dataset (``--data``; e.g. ``.smoke/data`` from
``scripts/make_smoke_data.sh``), logging every step:

* A: ``--steps N`` uninterrupted (checkpoints every ``--resume-at K`` steps);
* B: the same configuration stopped at step K, then started again with ``--steps N``: it resumes from
  its checkpoint of step K.

Checks (each reported in the JSON; the exit status is 1 when one fails):

* **loss falls**: the mean of the last W logged totals < 0.8 x the mean of the first W
  (W = min(20, N // 4));
* **finite**: every logged loss and every final parameter of A is finite;
* **resume**: B's losses after step K and its final parameters equal A's bit for bit on the CPU;
  on CUDA (deterministic algorithms on, ``CUBLAS_WORKSPACE_CONFIG=:4096:8``; ops without a
  deterministic CUDA kernel only warn), bit-identical or within a stated tolerance: the first
  resumed loss within 1e-3 relative, the mean relative loss difference after K below 2e-2;
* **speed**: steps/s = the median over windows of W steps of the training seconds the loop logs
  (batch, forward, backward, optimizer step; not validation or checkpoints), the first window
  (warm-up) left out.

``--bench``: run A only and report the speed (no resume, no loss rule), without deterministic
algorithms (the speed of an ordinary run).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

# Before torch initialises cuBLAS: its deterministic workspace (ignored on the CPU).
os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

LOSS_DROP = 0.8  # last-W mean < LOSS_DROP x first-W mean
FIRST_RESUMED_RTOL = 1e-3  # CUDA, when not bit-identical
MEAN_RESUMED_RTOL = 2e-2


def _parser() -> argparse.ArgumentParser:
    from physrelight.cli_common import positive_int

    p = argparse.ArgumentParser(prog="gpu_smoke.sh", description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="synth dataset folder (scripts/make_smoke_data.sh)")
    p.add_argument("--steps", type=positive_int, default=300, help="N, steps of the run (default: 300)")
    p.add_argument("--resume-at", type=positive_int, default=None, metavar="K",
                   help="step the interrupted run stops and resumes at (default: N // 2)")
    p.add_argument("--res", type=positive_int, default=200, help="training resolution (default: 200)")
    p.add_argument("--batch", type=positive_int, default=4, help="photo pairs per step (default: 4)")
    p.add_argument("--device", choices=("auto", "cpu", "cuda", "mps"), default="cuda", help="(default: cuda)")
    p.add_argument("--precision", choices=("fp32", "bf16", "fp16"), default="bf16", help="(default: bf16)")
    p.add_argument("--workers", type=int, default=0, help="DataLoader workers (default: 0)")
    p.add_argument("--threads", type=positive_int, default=2, help="torch CPU threads (default: 2)")
    p.add_argument("--out", default=None, help="folder for the runs (default: a temporary folder, removed)")
    p.add_argument("--json", default=None, help="write the figures here as JSON")
    p.add_argument("--bench", action="store_true", help="one run, speed only")
    return p


def _totals(run: Path) -> dict[int, float]:
    with (run / "train.csv").open() as f:
        return {int(r["step"]): float(r["total"]) for r in csv.DictReader(f)}


def _speed(run: Path, window: int) -> dict[str, object]:
    """Steps/s over consecutive windows of ``window`` logged steps (the first, warm-up, left out)."""
    with (run / "train.csv").open() as f:
        rows = [(int(r["step"]), float(r["seconds"])) for r in csv.DictReader(f)]
    rates = []
    for i in range(window, len(rows) - window + 1, window):  # windows after the first
        (s0, t0), (s1, t1) = rows[i - 1], rows[i + window - 1]
        if t1 > t0:
            rates.append((s1 - s0) / (t1 - t0))
    if not rates and len(rows) >= 2:  # too few steps for two windows: all but the first step
        (s0, t0), (s1, t1) = rows[0], rows[-1]
        rates = [(s1 - s0) / (t1 - t0)] if t1 > t0 else []
    return {"steps_per_s": statistics.median(rates) if rates else math.nan,
            "window_steps_per_s": [round(r, 3) for r in rates], "window": window}


def _params(run: Path) -> dict[str, "torch.Tensor"]:
    from safetensors.torch import load_file

    from learned import checkpoint as ckpt

    side = ckpt.latest_checkpoint(run)
    return {k: v for k, v in load_file(str(side.with_suffix(".safetensors"))).items() if k.startswith("model.")}


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    import torch

    from learned import runs
    from learned.train import TrainConfig, train

    try:
        device = runs.resolve_device(args.device)
        runs.check_compute(device, args.precision)
        if args.workers < 0:
            raise ValueError(f"--workers must be >= 0, got {args.workers}")
        n = args.steps
        k = args.resume_at if args.resume_at is not None else max(1, n // 2)
        if not args.bench and not 1 <= k < n:
            raise ValueError(f"--resume-at must lie in [1, --steps), got {k} with --steps {n}")
        if not Path(args.data, "manifest.json").is_file():
            raise ValueError(f"--data {args.data!r} is not a synth dataset folder (no manifest.json)")
    except ValueError as err:
        print(f"gpu_smoke: error: {err}", file=sys.stderr)
        return 2
    deterministic = device.type == "cuda" and not args.bench  # --bench times what a user's run gets
    if deterministic:
        torch.use_deterministic_algorithms(True, warn_only=True)

    tmp = None
    if args.out is None:
        tmp = tempfile.TemporaryDirectory(prefix="gpu_smoke_")
        out = Path(tmp.name)
    else:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        if any(out.iterdir()):
            print(f"gpu_smoke: error: --out {str(out)!r} is not empty (the runs would resume)", file=sys.stderr)
            return 2

    def config(name: str, steps: int) -> TrainConfig:
        return TrainConfig(stage="inverse", data=args.data, out=str(out / name), res=args.res, batch=args.batch,
                           steps=steps, seed=0, ckpt_every=n if args.bench else k, log_every=1, val_every=n,
                           val_images=4, val_split="all", threads=args.threads, progress=False,
                           device=args.device, precision=args.precision, workers=args.workers)

    window = max(1, min(20, n // 4))
    report: dict[str, object] = {"device": str(device), "torch": torch.__version__, "res": args.res,
                                 "batch": args.batch, "precision": args.precision, "steps": n,
                                 "workers": args.workers, "threads": args.threads,
                                 "deterministic_algorithms": deterministic}
    if device.type == "cuda":
        report["gpu"] = torch.cuda.get_device_name(device)
    wall = time.perf_counter()
    train(config("A", n))
    report["wall_seconds_A"] = round(time.perf_counter() - wall, 2)
    report.update(_speed(out / "A", window))
    checks: dict[str, bool] = {}
    if not args.bench:
        totals = _totals(out / "A")
        values = [totals[s] for s in sorted(totals)]
        first, last = statistics.fmean(values[:window]), statistics.fmean(values[-window:])
        report["loss"] = {"first_mean": first, "last_mean": last, "ratio": last / first, "window": window,
                          "rule": f"mean of the last {window} < {LOSS_DROP} x mean of the first {window}"}
        checks["loss_falls"] = last < LOSS_DROP * first
        params_a = _params(out / "A")
        checks["finite"] = all(math.isfinite(v) for v in values) and all(
            bool(torch.isfinite(t).all()) for t in params_a.values() if t.is_floating_point())

        train(config("B", k))  # stops at K, as a killed run would have left it
        train(config("B", n))  # the same command again resumes from step K
        resumed = _totals(out / "B")
        after = [s for s in sorted(totals) if s > k]
        rel = [abs(resumed[s] - totals[s]) / max(abs(totals[s]), 1e-12) for s in after]
        params_b = _params(out / "B")
        bit = sorted(resumed) == sorted(totals) and all(resumed[s] == totals[s] for s in totals) and all(
            torch.equal(params_a[name], params_b[name]) for name in params_a)
        max_diff = max(float((params_a[name].double() - params_b[name].double()).abs().max()) for name in params_a)
        first_rel = rel[0] if rel else 0.0
        mean_rel = statistics.fmean(rel) if rel else 0.0
        if device.type == "cuda":
            rule = (f"bit-identical, or first resumed loss within {FIRST_RESUMED_RTOL:g} relative and mean "
                    f"relative loss difference after step {k} below {MEAN_RESUMED_RTOL:g}")
            ok = bit or (first_rel <= FIRST_RESUMED_RTOL and mean_rel <= MEAN_RESUMED_RTOL)
        else:
            rule, ok = "bit-identical losses and parameters", bit
        report["resume"] = {"at": k, "bit_identical": bit, "max_param_abs_diff": max_diff,
                            "first_resumed_loss_rel_diff": first_rel, "mean_resumed_loss_rel_diff": mean_rel,
                            "rule": rule}
        checks["resume"] = ok
    report["checks"] = checks
    report["pass"] = all(checks.values())
    text = json.dumps(report, indent=1)
    print(text)
    if args.json:
        from physrelight import io

        io.write_json(args.json, report)
    if tmp is not None:
        tmp.cleanup()
    for name, ok in checks.items():
        if not ok:
            print(f"gpu_smoke: FAILED {name}", file=sys.stderr)
    return 0 if report["pass"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
