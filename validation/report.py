"""Run the checks and write ``report.md``, ``report.json`` and the charts.

``report.md`` reads on its own: what was checked, the numbers, a verdict per check
with its tolerance and where the tolerance comes from, the charts inline.
``report.json`` holds every figure; its top level also carries the headline keys
``sphere_pathtrace_over_exact``, ``sh_irradiance_error``, ``shadow_free_loss`` and
``lighting_solve_rel_error``.
"""

from __future__ import annotations

import datetime
import importlib
from pathlib import Path
from typing import Any, Callable, Sequence

from physrelight import io

from .checks import CHECKS, check_keys
from .common import CheckResult, Context, Level, Stopwatch, jsonable, machine, machine_line, md_cell

HEADLINE = {
    "sphere_pathtrace_over_exact": ("renderer_irradiance", "sphere_pathtrace_over_exact"),
    "sh_irradiance_error": ("sh_model", "sh_irradiance_error"),
    "shadow_free_loss": ("shadow_loss", "shadow_free_loss"),
    "lighting_solve_rel_error": ("lighting_solve", "lighting_solve_rel_error"),
}


def run_checks(level: Level, out_dir: str | Path, command: str, selection: Sequence[str] | None = None,
               progress: Callable[[str], None] = print) -> dict[str, Any]:
    """Run the selected checks at ``level``, write the report into ``out_dir``; return report.json's content."""
    keys = check_keys(selection)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    import synth.backend  # noqa: F401  (Mitsuba loads here, so machine() can name its version)

    synth.backend.load_mitsuba()
    ctx = Context(level=level, out_dir=out, command=command, machine=machine(), progress=progress)
    ctx.shared["results"] = {}
    results: list[CheckResult] = []
    with Stopwatch() as total:
        for i, (key, module, _) in enumerate(CHECKS, start=1):
            if key not in keys:
                continue
            progress(f"check {i}/{len(CHECKS)}: {key} ...")
            with Stopwatch() as t:
                res = importlib.import_module(module).run(ctx)
            res.seconds = t.seconds
            ctx.shared["results"][key] = res
            results.append(res)
            n_ok = sum(v.passed for v in res.verdicts)
            progress(f"check {i}/{len(CHECKS)}: {key}: {res.status} ({n_ok}/{len(res.verdicts)} verdicts, "
                     f"{t.seconds:.0f} s)")
    report = build_json(ctx, results, total.seconds)
    io.write_json(out / "report.json", report)
    (out / "report.md").write_text(build_markdown(ctx, results, total.seconds))
    return report


def build_json(ctx: Context, results: list[CheckResult], seconds: float) -> dict[str, Any]:
    """``physrelight validate``'s JSON report of ``results``."""
    by_key = {r.key: r for r in results}
    report: dict[str, Any] = {
        "format": "physrelight-validation", "version": 1,
        "command": ctx.command, "level": ctx.level.to_json(), "machine": ctx.machine,
        "date": datetime.datetime.now().isoformat(timespec="seconds"), "seconds": round(seconds, 1),
        "passed": all(r.passed for r in results),
        "checks": {r.key: r.to_json() for r in results},
    }
    for name, (key, fig) in HEADLINE.items():
        if key in by_key:
            report[name] = jsonable(by_key[key].figures.get(fig))
    if "bank" in ctx.shared:
        report["scene_bank_seconds"] = jsonable(ctx.shared["bank"].seconds)
    return report


def _verdict_table(res: CheckResult, limit: int = 60) -> str:
    rows = ["| verdict | value | tolerance | where the tolerance comes from | |", "| --- | ---: | --- | --- | --- |"]
    ordered = sorted(res.verdicts, key=lambda v: v.passed)  # failures first
    for v in ordered[:limit]:
        rows.append(f"| {md_cell(v.name)} | {v.value:.4g} | {md_cell(v.tolerance)} | {md_cell(v.source)} | "
                    f"{'pass' if v.passed else '**FAIL**'} |")
    if len(ordered) > limit:
        rows.append(f"| ... {len(ordered) - limit} more (all passed; see report.json) | | | | |")
    return "\n".join(rows)


def build_markdown(ctx: Context, results: list[CheckResult], seconds: float) -> str:
    """``physrelight validate``'s Markdown report of ``results``."""
    ok = all(r.passed for r in results)
    lines = [
        "# physrelight validation report", "",
        f"**Overall: {'PASS' if ok else 'FAIL'}** ({ctx.level.name} run, {seconds:.0f} s).", "",
        f"- Command: `{ctx.command}`",
        f"- Machine: {machine_line(ctx.machine)}; Python {ctx.machine.get('python')}, torch "
        f"{ctx.machine.get('torch')} ({ctx.machine.get('torch_threads')} threads)",
        f"- Date: {datetime.datetime.now().isoformat(timespec='minutes')}", "",
        "Every physical assumption of the library is checked against Mitsuba 3 path tracing or against theory. "
        "Each check states what it compares, the numbers, and a verdict whose tolerance comes from Monte Carlo "
        "noise (standard errors from independent renders) or from a theorem, never tuned to pass. Figures that "
        "attribute residuals to their causes are *diagnostic*: reported without a verdict. All numbers are also "
        "in `report.json`.", "",
        "| check | status | verdicts passed | seconds |", "| --- | --- | ---: | ---: |",
    ]
    for r in results:
        lines.append(f"| {r.title} | {r.status} | {sum(v.passed for v in r.verdicts)} / {len(r.verdicts)} | "
                     f"{r.seconds:.0f} |")
    lv = ctx.level
    lines += ["", "Settings: " + ", ".join([
        f"lightings {', '.join(lv.lightings)} (sky maps {lv.env_res} x {2 * lv.env_res})",
        f"convex objects at {lv.convex_res} px, {lv.convex_seeds} renders x {lv.convex_spp} spp",
        f"scene bank: a sphere on the ground (2 views) and generated scenes {', '.join(map(str, lv.scene_seeds))} "
        f"({lv.scene_views} views each) under {', '.join(lv.scene_lightings)}, {lv.scene_res} px, "
        f"{lv.scene_renders} renders x {lv.scene_spp} spp, shadows 2 x {lv.shadow_spp} spp"]) + ".", ""]
    for r in results:
        lines += [f"## {r.title}", "", r.summary, "", f"**Status: {r.status}**"
                  + (f" ({sum(v.passed for v in r.verdicts)}/{len(r.verdicts)} verdicts passed)." if r.verdicts
                     else " (no verdict: measurements only)."), ""]
        for t in r.tables:
            lines += [t, ""]
        for n in r.notes:
            lines += [n, ""]
        for path, caption in r.charts:
            lines += [f"![{caption}]({path})", "", f"*{caption}*", ""]
        if r.verdicts:
            lines += ["<details><summary>All verdicts of this check</summary>", "", _verdict_table(r), "",
                      "</details>", ""]
    return "\n".join(lines)
