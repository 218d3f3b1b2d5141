"""Held-out relighting evaluation: relit photo vs path-traced ground truth, per method.

The protocol (shared with the benchmark):

* **source**: the LDR photo of (scene, view v, lighting a), linearised with the sRGB curve
  as a user's photo would be;
* **target**: the path-traced ``radiance`` of (v, lighting b), ``b != a``, brought into the
  source photo's units (``radiance * 2**ev_a * wb_gains_a``), sRGB curve, no noise, no
  JPEG, clipped to [0, 1]; the camera stays, only the light changes;
* **lighting handed to the methods**: the true camera-frame SH of b and of a, both times
  ``2**ev_a * wb_gains_a``. Decomposition-based methods (albedo/lighting scale ambiguity)
  scale the target by the luminance-DC ratio of their own estimated source lighting
  over the given source lighting;
* **metrics** on the LDR images over the foreground (not sky, ground-truth normal valid):
  l1, SSIM (Wang et al., :func:`physrelight.metrics.ssim`), PSNR and CIEDE2000; mean over
  the (source, target) cases. A case whose target is clipped to 1 on every foreground pixel
  (an over-exposed target) is left out and counted (``"saturated_cases"``): it carries no
  information, since any prediction at least as bright matches it exactly (PSNR ``inf``).
  The benchmark does not apply this rule (its data has no such target today);
* **is the difference real**: ``proposed`` minus each other method, per case, with a 95 %
  bootstrap interval that resamples whole scenes (:func:`physrelight.stats.paired_bootstrap`;
  a scene's cases share its geometry, so they are not independent).

Methods: ``proposed`` (decomposition + ShadowNet + neural renderer), ``lambertian_sh``
(``albedo * shading(n; target)``, the InverseRenderNet-style relighting),
``shadownet_lambertian`` (times ShadowNet's target shadow) and ``identity`` (the source
photo unchanged: what doing nothing scores); on request ``quotient`` (the photo times the shading
ratio, :mod:`physrelight.quotient`, the estimated track). Optionally ``reference``: the ``proposed`` of a
second pipeline (another weights folder) on the same cases, so that two pipelines are compared
case by case with the same interval (``train evaluate-relight --reference-weights``).

The relighting itself goes through one callable with the signature of
:meth:`learned.Relighter.relight_linear` ``(image, sky, target, source_lighting, method)``
(a Relighter built from the shipped weights, or from the networks of a training run).
"""

from __future__ import annotations

import math
from pathlib import Path
from collections.abc import Iterator
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F

from physrelight import colour, metrics
from physrelight.stats import paired_bootstrap
from synth.dataset import SynthDataset, to_chw
from synth.photo import photo_gain

from .data import evenly_spread, load_photo

__all__ = ["METHODS", "case_batches", "evaluate_relight", "format_table", "informative_target", "relight_cases",
           "relit_scores"]

METHODS = ("proposed", "lambertian_sh", "shadownet_lambertian", "identity", "quotient")
DEFAULT_METHODS = METHODS[:4]  # what evaluate_relight scores unless told: the figures of docs/learned.md
_REPORTED = (*METHODS, "reference")  # what a result may hold: the methods and a second pipeline's proposed

Relight = Callable[..., dict[str, torch.Tensor]]


def relight_cases(ds: SynthDataset) -> list[tuple[str, int, int, int]]:
    """Every ``(scene, view, source light a, target light b)`` with ``b != a``."""
    out = []
    for scene in ds.scenes:
        nl = ds.num_lights(scene)
        for v in range(ds.num_views(scene)):
            for a in range(nl):
                out.extend((scene, v, a, b) for b in range(nl) if b != a)
    return out


