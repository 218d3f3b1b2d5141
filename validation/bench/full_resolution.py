"""``physrelight bench --full-resolution``: relighting at full resolution without halos, measured.

The learned pipeline relights at a working resolution (64 px, what its networks were trained at)
and brings the result back to the photo's size by ratio transfer
(:func:`physrelight.full_resolution.transfer_to_full_resolution`): ``full * up(relit_small / small)``. This
study measures, on a synthetic folder rendered at full resolution (``physrelight synth DIR --res
256``), against the path-traced target radiance:

* ``working``: the working-resolution relighting scored at the working resolution, against the
  full-resolution target box-downsampled to it (the 64-px figure of the same pairs: same scenes,
  cameras, photo nuisances and render noise; the photo seen at 64 px is the full one area-averaged,
  :func:`physrelight.full_resolution.working_resolution`);
* ``bilinear`` (before): the working result brought to full size with a bilinear ratio;
* ``guided`` (after): the same with the ratio's log upsampled by the guided filter on the photo's
  log luminance (:mod:`physrelight.guided_filter`);
* ``fast_guided`` (a candidate, not shipped): the guided filter's affine coefficients fitted on the
  working grid and applied to the full-resolution guide (:func:`transfer_fast_guided`);
* ``direct``: the networks run at full resolution, no transfer.

For each: the foreground l1 of display values (the bench's protocol,
:class:`validation.bench.protocols.Pair`) and the *halo error*, the same l1 within ``k`` pixels of a
depth discontinuity of the ground-truth depth (:func:`physrelight.metrics.edge_band_l1`), where a
ratio that does not follow the photo's edges is wrong. The full-resolution outputs are also scored
box-downsampled to the working resolution (``*_down``): what the transfer keeps of the working
result, apart from the detail and the render noise only the full-resolution target has.

Methods: ``quotient`` (the relight command line's default; the estimated source shading, its level
from the given source lighting: ``known_source=False``) and ``proposed`` (the neural renderer), both
given the source lighting as the bench gives it. Intervals: 95 % hierarchical bootstrap over scenes
then pairs (:func:`physrelight.stats.hierarchical_bootstrap`); differences paired, scenes resampled
(:func:`physrelight.stats.paired_bootstrap`). Seconds per image at one torch thread.
"""

from __future__ import annotations

import datetime
import json
import math
import statistics
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch
import torch.nn.functional as F

from physrelight import colour, metrics
from physrelight.stats import hierarchical_bootstrap, paired_bootstrap

from .data import BenchView, load_dataset
from .methods import to_chw
from .protocols import Pair, cross_pairs, informative_pairs

__all__ = ["CONFIGS", "HALO_K", "METHODS", "WORKING_RES", "box_down", "low_res_foreground", "low_res_target",
           "relight_variants", "run_full_resolution", "score_variants", "transfer_fast_guided", "transfer_variants"]

METHODS = ("quotient", "proposed")
WORKING_RES = 64
"""The networks' training resolution (``Relighter.res`` of the shipped weights)."""
CONFIGS = ("working", "bilinear", "guided", "fast_guided", "direct")
HALO_K = 2
"""Band half-width of the halo error, full-resolution pixels: a 6-px band across an edge, about one and a
half working pixels at 256 / 64 (the bilinear ratio's blur reaches one working pixel each side)."""
TIMING_THREADS = 1
BOOTSTRAP_SAMPLES = 2000


# ----------------------------------------------------------------------------- resampling


def box_down(x: torch.Tensor, factor: int) -> torch.Tensor:
    """Mean over ``factor x factor`` blocks: ``(B, C, H, W) -> (B, C, H / factor, W / factor)``.

    Raises:
        ValueError: not 4-D, ``factor`` not a positive integer, or ``H``, ``W`` not multiples of it.
    """
    if not isinstance(x, torch.Tensor) or x.ndim != 4:
        raise ValueError(f"x must be a (B, C, H, W) tensor, got {getattr(x, 'shape', type(x).__name__)}")
    if isinstance(factor, bool) or not isinstance(factor, int) or factor < 1:
        raise ValueError(f"factor must be a positive integer, got {factor!r}")
    if x.shape[-2] % factor or x.shape[-1] % factor:
        raise ValueError(f"image size {tuple(x.shape[-2:])} is not a multiple of the factor {factor}")
    return x if factor == 1 else F.avg_pool2d(x, factor)


