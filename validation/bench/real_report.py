"""``bench --real``'s report: intervals per panorama group, real.md / real.json, a chart and panels."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Callable, Sequence

import numpy as np

from physrelight import io, sh
from physrelight.stats import hierarchical_bootstrap

from ..common import jsonable, machine_line
from .real_metrics import (BOUNDARY_TOLERANCE, CAMERA_VARIANTS, ESTIMATES, SEGMENTERS, SELF_METHODS, SKY_SOURCES,
                           SUN_ESTIMATES, shading_error, sun_error_summary, targets_for)

GROUP_TITLES = {"heldout": "held out (sunrise)", "training": "training side (seen in training)",
                "indoor": "indoor (studio, the rooms)", "user": "your panoramas"}
PANEL_COLUMNS = 4
RELIGHT_DEFAULTS = dict(method="proposed", exposure="auto")
"""What `physrelight relight` passes by default that the Python API does not."""
TRAINED = ("The training-side panoramas (city, courtyard, forest; and, since issue 43, pm_city, pm_dawn, pm_night, "
           "pm_sky, pm_venice of `physrelight/data/hdri_more`, relit to every outdoor map while the first three keep "
           "their earlier targets) may be in the lighting prior's samples (`learned/lighting.py`), in synth's HDRI "
           "lightings and in the sky segmenter's real crops: their figures are marked *seen in training*. studio and "
           "the eight rooms of hdri_more (indoor) are only controls: no crop of theirs has sky. The held-out sunrise "
           "trained nothing, fitted nothing and chose nothing.")


def _interval(values: Sequence[float], groups: Sequence[str], samples: int, seed: int = 0) -> dict[str, Any] | None:
    v = np.asarray(values, dtype=np.float64)
    keep = np.isfinite(v)
    if not keep.any():
        return None
    mi = hierarchical_bootstrap(v[keep], np.asarray(groups)[keep], samples=samples, seed=seed)
    return {"mean": mi.mean, "lo": mi.lo, "hi": mi.hi, "panoramas": mi.groups, "crops": mi.cases}


def _crop_sky(c: dict[str, Any], source: str, metric: str) -> float:
    """A crop's relit-sky figure averaged over its targets (nan without any)."""
    vals = [t[source][metric] for t in c["sky"].values()]
    return float(np.mean(vals)) if vals else math.nan


def cross_view(crops: Sequence[dict[str, Any]], normals: np.ndarray, name: str) -> list[tuple[str, float]]:
    """(panorama, error) for every pair of crops of one panorama: estimate ``name``'s world-frame
    irradiance from one crop against the other's, scale-invariant, both ways averaged."""
    out = []
    by_pano: dict[str, list[dict[str, Any]]] = {}
    for c in crops:
        by_pano.setdefault(c["panorama"], []).append(c)
    for pano, cs in by_pano.items():
        E = [np.asarray(sh.irradiance(np.asarray(c["world_sh"][name]), normals)) for c in cs]
        for a, b in itertools.combinations(range(len(cs)), 2):
            out.append((pano, 0.5 * (shading_error(E[a], E[b]) + shading_error(E[b], E[a]))))
    return out


