"""Held-out quality of the inverse network vs the number of training scenes (docs/experiments/04-memorisation-and-data-scaling.md).

For each ``SCENES=RUN`` or ``SCENES=RUN@STEP`` (a run of ``physrelight train inverse`` on a dataset
of SCENES scenes), export the run's last checkpoint (or the one at STEP: a run that trains on past
the step the chart reports) with the shipped ShadowNet and prior and the lighting step
``map_relative``, once as trained and once with test-time mirror averaging, and evaluate
(:func:`learned.evaluate.evaluate_relighter`, the metrics of ``physrelight train evaluate``) on the
held-out dataset and on photos of the run's own training scenes (``--train-images`` of its
``train`` split): the gap between the two is what the network memorised. Writes
``OUT.json`` (every metric of every evaluation) and ``OUT.png`` (normal error, albedo si-MSE and
shadow AP against the scene count, with the trivial baselines and the issue's goals). ``OUT.json``
is rewritten atomically after each run; a run already in it at the same checkpoint step is not
evaluated again (re-run to resume, or to add a run).

    .venv/bin/python docs/experiments/scripts/learned_data_scaling_chart.py --heldout data/heldout \
        --runs 160=runs/inv_b_train160_mirror 640=runs/inv_a_train640_mirror \
        1280=runs/inv_c_train1280_mirror --out docs/experiments/results/learned_data_scaling
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import torch

from learned import checkpoint as ckpt
from learned.evaluate import evaluate_relighter
from learned.relighter import Relighter, fill_weights_folder
from physrelight.io import atomic_path, write_json

GOALS = {"normal_mae_deg": 20.0}  # and albedo: 2x better than the photo (drawn per point)


def export(sidecar: Path, dest: Path, mirror_average: bool) -> Path:
    """``dest`` = the checkpoint's inverse network + the shipped ShadowNet, prior and the rest (a Relighter folder)."""
    extra = {"lighting_solve": "map_relative", **({"mirror_average": "1"} if mirror_average else {})}
    ckpt.export_weights(sidecar, dest / "inverse.safetensors", "inverse", extra=extra)
    fill_weights_folder(dest)
    return dest


def measure(weights: Path, data: str, split: str, max_images: int | None) -> dict[str, float]:
    return evaluate_relighter(Relighter.load(weights), data, split, max_images)


def chart(results: dict[str, dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted(int(s) for s in results)
    pick = lambda key, which: [results[str(s)][which][key] for s in scenes]  # noqa: E731
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    panels = (("normal_mae_deg", "normal mean angular error (deg)"), ("albedo_si_mse", "albedo si-MSE"),
              ("shadow_ap", "shadow AP (sun labels)"))
    for ax, (key, title) in zip(axes, panels):
        ax.plot(scenes, pick(key, "heldout"), "o-", label="held-out")
        ax.plot(scenes, pick(key, "heldout_mirror_average"), "s--", label="held-out, mirror-averaged")
        ax.plot(scenes, pick(key, "train_scenes"), "^:", label="training scenes")
        if key == "normal_mae_deg":
            ax.axhline(GOALS[key], color="k", lw=0.8, ls="--", label="goal")
        if key == "albedo_si_mse":
            ax.plot(scenes, [v / 2 for v in pick("baseline_albedo_si_mse", "heldout")], "k--", lw=0.8,
                    label="goal (photo / 2)")
            ax.plot(scenes, pick("oracle_albedo_si_mse", "heldout"), color="grey", lw=0.8,
                    label="image-model ceiling")
        if key == "shadow_ap":
            ax.plot(scenes, pick("baseline_shadow_ap", "heldout"), "k--", lw=0.8, label="chance (held-out)")
        ax.set_xscale("log")
        ax.set_xticks(scenes, [str(s) for s in scenes])
        ax.minorticks_off()
        ax.set_xlabel("scenes in the training dataset")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    axes[1].legend(fontsize=7)
    axes[2].legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--heldout", required=True, help="held-out dataset (evaluated on its split 'all')")
    ap.add_argument("--runs", nargs="+", required=True, metavar="SCENES=RUN[@STEP]")
    ap.add_argument("--train-images", type=int, default=288, help="photos of the training scenes evaluated")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", required=True, help="output path without extension (.json and .png are written)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    out = Path(args.out)
    out_json = out.with_suffix(".json")
    results: dict[str, dict] = json.loads(out_json.read_text()) if out_json.is_file() else {}
    for item in args.runs:
        scenes, _, run = item.partition("=")
        run, at, step_text = run.partition("@")
        if not scenes.isdigit() or not run or (at and not step_text.isdigit()):
            raise SystemExit(f"--runs takes SCENES=RUN or SCENES=RUN@STEP, got {item!r}")
        run_path = Path(run)
        try:
            side = ckpt.checkpoint_at(run_path, int(step_text) if at else None)
        except ValueError as e:
            raise SystemExit(str(e)) from None
        step = json.loads(side.read_text())["step"]
        old = results.get(scenes)
        if old is not None and old.get("run") == run and old.get("step") == step:
            print(f"{scenes} scenes ({run}, step {step}): already measured in {out_json}", flush=True)
            continue
        data = json.loads((run_path / "config.json").read_text())["data"]
        with tempfile.TemporaryDirectory() as tmp:
            # the sidecar read above, so the step recorded is the one measured while the run trains on
            plain = export(side, Path(tmp) / "plain", False)
            mirrored = export(side, Path(tmp) / "mirror", True)
            results[scenes] = {
                "run": run, "data": data, "step": step,
                "heldout": measure(plain, args.heldout, "all", None),
                "heldout_mirror_average": measure(mirrored, args.heldout, "all", None),
                "train_scenes": measure(plain, data, "train", args.train_images),
            }
        write_json(out_json, results)
        r = results[scenes]
        print(f"{scenes} scenes ({run}): held-out normals {r['heldout']['normal_mae_deg']:.2f} deg "
              f"(mirror-averaged {r['heldout_mirror_average']['normal_mae_deg']:.2f}, training scenes "
              f"{r['train_scenes']['normal_mae_deg']:.2f}), albedo {r['heldout']['albedo_si_mse']:.4f}, "
              f"shadow AP {r['heldout']['shadow_ap']:.3f}", flush=True)
    chart(results, out.with_suffix(".png"))


if __name__ == "__main__":
    main()
