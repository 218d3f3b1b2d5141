"""What the sky-mask probes (studies 26, 28, 30, 44-46), the crop probes (studies 34-36) and the bench-pair
probes (studies 29, 33) share.

Sky masks: every ``bench --real --full`` crop (seed 0, 16 per panorama, fov 45-75 deg, 4 samples) of the
training panoramas or of the held-out one, each mask setting scored against the true sky: IoU and boundary
F (2 px) over the crops with sky, the fraction called sky on those without, the crops with sky refused.

Bench pairs: foreground l1 of several methods on the bench's cross-relighting pairs.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
import torch

from physrelight import metrics


def crop_panoramas(heldout: bool) -> tuple[str, list[Any]]:
    """``("heldout", [sunrise])`` or ``("training", [city, courtyard, forest])``."""
    from synth.panorama_crops import shipped_panoramas

    group = "heldout" if heldout else "training"
    return group, [p for p in shipped_panoramas() if p.group == group]


def bench_crops(panos: Sequence[Any]) -> Iterator[tuple[Any, Any]]:
    """``(panorama, crop)`` for every ``bench --real --full`` crop of ``panos`` (seed 0, 16 per panorama, fov
    45-75 deg, 4 samples), in order."""
    from synth.panorama_crops import make_crops

    for pano in panos:
        for c in make_crops(pano, 16, 0, fov_range=(45.0, 75.0), samples=4):
            yield pano, c


def score_sky_masks(panos: Sequence[Any], grid: Sequence[str],
                    masks_of: Callable[[torch.Tensor], dict[str, tuple[torch.Tensor, str]]]) -> dict[str, dict[str, Any]]:
    """Per setting of ``grid``, the lists ``iou``, ``f``, ``no_sky_called`` and the count ``refused_with_sky``.

    ``masks_of(linear photo (1, 3, H, W))`` gives every setting's ``(sky (1, 1, H, W) bool, reason)`` for one
    crop (so a probe can share work between settings)."""
    rows = {g: {"iou": [], "f": [], "no_sky_called": [], "refused_with_sky": 0} for g in grid}
    t0 = time.time()
    crops = list(bench_crops(panos))
    for i, (pano, c) in enumerate(crops):
        lin = c.linear()
        has_sky = c.sky.mean() >= 0.01
        masks = masks_of(lin)
        for g in grid:
            sky, why = masks[g]
            m = sky[0, 0].numpy()
            row = rows[g]
            if has_sky:
                row["iou"].append(metrics.mask_iou(m, c.sky))
                row["f"].append(metrics.boundary_f(m, c.sky, 2.0))
                row["refused_with_sky"] += bool(why)
            else:
                row["no_sky_called"].append(float(m.mean()))
        if i + 1 == len(crops) or crops[i + 1][0] is not pano:
            print(f"{pano.name}: {time.time() - t0:.0f} s", flush=True)
    return rows


def setting_summary(row: dict[str, Any]) -> dict[str, Any]:
    """The means and counts of one setting's :func:`score_sky_masks` row."""
    return {"iou": float(np.mean(row["iou"])), "boundary_f": float(np.mean(row["f"])),
            "no_sky_called": float(np.mean(row["no_sky_called"])) if row["no_sky_called"] else None,
            "refused_with_sky": row["refused_with_sky"], "crops_with_sky": len(row["iou"])}


def bench_l1(methods: dict[str, Callable[[Any], torch.Tensor]], pairs: Sequence[Any],
             progress: Callable[[str, torch.Tensor], None] | None = None) -> dict[str, torch.Tensor]:
    """Per method (``pair -> relit linear (1, 3, H, W)``), the ``(len(pairs),)`` foreground l1 against the
    path-traced target, the bench's way (:func:`validation.bench.scores.score`)."""
    from validation.bench.scores import score

    l1 = {}
    with torch.no_grad():
        for name, fn in methods.items():
            preds, T, M = [], [], []
            for p in pairs:
                fg, tgt = p.foreground(), p.target_display()
                preds.append(torch.where(fg, p.display(fn(p)), tgt))
                T.append(tgt)
                M.append(fg)
            l1[name] = score(preds, T, M, which=("l1",))["l1"]
            if progress is not None:
                progress(name, l1[name])
    return l1


def score_mask_variants(masks_of: Callable[[torch.Tensor], dict[Any, np.ndarray]], settings: Sequence[Any],
                        heldout: bool, lattice_composite: Callable[[Any, int], tuple] | None = None) -> dict[str, Any]:
    """Studies 44-46: the mean of IoU and boundary F (2 px) of each mask setting on the crops with sky ("plain"),
    on study 40's lattice composites of the training crops with >= 10 % sky ("lattice"; ``lattice_composite``
    is its ``composite(crop, seed)``, seeds 0 and 1) and the sky called on the crops without sky; each setting
    against the first with a bootstrap over crops (a crop's two composites stay together). Prints the table.

    ``masks_of(linear photo (1, 3, H, W))`` gives every setting's ``(H, W)`` bool mask for one photo."""
    from physrelight.stats import paired_bootstrap

    group, panos = crop_panoramas(heldout)
    sets = {"plain": {s: [] for s in settings}, "lattice": {s: [] for s in settings}}
    no_sky = {s: [] for s in settings}
    groups: dict[str, list[str]] = {"plain": [], "lattice": []}
    t0 = time.time()

    def add(name: str, masks: dict[Any, np.ndarray], truth: np.ndarray, crop_name: str) -> None:
        for s, m in masks.items():
            sets[name][s].append((metrics.mask_iou(m, truth) + metrics.boundary_f(m, truth, 2.0)) / 2)
        groups[name].append(crop_name)

    for pano, crop in bench_crops(panos):
        lin = crop.linear()
        if crop.sky.mean() < 0.01:
            for s, m in masks_of(lin).items():
                no_sky[s].append(float(m.mean()))
            continue
        add("plain", masks_of(lin), crop.sky, f"{pano.name}_{crop.index}")
        if lattice_composite is not None and not heldout and crop.sky.mean() >= 0.10:
            for seed in (0, 1):
                comp, truth, _ = lattice_composite(crop, seed)
                add("lattice", masks_of(comp), truth, f"{pano.name}_{crop.index}")
    out: dict[str, Any] = {"group": group, "seconds": time.time() - t0, "settings": [str(s) for s in settings]}
    for name, rows in sets.items():
        if not groups[name]:
            continue
        base = np.asarray(rows[settings[0]])
        out[name] = {}
        for s in settings:
            v = np.asarray(rows[s])
            entry: dict[str, Any] = {"mean_iou_f": float(v.mean()), "n": int(v.size)}
            line = f"{name:8s} {str(s):9s}: mean IoU/F {v.mean():.4f}"
            if s != settings[0]:
                d = paired_bootstrap(v, base, groups=np.asarray(groups[name]), seed=0)
                entry["minus_first"] = d._asdict()
                line += f"  {d.diff:+.4f} [{d.lo:+.4f}, {d.hi:+.4f}]"
            out[name][str(s)] = entry
            print(line, flush=True)
    out["no_sky_called"] = {str(s): float(np.mean(v)) if v else None for s, v in no_sky.items()}
    print("sky called on crops without sky:", {k: round(v, 4) for k, v in out["no_sky_called"].items() if v is not None})
    return out