def summarise(crops: Sequence[dict[str, Any]], samples: int) -> dict[str, Any]:
    """Every section's intervals for one group of crops (``"main"``: crops with sky; ``"apart"``:
    no-sky and mostly-ground crops, counted apart)."""
    main = [c for c in crops if c["stratum"] == "sky"]
    apart = [c for c in crops if c["stratum"] != "sky"]
    noskies = [c for c in crops if c["stratum"] == "no_sky"]

    def iv(cs: Sequence[dict[str, Any]], get: Callable[[dict[str, Any]], float]) -> dict[str, Any] | None:
        return _interval([get(c) for c in cs], [c["panorama"] for c in cs], samples) if cs else None

    out: dict[str, Any] = {"crops": len(crops), "sky_crops": len(main), "apart_crops": len(apart),
                           "no_sky_crops": len(noskies), "panoramas": sorted({c["panorama"] for c in crops})}
    out["segmentation"] = {m: {"iou": iv(main, lambda c, m=m: c["segmentation"][m]["iou"]),
                               "boundary_f": iv(main, lambda c, m=m: c["segmentation"][m]["boundary_f"]),
                               "sky_called_without_sky": iv(noskies, lambda c, m=m: c["segmentation"][m]["sky_called"])}
                           for m in SEGMENTERS}
    out["stability"] = {v: {"iou": iv(main, lambda c, v=v: c["stability"][v]["iou"]),
                            "boundary_f": iv(main, lambda c, v=v: c["stability"][v]["boundary_f"]),
                            "sky_called_without_sky": iv(noskies, lambda c, v=v: c["stability"][v]["sky_called"])}
                        for v in CAMERA_VARIANTS}
    out["lighting_stability"] = {v: iv([c for c in main if "lighting_stability" in c],
                                       lambda c, v=v: c["lighting_stability"][v]["shading_error"])
                                 for v in CAMERA_VARIANTS}
    out["lighting"] = {e: {"shading_error": iv(main, lambda c, e=e: c["lighting"][e]["shading_error"]),
                           "abs_level_stops": iv(main, lambda c, e=e: abs(c["lighting"][e]["level_stops"])),
                           "level_stops": iv(main, lambda c, e=e: c["lighting"][e]["level_stops"]),
                           "shading_error_apart": iv(apart, lambda c, e=e: c["lighting"][e]["shading_error"])}
                       for e in ESTIMATES}
    normals = sh.fibonacci_sphere(256)
    out["cross_view"] = {}
    for e in ("proposed", "prior_mean"):
        pairs = cross_view(crops, normals, e)
        out["cross_view"][e] = _interval([x for _, x in pairs], [p for p, _ in pairs], samples) if pairs else None
    out["sky"] = {s: {"l1": iv(main, lambda c, s=s: _crop_sky(c, s, "l1")),
                      "psnr": iv(main, lambda c, s=s: _crop_sky(c, s, "psnr"))} for s in SKY_SOURCES}
    with_self = [c for c in main if c["self"] is not None]
    apart_self = [c for c in apart if c["self"] is not None]
    out["self"] = {m: {k: iv(with_self, lambda c, m=m, k=k: c["self"][m][k])
                       for k in ("l1", "ssim", "psnr", "l1_at_best_gain", "ssim_at_best_gain", "psnr_at_best_gain")}
                   for m in SELF_METHODS if m != "identity"}
    out["self_apart"] = {m: {k: iv(apart_self, lambda c, m=m, k=k: c["self"][m][k]) for k in ("l1", "psnr")}
                         for m in SELF_METHODS if m != "identity"}
    sunny = [c for c in main if c.get("sun", {}).get("truth") is not None]
    out["sun"] = {"crops_with_sun": len(sunny), "crops_read": sum(c["sun"]["source"] == "sky" for c in sunny),
                  **{e: sun_error_summary([c["sun"]["estimates"][e] for c in sunny if e in c["sun"]["estimates"]])
                     for e in SUN_ESTIMATES}}
    read = [c for c in main if "ground_albedo_shading_error" in c.get("sun", {})]
    out["sun"]["ground_albedo_shading_error"] = {
        a: iv(read, lambda c, a=a: c["sun"]["ground_albedo_shading_error"][a])
        for a in (read[0]["sun"]["ground_albedo_shading_error"] if read else ())}
    out["sun"]["read_crops"] = len(read)
    out["pitch"] = {"abs_error_deg": iv(main, lambda c: abs(c["pitch"]["error_deg"])),
                    "error_deg": iv(main, lambda c: c["pitch"]["error_deg"])}
    out["declined"] = {"sky_crops": iv(main, lambda c: float(bool(c["no_sky_reason"]))),
                       "no_sky_crops": iv(noskies, lambda c: float(bool(c["no_sky_reason"])))}
    secs: dict[str, list[float]] = {}
    for c in crops:
        for k, v in c["seconds"].items():
            secs.setdefault(k, []).append(v)
    out["seconds_per_crop"] = {k: float(np.median(v)) for k, v in secs.items()}
    return out


# ----------------------------------------------------------------------------- markdown


def _cell(x: dict[str, Any] | None, digits: int = 3) -> str:
    if x is None:
        return "n/a"
    f = f"{{:.{digits}f}}"
    return f"{f.format(x['mean'])} [{f.format(x['lo'])}, {f.format(x['hi'])}]"


def _table(groups: list[str], summary: dict[str, Any], rows: Sequence[str], get: Callable[[dict[str, Any], str], Any],
           first: str, digits: int = 3) -> list[str]:
    head = f"| {first} | " + " | ".join(GROUP_TITLES[g] for g in groups) + " |"
    lines = [head, "|" + " --- |" * (len(groups) + 1)]
    for r in rows:
        lines.append(f"| {r} | " + " | ".join(_cell(get(summary[g], r), digits) for g in groups) + " |")
    return lines


