"""Check 6: speed against accuracy (measurements, no verdicts: timings depend on the machine).

Three charts, each stating the machine and the command:

* ground-truth error vs samples per pixel vs seconds: the convex sphere of check 1
  under a sunny and an overcast lighting, rendered at every spp of the level's ladder,
  error = rms relative per-pixel error against ``albedo E / pi``; with the cheapest
  spp meeting each check's noise requirement (derived from the measured
  ``error ~ c / sqrt(spp)`` and the figures of checks 1, 3, 4, 5);
* render time vs resolution for a generated scene (path tracing, geometry buffers,
  shadows);
* SH order vs irradiance error vs evaluation time (orders 0-8).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from physrelight import sh
from synth import cameras as _cameras
from synth import render as _render
from synth.scene import generate_scene

from . import charts, scenes
from .common import LUMINANCE, CheckResult, Context
from .renderer_irradiance import MAX_SPREAD, TERMINATOR
from .sh_model import evaluation_seconds, irradiance_errors

SPP_LIGHTINGS = ("sunsky", "overcast")


def _median_time(fn: Any, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def spp_sweep(ctx: Context, lname: str) -> dict[str, Any]:
    """Error and time per spp for the convex sphere under ``lname``."""
    lv = ctx.level
    light = scenes.get_lighting(lname, lv.env_res)
    cam = scenes.convex_view(lv.convex_res)
    scene = _render.build_scene(scenes.convex_spec("sphere"), [cam], light, spp=16)
    geo = _render.render_geometry(scene, 0, cam, spp=64, seed=1)
    spread = scenes.footprint_spread(scene, 0, spp=64, seed=2)
    nw = scenes.world_normals(geo.normal, cam)
    ok = (~geo.sky_mask) & (geo.coverage >= 1 - 1e-6) & (spread < MAX_SPREAD)
    if light.has_sun:
        ok &= np.abs(nw @ light.sun_direction) > TERMINATOR
    exact = (np.asarray(scenes.CONVEX_ALBEDO) * light.irradiance_reference(nw[ok]) / math.pi) @ LUMINANCE
    integ = scenes.path_integrator(8)
    out: dict[str, Any] = {"spp": [], "rms_rel_error": [], "seconds": [], "ratio_se_1_render": []}
    for spp in lv.spp_ladder:
        seeds = list(range(4))
        runs = np.stack([scenes.render_film(scene, integ, 0, spp, 500 + s)[..., :3][ok] @ LUMINANCE for s in seeds])
        secs = _median_time(lambda: scenes.render_film(scene, integ, 0, spp, 999), lv.timing_repeats)
        out["spp"].append(spp)
        out["rms_rel_error"].append(float(np.sqrt((((runs - exact) / exact) ** 2).mean())))
        out["ratio_se_1_render"].append(float((runs.sum(1) / exact.sum()).std(ddof=1)))
        out["seconds"].append(secs)
    # error ~ c / sqrt(spp): fit c in log space
    s, e = np.array(out["spp"], float), np.array(out["rms_rel_error"])
    out["c"] = float(np.exp(np.mean(np.log(e * np.sqrt(s)))))
    out["pixels"] = int(ok.sum())
    out["resolution"] = lv.convex_res
    return out


def cheapest_spp(ctx: Context, sweeps: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Cheapest power-of-two spp meeting each check's noise requirement (variance ~ 1/spp).

    Requirements (stated, then scaled from the noise measured in this run):
    check 1: 4 standard errors of the mean ratio over the level's seeds <= 0.5 %;
    check 3: the noise floor of the consistent model <= 10 % of the loss with the direct ratio;
    check 4: the 4-se solve tolerance (image space) <= 1 %;
    check 5: the noise-limited PSNR >= the paper oracle's PSNR + 10 dB.
    """
    lv = ctx.level
    results = ctx.shared.get("results", {})
    out: dict[str, Any] = {}

    def pow2(x: float) -> int:
        return int(2 ** math.ceil(math.log2(max(1.0, x))))

    se1 = max(np.median([sw["ratio_se_1_render"][i] * math.sqrt(sw["spp"][i]) for i in range(len(sw["spp"]))])
              for sw in sweeps.values())  # se of one render's ratio at 1 spp
    need = (4 * se1 / math.sqrt(lv.convex_seeds) / 0.005) ** 2
    out["check1"] = {"spp": pow2(need), "requirement": "4 se of the mean ratio <= 0.5 %"}
    if "shadow_loss" in results:
        a = results["shadow_loss"].figures["shadow_free_loss"]["attribution_all"]
        ratio = a["noise_floor_direct"] / max(0.1 * a["with_direct_ratio"], 1e-30)
        out["check3"] = {"spp": pow2(lv.scene_spp * ratio),
                         "requirement": "noise floor <= 10 % of the loss with the direct ratio (spp per render, "
                                        f"{lv.scene_renders} renders)"}
    if "lighting_solve" in results:
        tols = [f["direct_vs_exact_tolerance"] - f.get("yardstick_error", 0) - f.get("occlusion_allowance", 0)
                for f in results["lighting_solve"].figures["per_view"] if "direct_vs_exact_tolerance" in f]
        if tols:
            ratio = (float(np.median(tols)) / 0.01) ** 2
            out["check4"] = {"spp": pow2(lv.scene_spp * ratio), "requirement": "4 se of the solve (image space) <= 1 %"}
    if "relight_ceiling" in results:
        c = results["relight_ceiling"].figures["ceiling_all"]
        gap = (c["paper"]["psnr"] + 10.0) - (c["noise_half_means"]["psnr"] + 6.0)  # dB more needed
        out["check5"] = {"spp": pow2(lv.scene_spp * 10 ** (gap / 10)),
                         "requirement": "noise-limited PSNR >= paper oracle PSNR + 10 dB"}
    return out


