"""Check 5: the relighting ceiling.

An oracle relights with everything a perfect decomposition would give: ground-truth
albedo and normals, the target lighting's SH shading and the ground-truth shadow under
the target lighting: ``oracle = s * albedo * shading(n; L_target)``. Compared with the
path-traced render under the target lighting (foreground pixels with coherent
footprints, display values: exposure of the target lighting, clipped to [0, 1], sRGB
encoded), it is the best any SH-based renderer of the paper's image model can do on
these scenes. The gap is split by removing one effect at a time:

1. paper: order-2 SH, synth shadow (``shadow.exr``), against the full render;
2. order-4 SH;
3. exact irradiance (no SH truncation);
4. the direct-light ratio as shadow (the shadow definition);
5. against the direct-light render (no interreflection): what remains is noise.

Metrics: l1, SSIM, PSNR (:mod:`physrelight.metrics`), plus the noise floor (two
half-means of the renders compared with each other).

Verdict (the oracle's ingredients are right where nothing is unmodelled): on pixels
nothing occludes, the direct-light render equals ``albedo E / pi``
(luminance) per pixel (unoccluded: two shadow renders and a ray cast in fixed directions
agree): the share of ``|z| > 4`` is within 4 binomial sd of its null
rate. z uses the per-pixel standard error over the K renders combined with the albedo's
(two G-buffer renders of many more samples, a small part); its null is taken as
Student's t with K-1 dof; the deviation is first reduced by the yardstick's quadrature
error and the ray cast's direction resolution.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from physrelight import colour, metrics

from . import charts
from .common import LUMINANCE, CheckResult, Context, binomial_upper, t_tail
from .renderer_irradiance import lighting_yardstick
from .scenes import BankView, bank
from .shadow_loss import chw, exact_shading, sh_shading

STAGES = (("paper", "SH order 2, synth shadow, vs full render"),
          ("order4", "SH order 4"),
          ("exact", "exact irradiance (no truncation)"),
          ("ratio", "direct-ratio shadow"),
          ("direct", "vs direct-light render (no interreflection)"))


def display(x: np.ndarray) -> torch.Tensor:
    """``(H, W, 3)`` exposure-scaled linear radiance -> ``(1, 3, H, W)`` float32 sRGB in [0, 1]
    (float32: display values need no more, and SSIM's convolutions run ~10x faster)."""
    return colour.linear_to_srgb(chw(np.clip(x, 0.0, 1.0)).float())


def compare(pred: np.ndarray, target: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """l1, SSIM, PSNR of display images on ``mask`` (outside it ``pred`` takes ``target``'s values)."""
    p = np.where(mask[..., None], pred, target)
    a, b = display(p), display(target)
    mk = chw(mask.astype(np.float64)).float()
    return {"l1": float(metrics.l1(a, b, mk)), "ssim": float(metrics.ssim(a, b, mk)),
            "psnr": float(metrics.psnr(a, b, mk))}


def oracles(v: BankView) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``stage -> (oracle, target)`` exposure-scaled linear images."""
    e = v.exposure
    full, direct = v.full.mean(0) * e, v.direct.mean(0) * e
    s, r = v.shadow[..., None], v.direct_ratio[..., None]
    ex = exact_shading(v)
    return {"paper": (s * v.albedo * sh_shading(v, 2), full), "order4": (s * v.albedo * sh_shading(v, 4), full),
            "exact": (s * v.albedo * ex, full), "ratio": (r * v.albedo * ex, full),
            "direct": (r * v.albedo * ex, direct)}


def evaluate_view(v: BankView) -> dict[str, Any]:
    """The relighting ceiling's figures on one view of the scene bank."""
    m = v.mask()
    f: dict[str, Any] = {"view": v.name, "lighting": v.lighting_name, "pixels": int(m.sum())}
    for stage, (pred, target) in oracles(v).items():
        f[stage] = compare(pred, target, m)
    k = v.full.shape[0] // 2
    f["noise_half_means"] = compare(v.full[:k].mean(0) * v.exposure, v.full[k:].mean(0) * v.exposure, m)
    # verdict: unshadowed pixels, direct render vs albedo E / pi, per-pixel z (luminance)
    free = m & v.unoccluded
    runs = v.direct[:, free] @ LUMINANCE
    exact = (v.albedo * v.irradiance / math.pi)[free] @ LUMINANCE
    # The albedo is a Monte Carlo footprint average too: +- its standard error, in luminance.
    exact_sem = (np.abs(v.albedo_sem * v.irradiance / math.pi) @ LUMINANCE)[free]
    allowance = v.occlusion_resolution[free]
    q = lighting_yardstick(v.light)
    if runs.shape[1]:
        mean = runs.mean(0)
        sem = runs.std(0, ddof=1) / math.sqrt(runs.shape[0])
        dev = np.maximum(np.abs(mean - exact) - (allowance + q) * exact, 0.0)
        sd = np.sqrt(sem**2 + exact_sem**2)
        ok = sd > 0  # a pixel without sample variance (black) has no z
        f["_z"] = dev[ok] / sd[ok]
    else:
        f["_z"] = np.zeros(0)
    f["free_pixels"] = int(free.sum())
    return f


SUMMARY = (
    "How good can relighting with the paper's image model get? An *oracle* relights each view with the "
    "ground-truth albedo and normals, the target lighting's SH shading and the ground-truth target shadow, and "
    "is compared with the path-traced render under the target lighting (foreground pixels; display values: "
    "target exposure, clipped, sRGB). This is the ceiling of any SH-based relighting on these scenes. The gap "
    "is then split by removing SH truncation, the shadow definition and interreflections one at a time. The "
    "verdict checks the oracle's ingredients where nothing is unmodelled (unshadowed pixels, direct light): "
    "there it must match the render within Monte Carlo noise."
)


def run(ctx: Context) -> CheckResult:
    """Check 5 at ``ctx.level``: the relighting ceiling (see the module's docstring)."""
    res = CheckResult("relight_ceiling", "5. Relighting ceiling", SUMMARY)
    views = bank(ctx).views()
    per = [evaluate_view(v) for v in views]
    lightings = list(dict.fromkeys(f["lighting"] for f in per))
    table = ["| stage | " + " | ".join(f"{ln} l1 / SSIM / PSNR" for ln in lightings) + " |",
             "| --- |" + " ---: |" * len(lightings)]
    agg: dict[str, dict[str, dict[str, float]]] = {}
    for stage, label in list(STAGES) + [("noise_half_means", "noise floor (half-means vs each other)")]:
        agg[stage] = {}
        cells = []
        for ln in lightings:
            rows = [f[stage] for f in per if f["lighting"] == ln]
            a = {k: float(np.mean([r[k] for r in rows])) for k in ("l1", "ssim", "psnr")}
            agg[stage][ln] = a
            cells.append(f"{a['l1']:.4f} / {a['ssim']:.3f} / {a['psnr']:.1f} dB")
        table.append(f"| {label} | " + " | ".join(cells) + " |")
    res.tables.append("Mean over the views of each lighting (target = the view's own lighting). Each stage removes "
                      "one more unmodelled effect:\n\n" + "\n".join(table))

    z = np.concatenate([f.pop("_z") for f in per])
    k = views[0].direct.shape[0]
    p0 = t_tail(4.0, k - 1)
    share = float(np.mean(z > 4.0)) if z.size else 0.0
    bound = binomial_upper(p0, int(z.size))
    res.check("unshadowed pixels: direct render = albedo E / pi", share, share <= bound,
              f"share of |z| > 4 <= {bound:.4f}",
              f"P(|t_{k - 1}| > 4) = {p0:.3f} over {z.size} pixels + 4 binomial sd + 1 pixel, after the yardstick's "
              "quadrature error and the ray cast's direction resolution")
    res.figures = {
        "relight_ceiling": agg,
        "ceiling_all": {s: {m: float(np.mean([f[s][m] for f in per])) for m in ("l1", "ssim", "psnr")}
                        for s, _ in list(STAGES) + [("noise_half_means", "")]},
        "verdict": {"pixels": int(z.size), "share_z4": share, "bound": bound, "p_null": p0},
        "per_view": per,
        "display": "exposure of the target lighting (white horizontal surface = 0.18), clipped to [0, 1], sRGB",
    }
    res.charts.append((_chart(ctx, agg, lightings), "PSNR of the oracle against the path-traced target per stage "
                       "(higher is better); the dotted line is the noise floor."))
    sunny = next((v for v in views if v.light.has_sun and not v.is_sphere), views[0])
    res.charts.append((_panel(ctx, sunny), f"{sunny.name}: the path-traced target, the paper's oracle (SH 2, synth "
                       "shadow), the oracle with exact irradiance and the direct-ratio shadow, and the paper oracle's "
                       "absolute error (x4)."))
    return res


def _chart(ctx: Context, agg: dict[str, dict[str, dict[str, float]]], lightings: list[str]) -> str:
    fig, ax = charts.figure(8.0, 4.2)
    w = 0.8 / len(lightings)
    for i, ln in enumerate(lightings):
        x = np.arange(len(STAGES)) + (i - (len(lightings) - 1) / 2) * w
        ax.bar(x, [agg[s][ln]["psnr"] for s, _ in STAGES], w, label=ln, color=f"C{i}")
        ax.hlines(agg["noise_half_means"][ln]["psnr"] + 6.0, x[0] - w / 2, x[-1] + w / 2, colors=f"C{i}",
                  linestyles=":")
    ax.set_xticks(np.arange(len(STAGES)), [s for s, _ in STAGES])
    ax.set_xlabel("stage (effects removed cumulatively, left to right)")
    ax.set_ylabel("PSNR on foreground pixels (dB, sRGB)")
    ax.legend(fontsize=8)
    return charts.save(fig, ctx, "check5_ceiling", "Check 5: oracle relighting vs path-traced target")


def _panel(ctx: Context, v: BankView) -> str:
    o = oracles(v)
    m = v.mask()[..., None]
    target = o["paper"][1]
    imgs = [target, np.where(m, o["paper"][0], target), np.where(m, o["ratio"][0], target),
            np.where(m, np.abs(o["paper"][0] - target) * 4, 0.0)]
    titles = ["path-traced target", "oracle: SH 2 + synth shadow", "oracle: exact E + direct ratio", "|error| x4"]
    fig, axes = charts.figure(10.0, 3.2, ncols=4)
    for ax, img, title in zip(axes, imgs, titles):
        ax.imshow(display(img)[0].permute(1, 2, 0).numpy())
        ax.set_title(title, fontsize=8)
        ax.set_xlabel("x (pixels)", fontsize=7)
        ax.set_ylabel("y (pixels)", fontsize=7)
        ax.tick_params(labelsize=6)
    return charts.save(fig, ctx, "check5_panel", f"Check 5: {v.name}")