def markdown(report: dict[str, Any], chart: str, panels: list[str]) -> str:
    """``bench --real``'s report (``real.md``) from its JSON, the summary chart and the panels."""
    s = report["summary"]
    groups = [g for g in GROUP_TITLES if g in s]
    m = report["machine"]
    lines = [
        "# bench --real: the pipeline on real photos with exactly known lighting", "",
        f"Command: `{report['command']}`  ", f"Machine: {machine_line(m)}, torch {m.get('torch')} "
        f"({m.get('torch_threads')} threads); {m['shared']}.  ",
        f"Date: {report['date']}; {report['seconds']:.0f} s; weights: `{report['weights']}`.", "",
        "Every figure is a mean with a 95 % bootstrap interval that resamples panoramas, then crops within "
        "each (one panorama: crops only). Crops without sky (< 1 % of pixels) or looking mostly at the ground "
        "are counted apart.", "", "## Panoramas", "",
        "| panorama | group | sky mask | crops | with sky | apart |", "| --- | --- | --- | --- | --- | --- |",
    ]
    for p in report["panoramas"]:
        cs = [c for c in report["crops"] if c["panorama"] == p["name"]]
        n_sky = sum(c["stratum"] == "sky" for c in cs)
        lines.append(f"| {p['name']} | {p['group']} | {p['mask']} | {len(cs)} | {n_sky} | {len(cs) - n_sky} |")
    lines += ["", TRAINED, ""]
    lines += ["## (a) Sky segmentation (full resolution)", "",
              "IoU with the true sky (crops with sky):", ""]
    lines += _table(groups, s, SEGMENTERS, lambda g, r: g["segmentation"][r]["iou"], "segmenter")
    lines += ["", f"Boundary F ({report['boundary_tolerance_px']:g} px tolerance):", ""]
    lines += _table(groups, s, SEGMENTERS, lambda g, r: g["segmentation"][r]["boundary_f"], "segmenter")
    lines += ["", "Fraction of the image called sky on crops without sky (0 is right):", ""]
    lines += _table(groups, s, SEGMENTERS, lambda g, r: g["segmentation"][r]["sky_called_without_sky"], "segmenter")
    lines += ["", "`segmenter` is what `relight` uses: the segmenter at 128 px, kept where it is a plausible sky, "
              "brought to full resolution along the photo's edges (`learned.sky_segmentation.sky_mask_full_resolution`); "
              "`segmenter_64px` is the mask it replaced (64 px, bilinear). Fraction of crops where `relight` finds no "
              "plausible sky and says so (on crops with sky / without):", ""]
    lines += _table(groups, s, ("sky_crops", "no_sky_crops"), lambda g, r: g["declined"][r], "crops")
    lines += ["", "Stability: the same crops as another camera setting would have stored them (exposure one stop "
              "down or up; a white-balance cast, red x 1.1 and blue x 0.9 or the reverse; JPEG quality 50; noise of "
              "2 % of white), `segmenter` IoU, boundary F and the sky called on crops without sky:", ""]

    def stability(g: dict[str, Any], row: str, key: str) -> Any:
        return g["segmentation"]["segmenter"][key] if row == "as is" else g["stability"][row][key]

    for key, title in (("iou", "IoU"), ("boundary_f", "boundary F"), ("sky_called_without_sky", "sky called without sky")):
        lines += ["", f"{title}:", ""] if key != "iou" else []
        lines += _table(groups, s, ("as is", *CAMERA_VARIANTS), lambda g, r, key=key: stability(g, r, key), "camera")
    lines += ["", "Pitch estimated from the sky's horizon (`physrelight.horizon.estimate_pitch`), error in degrees "
              "(absolute, then signed):", ""]
    lines += _table(groups, s, ("abs_error_deg", "error_deg"), lambda g, r: g["pitch"][r], "pitch", 2)
    lines += ["", "## (b) Lighting from a real photo", "",
              "Scale-invariant irradiance error on the unit sphere (the estimate's order-2 irradiance, best single "
              "gain, against the panorama's exact irradiance; `truth_order2` is the ceiling of any order-2 "
              "estimate):", ""]
    lines += _table(groups, s, ESTIMATES, lambda g, r: g["lighting"][r]["shading_error"], "estimate")
    lines += ["", "Stability: `proposed`'s shading error when the crop comes as another camera setting would have "
              "stored it (the settings of (a), each on its own mask). An exposure changes only the level, which this "
              "error ignores; a colour cast is, to the photo, a change of the light's colour, so it counts:", ""]

    def lighting_stability(g: dict[str, Any], row: str) -> Any:
        return g["lighting"]["proposed"]["shading_error"] if row == "as is" else g["lighting_stability"].get(row)

    lines += _table(groups, s, ("as is", *CAMERA_VARIANTS), lighting_stability, "camera")
    lines += ["", "Level error |log2(DC estimate / DC truth)| in stops (the estimate's units are the linearised "
              "photo's; the albedo-lighting scale is part of it):", ""]
    lines += _table(groups, s, ESTIMATES[:-1], lambda g, r: g["lighting"][r]["abs_level_stops"], "estimate", 2)
    lines += ["", "Signed level error in stops:", ""]
    lines += _table(groups, s, ESTIMATES[:-1], lambda g, r: g["lighting"][r]["level_stops"], "estimate", 2)
    lines += ["", "The same on the crops counted apart (no sky, or mostly ground):", ""]
    lines += _table(groups, s, ESTIMATES, lambda g, r: g["lighting"][r]["shading_error_apart"], "estimate")
    lines += ["", "### The sun's position", "",
              "Crops with sky whose panorama has a sun above the horizon (`physrelight.envmap.split_sun`); each "
              "estimate is a direction in the camera's frame brought into the panorama's by the crop's true camera "
              "(its yaw known). `sky_reader`: the sky's posterior MAP (`learned.sky_lighting.read_sky_lighting`, "
              "the segmenter's mask, relight's camera: the field of view given, the pitch from the sky's horizon) "
              "where it is informative, else `proposed`'s: what `RelightOptions(source_estimate=\"sky\")` uses; "
              "`sky_only`: the same on the crops it reads only; `proposed`: the dominant direction (luminance band "
              "1) of the decomposition's order-2 lighting, today's estimate; `prior_mean`: that of the lighting "
              "prior's mean, a fixed guess (2.3 deg from the camera's up axis). Absolute errors in degrees, median "
              "/ 90th percentile (crops):", ""]
    sun_groups = [g for g in groups if s[g].get("sun", {}).get("crops_with_sun")]
    lines += ["| estimate | " + " | ".join(f"{GROUP_TITLES[g]}: azimuth | elevation" for g in sun_groups) + " |",
              "|" + " --- |" * (2 * len(sun_groups) + 1)]
    for e in SUN_ESTIMATES:
        cells = []
        for g in sun_groups:
            x = s[g]["sun"][e]
            cells += (["n/a", "n/a"] if x is None else
                      [f"{x['azimuth_error_deg']['median']:.1f} / {x['azimuth_error_deg']['p90']:.1f} ({x['crops']})",
                       f"{x['elevation_error_deg']['median']:.1f} / {x['elevation_error_deg']['p90']:.1f}"])
        lines.append(f"| {e} | " + " | ".join(cells) + " |")
    lines += ["", "Crops with a sun / read by the sky: " + "; ".join(
        f"{GROUP_TITLES[g]} {s[g]['sun']['crops_with_sun']} / {s[g]['sun']['crops_read']}" for g in sun_groups) + ".",
              "", "The sky's reading's shading error with the ground below the horizon at each reflectance "
              "(`learned.sky_lighting.sky_sun_sh`; 0: black), on the crops with sky it reads:", ""]
    albedos = sorted({a for g in groups for a in s[g].get("sun", {}).get("ground_albedo_shading_error", {})}, key=float)
    lines += _table(groups, s, albedos, lambda g, r: g["sun"]["ground_albedo_shading_error"].get(r), "ground albedo")
    lines += ["", "Cross-view consistency: two crops of one panorama, their estimates turned into the world frame, "
              "scale-invariant irradiance difference (every pair of crops; 0 for the truth):", ""]
    lines += _table(groups, s, ("proposed", "prior_mean"), lambda g, r: g["cross_view"][r], "estimate")
    lines += ["", "## (c) The relit sky", "",
              "Each crop relit to other panoramas; its sky against the target seen through the same camera at the "
              "output's exposure, over the true sky pixels (sRGB). Sky sources, all composited on the segmenter's "
              "mask over the `quotient` foreground: `target` (what `relight` renders: the target through the "
              "camera it estimates, the crop's field of view as EXIF would give it and the pitch from the sky's "
              "horizon), `fit` (the outdoor sky model fitted to the target's order-2 SH, `physrelight.sky_model`, "
              "through the same estimated camera: what `relight --sh --sky-source fit` paints), `skygan` (SkyGAN's "
              "sky), `sh_radiance` (the target's order-2 SH radiance), `keep` (the "
              "photo's own sky: identity's and the synthetic methods'), `exact_view` (the target through the true "
              "camera: the ceiling, limited only by the mask).", "", "l1:", ""]
    lines += _table(groups, s, SKY_SOURCES, lambda g, r: g["sky"][r]["l1"], "sky source")
    lines += ["", "PSNR (dB):", ""]
    lines += _table(groups, s, SKY_SOURCES, lambda g, r: g["sky"][r]["psnr"], "sky source", 2)
    lines += ["", "## (d) Self-relighting (target = the crop's own panorama; the output should be the input)", "",
              "Foreground (true non-sky) at full resolution, against the photo; identity is exact by construction. "
              "`quotient_known` is the known-source track (the quotient divides by the given source lighting: exact "
              "by construction when the target is the source); every other method is on the estimated track "
              "(the decomposition's lighting, its level from the given source). l1:", ""]
    names = [n for n in SELF_METHODS if n != "identity"]
    lines += _table(groups, s, names, lambda g, r: g["self"][r]["l1"], "method", 4)
    lines += ["", "SSIM:", ""]
    lines += _table(groups, s, names, lambda g, r: g["self"][r]["ssim"], "method")
    lines += ["", "PSNR (dB):", ""]
    lines += _table(groups, s, names, lambda g, r: g["self"][r]["psnr"], "method", 2)
    lines += ["", "The same after each output's best single gain (its level removed, its structure kept: "
              "`validation.bench.protocols.display_at_best_gain`, as `bench --full`'s exposure-invariant columns), "
              "l1, SSIM and PSNR (dB):", ""]
    lines += _table(groups, s, names, lambda g, r: g["self"][r]["l1_at_best_gain"], "method", 4)
    lines += [""]
    lines += _table(groups, s, names, lambda g, r: g["self"][r]["ssim_at_best_gain"], "method")
    lines += [""]
    lines += _table(groups, s, names, lambda g, r: g["self"][r]["psnr_at_best_gain"], "method", 2)
    lines += ["", "The crops counted apart (no sky, or mostly ground), l1 and PSNR (dB):", ""]
    lines += _table(groups, s, names, lambda g, r: g["self_apart"][r]["l1"], "method", 4)
    lines += [""]
    lines += _table(groups, s, names, lambda g, r: g["self_apart"][r]["psnr"], "method", 2)
    lines += ["", "Median seconds per crop (2 torch threads unless stated; indicative):", "",
              "| group | " + " | ".join(sorted({k for g in groups for k in s[g]['seconds_per_crop']})) + " |"]
    keys = sorted({k for g in groups for k in s[g]["seconds_per_crop"]})
    lines.append("|" + " --- |" * (len(keys) + 1))
    for g in groups:
        lines.append(f"| {g} | " + " | ".join(f"{s[g]['seconds_per_crop'].get(k, math.nan):.3f}" for k in keys) + " |")
    lines += ["", f"![summary]({chart})", "", "## (e) Panels", "",
              "Each: input | relit to up to three targets (`relight`'s own path, SkyGAN sky, the true camera) | "
              "true sky | segmenter's sky | albedo | normals | shadow.", ""]
    lines += [f"![{Path(p).stem}]({p})" for p in panels]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- chart and panels


