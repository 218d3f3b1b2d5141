"""Run the benchmark: gather the views, run every method on every pair, time it, score it.

Levels (:data:`LEVELS`): ``quick`` renders its own small held-out set (or takes the first
scenes of ``--data``) and runs in a few minutes on 2 cores; ``full`` takes every scene of
``--data`` (default ``data/heldout``) plus generated strata and time-lapse scenes.
"""

from __future__ import annotations

import copy
import datetime
import math
import os
import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from .data import BenchView, LightSpec, Recipe, load_dataset, render_recipes, timelapse_lights
from .methods import ABS_NAME, AnalysisBySynthesis, Learned, OracleSH, build_methods
from .protocols import VARIANTS, Pair, cross_pairs, describe_pairs, informative_pairs, timelapse_pairs
from .scores import GAIN_METRICS, MethodRun, score

S = LightSpec
# Scenes rendered when no --data is given (quick): sky-model lightings with chosen sun positions.
QUICK_BASE = (
    Recipe("quick_a", "quick", 101, 2, (S("sunsky", 50, 30), S("evening", 8, 200), S("overcast", 40, 110))),
)
QUICK_EXTRA = (
    Recipe("quick_glossy", "glossy", 102, 2, (S("sunsky", 35, 300), S("sunsky", 16, 120), S("overcast", 30, 0)),
           glossy_fraction=1.0),
    Recipe("quick_bright", "bright_albedo", 103, 1, (S("sunsky", 45, 90), S("evening", 3, 270)), albedo_scale=1.8),
    Recipe("quick_dark", "dark_albedo", 104, 1, (S("sunsky", 60, 150), S("evening", 12, 330)), albedo_scale=0.35),
    Recipe("quick_timelapse", "timelapse", 105, 1, timelapse_lights((7.0, 9.5, 12.0, 14.5, 17.0))),
)
FULL_EXTRA = (
    Recipe("glossy_1", "glossy", 201, 2, (S("sunsky", 35, 300), S("sunsky", 16, 120), S("overcast", 30, 0)),
           glossy_fraction=1.0),
    Recipe("glossy_2", "glossy", 202, 2,
           (S("sunsky", 55, 45), S("evening", 6, 250), S("hdri", hdri="city", azimuth=90)), glossy_fraction=1.0),
    Recipe("bright_1", "bright_albedo", 203, 2, (S("sunsky", 45, 90), S("evening", 3, 270), S("overcast", 50, 0)),
           albedo_scale=1.8),
    Recipe("dark_1", "dark_albedo", 204, 2, (S("sunsky", 60, 150), S("evening", 12, 330), S("overcast", 35, 200)),
           albedo_scale=0.35),
    Recipe("twilight_1", "twilight", 205, 2, (S("evening", 2.5, 100), S("evening", 3.5, 280), S("sunsky", 40, 10))),
    Recipe("timelapse_1", "timelapse", 206, 1, timelapse_lights((6.5, 8.0, 9.5, 11.0, 12.5, 14.0, 15.5, 17.0))),
    Recipe("timelapse_2", "timelapse", 207, 1, timelapse_lights((6.5, 8.0, 9.5, 11.0, 12.5, 14.0, 15.5, 17.0))),
)


@dataclass(frozen=True)
class BenchLevel:
    """Everything that sets a run's size.

    Attributes:
        name: ``"quick"`` or ``"full"``.
        base: scenes rendered when no data folder is given (None: a data folder is required).
        extra: scenes always rendered (strata and time-lapse).
        data_scenes: how many scenes of the data folder to use (None = all).
        variant_views: the first view of this many scenes gets the dark and noise+JPEG variants.
        spp, env_res, texture_size: rendering of the generated scenes (64 px).
        sweep_pairs: cross pairs (evenly spread) of the speed/accuracy sweep of ``proposed``.
        sweep_res: working resolutions of the sweep; sweep_widths: inverse nets of ``runs/width_W``.
        abs_sources: source photos fitted by analysis by synthesis (each relit to all its targets).
        abs_steps, abs_spp: its optimisation steps and samples per pixel per step.
    """

    name: str
    base: tuple[Recipe, ...] | None
    extra: tuple[Recipe, ...]
    data_scenes: int | None
    variant_views: int
    spp: int = 32
    env_res: int = 32
    texture_size: int = 64
    sweep_pairs: int = 48
    sweep_res: tuple[int, ...] = (32, 64, 128)
    sweep_widths: tuple[int, ...] = (4, 8, 16)
    abs_sources: int = 2
    abs_steps: int = 25
    abs_spp: int = 8

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "base": [r.name for r in self.base or ()], "extra": [r.name for r in self.extra],
                "data_scenes": self.data_scenes, "variant_views": self.variant_views, "spp": self.spp,
                "env_res": self.env_res, "texture_size": self.texture_size, "sweep_pairs": self.sweep_pairs,
                "sweep_res": list(self.sweep_res), "sweep_widths": list(self.sweep_widths),
                "abs_sources": self.abs_sources, "abs_steps": self.abs_steps, "abs_spp": self.abs_spp}