def resolution_sweep(ctx: Context) -> dict[str, Any]:
    """Seconds per render vs image size for a generated scene (spp 16, shadow spp 16)."""
    lv = ctx.level
    spec = generate_scene(lv.scene_seeds[0])
    light = scenes.get_lighting("sunsky", lv.env_res)
    out: dict[str, Any] = {"res": [], "path": [], "gbuffer": [], "shadow": []}
    for res in lv.res_ladder:
        cam = _cameras.sample_views(spec, 1, seed=lv.scene_seeds[0] + 1000, width=res, height=res)[0]
        scene = _render.build_scene(spec, [cam], light, spp=16)
        integ = scenes.path_integrator(8)
        scenes.render_film(scene, integ, 0, 16, 0)  # warm the kernel cache for this size
        out["res"].append(res)
        out["path"].append(_median_time(lambda: scenes.render_film(scene, integ, 0, 16, 1), lv.timing_repeats))
        out["gbuffer"].append(_median_time(lambda: _render.render_geometry(scene, 0, cam, 16, 2), lv.timing_repeats))
        out["shadow"].append(_median_time(lambda: _render.render_lit(scene, 0, light, 1, 16, 3), lv.timing_repeats))
    return out


def order_sweep(ctx: Context, orders: tuple[int, ...] = tuple(range(9))) -> dict[str, Any]:
    """Irradiance error over the sphere and evaluation time per SH order."""
    lv = ctx.level
    n = sh.fibonacci_sphere(1000)
    out: dict[str, Any] = {"orders": list(orders), "seconds": [evaluation_seconds(o, repeats=lv.timing_repeats)
                                                               for o in orders], "errors": {}}
    for lname in lv.scene_lightings:
        light = scenes.get_lighting(lname, lv.env_res)
        exact = light.irradiance_reference(n)
        power = scenes.total_power(light)
        out["errors"][lname] = [irradiance_errors(exact, np.asarray(sh.irradiance(light.sh(o), n)), power)
                                for o in orders]
    return out


SUMMARY = (
    "What accuracy costs. (a) The ground-truth error of a path-traced image against the exact answer, as a "
    "function of samples per pixel and of seconds, and the cheapest sample count that meets each check's noise "
    "requirement. (b) Render time against image size. (c) SH order against irradiance error and evaluation time. "
    "Timings depend on the machine (stated on every chart), so this check has no verdict."
)


