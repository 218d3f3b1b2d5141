"""Study 40 probe: the sky mask's colour growth on real crops with composited lattices (a ground truth of thin
structures over real skies).

Over each ``bench --real --full`` crop of the training panoramas with >= 10 % true sky, two seeded structures
(a truss tower and 0-3 power lines) are rasterised at 4 x 4 samples per pixel and composited over the photo's
linear values; the true sky is the crop's where the structures cover under half a pixel. Each setting
``REACH:SPREAD`` of the growth (``learned.sky_segmentation.grow_sky_by_colour``, degree 2, clamped) is applied
to the shipped mask and scored by IoU and boundary F (2 px). ``--heldout`` scores sunrise's own crops (its
pylons are real lattices; no structure is drawn there), once, after the choice. ``--save DIR`` writes a few
composites and their masks for a look.

    .venv/bin/python docs/experiments/scripts/40_lattice_sky_probe.py -o docs/experiments/results/40_lattice_training.json
    .venv/bin/python docs/experiments/scripts/40_lattice_sky_probe.py --heldout --only 0:0.1 --only R:S -o docs/experiments/results/40_sunrise.json
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_crop_scores import bench_crops, crop_panoramas  # noqa: E402

from learned import Relighter  # noqa: E402
from learned import sky_segmentation as ss  # noqa: E402
from physrelight import colour, io, metrics  # noqa: E402
from physrelight.stats import paired_bootstrap  # noqa: E402

GRID = ("0:0.1", "0.05:0.05", "0.05:0.1", "0.1:0.05", "0.1:0.1", "0.2:0.05", "0.2:0.1")
SS = 4  # samples per pixel and axis


def _segments_coverage(segs: np.ndarray, widths: np.ndarray, h: int, w: int) -> np.ndarray:
    """``(h, w)`` coverage in [0, 1] of thick segments ``(N, 4)`` (x0, y0, x1, y1 in pixels) of ``widths (N,)``."""
    ys, xs = np.mgrid[0:h * SS, 0:w * SS]
    px, py = (xs + 0.5) / SS, (ys + 0.5) / SS
    hit = np.zeros((h * SS, w * SS), dtype=bool)
    for (x0, y0, x1, y1), t in zip(segs, widths):
        lo_x, hi_x = int(max(0, (min(x0, x1) - t) * SS)), int(min(w * SS, (max(x0, x1) + t) * SS + 1))
        lo_y, hi_y = int(max(0, (min(y0, y1) - t) * SS)), int(min(h * SS, (max(y0, y1) + t) * SS + 1))
        if lo_x >= hi_x or lo_y >= hi_y:
            continue
        qx, qy = px[lo_y:hi_y, lo_x:hi_x], py[lo_y:hi_y, lo_x:hi_x]
        dx, dy = x1 - x0, y1 - y0
        u = np.clip(((qx - x0) * dx + (qy - y0) * dy) / max(dx * dx + dy * dy, 1e-12), 0.0, 1.0)
        d2 = (qx - x0 - u * dx) ** 2 + (qy - y0 - u * dy) ** 2
        hit[lo_y:hi_y, lo_x:hi_x] |= d2 <= (t / 2) ** 2
    return hit.reshape(h, SS, w, SS).mean(axis=(1, 3))


def tower(rng: np.random.Generator, h: int, w: int, sky: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A truss tower's segments and widths (pixels)."""
    rows = np.nonzero(sky.any(axis=1))[0]
    lowest = int(rows.max()) if rows.size else h - 1
    base_y = float(rng.uniform(lowest, h + 0.2 * h))
    top_y = float(rng.uniform(-0.2 * h, h / 3))
    xc = float(rng.uniform(0.15, 0.85) * w)
    half_b = float(rng.uniform(0.10, 0.35) * w / 2)
    half_t = half_b * float(rng.uniform(0.2, 0.6))
    t = float(rng.uniform(0.6, 2.0))

    def edge(y: float) -> tuple[float, float]:
        f = (y - top_y) / (base_y - top_y)
        half = half_t + f * (half_b - half_t)
        return xc - half, xc + half

    segs, widths = [], []
    for side in (0, 1):
        segs.append((edge(top_y)[side], top_y, edge(base_y)[side], base_y))
        widths.append(1.5 * t)
    step = float(rng.uniform(0.06, 0.15) * h)
    ys = np.arange(top_y, base_y, step).tolist() + [base_y]
    for y in ys:
        segs.append((*edge(y)[:1], y, edge(y)[1], y))
        widths.append(t)
    for y0, y1 in zip(ys[:-1], ys[1:]):
        (a0, b0), (a1, b1) = edge(y0), edge(y1)
        segs += [(a0, y0, b1, y1), (b0, y0, a1, y1)]
        widths += [t, t]
    return np.asarray(segs, dtype=np.float64), np.asarray(widths, dtype=np.float64)