QUICK = BenchLevel("quick", base=QUICK_BASE, extra=QUICK_EXTRA, data_scenes=2, variant_views=2, sweep_pairs=48,
                   abs_sources=2, abs_steps=25, abs_spp=8)
FULL = BenchLevel("full", base=None, extra=FULL_EXTRA, data_scenes=None, variant_views=24, sweep_pairs=96,
                  abs_sources=8, abs_steps=40, abs_spp=8)
LEVELS = {"quick": QUICK, "full": FULL}
DEFAULT_FULL_DATA = "data/heldout"


# ----------------------------------------------------------------------------- evaluation


def evaluate(name: str, method: Callable[[Pair], torch.Tensor], pairs: Sequence[Pair],
             progress: Callable[[str], None] = lambda m: None) -> MethodRun:
    """Run ``method`` on every pair (timed), never crash: a failure is recorded and the input is
    scored in its place; non-finite outputs are counted and zeroed."""
    preds, gained, targets, masks, seconds, failures, nonfinite = [], [], [], [], [], [], 0
    t_report = time.perf_counter()
    for i, p in enumerate(pairs):
        t0 = time.perf_counter()
        try:
            with torch.no_grad():
                out = method(p)
        except Exception as err:  # noqa: BLE001 - the benchmark reports failures instead of dying
            failures.append(f"{p.key}: {type(err).__name__}: {err}")
            out = p.image()
        seconds.append(time.perf_counter() - t0)
        if out.shape != p.image().shape:
            failures.append(f"{p.key}: output shape {tuple(out.shape)} != input {tuple(p.image().shape)}")
            out = p.image()
        if not bool(torch.isfinite(out).all()):
            nonfinite += 1
            out = torch.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)
        fg, tgt = p.foreground(), p.target_display()
        preds.append(torch.where(fg, p.display(out.float()), tgt))
        gained.append(torch.where(fg, p.display_at_best_gain(out.float()), tgt))
        targets.append(tgt)
        masks.append(fg)
        if time.perf_counter() - t_report > 30:
            progress(f"  {name}: {i + 1}/{len(pairs)} pairs")
            t_report = time.perf_counter()
    values = score(preds, targets, masks)
    values.update({"gain_" + k: v for k, v in score(gained, targets, masks,
                                                     which=[m.removeprefix("gain_") for m in GAIN_METRICS]).items()})
    return MethodRun(name, [p.key for p in pairs], values, seconds, nonfinite, failures, method)


def spread(n: int, k: int) -> list[int]:
    """``k`` indices evenly spread over ``range(n)`` (all of them if ``k >= n``)."""
    if k >= n:
        return list(range(n))
    return sorted(set(np.linspace(0, n - 1, k).round().astype(int).tolist()))


# ----------------------------------------------------------------------------- the run


