"""Check 1: the renderer against exact irradiance.

A Lambertian convex object (sphere, box, ellipsoid) floats under each lighting. Nothing
shadows it and no light bounces between its surfaces, so the radiance a path tracer
converges to is exactly ``albedo * E(n) / pi``, with ``E`` the brute-force quadrature
of the lighting (:meth:`synth.lighting.Lighting.irradiance_reference`: sky texel sum +
delta sun). The check renders K independent images (seeds), and compares

* the mean ratio ``sum(path traced) / sum(exact)`` (luminance) with its standard error
  ``sqrt(sum_p sem_p^2) / sum_p exact_p`` from the per-pixel sample variances (pixels
  are independent, so this has thousands of degrees of freedom and 4 se is a normal
  4-sigma bound): ``|r - 1| <= 4 se + q``, where ``q`` is the
  yardstick's own quadrature error (measured by a 3x finer quadrature, not assumed);
* a per-pixel z-test: ``z = (mean - exact) / sem`` with the per-pixel sample standard
  error over the K renders. Under the null z follows Student's t with K-1 degrees of
  freedom, so the share of pixels with ``|z| > 4`` must stay within 4 binomial standard
  deviations of ``P(|t_{K-1}| > 4)``.

Pixels compared (criteria fixed in advance, from the pixel footprint, not from the
result): wholly on the object (coverage 1); a coherent normal over the footprint
(``1 - |mean n| < 2e-3``, i.e. an rms normal spread under ~0.063 rad: no crease or
silhouette inside the pixel, so ``E`` at the pixel centre stands for the footprint to
~0.2 %); for lightings with a sun, ``|n . s| > 0.2`` (three times that spread away from
the sun's terminator, where ``max(0, n . s)`` has a kink that footprint averaging
smooths at first order).
"""

from __future__ import annotations

import math
import weakref
from typing import Any

import numpy as np

from physrelight import envmap
from synth import lighting as _lighting
from synth import render as _render

from . import charts, scenes
from .common import LUMINANCE, CheckResult, Context, binomial_upper, per_pixel_stats, t_tail

MAX_SPREAD = 2e-3
TERMINATOR = 0.2
Z = 4.0

SUMMARY = (
    "A white-ish Lambertian **convex** object (sphere, box, ellipsoid; albedo (0.6, 0.45, 0.3)) floats "
    "alone under each lighting. Nothing shadows it and light cannot bounce between its surfaces, so the "
    "radiance the path tracer converges to is exactly `albedo * E(n) / pi`, where `E` is the brute-force "
    "quadrature of the lighting's sky map plus the delta sun. Each case is rendered with K independent "
    "seeds; the mean ratio path-traced / exact must be 1 within 4 standard errors (plus the yardstick's "
    "own quadrature error), and the per-pixel z-scores (per-pixel sample variance over the seeds) must "
    "show no more |z| > 4 outliers than Student's t allows. Pixels: wholly on the object, no crease or "
    "silhouette inside the footprint (1 - |mean n| < 2e-3), and |n.s| > 0.2 away from the sun's terminator."
)