def low_res_target(pair: Pair, factor: int) -> torch.Tensor:
    """``(1, 3, H / f, W / f)`` the pair's target seen at ``1 / factor`` of its resolution: the path-traced
    radiance box-averaged (what a render at that size integrates over a pixel), exposed like the source,
    sRGB, clipped (as :meth:`Pair.target_display`)."""
    rad = to_chw(pair.view.radiance[pair.target]).double() * torch.as_tensor(pair.gain)[None, :, None, None]
    rad = rad * 2.0 ** pair.eval_stops
    return colour.to_ldr(box_down(rad.clamp_min(0.0), factor).float())


def low_res_foreground(foreground: torch.Tensor, factor: int) -> torch.Tensor:
    """``(B, 1, H / f, W / f)`` bool: the low-resolution pixels at least half covered by ``foreground``
    ``(B, 1, H, W)`` (the majority rule :func:`physrelight.full_resolution.working_resolution` applies to the sky)."""
    return box_down(foreground.float(), factor) >= 0.5


# ----------------------------------------------------------------------------- the four outputs


def _log_luminance(x: torch.Tensor, eps: float) -> torch.Tensor:
    """``(B, 1, H, W)`` log luminance of linear ``x (B, 3, H, W)``, floored at ``eps`` (as the shipped transfer)."""
    lum = (x.clamp_min(0) * x.new_tensor(colour.LUMINANCE)[None, :, None, None]).sum(1, keepdim=True)
    return torch.log(lum.clamp_min(eps))