def gather_views(level: BenchLevel, data: str | Path | None,
                 progress: Callable[[str], None]) -> tuple[list[BenchView], dict[str, Any]]:
    """The views of a run and a description of where they come from."""
    kw = {"spp": level.spp, "env_res": level.env_res, "texture_size": level.texture_size}
    views: list[BenchView] = []
    info: dict[str, Any] = {}
    if data is None and level.base is None:
        data = DEFAULT_FULL_DATA
    t0 = time.perf_counter()
    if data is not None:
        views += load_dataset(data, max_scenes=level.data_scenes)
        info["data"] = str(data)
        info["data_scenes"] = len({v.scene for v in views})
    else:
        views += render_recipes(level.base, progress, **kw)
        info["data"] = None
        info["generated_base"] = [r.name for r in level.base]
    views += render_recipes(level.extra, progress, **kw)
    info["generated"] = [{"name": r.name, "group": r.group, "views": r.views, "glossy_fraction": r.glossy_fraction,
                          "albedo_scale": r.albedo_scale, "lights": [l.__dict__ for l in r.lights]}
                         for r in (level.extra + ((level.base or ()) if data is None else ()))]
    info["seconds"] = round(time.perf_counter() - t0, 1)
    return views, info


def run_bench(level: BenchLevel, data: str | Path | None, out_dir: str | Path, command: str, threads: int = 2,
              runs_dir: str | Path = "runs", with_abs: bool = True,
              progress: Callable[[str], None] = print, weights: str | Path | None = None) -> dict[str, Any]:
    """Run the benchmark at ``level`` and write ``bench.md``, ``bench.json`` and ``charts/`` into ``out_dir``.

    ``weights`` is the learned methods' weights folder (:meth:`learned.Relighter.load`; None:
    the shipped ``learned/weights``), so a candidate pipeline is benchmarked without touching them.

    Returns:
        bench.json's content.
    """
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return _run(level, data, out_dir, command, runs_dir, with_abs, progress, weights)
    finally:
        torch.set_num_threads(before)  # the caller's setting (tests run in one process)


def _run(level: BenchLevel, data: str | Path | None, out_dir: str | Path, command: str, runs_dir: str | Path,
         with_abs: bool, progress: Callable[[str], None], weights: str | Path | None = None) -> dict[str, Any]:
    from learned import Relighter
    from synth.backend import load_mitsuba

    from ..common import machine
    from .report import write_report

    relighter = Relighter.load(weights)  # first: a bad weights folder fails before minutes of rendering
    load_mitsuba(differentiable=with_abs)
    t_start = time.perf_counter()
    load_before = os.getloadavg()
    views, data_info = gather_views(level, data, progress)
    progress(f"{len(views)} views ready ({data_info['seconds']:.0f} s)")
    if len({v.name for v in views}) != len(views):
        raise ValueError("view names must be unique: a data folder scene has the name of a generated one")
    variant_views = [v.name for v in views if v.view == 0 and v.group != "timelapse"][: level.variant_views]
    cross, saturated = informative_pairs(cross_pairs(views, VARIANTS, variant_views))
    tl, saturated_tl = informative_pairs(timelapse_pairs(views))
    saturated += saturated_tl
    if saturated:
        progress(f"{len(saturated)} pairs left out: target clipped on the whole foreground")
    pairs = cross + tl  # cross first: an index into cross is an index into pairs

    phases = {"data": data_info["seconds"]}
    t0 = time.perf_counter()
    methods = build_methods(relighter)
    runs: dict[str, MethodRun] = {}
    for name, m in methods.items():
        progress(f"method {name}: {len(pairs)} pairs ...")
        runs[name] = evaluate(name, m, pairs, progress)
    diagnostics = {}
    for shadow in ("sun", "direct"):
        o = OracleSH(shadow)
        diagnostics[o.name] = evaluate(o.name, o, pairs)
    phases["methods"] = round(time.perf_counter() - t0, 1)
    t0 = time.perf_counter()

    # speed vs accuracy: proposed at other working resolutions and with the width-chart inverse nets
    base_idx = [i for i, p in enumerate(cross) if not p.variant]
    sub = [base_idx[i] for i in spread(len(base_idx), level.sweep_pairs)]
    sweep_pairs = [cross[i] for i in sub]
    sweep: list[dict[str, Any]] = []
    notes: list[str] = []
    for r in level.sweep_res:
        if r == relighter.res:
            run = runs["proposed"]
            sel = sub
        else:
            progress(f"sweep: proposed at {r} px ...")
            run = evaluate(f"proposed@{r}", Learned(relighter, "proposed", res=r), sweep_pairs)
            sel = None
        sweep.append({"kind": "resolution", "res": r, "width": int(relighter.inverse.width)
                      if hasattr(relighter.inverse, "width") else None,
                      "l1": run.mean(sel)["l1"], "seconds_per_image": _median([run.seconds[i] for i in sel]
                                                                             if sel is not None else run.seconds)})
    for w in level.sweep_widths:
        path = Path(runs_dir) / f"width_{w}"
        try:
            from learned.networks import load_inverse

            net = load_inverse(path)
        except (FileNotFoundError, ValueError) as err:
            notes.append(f"width {w}: skipped ({path} missing or unreadable: {err})")
            continue
        r2 = copy.copy(relighter)  # the same pipeline with another inverse network
        r2.inverse = net
        progress(f"sweep: proposed with the width-{w} inverse net ...")
        run = evaluate(f"proposed_w{w}", Learned(r2, "proposed"), sweep_pairs)
        sweep.append({"kind": "width", "res": relighter.res, "width": w, "run": str(path), "l1": run.mean()["l1"],
                      "seconds_per_image": _median(run.seconds)})
    phases["sweep"] = round(time.perf_counter() - t0, 1)
    t0 = time.perf_counter()
    sweep_methods = {name: {"l1": runs[name].mean(sub)["l1"], "seconds_per_image": _median(runs[name].seconds)}
                     for name in runs}

    # analysis by synthesis on a few source photos (each relit to all its targets)
    abs_result: dict[str, Any] | None = None
    if with_abs and level.abs_sources > 0:
        abs_result = _run_abs(level, cross, runs, progress)
    phases["analysis_by_synthesis"] = round(time.perf_counter() - t0, 1)

    report = {
        "format": "physrelight-bench", "version": 1, "command": command, "level": level.to_json(),
        "machine": {**machine(), "torch_threads": torch.get_num_threads(),
                    "load_average_before": [round(x, 2) for x in load_before],
                    "load_average_after": [round(x, 2) for x in os.getloadavg()],
                    "shared": "the machine is shared with other jobs: timings are medians and indicative"},
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "data": {**data_info, "views": len(views), "pairs": describe_pairs(pairs),
                 "saturated_pairs": len(saturated), "saturated_pair_keys": saturated},
        "renderer_weights": relighter.renderer is not None, "phase_seconds": phases,
        "renderer_base": relighter.renderer_base,
        "weights": "learned/weights" if weights is None else str(weights),
    }
    report["seconds"] = round(time.perf_counter() - t_start, 1)
    return write_report(out_dir, report, pairs, runs, diagnostics, sweep, sweep_methods, len(sub), notes,
                        abs_result, progress)