def load_case(ds: SynthDataset, scene: str, view: int, a: int, b: int, res: int) -> dict[str, torch.Tensor]:
    """One case: source ``image (3, H, W)`` linear, ``sky``, ``fg`` ``(1, H, W)`` bool, ``target_ldr
    (3, H, W)``, ``target_sh`` / ``source_sh`` ``(9, 3)`` in the source photo's units."""
    photo = load_photo(ds, scene, view, a, res)
    src = ds.load(scene, view, a, keys=("photo_params", "sh", "normal"))
    dst = ds.load(scene, view, b, keys=("radiance", "sh"))
    gain = photo_gain(src["photo_params"])
    radiance = to_chw((dst["radiance"] * gain[None, None, :]).astype(np.float32))
    normal = to_chw(src["normal"])
    if radiance.shape[-1] != res:
        radiance = F.interpolate(radiance[None], size=(res, res), mode="area")[0]
        normal = F.interpolate(normal[None], size=(res, res), mode="nearest")[0]
    target_ldr = colour.to_ldr(radiance.clamp_min(0))
    fg = ~photo["sky"] & (normal.norm(dim=0, keepdim=True) > 0.5)
    return {"image": photo["image"], "sky": photo["sky"], "fg": fg, "target_ldr": target_ldr,
            "target_sh": torch.from_numpy(dst["sh"]["2"] * gain[None, :]).float(),
            "source_sh": torch.from_numpy(src["sh"]["2"] * gain[None, :]).float()}


def informative_target(target_ldr: torch.Tensor, fg: torch.Tensor) -> bool:
    """False when the LDR target ``(3, H, W)`` is clipped to 1 in every channel of every
    foreground pixel ``fg (1, H, W)``: such a case cannot rank methods (every prediction that
    is bright enough is exact)."""
    return bool((target_ldr[:, fg[0]] < 1.0).any())


def relit_scores(pred: torch.Tensor, target: torch.Tensor, fg: torch.Tensor) -> dict[str, np.ndarray]:
    """Per-image l1, SSIM, PSNR, CIEDE2000 of LDR ``(B, 3, H, W)`` over ``fg (B, 1, H, W)``."""
    m = fg.float()
    return {"l1": metrics.l1(pred, target, m, reduction="none").numpy(),
            "ssim": metrics.ssim(pred, target, m, reduction="none").numpy(),
            "psnr": metrics.psnr(pred, target, m, reduction="none").numpy(),
            "ciede2000": metrics.delta_e2000(pred, target, m, encoding="srgb", reduction="none").numpy()}


def case_batches(ds: SynthDataset, cases: list, res: int = 64, batch_size: int = 16, progress: bool = False
                 ) -> Iterator[tuple[dict[str, torch.Tensor], list[str], int]]:
    """Batches of the scorable relighting cases of ``ds``, in order: yields ``(batch, scenes, saturated)``.

    ``batch`` stacks :func:`load_case`'s tensors (``(B, ...)``), ``scenes`` names each case's scene, and
    ``saturated`` counts the cases of this chunk left out because their target is clipped on the whole
    foreground (:func:`informative_target`). Cases without foreground pixels 5 px from the border (SSIM's
    window) are skipped uncounted. A chunk with nothing left yields an empty ``batch`` and ``scenes``, so its
    ``saturated`` still reaches the caller."""
    from tqdm import tqdm

    r = 5  # SSIM needs mask pixels at least 5 px from the border
    for start in tqdm(range(0, len(cases), batch_size), disable=not progress, desc="evaluate relight"):
        loaded, scenes, saturated = [], [], 0
        for c in cases[start:start + batch_size]:
            case = load_case(ds, *c, res=res)
            if not bool(case["fg"][:, r:-r, r:-r].any()):
                continue
            if not informative_target(case["target_ldr"], case["fg"]):
                saturated += 1
                continue
            loaded.append(case)
            scenes.append(c[0])
        batch = {k: torch.stack([c[k] for c in loaded]) for k in loaded[0]} if loaded else {}
        yield batch, scenes, saturated