def transfer_fast_guided(full: torch.Tensor, small: torch.Tensor, relit_small: torch.Tensor, eps: float = 1e-3,
                         guide_eps: float | None = None, radius: int = 1) -> torch.Tensor:
    """Ratio transfer whose guided filter is fitted at the working resolution (the *fast guided filter*,
    He and Sun 2015): a candidate studied here beside :func:`physrelight.full_resolution.transfer_to_full_resolution`.

    The shipped guided transfer filters the *bilinearly upsampled* log ratio at full resolution: the
    bilinear ramp across an edge lies on both sides of it, where the guide is flat, and a guided filter
    keeps what is flat in the guide, so the ramp survives beside the edge. Here the local affine model
    ``log ratio = a log L + b`` is fitted on the working grid (guide: the full photo's log luminance
    area-averaged to it; window ``(2 radius + 1)^2`` working pixels; ridge ``guide_eps``, default
    :data:`physrelight.full_resolution.GUIDE_EPS`), its window-averaged ``a, b`` upsampled bilinearly, and applied
    to the full-resolution guide: where the model holds, the step comes back at the photo's edge.

    Shapes and the black-pixel fallback as :func:`physrelight.full_resolution.transfer_to_full_resolution`:
    ``full (B, 3, H, W)``, ``small``/``relit_small (B, 3, h, w)`` -> ``(B, 3, H, W)``; ``relit_small``
    itself when the sizes agree. A working pixel darker than ``eps`` (no ratio) gets no weight in the fit,
    so a constant ratio stays constant next to black pixels too (``a = 0``).
    """
    from physrelight.full_resolution import GUIDE_EPS
    from physrelight.guided_filter import box_filter

    if full.shape[-2:] == small.shape[-2:]:
        return relit_small
    ge = GUIDE_EPS if guide_eps is None else guide_eps
    size = full.shape[-2:]

    def up(x: torch.Tensor) -> torch.Tensor:
        return F.interpolate(x, size=size, mode="bilinear", align_corners=False)

    guide = _log_luminance(full, eps)
    guide_lo = F.interpolate(guide, size=small.shape[-2:], mode="area")
    # A working pixel darker than eps has no ratio: it gets no weight in the fit (a 0 ratio there would
    # pull its neighbours' ratio towards 0, a dark halo), and the fallback below covers it.
    w = (small > eps).all(dim=1, keepdim=True).to(small.dtype)
    p = torch.log((relit_small / small.clamp_min(eps)).clamp_min(1e-6)) * w

    def mean(x: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:  # weighted window mean, 0 without weight
        return box_filter(weight * x, radius) / box_filter(weight, radius).clamp_min(1e-12)

    mean_i, mean_p = mean(guide_lo, w), mean(p, w)
    a = (mean(guide_lo * p, w) - mean_i * mean_p) / (mean(guide_lo * guide_lo, w) - mean_i**2 + ge)
    b = mean_p - a * mean_i
    fitted = (box_filter(w, radius) > 0).to(w.dtype)  # windows with a lit pixel: their (a, b) exist
    a, b = mean(a, fitted), mean(b, fitted)
    known = (box_filter(fitted, radius) > 0).to(w.dtype)
    norm = up(known).clamp_min(1e-12)  # upsample only the coefficients that exist (normalised convolution)
    ratio = torch.exp(up(known * a) / norm * guide + up(known * b) / norm)
    return torch.where(up(small) > eps, full * ratio, up(relit_small))


def transfer_variants(full: torch.Tensor, small: torch.Tensor, relit_small: torch.Tensor,
                      sky: torch.Tensor) -> dict[str, torch.Tensor]:
    """A working-resolution relighting brought to full size three ways.

    Args:
        full: ``(B, 3, H, W)`` linear photo; sky ``(B, 1, H, W)`` bool (kept from ``full``).
        small, relit_small: ``(B, 3, h, w)`` the working photo and its relighting.

    Returns:
        ``{"bilinear", "guided", "fast_guided"}``: ``(B, 3, H, W)`` linear (sky pixels = ``full``):
        :func:`physrelight.full_resolution.transfer_to_full_resolution` with ``guided=False`` (before) and
        ``guided=True`` (after, shipped), and :func:`transfer_fast_guided` (candidate).
    """
    from physrelight.full_resolution import transfer_to_full_resolution

    out = {name: transfer_to_full_resolution(full, small, relit_small, guided=guided)
           for name, guided in (("bilinear", False), ("guided", True))}
    out["fast_guided"] = transfer_fast_guided(full, small, relit_small)
    return {k: torch.where(sky, full, v) for k, v in out.items()}


def relight_variants(relighter: Any, image: torch.Tensor, sky: torch.Tensor, target: torch.Tensor,
                     source_lighting: torch.Tensor, method: str, working_res: int = WORKING_RES,
                     decompositions: dict[str, Any] | None = None) -> dict[str, torch.Tensor]:
    """The four outputs of :data:`CONFIGS` for one photo and target.

    Args:
        relighter: a loaded :class:`learned.Relighter`.
        image: ``(1, 3, H, W)`` linear photo; sky ``(1, 1, H, W)`` bool.
        target, source_lighting: ``(1, 9, 3)`` camera-frame SH in the photo's units.
        method: ``"quotient"`` or ``"proposed"`` (:meth:`learned.Relighter.relight_linear`;
            ``known_source=False``).
        working_res: short side of the working resolution.
        decompositions: ``{"small": ..., "full": ...}`` :meth:`learned.Relighter.decompose_linear` of
            the working and the full image (reused across targets), or None (decomposed here).

    Returns:
        ``working`` ``(1, 3, h, w)``; ``bilinear``, ``guided``, ``fast_guided`` (:func:`transfer_variants`),
        ``direct`` ``(1, 3, H, W)``; all linear.
    """
    from physrelight.full_resolution import working_resolution

    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    dec = decompositions or {}
    small, small_sky = working_resolution(image, sky, working_res)
    kw = dict(source_lighting=source_lighting, method=method, known_source=False)
    working = relighter.relight_linear(small, small_sky, target, decomposition=dec.get("small"), **kw)["relit"]
    out = {"working": working, **transfer_variants(image, small, working, sky)}
    out["direct"] = relighter.relight_linear(image, sky, target, decomposition=dec.get("full"), **kw)["relit"]
    return out


def score_variants(pair: Pair, outputs: dict[str, torch.Tensor], depth: torch.Tensor, factor: int,
                   k: int = HALO_K) -> dict[str, float]:
    """Metrics of :func:`relight_variants`' outputs for one pair (display values, foreground).

    ``depth`` ``(1, 1, H, W)`` ground-truth z-depth (0 on sky). Returns ``l1_<config>`` for each of
    :data:`CONFIGS` (``working`` at ``1 / factor`` of the resolution), ``halo_<config>`` for the
    full-resolution ones (:func:`physrelight.metrics.edge_band_l1`, NaN without a depth edge in the
    foreground), ``l1_<config>_down`` (the full-resolution output box-downsampled, scored as
    ``working``) and ``band_share`` (the band's share of the foreground).
    """
    target, fg = pair.target_display().double(), pair.foreground()
    target_lo, fg_lo = low_res_target(pair, factor).double(), low_res_foreground(fg, factor)
    out: dict[str, float] = {"l1_working": float(metrics.l1(pair.display(outputs["working"]).double(), target_lo,
                                                            fg_lo))}
    for name in CONFIGS[1:]:
        shown = pair.display(outputs[name]).double()
        out[f"l1_{name}"] = float(metrics.l1(shown, target, fg))
        out[f"halo_{name}"] = float(metrics.edge_band_l1(shown, target, depth, fg, k=k))
        down = pair.display(box_down(outputs[name].double(), factor)).double()
        out[f"l1_{name}_down"] = float(metrics.l1(down, target_lo, fg_lo))
    band = torch.as_tensor(metrics.edge_band(depth, k)) & fg
    out["band_share"] = float(band.sum() / fg.sum())
    return out


# ----------------------------------------------------------------------------- the study


def native_scores(relighter: Any, root: str | Path, full_views: Sequence[BenchView],
                  full_root: str | Path) -> dict[tuple[str, str], float]:
    """``{(method, pair key): l1}`` of each method on a folder of the same scenes rendered natively at the
    working resolution (``data/heldout``), relit there and scored as the bench scores it.

    Raises:
        ValueError: a scene of ``full_views`` is missing from ``root``, or its cameras or lightings differ
            (not the same scenes: the comparison would be meaningless).
    """
    from synth.dataset import SynthDataset

    lo, hi = SynthDataset(root, split="all", mode="full"), SynthDataset(full_root, split="all", mode="full")
    scenes = sorted({v.scene for v in full_views})
    for scene in scenes:
        if scene not in lo.scenes:
            raise ValueError(f"{str(root)!r} has no {scene}: --native-data must hold the same scenes")
        a, b = lo.record(scene), hi.record(scene)
        same = len(a["views"]) == len(b["views"]) and len(a["lights"]) == len(b["lights"]) and all(
            np.allclose(x["world_to_camera"], y["world_to_camera"]) for x, y in zip(a["views"], b["views"])) and all(
            np.allclose(x["sh"]["world"]["2"], y["sh"]["world"]["2"]) for x, y in zip(a["lights"], b["lights"]))
        if not same:
            raise ValueError(f"{scene} of {str(root)!r} is not the scene of {str(full_root)!r} (cameras or lightings "
                             "differ): render both with the same seed")
    views = [v for v in load_dataset(root, max_scenes=len(lo.scenes), with_physical=False) if v.scene in scenes]
    out: dict[tuple[str, str], float] = {}
    dec: dict[tuple[str, int], Any] = {}
    for p in cross_pairs(views):
        key = (p.view.name, p.source)
        if key not in dec:
            dec.clear()
            dec[key] = relighter.decompose_linear(p.image(), p.sky())
        for method in METHODS:
            relit = relighter.relight_linear(p.image(), p.sky(), p.target_lighting(), source_lighting=p.source_lighting(),
                                             method=method, decomposition=dec[key], known_source=False)["relit"]
            out[(method, p.key)] = float(metrics.l1(p.display(relit).double(), p.target_display().double(),
                                                    p.foreground()))
        p.release()
    return out


def _timed(fn: Callable[[], Any], threads: int = TIMING_THREADS) -> float:
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        t0 = time.perf_counter()
        fn()
        return time.perf_counter() - t0
    finally:
        torch.set_num_threads(before)


def time_configs(relighter: Any, pairs: Sequence[Pair], working_res: int = WORKING_RES) -> dict[str, dict[str, float]]:
    """Median seconds per image (photo to relit photo, decomposition included) at one torch thread.

    ``{method: {config: seconds}}`` for :data:`CONFIGS`; ``working`` is the working-resolution step alone
    (resize, decompose, relight), ``bilinear``/``guided``/``fast_guided`` that plus the transfer.
    """
    from physrelight.full_resolution import transfer_to_full_resolution, working_resolution

    out: dict[str, dict[str, float]] = {}
    for method in METHODS:
        secs: dict[str, list[float]] = {c: [] for c in CONFIGS}
        for i, p in enumerate([pairs[0], *pairs]):  # the first once more as a warm-up, not counted
            image, sky, tgt, src = p.image(), p.sky(), p.target_lighting(), p.source_lighting()
            kw = dict(source_lighting=src, method=method)
            small: dict[str, torch.Tensor] = {}

            def work() -> None:
                small["image"], s = working_resolution(image, sky, working_res)
                small["relit"] = relighter.relight_linear(small["image"], s, tgt, **kw)["relit"]

            t = {"working": _timed(work)}
            transfers = {"bilinear": lambda: transfer_to_full_resolution(image, small["image"], small["relit"], guided=False),
                         "guided": lambda: transfer_to_full_resolution(image, small["image"], small["relit"], guided=True),
                         "fast_guided": lambda: transfer_fast_guided(image, small["image"], small["relit"])}
            for name, fn in transfers.items():
                t[name] = t["working"] + _timed(fn)
            t["direct"] = _timed(lambda: relighter.relight_linear(image, sky, tgt, **kw))
            if i:
                for c in CONFIGS:
                    secs[c].append(t[c])
        out[method] = {c: statistics.median(v) for c, v in secs.items()}
    return out


def _interval(values: np.ndarray, groups: np.ndarray) -> dict[str, float]:
    ok = np.isfinite(values)
    if not ok.any():
        return {"mean": math.nan, "lo": math.nan, "hi": math.nan, "n": 0}
    m = hierarchical_bootstrap(values[ok], groups[ok], samples=BOOTSTRAP_SAMPLES, seed=0)
    return {"mean": m.mean, "lo": m.lo, "hi": m.hi, "n": m.cases}


def _difference(a: np.ndarray, b: np.ndarray, groups: np.ndarray) -> dict[str, float]:
    ok = np.isfinite(a) & np.isfinite(b)
    if not ok.any():
        return {"diff": math.nan, "lo": math.nan, "hi": math.nan, "n": 0}
    d = paired_bootstrap(a[ok], b[ok], groups[ok], samples=BOOTSTRAP_SAMPLES, seed=0)
    return {"diff": d.diff, "lo": d.lo, "hi": d.hi, "n": int(ok.sum())}


DIFFERENCES = (
    ("l1_guided", "l1_bilinear", "l1: guided - bilinear (after - before)"),
    ("halo_guided", "halo_bilinear", "halo: guided - bilinear (after - before)"),
    ("l1_guided", "l1_working", "l1: full resolution (guided) - working resolution"),
    ("l1_guided", "l1_native", "l1: full resolution (guided) - native working-resolution render"),
    ("l1_bilinear", "l1_working", "l1: full resolution (bilinear) - working resolution"),
    ("l1_fast_guided", "l1_guided", "l1: fast guided (candidate) - guided"),
    ("halo_fast_guided", "halo_guided", "halo: fast guided (candidate) - guided"),
    ("l1_direct", "l1_guided", "l1: direct at full resolution - guided transfer"),
    ("halo_direct", "halo_guided", "halo: direct at full resolution - guided transfer"),
)


def summarise(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Means with intervals and paired differences per method, from per-pair records."""
    out: dict[str, Any] = {}
    for method in METHODS:
        rs = [r for r in records if r["method"] == method]
        if not rs:
            continue
        groups = np.array([r["scene"] for r in rs])
        keys = [k for k in rs[0] if k.startswith(("l1_", "halo_")) or k == "band_share"]
        vals = {k: np.array([r[k] for r in rs], dtype=np.float64) for k in keys}
        out[method] = {"pairs": len(rs), "scenes": len(set(groups)),
                       "means": {k: _interval(v, groups) for k, v in vals.items()},
                       "differences": {f"{a} - {b}": {**_difference(vals[a], vals[b], groups), "label": label}
                                       for a, b, label in DIFFERENCES if a in vals and b in vals}}
    return out


def run_full_resolution(data: str | Path, out_dir: str | Path, command: str, working_res: int = WORKING_RES,
                        threads: int = 1, weights: str | Path | None = None, max_scenes: int | None = None,
                        timing_pairs: int = 6, k: int = HALO_K, native: str | Path | None = None,
                        progress: Callable[[str], None] = lambda m: None) -> dict[str, Any]:
    """Run the study on a synth folder; write ``OUT/full_resolution.json`` and ``OUT/full_resolution.md``.

    Args:
        data: a :mod:`synth.writer` folder rendered at a multiple of ``working_res`` (square).
        out_dir: report folder. command: the command line, for the report.
        threads: torch threads while scoring (timing always runs at :data:`TIMING_THREADS`).
        weights: the learned weights folder (None: the shipped ones).
        max_scenes: the first scenes only (None: all). timing_pairs: pairs timed per method.
        k: halo band half-width in full-resolution pixels.
        native: a folder of the same scenes rendered at the working resolution (``data/heldout``; checked
            by :func:`native_scores`), scored as ``l1_native`` per pair; None: not scored.

    Raises:
        ValueError: the folder's resolution is not a multiple of ``working_res`` above it.
    """
    from learned import Relighter
    from physrelight.full_resolution import working_resolution

    t_start = time.perf_counter()
    relighter = Relighter.load(weights)  # a bad weights folder fails before any loading
    views = load_dataset(data, max_scenes=max_scenes, with_physical=False)
    size = views[0].photo[0].shape[:2]
    if size[0] != size[1] or size[0] % working_res or size[0] <= working_res:
        raise ValueError(f"{str(data)!r} is rendered at {size[1]}x{size[0]}: the study needs a square render at a "
                         f"multiple of the working resolution {working_res} above it (physrelight synth --res 256)")
    factor = size[0] // working_res
    pairs, saturated = informative_pairs(cross_pairs(views))
    progress(f"full resolution: {len(pairs)} pairs of {len(views)} views at {size[0]} px, working at {working_res} px")
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    records: list[dict[str, Any]] = []
    try:
        if native is not None:  # first: a folder of other scenes fails before the long part
            progress(f"the same scenes rendered at {working_res} px: {native}")
            nat = native_scores(relighter, native, views, data)
        decs: dict[tuple[str, int], dict[str, Any]] = {}
        for i, p in enumerate(pairs):
            key = (p.view.name, p.source)
            if key not in decs:
                decs.clear()  # pairs come grouped by (view, source): keep one decomposition pair in memory
                image, sky = p.image(), p.sky()
                small, small_sky = working_resolution(image, sky, working_res)
                decs[key] = {"small": relighter.decompose_linear(small, small_sky),
                             "full": relighter.decompose_linear(image, sky)}
            for method in METHODS:
                outs = relight_variants(relighter, p.image(), p.sky(), p.target_lighting(), p.source_lighting(),
                                        method, working_res, decs[key])
                records.append({"key": p.key, "scene": p.view.scene, "method": method,
                                **score_variants(p, outs, to_chw(p.view.depth), factor, k)})
            p.release()
            if (i + 1) % 24 == 0 or i + 1 == len(pairs):
                progress(f"  {i + 1}/{len(pairs)} pairs")
        for r in records:
            if native is not None:
                r["l1_native"] = nat.get((r["method"], r["key"]), math.nan)
        progress(f"timing {timing_pairs} pairs per method at {TIMING_THREADS} thread")
        seconds = time_configs(relighter, pairs[:: max(1, len(pairs) // timing_pairs)][:timing_pairs], working_res)
    finally:
        torch.set_num_threads(before)
    report = {
        "command": command, "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "data": str(data), "native_data": None if native is None else str(native), "full_res": int(size[0]), "working_res": working_res, "halo_k": k,
        "depth_edge_threshold": metrics.DEPTH_EDGE_THRESHOLD, "methods": list(METHODS),
        "views": len(views), "scenes": len({v.scene for v in views}), "pairs": len(pairs),
        "saturated_pairs_left_out": saturated, "seconds_per_image_1_thread": seconds,
        "summary": summarise(records), "records": records, "seconds": time.perf_counter() - t_start,
    }
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "full_resolution.json").write_text(json.dumps(report, indent=1, allow_nan=True))
    (out / "full_resolution.md").write_text(markdown(report))
    return report


# ----------------------------------------------------------------------------- the report


def _cell(m: dict[str, float]) -> str:
    return "n/a" if not math.isfinite(m["mean"]) else f"{m['mean']:.4f} [{m['lo']:.4f}, {m['hi']:.4f}]"


def markdown(report: dict[str, Any]) -> str:
    """The report's markdown: tables of l1, halo error, differences and seconds per image."""
    full, work = report["full_res"], report["working_res"]
    lines = [
        f"# Relighting at full resolution ({full} px) without halos",
        "",
        f"`{report['command']}` ({report['date']}, {report['seconds']:.0f} s). Data `{report['data']}`: "
        f"{report['scenes']} scenes, {report['views']} views, {report['pairs']} cross-relighting pairs "
        f"({len(report['saturated_pairs_left_out'])} saturated pairs left out). Foreground l1 of display values "
        f"against the path-traced target; halo = the same l1 within {report['halo_k']} px of a depth edge "
        f"(relative jump > {report['depth_edge_threshold']:g}, or surface next to sky; "
        "`physrelight.metrics.edge_band_l1`). Mean [95 % interval, scenes then pairs resampled].",
        "",
        "Configurations:",
        f"- `working`: relit at {work} px, scored at {work} px against the target box-downsampled to {work} px;",
        f"- `bilinear` (before): the {work}-px relighting brought to {full} px by a bilinear ratio;",
        f"- `guided` (after): the same with the guided-filter ratio (the shipped default);",
        f"- `fast_guided` (candidate): the guided filter's affine coefficients fitted at {work} px and applied "
        f"at {full} px (`transfer_fast_guided`, the same ridge);",
        f"- `direct`: the networks run at {full} px.",
        "",
    ]
    for method, s in report["summary"].items():
        m = s["means"]
        lines += [f"## {method} ({s['pairs']} pairs, {s['scenes']} scenes)", "",
                  f"| configuration | l1 at {full} px | halo l1 at {full} px | l1 of the output box-downsampled to "
                  f"{work} px | seconds / image (1 thread) |", "| --- | --- | --- | --- | --- |"]
        sec = report["seconds_per_image_1_thread"].get(method, {})
        if "l1_native" in m:
            lines.append(f"| native {work}-px render (`{report['native_data']}`, the bench's figure) | "
                         f"{_cell(m['l1_native'])} (at {work} px) | | | |")
        lines.append(f"| working ({work} px) | {_cell(m['l1_working'])} (at {work} px) | | "
                     f"{_cell(m['l1_working'])} | {sec.get('working', math.nan):.3f} |")
        for c in CONFIGS[1:]:
            lines.append(f"| {c} | {_cell(m[f'l1_{c}'])} | {_cell(m[f'halo_{c}'])} | {_cell(m[f'l1_{c}_down'])} | "
                         f"{sec.get(c, math.nan):.3f} |")
        d = s["differences"]["l1_guided - l1_working"]
        verdict = "no worse" if d["diff"] <= 0 else "worse" if d["lo"] > 0 else "not resolved (mean above 0, interval spans 0)"
        h = s["differences"]["halo_guided - halo_bilinear"]
        removes = "removes halo" if h["hi"] < 0 else "adds halo" if h["lo"] > 0 else "halo change not resolved"
        lines += ["", f"Verdicts: full resolution (guided) against {work} px: **{verdict}** "
                  f"({d['diff']:+.4f} [{d['lo']:+.4f}, {d['hi']:+.4f}]); guided against bilinear: **{removes}** "
                  f"({h['diff']:+.4f} [{h['lo']:+.4f}, {h['hi']:+.4f}]). "
                  f"Band share of the foreground: {m['band_share']['mean']:.3f}.", "",
                  "| paired difference | mean [95 % interval] | pairs |", "| --- | --- | --- |"]
        for d in s["differences"].values():
            lines.append(f"| {d['label']} | {d['diff']:+.4f} [{d['lo']:+.4f}, {d['hi']:+.4f}] | {d['n']} |")
        lines.append("")
    return "\n".join(lines)


DEFAULT_DATA = "data/heldout256"


def main(args: Any, progress: Callable[[str], None]) -> int:
    """``physrelight bench --full-resolution`` (:mod:`validation.bench.cli`): run, print where the report went."""
    import shlex

    if args.real or args.hdri_dir is not None:
        raise ValueError("--full-resolution is a synthetic study: it takes --data, not --real/--hdri-dir")
    data = args.data or DEFAULT_DATA
    words = ["physrelight", "bench", "--full-resolution", "--data", data, "-o", args.output]
    if args.threads != 1:
        words += ["--threads", str(args.threads)]
    if args.weights is not None:
        words += ["--weights", args.weights]
    if args.native_data is not None:
        words += ["--native-data", args.native_data]
    report = run_full_resolution(data, args.output, " ".join(shlex.quote(w) for w in words), threads=args.threads,
                                 weights=args.weights, native=args.native_data, progress=progress)
    print(f"bench --full-resolution done in {report['seconds']:.0f} s ({report['pairs']} pairs) -> "
          f"{args.output}/full_resolution.md")
    return 0