def _median(xs: Sequence[float]) -> float:
    return float(statistics.median(xs)) if xs else math.nan


def _run_abs(level: BenchLevel, cross: list[Pair], runs: dict[str, MethodRun],
             progress: Callable[[str], None]) -> dict[str, Any]:
    """Fit ``level.abs_sources`` source photos (distinct scenes, varied lightings) and relight them."""
    base = [p for p in cross if not p.variant and p.view.physical is not None]
    # One photo per scene, in data order, cycling through the lightings so the kinds vary (deterministic).
    sources: list[tuple[str, int]] = []
    for p in base:
        if p.view.scene in {n.split("/")[0] for n, _ in sources}:
            continue
        sources.append((p.view.name, len(sources) % p.view.num_lights))
        if len(sources) >= level.abs_sources:
            break
    chosen = [p for p in base if (p.view.name, p.source) in sources]
    method = AnalysisBySynthesis(steps=level.abs_steps, fit_spp=level.abs_spp)
    progress(f"method {ABS_NAME}: {len(sources)} photos fitted, {len(chosen)} pairs ...")
    run = evaluate(ABS_NAME, method, chosen, progress)
    same = {name: r.mean([r.keys.index(k) for k in run.keys]) for name, r in runs.items()}
    return {"run": run, "photos": len(sources), "pairs": len(chosen), "fit_seconds": method.fit_seconds,
            "render_seconds": method.render_seconds, "final_loss": method.final_loss,
            "seconds_per_image": method.seconds_per_image(), "same_pairs": same, "steps": level.abs_steps,
            "spp": level.abs_spp, "sources": [f"{n}:{l}" for n, l in sources]}