def run(ctx: Context) -> CheckResult:
    """Check 6 at ``ctx.level``: speed against accuracy (see the module's docstring)."""
    res = CheckResult("speed", "6. Speed vs accuracy", SUMMARY)
    ctx.progress("  check 6: spp sweep")
    sweeps = {ln: spp_sweep(ctx, ln) for ln in SPP_LIGHTINGS}
    need = cheapest_spp(ctx, sweeps)
    ctx.progress("  check 6: resolution sweep")
    rs = resolution_sweep(ctx)
    ctx.progress("  check 6: SH order sweep")
    os_ = order_sweep(ctx)
    res.figures = {"spp_sweep": sweeps, "cheapest_spp": need, "resolution_sweep": rs, "order_sweep": os_}
    t = ["| spp | " + " | ".join(f"{ln}: rms rel. error / s per render" for ln in sweeps) + " |",
         "| ---: |" + " ---: |" * len(sweeps)]
    for i, spp in enumerate(ctx.level.spp_ladder):
        t.append(f"| {spp} | " + " | ".join(f"{100 * sw['rms_rel_error'][i]:.1f} % / {sw['seconds'][i]:.3f}"
                                             for sw in sweeps.values()) + " |")
    res.tables.append(f"Sphere of check 1 ({ctx.level.convex_res} px): per-pixel error against albedo E / pi "
                      "and seconds per render:\n\n" + "\n".join(t) + "\n\nFitted error at 1 spp: " + ", ".join(
                          f"{ln} {100 * sw['c']:.0f} %" for ln, sw in sweeps.items()) + " (error ~ c / sqrt(spp)).")
    t = ["| check | requirement | cheapest spp |", "| --- | --- | ---: |"]
    for k, v in need.items():
        t.append(f"| {k} | {v['requirement']} | {v['spp']} |")
    res.tables.append("Cheapest power-of-two spp meeting each check's noise requirement, from the noise measured "
                      "in this run (variance ~ 1/spp):\n\n" + "\n".join(t))
    t = ["| size | path tracing (16 spp) | geometry buffers (16 spp) | shadows (16 spp) |",
         "| ---: | ---: | ---: | ---: |"]
    for i, r in enumerate(rs["res"]):
        t.append(f"| {r} x {r} | {rs['path'][i]:.3f} s | {rs['gbuffer'][i]:.3f} s | {rs['shadow'][i]:.3f} s |")
    res.tables.append("Render time vs resolution, generated scene, sunsky (median of "
                      f"{ctx.level.timing_repeats}):\n\n" + "\n".join(t))
    t = ["| order | shading 256 x 256 | " + " | ".join(f"{ln} mean rel. / max dE/int L" for ln in os_["errors"]) + " |",
         "| ---: | ---: |" + " ---: |" * len(os_["errors"])]
    for i, o in enumerate(os_["orders"]):
        t.append(f"| {o} | {1e3 * os_['seconds'][i]:.1f} ms | " + " | ".join(
            f"{100 * e[i]['mean_rel']:.1f} % / {e[i]['max_fraction']:.3f}" for e in os_["errors"].values()) + " |")
    res.tables.append("SH order vs irradiance error over the sphere vs evaluation time:\n\n" + "\n".join(t))
    res.charts.append((_spp_chart(ctx, sweeps), "Left: rms relative per-pixel error vs spp (dashed: c / sqrt(spp)). "
                       "Right: the same error vs seconds per render."))
    res.charts.append((_res_chart(ctx, rs), "Seconds per render vs image size (log-log)."))
    res.charts.append((_order_chart(ctx, os_), "Mean relative irradiance error over the sphere per SH order "
                       "(left axis) and evaluation time (right axis, black)."))
    res.notes.append("Diagnostic only: no verdict (timings are the machine's, not the code's).")
    return res


def _spp_chart(ctx: Context, sweeps: dict[str, dict[str, Any]]) -> str:
    fig, (a1, a2) = charts.figure(10.0, 4.0, ncols=2)
    for i, (ln, sw) in enumerate(sweeps.items()):
        s = np.array(sw["spp"], float)
        a1.loglog(s, 100 * np.array(sw["rms_rel_error"]), "o-", color=f"C{i}", label=ln)
        a1.loglog(s, 100 * sw["c"] / np.sqrt(s), "--", color=f"C{i}", lw=0.8)
        a2.loglog(sw["seconds"], 100 * np.array(sw["rms_rel_error"]), "o-", color=f"C{i}", label=ln)
    a1.set_xlabel("samples per pixel")
    a2.set_xlabel("seconds per render")
    for a in (a1, a2):
        a.set_ylabel("rms relative error per pixel (%)")
        a.legend(fontsize=8)
    return charts.save(fig, ctx, "check6_spp", "Check 6: path-tracing error vs spp and time (sphere, check 1)")


def _res_chart(ctx: Context, rs: dict[str, Any]) -> str:
    fig, ax = charts.figure(6.5, 4.0)
    for k in ("path", "gbuffer", "shadow"):
        ax.loglog(rs["res"], rs[k], "o-", label=k)
    ax.set_xlabel("image width = height (pixels)")
    ax.set_ylabel("seconds per render (16 spp)")
    ax.legend(fontsize=8)
    return charts.save(fig, ctx, "check6_resolution", "Check 6: render time vs resolution")


def _order_chart(ctx: Context, os_: dict[str, Any]) -> str:
    fig, ax = charts.figure(7.0, 4.0)
    for i, (ln, errs) in enumerate(os_["errors"].items()):
        ax.semilogy(os_["orders"], [100 * e["mean_rel"] for e in errs], "o-", color=f"C{i}", label=ln)
    ax.set_xlabel("SH order")
    ax.set_ylabel("mean relative irradiance error (%)")
    ax.legend(fontsize=8, loc="upper center")
    ax2 = ax.twinx()
    ax2.plot(os_["orders"], [1e3 * s for s in os_["seconds"]], "ks--", ms=4)
    ax2.set_ylabel("shading 256 x 256 (ms)")
    return charts.save(fig, ctx, "check6_order", "Check 6: SH order vs error vs evaluation time")