def _chart(out: Path, report: dict[str, Any]) -> str:
    from ..charts import figure, save

    s = report["summary"]
    groups = [g for g in GROUP_TITLES if g in s]
    ctx = SimpleNamespace(machine=report["machine"], command=report["command"], chart_dir=out / "charts")
    ctx.chart_dir.mkdir(parents=True, exist_ok=True)
    fig, axes = figure(12.0, 4.0, ncols=3)
    panels = [("(a) sky IoU", SEGMENTERS, lambda g, r: g["segmentation"][r]["iou"]),
              ("(c) relit sky PSNR (dB)", SKY_SOURCES, lambda g, r: g["sky"][r]["psnr"]),
              ("(d) self-relighting PSNR (dB)", [n for n in SELF_METHODS if n != "identity"],
               lambda g, r: g["self"][r]["psnr"])]
    width = 0.8 / max(len(groups), 1)
    for ax, (title, rows, get) in zip(axes, panels):
        for j, g in enumerate(groups):
            vals = [get(s[g], r) for r in rows]
            x = np.arange(len(rows)) + j * width
            mean = [v["mean"] if v else np.nan for v in vals]
            err = np.array([[v["mean"] - v["lo"], v["hi"] - v["mean"]] if v else [0, 0] for v in vals]).T
            ax.bar(x, mean, width, yerr=err, capsize=2, label=GROUP_TITLES[g])
        ax.set_xticks(np.arange(len(rows)) + 0.4 - width / 2, rows, rotation=20, fontsize=8)
        ax.set_title(title, fontsize=9)
    axes[0].legend(fontsize=7)
    return save(fig, ctx, "real_summary", "bench --real: means with 95 % bootstrap intervals")