def fine_sky_irradiance(sky: np.ndarray, normals: np.ndarray, factor: int = 3) -> np.ndarray:
    """``(N, 3)`` irradiance of the map's bilinear interpolant by a ``factor``-times finer
    midpoint quadrature (the yardstick for the yardstick).

    Args:
        sky: ``(H, W, 3)`` lat-long map.
        normals: ``(N, 3)`` unit world normals.
        factor: refinement of rows and columns.
    """
    h, w = sky.shape[:2]
    rows, cols = factor * (h - 1), factor * w
    dt, dp = math.pi / rows, 2 * math.pi / cols
    theta = (np.arange(rows) + 0.5) * dt
    phi = (np.arange(cols) + 0.5) * dp
    st = np.sin(theta)[:, None]
    d = np.stack(np.broadcast_arrays(st * np.sin(phi), np.cos(theta)[:, None], -st * np.cos(phi)), -1).reshape(-1, 3)
    radiance = np.asarray(envmap.sample(sky.astype(np.float64), d))
    lw = radiance * np.repeat(np.sin(theta) * dt * dp, cols)[:, None]
    keep = lw.sum(axis=1) > 0
    d, lw = d[keep], lw[keep]
    out = np.zeros((normals.shape[0], 3))
    step = max(1, (1 << 22) // max(1, d.shape[0]))
    for i in range(0, normals.shape[0], step):
        out[i:i + step] = np.clip(normals[i:i + step] @ d.T, 0.0, None) @ lw
    return out


def yardstick_error(light: _lighting.Lighting, normals: np.ndarray) -> float:
    """Relative quadrature error of :meth:`Lighting.irradiance_reference` on ``normals``:
    ``max |E_ref - E_fine| / mean E_ref`` (luminance), the sun being exact in both."""
    ref = light.irradiance_reference(normals)
    sky_ref = np.asarray(envmap.irradiance_reference(light.sky.astype(np.float64), normals))
    fine = fine_sky_irradiance(light.sky, normals)
    err = np.abs((sky_ref - fine) @ LUMINANCE)
    return float(err.max() / max(float((ref @ LUMINANCE).mean()), 1e-30))


_YARDSTICK: "weakref.WeakKeyDictionary[_lighting.Lighting, float]" = weakref.WeakKeyDictionary()


def lighting_yardstick(light: _lighting.Lighting) -> float:
    """:func:`yardstick_error` over 400 normals spread over the sphere (cached per lighting):
    an upper bound for any subset of normals up to the sampling of the sphere."""
    if light not in _YARDSTICK:
        from physrelight import sh

        _YARDSTICK[light] = yardstick_error(light, sh.fibonacci_sphere(400))
    return _YARDSTICK[light]


def compare_case(shape: str, light: _lighting.Lighting, res: int, spp: int, seeds: int,
                 seed0: int = 0) -> dict[str, Any]:
    """Render one shape under one lighting K times and compare with ``albedo E / pi``.

    Returns:
        Figures: ``ratio``, ``ratio_se``, ``n_pixels``, ``frac_z4``, ``p_z4_null``,
        ``frac_z4_bound``, ``yardstick_error``, ``seconds_per_render`` and, for charts,
        ``_mean``/``_exact`` luminance per compared pixel.
    """
    import time

    spec = scenes.convex_spec(shape)
    cam = scenes.convex_view(res)
    scene = _render.build_scene(spec, [cam], light, spp=spp)
    geo = _render.render_geometry(scene, 0, cam, spp=64, seed=seed0 + 1)
    spread = scenes.footprint_spread(scene, 0, spp=64, seed=seed0 + 2)
    t0 = time.perf_counter()
    runs = scenes.radiance_runs(scene, 0, spp, [seed0 + 100 + k for k in range(seeds)])
    seconds = (time.perf_counter() - t0) / seeds
    nw = scenes.world_normals(geo.normal, cam)
    ok = (~geo.sky_mask) & (geo.coverage >= 1 - 1e-6) & (spread < MAX_SPREAD)
    if light.has_sun:
        ok &= np.abs(nw @ light.sun_direction) > TERMINATOR
    albedo = np.asarray(scenes.CONVEX_ALBEDO)
    exact = albedo * light.irradiance_reference(nw[ok]) / math.pi
    e = exact @ LUMINANCE
    per_seed = runs[:, ok] @ LUMINANCE  # (K, N)
    mean, sem = per_pixel_stats(per_seed)
    ratios = per_seed.sum(axis=1) / e.sum()
    z = (mean - e) / np.maximum(sem, 1e-12 * e)
    k = per_seed.shape[0]
    p0 = t_tail(Z, k - 1)
    n = int(ok.sum())
    return {
        "ratio": float(mean.sum() / e.sum()),
        # Pooled over pixels (independent sampler streams): thousands of degrees of freedom,
        # so 4 se is a normal 4-sigma bound; the spread of the K per-seed ratios (K-1 dof) is reported too.
        "ratio_se": float(np.sqrt((sem**2).sum()) / e.sum()),
        "ratio_se_seeds": float(ratios.std(ddof=1) / math.sqrt(k)),
        "n_pixels": n,
        "frac_z4": float(np.mean(np.abs(z) > Z)),
        "p_z4_null": p0,
        "frac_z4_bound": binomial_upper(p0, n),
        "yardstick_error": yardstick_error(light, nw[ok][:: max(1, n // 400)]),
        "median_rel_sem_per_pixel": float(np.median(sem / e) * math.sqrt(k)),
        "seconds_per_render": seconds,
        "_mean": mean, "_exact": e,
    }


def run(ctx: Context) -> CheckResult:
    """The renderer's irradiance check at ``ctx.level`` (see the module's docstring)."""
    lv = ctx.level
    res = CheckResult("renderer_irradiance", "1. Renderer vs exact irradiance", SUMMARY)
    table = ["| shape | lighting | pixels | mean ratio | 4 se + q | \\|z\\|>4 share | allowed | verdict |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | --- |"]
    figs: dict[str, dict[str, Any]] = {}
    scatter: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for shape in lv.shapes:
        figs[shape] = {}
        for li, lname in enumerate(lv.lightings):
            ctx.progress(f"  check 1: {shape} under {lname}")
            light = scenes.get_lighting(lname, lv.env_res)
            f = compare_case(shape, light, lv.convex_res, lv.convex_spp, lv.convex_seeds, seed0=1000 * li)
            if shape == "sphere":
                scatter[lname] = (f["_exact"], f["_mean"])
            f = {k: v for k, v in f.items() if not k.startswith("_")}
            figs[shape][lname] = f
            tol = Z * f["ratio_se"] + f["yardstick_error"]
            ok1 = res.check(f"{shape} / {lname}: mean ratio", f["ratio"], abs(f["ratio"] - 1) <= tol,
                            f"|r - 1| <= {tol:.4f}",
                            f"4 standard errors of the ratio (pooled per-pixel variances, {lv.convex_seeds} seeds) + the yardstick's "
                            f"quadrature error {f['yardstick_error']:.1e} (3x finer quadrature)")
            ok2 = res.check(f"{shape} / {lname}: per-pixel z", f["frac_z4"], f["frac_z4"] <= f["frac_z4_bound"],
                            f"share of |z| > 4 <= {f['frac_z4_bound']:.4f}",
                            f"P(|t_{lv.convex_seeds - 1}| > 4) = {f['p_z4_null']:.1e} over {f['n_pixels']} "
                            "pixels + 4 binomial sd + 1 pixel")
            table.append(f"| {shape} | {lname} | {f['n_pixels']} | {f['ratio']:.4f} | {tol:.4f} | "
                         f"{f['frac_z4']:.4f} | {f['frac_z4_bound']:.4f} | {'pass' if ok1 and ok2 else 'FAIL'} |")
    sphere = [figs["sphere"][n]["ratio"] for n in lv.lightings] if "sphere" in figs else []
    res.figures = {
        "sphere_pathtrace_over_exact": float(np.mean(sphere)) if sphere else None,
        "sphere_pathtrace_over_exact_per_lighting": {n: figs["sphere"][n]["ratio"] for n in lv.lightings}
        if sphere else {},
        "all_shapes_mean_ratio": float(np.mean([f["ratio"] for s in figs.values() for f in s.values()])),
        "cases": figs,
        "settings": {"resolution": lv.convex_res, "spp_per_render": lv.convex_spp, "renders": lv.convex_seeds,
                     "env_res": lv.env_res, "max_footprint_spread": MAX_SPREAD, "terminator_cos": TERMINATOR},
        "lightings": {n: scenes.describe_lighting(scenes.get_lighting(n, lv.env_res)) for n in lv.lightings},
    }
    res.tables.append("\n".join(table))
    res.charts.append((_ratio_chart(ctx, figs), "Mean ratio path-traced / exact per shape and lighting, "
                       "with 4 standard errors (bars). 1 is the physics."))
    res.charts.append((_scatter_chart(ctx, scatter), "Per-pixel luminance of the sphere: path-traced mean over "
                       "the seeds vs albedo E(n)/pi, one point per compared pixel."))
    return res


def _ratio_chart(ctx: Context, figs: dict[str, dict[str, Any]]) -> str:
    fig, ax = charts.figure(8.0, 4.0)
    names = list(ctx.level.lightings)
    width = 0.8 / max(1, len(figs))
    for i, (shape, cases) in enumerate(figs.items()):
        x = np.arange(len(names)) + (i - (len(figs) - 1) / 2) * width
        y = [cases[n]["ratio"] for n in names]
        err = [Z * cases[n]["ratio_se"] + cases[n]["yardstick_error"] for n in names]
        ax.errorbar(x, y, yerr=err, fmt="o", capsize=3, label=shape)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(np.arange(len(names)), names)
    ax.set_xlabel("lighting")
    ax.set_ylabel("path traced / exact (luminance, unitless)")
    ax.legend(fontsize=8)
    return charts.save(fig, ctx, "check1_ratio", "Check 1: path-traced radiance / (albedo E / pi), mean over pixels")


def _scatter_chart(ctx: Context, scatter: dict[str, tuple[np.ndarray, np.ndarray]]) -> str:
    fig, ax = charts.figure(5.5, 4.6)
    lo, hi = np.inf, 0.0
    for name, (e, m) in scatter.items():
        scale = 1.0 / max(float(e.mean()), 1e-30)  # each lighting in units of its own mean
        ax.plot(e * scale, m * scale, ".", ms=2, alpha=0.5, label=name)
        lo, hi = min(lo, float((e * scale).min())), max(hi, float((e * scale).max()))
    ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
    ax.set_xlabel("exact albedo E/pi (relative to the mean, unitless)")
    ax.set_ylabel("path-traced mean (same units)")
    ax.legend(fontsize=7, markerscale=4)
    return charts.save(fig, ctx, "check1_scatter", "Check 1: sphere pixels, path traced vs exact")