def evaluate_relight(relight: Relight, root: str | Path, split: str = "all", res: int = 64,
                     max_cases: int | None = None, methods: tuple[str, ...] = DEFAULT_METHODS, batch_size: int = 16,
                     progress: bool = False, reference: Relight | None = None) -> dict[str, dict[str, float] | float]:
    """Relighting metrics of each method over the held-out cases.

    Args:
        relight: ``(image, sky, target, source_lighting, method) -> {"relit": (B, 3, H, W), ...}``
            (``Relighter.relight_linear``).
        root, split: dataset with ground truth (``mode="full"``) and the split to use.
        res: resolution the pipeline runs at (the inverse network's, 64).
        max_cases: at most this many cases, evenly spread; None = all.
        methods: among :data:`METHODS`.
        reference: a second pipeline's relight callable (same signature); its ``proposed`` is
            scored as the method ``"reference"``. None: no comparison.

    Returns:
        ``{method: {"l1", "ssim", "psnr", "ciede2000"}, "cases": n, "saturated_cases": k}`` (means
        over the n scored cases; PSNR is the mean of per-case dB; k cases left out because their
        target is clipped on the whole foreground) and, when ``proposed`` is among the methods,
        ``"paired": {method: {metric: {"diff", "lo", "hi"}}}``: ``proposed - method``, its
        95 % scene-bootstrap interval (2000 resamples, seed 0) and ``"scenes"``.
    """
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise ValueError(f"unknown methods {bad}; known: {list(METHODS)}")
    ds = SynthDataset(root, split=split, mode="full")
    cases = relight_cases(ds)
    if not cases:
        raise ValueError(f"{str(root)!r} has no relighting cases in split {split!r} (needs >= 2 lightings)")
    cases = evenly_spread(cases, max_cases)
    pipelines = {m: (relight, m) for m in methods}
    if reference is not None:
        pipelines["reference"] = (reference, "proposed")
    acc: dict[str, dict[str, list[np.ndarray]]] = {m: {} for m in pipelines}
    scenes: list[str] = []
    saturated = 0
    for batch, batch_scenes, left_out in case_batches(ds, cases, res, batch_size, progress):
        saturated += left_out
        if not batch_scenes:
            continue
        scenes += batch_scenes
        for m, (fn, method) in pipelines.items():
            if method == "identity":
                pred = colour.to_ldr(batch["image"])
            else:
                with torch.no_grad():
                    out = fn(batch["image"], batch["sky"], batch["target_sh"], batch["source_sh"], method)
                pred = colour.to_ldr(out["relit"].clamp_min(0))
            for k, v in relit_scores(pred, batch["target_ldr"], batch["fg"]).items():
                acc[m].setdefault(k, []).append(v)
    per_case = {m: {k: np.concatenate(v) for k, v in acc[m].items()} for m in pipelines}
    result: dict[str, dict | float] = {m: {k: float(np.mean(v)) for k, v in per_case[m].items()} for m in pipelines}
    result["cases"] = float(len(scenes))
    result["saturated_cases"] = float(saturated)
    if "proposed" in methods and scenes:
        result["paired"] = {m: {k: paired_bootstrap(per_case["proposed"][k], v, groups=scenes)._asdict()
                                for k, v in per_case[m].items()}
                            for m in pipelines if m != "proposed"}
    return result


def format_table(result: dict) -> str:
    """A markdown table of :func:`evaluate_relight`'s result."""
    lines = ["| method | l1 | SSIM | PSNR dB | CIEDE2000 |", "| --- | --- | --- | --- | --- |"]
    for m in _REPORTED:
        if m in result:
            v = result[m]
            lines.append(f"| {m} | {v['l1']:.4f} | {v['ssim']:.4f} | {v['psnr']:.2f} | {v['ciede2000']:.2f} |")
    lines.append(f"\n{int(result['cases'])} cases"
                 + (f" ({int(result['saturated_cases'])} left out: target clipped on the whole foreground)"
                    if result.get("saturated_cases") else ""))
    for m, per in result.get("paired", {}).items():
        cells = ", ".join(f"{name} {per[k]['diff']:+.4f} [{per[k]['lo']:+.4f}, {per[k]['hi']:+.4f}]"
                          for k, name in (("l1", "l1"), ("ssim", "SSIM"), ("psnr", "PSNR"), ("ciede2000", "CIEDE")))
        groups = next(iter(per.values()))["groups"]
        lines.append(f"proposed - {m} (95 % interval, {groups} scenes resampled): {cells}")
    return "\n".join(lines)


def finite(result: dict) -> bool:
    """True when every metric of every method is finite."""
    return all(math.isfinite(x) for m in _REPORTED if m in result for x in result[m].values())