def _label(tile: np.ndarray, text: str) -> np.ndarray:
    from PIL import Image, ImageDraw

    im = Image.fromarray(np.clip(np.round(tile * 255), 0, 255).astype(np.uint8))
    ImageDraw.Draw(im).text((3, 2), text, fill=(255, 255, 0))
    return np.asarray(im).astype(np.float32) / 255.0


def write_panel(path: Path, relighter: Any, crop: Any, targets: Sequence[Any], seed: int = 0) -> None:
    """input | relit to each target (``relight_layers``: the user's path, with the true camera) |
    true sky | segmenter's sky | albedo | normals | shadow, four tiles a row, each at 2x."""
    import warnings

    tiles = [_label(crop.display(), "input")]
    layers = None
    kw = dict(world_to_camera=crop.world_to_camera, seed=seed, fov_deg=crop.fov_deg, **RELIGHT_DEFAULTS)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="no sky relit", category=UserWarning)  # counted in (a) instead
        for t in targets[:3]:
            layers = relighter.relight_layers(crop.photo, t.env, **kw)
            tiles.append(_label(layers["relit"], f"-> {t.name}"))
        if layers is None:
            layers = relighter.relight_layers(crop.photo, np.asarray(crop.panorama.sh(2)), **kw)
    grey = lambda m: np.repeat(np.asarray(m, np.float32).reshape(*crop.size, 1), 3, axis=-1)  # noqa: E731
    tiles += [_label(grey(crop.sky), "true sky"), _label(grey(layers["sky_mask"][..., 0]), "segmenter"),
              _label(layers["albedo"], "albedo"), _label(layers["normals"], "normals"),
              _label(grey(layers["shadow"][..., 0]), "shadow")]
    tiles += [np.ones_like(tiles[0])] * (-len(tiles) % PANEL_COLUMNS)
    h, w = crop.size
    grid = np.ones((len(tiles) // PANEL_COLUMNS * (h + 2), PANEL_COLUMNS * (w + 2), 3), np.float32)
    for i, t in enumerate(tiles):
        r, c = divmod(i, PANEL_COLUMNS)
        grid[r * (h + 2): r * (h + 2) + h, c * (w + 2): c * (w + 2) + w] = t
    io.write_png(path, np.repeat(np.repeat(grid, 2, axis=0), 2, axis=1))


def write_real_report(out_dir: str | Path, report: dict[str, Any], relighter: Any, crops_by_pano: dict[str, list[Any]],
                      target_pool: Sequence[Any], level: Any, progress: Callable[[str], None] = print) -> dict[str, Any]:
    """Summarise ``report["crops"]`` per group, draw the chart and panels, write real.md and real.json."""
    out = Path(out_dir)
    (out / "panels").mkdir(parents=True, exist_ok=True)
    crops = report["crops"]
    report["boundary_tolerance_px"] = BOUNDARY_TOLERANCE
    report["summary"] = {g: summarise([c for c in crops if c["group"] == g], level.bootstrap)
                         for g in GROUP_TITLES if any(c["group"] == g for c in crops)}
    report["trained_on"] = TRAINED
    panels = []
    for name, cs in crops_by_pano.items():
        for c in cs[: level.panels]:
            rel = f"panels/{name}_{c.index}.png"
            write_panel(out / rel, relighter, c, targets_for(c.panorama, target_pool, 3, c.index))
            panels.append(rel)
    progress(f"{len(panels)} panels -> {out / 'panels'}")
    chart = _chart(out, report)
    report["charts"] = [chart]
    report["panels"] = panels
    report = jsonable(report)
    io.write_json(out / "real.json", report)
    md = markdown(report, chart, panels)
    with io.atomic_path(out / "real.md", ".md") as tmp:
        tmp.write_text(md)
    return report