def power_lines(rng: np.random.Generator, h: int, w: int, sky: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """0-3 sagging lines across the frame, as short segments."""
    segs, widths = [], []
    rows = np.nonzero(sky.any(axis=1))[0]
    lowest = int(rows.max()) if rows.size else h // 2
    for _ in range(int(rng.integers(0, 4))):
        y_a, y_b = rng.uniform(0, max(lowest, 2), 2)
        sag = float(rng.uniform(0.02, 0.12) * h)
        t = float(rng.uniform(0.5, 1.0))
        xs = np.linspace(-2, w + 2, 40)
        f = (xs + 2) / (w + 4)
        ys = y_a + (y_b - y_a) * f + 4 * sag * f * (1 - f)
        for i in range(len(xs) - 1):
            segs.append((xs[i], ys[i], xs[i + 1], ys[i + 1]))
            widths.append(t)
    return np.asarray(segs, dtype=np.float64).reshape(-1, 4), np.asarray(widths, dtype=np.float64)


def composite(crop, seed: int) -> tuple[torch.Tensor, np.ndarray, np.ndarray]:
    """``(linear photo (1, 3, h, w), true sky (h, w) bool, coverage (h, w))`` of ``crop`` with a structure drawn."""
    rng = np.random.default_rng([40, crop.index, seed, sum(map(ord, crop.panorama.name))])
    h, w = crop.size
    lin = crop.linear()[0].permute(1, 2, 0).numpy().astype(np.float64)
    fg = ~crop.sky
    base = np.median(lin[fg], axis=0) if fg.any() else np.full(3, 0.1)
    out = lin.copy()
    cover_all = np.zeros((h, w))
    for segs, widths in (tower(rng, h, w, crop.sky), power_lines(rng, h, w, crop.sky)):
        if len(segs) == 0:
            continue
        a = _segments_coverage(segs, widths, h, w)[..., None]
        col = base * float(rng.uniform(0.3, 1.5))
        out = (1 - a) * out + a * col
        cover_all = 1 - (1 - cover_all) * (1 - a[..., 0])
    disp = np.round(np.clip(colour.to_ldr(out), 0, 1) * 255) / 255
    photo = colour.from_ldr(torch.from_numpy(disp).permute(2, 0, 1)[None].float())
    return photo, crop.sky & (cover_all < 0.5), cover_all


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true", help="sunrise's own crops, no structure drawn (read once)")
    ap.add_argument("--only", action="append", default=[], help="REACH:SPREAD settings (default: the grid)")
    ap.add_argument("--save", help="a folder for a few composites and masks")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = Relighter.load().sky_segmenter
    grid = args.only or list(GRID)
    group, panos = crop_panoramas(args.heldout)
    rows = {g: {"iou": [], "f": []} for g in grid}
    names, t0 = [], time.time()
    for pano, crop in bench_crops(panos):
        if crop.sky.mean() < (0.01 if args.heldout else 0.10):
            continue
        samples = [(crop.linear(), crop.sky, None)] if args.heldout else [composite(crop, s) for s in (0, 1)]
        for k, (lin, truth, cover) in enumerate(samples):
            base, _ = ss.sky_mask_full_resolution(model, lin, grow=0.0)
            for g in grid:
                reach, spread = (float(x) for x in g.split(":"))
                r_px = int(round(reach * min(lin.shape[-2:])))
                m = ss.grow_sky_by_colour(base, lin, r_px, max_spread=spread)[0, 0].numpy()
                rows[g]["iou"].append(metrics.mask_iou(m, truth))
                rows[g]["f"].append(metrics.boundary_f(m, truth, 2.0))
            names.append(f"{pano.name}_{crop.index}_{k}")
            if args.save and len(names) <= 12:
                d = Path(args.save)
                d.mkdir(parents=True, exist_ok=True)
                grown = ss.grow_sky_by_colour(base, lin, int(round(0.1 * min(lin.shape[-2:]))), max_spread=0.1)
                panel = [colour.to_ldr(lin[0].permute(1, 2, 0)).numpy()] + [
                    np.repeat(x[..., None].astype(np.float32), 3, -1) for x in
                    (truth, base[0, 0].numpy(), grown[0, 0].numpy())]
                io.write_png(d / f"{names[-1]}.png", np.concatenate(panel, 1))
    print(f"{len(names)} samples, {time.time() - t0:.0f} s", flush=True)
    out = {"group": group, "samples": names, "settings": {}, "minus_0": {}}
    for g, row in rows.items():
        iou, f = np.asarray(row["iou"]), np.asarray(row["f"])
        out["settings"][g] = {"iou": float(iou.mean()), "boundary_f": float(f.mean()), "mean": float((iou + f).mean() / 2),
                              "per_sample_mean": [round(float(x), 4) for x in (iou + f) / 2]}
        print(f"{g:>10}: IoU {iou.mean():.4f}  F {f.mean():.4f}  mean {(iou + f).mean() / 2:.4f}", flush=True)
    ref = [g for g in grid if g.startswith("0:")]
    if ref:
        base_m = np.asarray(out["settings"][ref[0]]["per_sample_mean"])
        # a crop's two structures stay together: resample crops
        crop_of = np.asarray(["_".join(n.split("_")[:2]) for n in names])
        for g in grid:
            if g == ref[0]:
                continue
            d = paired_bootstrap(out["settings"][g]["per_sample_mean"], base_m, groups=crop_of, seed=0)
            out["minus_0"][g] = d._asdict()
            print(f"{g:>10} minus reach 0: {d.diff:+.4f} [{d.lo:+.4f}, {d.hi:+.4f}] over {d.groups} crops", flush=True)
    io.write_json(args.out, out)


if __name__ == "__main__":
    main()
