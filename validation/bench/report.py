"""``bench.md`` (the paper's table layouts, verdicts, strata, charts inline), ``bench.json`` and the charts."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from physrelight import io

from .. import charts
from ..common import jsonable, machine_line
from .methods import ABS_NAME, METHODS, TRACKS
from .protocols import Pair
from .strata import STRATA, members

if TYPE_CHECKING:
    from .scores import MethodRun

DEGRADES = 1.25
"""A method *degrades* on a stratum when its l1 there exceeds its all-data l1 by this factor."""

LABELS = {"l1": "l1", "mse": "MSE", "ssim": "SSIM", "dssim": "DSSIM", "psnr": "PSNR (dB)", "ciede2000": "CIEDE2000"}
KIND_ORDER = ("sunsky", "evening", "overcast", "hdri")


def _paired(a: "MethodRun", b: "MethodRun", pairs: list[Pair], idx: Sequence[int]) -> dict[str, Any]:
    """Method ``a`` against ``b`` on the pairs ``idx``, l1: the mean difference ``a - b`` (negative:
    ``a`` is better), the pairs and the scenes where ``a`` is better, and the standard error of the
    mean over scenes (each scene's mean difference is one sample)."""
    d = a.values["l1"][list(idx)] - b.values["l1"][list(idx)]
    scenes: dict[str, list[float]] = {}
    for i, x in zip(idx, d):
        scenes.setdefault(pairs[i].view.scene, []).append(float(x))
    per_scene = np.array([np.mean(v) for v in scenes.values()])
    se = float(per_scene.std(ddof=1) / math.sqrt(len(per_scene))) if len(per_scene) > 1 else math.nan
    return {"mean_diff": float(d.mean()) if len(d) else math.nan, "pairs": int(len(d)),
            "pairs_better": int((d < 0).sum()), "scenes": int(len(per_scene)),
            "scenes_better": int((per_scene < 0).sum()), "scene_mean_diff": float(per_scene.mean())
            if len(per_scene) else math.nan, "scene_se": se}


def _fmt(x: float, metric: str = "l1") -> str:
    if x is None or not math.isfinite(x):
        return "n/a"
    if metric == "psnr":
        return f"{x:.2f}"
    if metric == "ciede2000":
        return f"{x:.2f}"
    if metric in ("ssim",):
        return f"{x:.3f}"
    return f"{x:.4f}"


def _entry(run: "MethodRun", idx: Sequence[int]) -> dict[str, Any]:
    d = run.mean(idx)
    d["pairs"] = len(idx)
    return d


def write_report(out_dir: str | Path, report: dict[str, Any], pairs: list[Pair], runs: dict[str, "MethodRun"],
                 diagnostics: dict[str, "MethodRun"], sweep: list[dict[str, Any]], sweep_methods: dict[str, Any],
                 sweep_pairs: int, notes: list[str], abs_result: dict[str, Any] | None,
                 progress: Callable[[str], None] = print) -> dict[str, Any]:
    """Fill ``report`` (bench.json) with every figure and write bench.md and the charts into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    strata = members(pairs)
    all_idx = strata["all"]
    tl_idx = [i for i, p in enumerate(pairs) if p.protocol == "timelapse"]
    kinds = [k for k in KIND_ORDER if any(pairs[i].view.lights[pairs[i].source].kind == k for i in all_idx)]
    by_kind = {k: [i for i in all_idx if pairs[i].view.lights[pairs[i].source].kind == k] for k in kinds}

    methods: dict[str, Any] = {}
    for name, run in runs.items():
        e = _entry(run, all_idx)
        e["seconds_per_image"] = float(np.median(run.seconds)) if run.seconds else math.nan
        e["nonfinite"] = run.nonfinite
        e["failures"] = len(run.failures)
        e["timelapse"] = _entry(run, tl_idx) if tl_idx else None
        e["by_source_lighting"] = {k: _entry(run, ix) for k, ix in by_kind.items()}
        methods[name] = e
    if abs_result is not None:
        r = abs_result["run"]
        e = _entry(r, list(range(len(r.keys))))
        e.update(seconds_per_image=abs_result["seconds_per_image"], nonfinite=r.nonfinite, failures=len(r.failures),
                 photos=abs_result["photos"], subset=True, fit_seconds=abs_result["fit_seconds"],
                 render_seconds=abs_result["render_seconds"], final_photo_loss=abs_result["final_loss"],
                 steps=abs_result["steps"], spp=abs_result["spp"], sources=abs_result["sources"],
                 same_pairs_other_methods=abs_result["same_pairs"])
        methods[ABS_NAME] = e

    strata_json: dict[str, Any] = {}
    plain = {(p.view.name, p.source, p.target, p.protocol): i for i, p in enumerate(pairs) if not p.variant}
    for key, desc, _ in STRATA:
        ix = strata[key]
        # A source variant is also compared with the same pairs' photos as rendered (the all-data
        # figure mixes in other views).
        same = [plain[(pairs[i].view.name, pairs[i].source, pairs[i].target, pairs[i].protocol)] for i in ix
                if pairs[i].variant]
        entry: dict[str, Any] = {"description": desc, "pairs": len(ix), "methods": {}}
        for name, run in runs.items():
            if not ix:
                continue
            m = _entry(run, ix)
            base = methods[name]["l1"]
            m["l1_vs_all"] = m["l1"] / base if base > 0 else math.nan
            m["l1_minus_all"] = m["l1"] - base
            if same:
                ref = float(np.mean(run.values["l1"][same]))
                m["l1_same_pairs_as_rendered"] = ref
                m["l1_vs_same_pairs"] = m["l1"] / ref if ref > 0 else math.nan
            entry["methods"][name] = m
        strata_json[key] = entry

    l1 = {n: methods[n]["l1"] for n in runs}
    physics_ok = l1["oracle_sh_shadow"] < l1["oracle_sh"]
    proposed_ok = l1["proposed"] < l1["lambertian_sh"] and l1["proposed"] < l1["identity"]
    finite_ok = all(r.nonfinite == 0 and not r.failures for r in list(runs.values()) + list(diagnostics.values())) \
        and all(np.all(np.isfinite(v)) for r in runs.values() for v in r.values.values())
    if abs_result is not None:
        finite_ok = finite_ok and abs_result["run"].nonfinite == 0 and not abs_result["run"].failures
    # How sure the ordering is: per-pair differences are not independent (the pairs of one scene
    # share its photo and decomposition), so the scene is the unit: its mean l1 difference.
    paired = {other: _paired(runs["proposed"], runs[other], pairs, all_idx) for other in ("lambertian_sh", "identity")}
    verdicts = {
        "physics_ordering": {"passed": bool(physics_ok), "what": "oracle_sh_shadow l1 < oracle_sh l1 (all data)",
                             "values": [l1["oracle_sh_shadow"], l1["oracle_sh"]]},
        "proposed_ordering": {"passed": bool(proposed_ok),
                              "what": "proposed l1 < lambertian_sh l1 and proposed l1 < identity l1 (all data)",
                              "values": [l1["proposed"], l1["lambertian_sh"], l1["identity"]],
                              "paired": paired},
        "finite": {"passed": bool(finite_ok), "what": "no failure and no NaN/inf output for any method on any pair"},
    }
    if "quotient" in runs:
        # The shipped renderer is a learned gain on the quotient image (study 29): it must improve on that base.
        verdicts["renderer_ordering"] = {
            "passed": bool(l1["proposed"] < l1["quotient"]),
            "what": "proposed l1 < quotient l1: the renderer improves on the quotient image it multiplies "
                    "(estimated track, all data)",
            "values": [l1["proposed"], l1["quotient"]],
            "paired": {"quotient": _paired(runs["proposed"], runs["quotient"], pairs, all_idx)}}
    report.update(methods=methods, strata=strata_json, verdicts=verdicts,
                  protocols={"cross": {"pairs": len(all_idx),
                                       "source_lightings": {k: len(v) for k, v in by_kind.items()}},
                             "timelapse": {"pairs": len(tl_idx)}},
                  diagnostics={n: {**_entry(r, all_idx), "by_target_lighting": _by_target(r, pairs, all_idx)}
                               for n, r in diagnostics.items()},
                  oracle_by_target_lighting={n: _by_target(runs[n], pairs, all_idx) for n in ("oracle_sh",
                                                                                             "oracle_sh_shadow")},
                  speed={"sweep": sweep, "methods": sweep_methods, "pairs": sweep_pairs, "notes": notes},
                  failures={n: r.failures[:20] for n, r in runs.items() if r.failures})

    ctx = SimpleNamespace(machine=report["machine"], command=report["command"], chart_dir=out / "charts")
    ctx.chart_dir.mkdir(parents=True, exist_ok=True)
    chart_paths = [
        (_speed_chart(ctx, sweep, sweep_methods, sweep_pairs, methods.get(ABS_NAME)),
         "Seconds per image against l1 (lower left is better). Methods on the sweep's pairs; the lines sweep "
         "`proposed` over working resolution and inverse-network width."),
        (_strata_chart(ctx, strata_json, methods), "l1 on each stratum divided by the method's all-data l1 "
         f"(1 = no change; above the dashed line at {DEGRADES} the method degrades)."),
        (_panel(ctx, pairs, runs, all_idx), "One cross-relighting pair: source photo, path-traced target and each "
         "method's output (display values; sky pixels are the input's)."),
    ]
    report["charts"] = [p for p, _ in chart_paths]
    report = jsonable(report)
    io.write_json(out / "bench.json", report)
    (out / "bench.md").write_text(markdown(report, chart_paths))
    return report


def _by_target(run: "MethodRun", pairs: list[Pair], idx: Sequence[int]) -> dict[str, float]:
    out = {}
    for k in KIND_ORDER:
        ix = [i for i in idx if pairs[i].view.lights[pairs[i].target].kind == k]
        if ix:
            out[k] = float(np.mean(run.values["l1"][ix]))
    return out


# ----------------------------------------------------------------------------- markdown


def _method_rows(report: dict[str, Any], names: Sequence[str]) -> list[str]:
    return [n for n in names if n in report["methods"]]


def markdown(report: dict[str, Any], chart_paths: list[tuple[str, str]]) -> str:
    """The bench report (``report.md``) from its JSON and the charts' ``(title, path)``."""
    m, mach, v = report["methods"], report["machine"], report["verdicts"]
    names = _method_rows(report, METHODS)
    lines = ["# physrelight relighting benchmark", "",
             f"- Command: `{report['command']}`",
             f"- Machine: {machine_line(mach)}; Python {mach.get('python')}, torch {mach.get('torch')}, "
             f"{mach.get('torch_threads')} torch threads; load average {mach.get('load_average_before')} before, "
             f"{mach.get('load_average_after')} after ({mach.get('shared')})",
             f"- Date: {report['date']}; {report['seconds']:.0f} s in all", ""]
    d = report["data"]
    src = f"`{d['data']}` ({d.get('data_scenes')} scenes)" if d.get("data") else \
        f"generated scenes {', '.join(d.get('generated_base', []))}"
    lines += [f"Data: {src} plus generated strata and time-lapse scenes "
              f"({', '.join(g['name'] for g in d['generated'] if g['name'] not in d.get('generated_base', []))}), "
              f"{d['views']} views, 64 px. Pairs: "
              + ", ".join(f"{k} {x['pairs']} ({x['views']} views)" for k, x in d["pairs"].items()) + ".", ""]
    lines += ["Protocol: the source is the LDR photo; the target is the path-traced radiance under the other "
              "lighting with the source photo's exposure and white balance, sRGB, clipped; metrics on foreground "
              "pixels (not sky, valid normal) of display values. Methods get the camera-frame SH of the target and "
              "source lightings in the photo's linear units. Seconds per image: median over pairs, one image per "
              "call, decomposition included.", ""]
    lines += ["## Verdicts", ""]
    for key, label in (("physics_ordering", "Physics ordering"), ("proposed_ordering", "Proposed vs baselines"),
                       ("renderer_ordering", "Renderer vs its quotient base"), ("finite", "No crash, no NaN")):
        if key not in v:
            continue
        x = v[key]
        subject = x.get("subject", "proposed")
        vals = ""
        if x.get("values"):
            vals = " (" + ", ".join(_fmt(y) for y in x["values"]) + ")"
        lines.append(f"- **{label}: {'PASS' if x['passed'] else 'FAIL'}**: {x['what']}{vals}")
        for other, q in x.get("paired", {}).items():
            lines.append(f"  - {subject} - {other}: l1 {q['mean_diff']:+.4f} on average; {subject} better on "
                         f"{q['pairs_better']} of {q['pairs']} pairs and {q['scenes_better']} of {q['scenes']} scenes "
                         f"(scene means {q['scene_mean_diff']:+.4f} +- {q['scene_se']:.4f} s.e.)")
    if report.get("renderer_weights"):
        lines.append(f"- `proposed` runs the neural renderer of `{report.get('weights', 'learned/weights')}`: "
                     + ("a learned gain on the `quotient` image (the sun by its exact cosine, as `quotient` has it), "
                        "given the decomposition and ShadowNet's target shadow; with its gain at zero it is `quotient`."
                        if report.get("renderer_base") == "quotient" else
                        "a gain on the Lambertian render of the decomposition with ShadowNet's target shadow; "
                        "`shadownet_lambertian` is the same pipeline with the Lambertian image model in place of the "
                        "renderer."))
    else:
        lines.append("- No neural-renderer weights are shipped yet: `proposed` falls back to "
                     "`shadownet_lambertian` (identical numbers, see learned/relighter.py).")
    lines.append("")

    # Table 2 layout: methods x source lighting
    kinds = list(report["protocols"]["cross"]["source_lightings"])
    lines += ["## Cross-relighting (the paper's Table 2 layout)", "",
              "Each view under each source lighting relit to every other lighting of its scene. Cells: l1 / SSIM, "
              "by the source photo's lighting kind.", "",
              "| track | method | " + " | ".join(f"{k} ({report['protocols']['cross']['source_lightings'][k]})"
                                                 for k in kinds)
              + " | all |", "| --- | --- |" + " ---: |" * (len(kinds) + 1)]
    track_of = {n: t for t, ns in TRACKS.items() for n in ns}
    for n in names:
        cells = [f"{_fmt(m[n]['by_source_lighting'][k]['l1'])} / {_fmt(m[n]['by_source_lighting'][k]['ssim'], 'ssim')}"
                 for k in kinds]
        lines.append(f"| {track_of.get(n, '')} | {n} | " + " | ".join(cells)
                     + f" | {_fmt(m[n]['l1'])} / {_fmt(m[n]['ssim'], 'ssim')} |")
    lines += ["", "All metrics, all cross-relighting pairs, by lighting track (*estimated*: only the target lighting "
              "is given, its level from the given source; *known*: the photo's own lighting is given too; *oracle*: "
              "ground-truth albedo and normals). The last three columns are exposure-invariant: l1, SSIM and PSNR "
              "after the output's best single gain per image (the gain minimising its foreground l1, searched "
              "from the least-squares gain in linear radiance), i.e. structure apart from level:", "",
              "| track | method | " + " | ".join(LABELS[k] for k in LABELS)
              + " | s / image | l1 at best gain | SSIM at best gain | PSNR at best gain |",
              "| --- | --- |" + " ---: |" * 10]
    for n in names:
        gain = " | ".join(_fmt(m[n].get("gain_" + k, math.nan), k) for k in ("l1", "ssim", "psnr"))
        lines.append(f"| {track_of.get(n, '')} | {n} | " + " | ".join(_fmt(m[n][k], k) for k in LABELS) +
                     f" | {m[n]['seconds_per_image']:.3f} | {gain} |")
    ot = report["oracle_by_target_lighting"]
    diag = report["diagnostics"]
    lines += ["", "The oracles by *target* lighting kind (l1). `oracle_sh_shadow` multiplies the sun's light by its "
              "true visibility and leaves the sky's light alone (without a sun: the true direct-light ratio). "
              "Diagnostics: multiplying the *whole* SH shading by the sun's visibility (`shadow.exr`) or by the "
              "direct-light ratio (`direct_shadow.exr`), i.e. the paper's `s * albedo * shading` with those "
              "shadows:", "",
              "| oracle | " + " | ".join(ot["oracle_sh"]) + " | all |",
              "| --- |" + " ---: |" * (len(ot["oracle_sh"]) + 1)]
    for n in ("oracle_sh", "oracle_sh_shadow"):
        lines.append(f"| {n} | " + " | ".join(_fmt(ot[n][k]) for k in ot["oracle_sh"]) + f" | {_fmt(m[n]['l1'])} |")
    for n, x in diag.items():
        lines.append(f"| {n} (diagnostic) | " + " | ".join(_fmt(x['by_target_lighting'].get(k, math.nan))
                                                           for k in ot["oracle_sh"]) + f" | {_fmt(x['l1'])} |")

    # Table 1 layout: time-lapse
    if report["protocols"]["timelapse"]["pairs"]:
        lines += ["", "## Time-lapse (the paper's Table 1 layout)", "",
                  "One view, the sun moving through a day (clear sky, 40 deg N); every frame relit with the lighting "
                  f"of every other frame: {report['protocols']['timelapse']['pairs']} pairs.", "",
                  "| method | " + " | ".join(LABELS[k] for k in LABELS) + " |", "| --- |" + " ---: |" * 6]
        for n in names:
            t = m[n]["timelapse"]
            lines.append(f"| {n} | " + " | ".join(_fmt(t[k], k) for k in LABELS) + " |")

    # analysis by synthesis
    if ABS_NAME in m:
        a = m[ABS_NAME]
        same = a["same_pairs_other_methods"]
        lines += ["", "## Analysis by synthesis (differentiable path tracing)", "",
                  f"`{ABS_NAME}`: {a['photos']} source photos fitted ({a['steps']} Adam steps at {a['spp']} spp, "
                  f"textures from grey, sky map and sun irradiance from the given source lighting), each re-rendered "
                  f"under all its targets: {a['pairs']} pairs ({', '.join(a['sources'])}). The other methods on the "
                  "same pairs:", "",
                  "| method | l1 | SSIM | PSNR (dB) | CIEDE2000 | s / image |",
                  "| --- | ---: | ---: | ---: | ---: | ---: |",
                  f"| {ABS_NAME} | {_fmt(a['l1'])} | {_fmt(a['ssim'], 'ssim')} | {_fmt(a['psnr'], 'psnr')} | "
                  f"{_fmt(a['ciede2000'], 'ciede2000')} | {a['seconds_per_image']:.2f} |"]
        for n in names:
            lines.append(f"| {n} | {_fmt(same[n]['l1'])} | {_fmt(same[n]['ssim'], 'ssim')} | "
                         f"{_fmt(same[n]['psnr'], 'psnr')} | {_fmt(same[n]['ciede2000'], 'ciede2000')} | "
                         f"{m[n]['seconds_per_image']:.3f} |")
        fit = a["fit_seconds"]
        lines += ["", f"Fit {np.median(fit):.1f} s per photo (median of {len(fit)}), final render "
                  f"{np.median(a['render_seconds']):.2f} s per target; final relative photo loss "
                  + ", ".join(f"{x:.4f}" for x in a["final_photo_loss"]) + "."]

    # speed vs accuracy
    sp = report["speed"]
    lines += ["", "## Speed vs accuracy", "",
              f"Seconds per image (median, {mach.get('torch_threads')} torch threads) against l1 on {sp['pairs']} "
              "cross-relighting pairs spread over the data. `proposed` is swept over working resolution (the photo "
              "resampled so its short side is the resolution, relit there, brought back by ratio transfer) and over "
              "the inverse network's width (`runs/width_W`: the width chart's nets, trained 500 steps, swapped into the "
              "otherwise unchanged pipeline: the shipped ShadowNet"
              + (" and neural renderer, which were trained on the shipped inverse net's decompositions" if
                 report.get("renderer_weights") else "") + ").", "",
              "| setting | working res | inverse width | l1 | s / image |", "| --- | ---: | ---: | ---: | ---: |"]
    for s in sp["sweep"]:
        lines.append(f"| proposed ({s['kind']}) | {s['res']} | {s['width']} | {_fmt(s['l1'])} | "
                     f"{s['seconds_per_image']:.3f} |")
    for n, s in sp["methods"].items():
        lines.append(f"| {n} | 64 | | {_fmt(s['l1'])} | {s['seconds_per_image']:.3f} |")
    for note in sp["notes"]:
        lines.append(f"\nNote: {note}")

    # strata
    lines += ["", "## Failure modes (strata)", "",
              f"l1 on each stratum and, in brackets, its ratio to the method's all-data l1 (**bold**: degrades by more "
              f"than {int(round((DEGRADES - 1) * 100))} %). Non-finite outputs and failures: counted over every pair "
              "(see the verdict above).", "",
              "| stratum | pairs | " + " | ".join(names) + " |", "| --- | ---: |" + " ---: |" * len(names)]
    for key, desc, _ in STRATA:
        s = report["strata"][key]
        if not s["pairs"]:
            lines.append(f"| {key} | 0 | " + " | ".join("no pairs" for _ in names) + " |")
            continue
        cells = []
        for n in names:
            x = s["methods"][n]
            r = x["l1_vs_all"]
            txt = f"{_fmt(x['l1'])} (x{r:.2f}"
            if "l1_vs_same_pairs" in x:
                txt += f"; x{x['l1_vs_same_pairs']:.2f} same photos"
            txt += ")"
            cells.append(f"**{txt}**" if r > DEGRADES else txt)
        lines.append(f"| {key} | {s['pairs']} | " + " | ".join(cells) + " |")
    lines += ["", "For the source variants (dark input, noise + JPEG, on the first view of some scenes) the second "
              "ratio compares with the same pairs relit from the photo as rendered.", "", "Strata:", ""]
    lines += [f"- `{k}`: {d}" for k, d, _ in STRATA]
    worst = []
    for n in names:
        bad = [(k, report["strata"][k]["methods"][n]["l1_vs_all"]) for k, _, _ in STRATA
               if report["strata"][k]["pairs"] and report["strata"][k]["methods"][n]["l1_vs_all"] > DEGRADES]
        if bad:
            worst.append(f"- `{n}` degrades on " + ", ".join(f"{k} (+{(r - 1) * 100:.0f} %)" for k, r in bad))
    lines += ["", "Where the methods degrade (l1 above the all-data figure by more than "
              f"{int(round((DEGRADES - 1) * 100))} %):", ""] + (worst or ["- nowhere"])
    lines.append("")
    for path, caption in chart_paths:
        lines += [f"![{caption}]({path})", "", f"*{caption}*", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- charts


def _speed_chart(ctx: Any, sweep: list[dict[str, Any]], methods: dict[str, Any], n: int,
                 abs_entry: dict[str, Any] | None) -> str:
    fig, ax = charts.figure(8.0, 4.8)
    for i, (name, s) in enumerate(methods.items()):
        if math.isfinite(s["l1"]):
            ax.scatter([max(s["seconds_per_image"], 1e-5)], [s["l1"]], color=f"C{i}", label=name, zorder=3)
    for kind, marker in (("resolution", "o-"), ("width", "s--")):
        pts = [s for s in sweep if s["kind"] == kind]
        if len(pts) > 1:
            pts = sorted(pts, key=lambda s: s["seconds_per_image"])
            ax.plot([s["seconds_per_image"] for s in pts], [s["l1"] for s in pts], marker, color="0.3", lw=1,
                    ms=4, label=f"proposed: {kind} sweep")
            for s in pts:
                txt = f"{s['res']} px" if kind == "resolution" else f"w{s['width']}"
                ax.annotate(txt, (s["seconds_per_image"], s["l1"]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")
    if abs_entry is not None and math.isfinite(abs_entry.get("seconds_per_image", math.nan)):
        ax.scatter([abs_entry["seconds_per_image"]], [abs_entry["l1"]], marker="*", s=120, color="k",
                   label=f"{ABS_NAME} ({abs_entry['pairs']} pairs)", zorder=3)
    ax.set_xscale("log")
    ax.set_xlabel("seconds per image (median, log scale)")
    ax.set_ylabel(f"l1 on foreground, display values ({n} pairs)")
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)
    return charts.save(fig, ctx, "speed_accuracy", "Relighting: speed vs accuracy")


def _strata_chart(ctx: Any, strata: dict[str, Any], methods: dict[str, Any]) -> str:
    names = [n for n in METHODS if n in methods]
    keys = [k for k, _, _ in STRATA if strata[k]["pairs"]]
    fig, ax = charts.figure(9.0, 4.4)
    w = 0.8 / max(len(names), 1)
    for i, n in enumerate(names):
        x = np.arange(len(keys)) + (i - (len(names) - 1) / 2) * w
        ax.bar(x, [strata[k]["methods"][n]["l1_vs_all"] for k in keys], w, label=n, color=f"C{i}")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.axhline(DEGRADES, color="k", lw=0.8, ls="--")
    ax.set_xticks(np.arange(len(keys)), keys, rotation=25, ha="right", fontsize=8)
    ax.set_xlabel("stratum")
    ax.set_ylabel("l1 on the stratum / all-data l1")
    ax.legend(fontsize=7, ncol=3)
    return charts.save(fig, ctx, "strata", "Failure modes: degradation per stratum")


def _panel(ctx: Any, pairs: list[Pair], runs: dict[str, "MethodRun"], idx: Sequence[int]) -> str:
    import torch

    # The pair of a Lambertian view where the oracle with shadow gains most over the plain oracle: shadows visible.
    idx = [i for i in idx if pairs[i].view.glossy_share() < 0.2] or list(idx)
    gain = runs["oracle_sh"].values["l1"][idx] - runs["oracle_sh_shadow"].values["l1"][idx]
    p = pairs[idx[int(np.argmax(gain))]]
    imgs = [("source photo", p.photo), ("target (path traced)", p.target_display()[0].permute(1, 2, 0).numpy())]
    for n, r in runs.items():
        method = getattr(r, "method", None)
        if method is None:
            continue
        with torch.no_grad():
            out = p.display(method(p))[0].permute(1, 2, 0).numpy()
        imgs.append((n, out))
    fig, axes = charts.figure(2.0 * len(imgs), 2.6, ncols=len(imgs))
    for ax, (title, img) in zip(axes, imgs):
        ax.imshow(np.clip(img, 0, 1))
        ax.set_title(title, fontsize=7)
        ax.set_xlabel("x (px)", fontsize=6)
        ax.set_ylabel("y (px)", fontsize=6)
        ax.tick_params(labelsize=5)
    return charts.save(fig, ctx, "panel", f"Example: {p.key} ({p.view.lights[p.source].label} -> "
                       f"{p.view.lights[p.target].label})")
