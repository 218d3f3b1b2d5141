"""Check 7: the differentiable renderer's gradients (Mitsuba ``prb`` through ``dr.wrap`` into torch).

Two checks of :mod:`synth.differentiable`:

1. *AD vs finite differences.* For each input type (an albedo texture seen directly and
   through one bounce, the sky map, the sun's irradiance), the adjoint directional
   derivative of ``sum(W * image)`` along a random direction is compared with a central
   finite difference with fixed primal seeds. Both estimate the derivative of the
   expected image without bias (for fixed random numbers the estimate is a polynomial of
   degree <= ``max_depth - 1`` in albedo and linear in radiance, so central differences
   are exact up to float round-off). Tolerance: ``|ad - fd| <= t * SE + 1e-4 |fd|`` with
   SE the combined standard error over the seeds and ``t`` the Student-t quantile for a
   1e-3 two-sided tail (dof = 2 (seeds - 1)); 1e-4 covers float32 round-off.
2. *SH image model vs Mitsuba.* A convex Lambertian sphere under direct light only: the
   torch image model ``albedo * shading_SH(n)`` (order 4, exact camera-frame SH of the
   lighting) and the Mitsuba render agree in the mean over the sphere and in the
   gradient w.r.t. the albedo, within the order-4 truncation error of that lighting's
   shading on the sphere's normals (computed by brute force) plus 4 Monte Carlo SE.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from physrelight import image_model
from synth import lighting as _lighting
from synth import render as _render
from synth.differentiable import DifferentiableRenderer, gradient_check

from .common import CheckResult, Context, t_tail
from .scenes import sphere_spec, view


def _t_quantile(p_two_sided: float, dof: int) -> float:
    """Smallest t with two-sided tail <= p (bisection on :func:`validation.common.t_tail`)."""
    lo, hi = 0.0, 100.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if t_tail(mid, dof) > p_two_sided:
            lo = mid
        else:
            hi = mid
    return hi


def run(ctx: Context) -> CheckResult:
    """The gradient check at ``ctx.level`` (see the module's docstring)."""
    quick = ctx.level.name == "quick"
    res = CheckResult(
        key="gradients", title="7. Differentiable rendering: gradients through Mitsuba",
        summary=("Mitsuba's path tracer is exposed to torch (`synth.differentiable`): the rendered image is a "
                 "torch function of the albedo textures, the sky map and the sun's irradiance. Its adjoint "
                 "gradients are checked against central finite differences, and the torch SH image model "
                 "against the Mitsuba render of a convex Lambertian sphere, in value and in gradient."))
    light = _lighting.sunsky(5, elevation_deg=35.0, azimuth_deg=200.0, turbidity=3.0, resolution=16)
    size, seeds = (24, 6) if quick else (48, 12)
    spec = sphere_spec(with_ground=True)
    cam = view([0.4, 1.8, 4.0], [0, 1.5, 0], size=size)
    renderer = DifferentiableRenderer(spec, cam, light, spp=16, max_depth=3)
    sky = renderer.parameters()["sky"]
    steps = {"texture/sphere": 0.05, "texture/ground": 0.05,
             "sky": 0.02 * float(sky.abs().mean()) * math.sqrt(sky.numel()),
             "sun_irradiance": 0.02 * float(renderer.parameters()["sun_irradiance"].norm())}
    t = _t_quantile(1e-3, 2 * (seeds - 1))
    rows, figs = [], {}
    for name, step in steps.items():
        ctx.progress(f"  gradient check: {name}")
        c = gradient_check(renderer, name, step, seeds=seeds)
        figs[name] = {"ad": c.ad, "fd": c.fd, "standard_error": c.standard_error, "relative_error": c.relative_error,
                      "z": c.z, "seeds": seeds}
        res.check(f"AD vs FD: {name}", c.relative_error, abs(c.ad - c.fd) <= t * c.standard_error + 1e-4 * abs(c.fd),
                  f"|ad - fd| <= {t:.2f} SE + 1e-4 |fd| (SE = {c.standard_error:.3g})",
                  f"Student-t, 1e-3 two-sided tail, {2 * (seeds - 1)} dof; float32 round-off")
        rows.append(f"| {name} | {c.ad:.5g} | {c.fd:.5g} | {c.standard_error:.3g} | {c.relative_error:.2%} | {c.z:+.2f} |")
    res.tables.append("| input | AD | finite difference | SE | relative error | z |\n| --- | --- | --- | --- | --- | --- |\n"
                      + "\n".join(rows))
    res.figures["ad_vs_fd"] = figs
    res.figures["sh_model_vs_mitsuba"] = _sh_model(res, light, size, seeds)
    return res


def _sh_model(res: CheckResult, light: _lighting.Lighting, size: int, seeds: int) -> dict[str, Any]:
    spec = sphere_spec(with_ground=False)
    cam = view([0.3, 1.6, 4.0], [0, 1.5, 0], size=size)
    renderer = DifferentiableRenderer(spec, cam, light, spp=32, max_depth=2)
    scene = _render.build_scene(spec, [cam], light, spp=4, max_depth=2)
    geo = _render.render_geometry(scene, 0, cam, spp=4, seed=0)
    full = (geo.coverage == 1) & ~geo.sky_mask
    T = np.asarray(cam.world_to_camera, dtype=np.float64)
    normals = torch.from_numpy(geo.normal).permute(2, 0, 1)[None].double()
    shading = image_model.shading(normals, torch.from_numpy(light.sh(4, T)))[0].permute(1, 2, 0).numpy()
    n_world = geo.normal[full].astype(np.float64) @ T[:3, :3]
    exact = light.irradiance_reference(n_world) / math.pi
    truncation = float(np.abs((shading[full] - exact)).sum() / exact.sum())  # relative, summed over the sphere
    albedo0 = renderer.parameters()["texture/sphere"]
    sums, grads = [], []
    w = torch.from_numpy(np.repeat(full[..., None], 3, axis=-1)).float()
    for s in range(seeds):
        a = albedo0.clone().requires_grad_(True)
        img = renderer.render({"texture/sphere": a}, seed=10 + s)
        (img * w).sum().backward()
        sums.append(float((img.detach() * w).sum()))
        grads.append(a.grad.sum(dim=(0, 1)).numpy())
    rho = albedo0.double().mean(dim=(0, 1)).numpy()
    model_sum = float((rho * shading[full]).sum())
    model_grad = shading[full].sum(axis=0)
    mean_sum, se_sum = float(np.mean(sums)), float(np.std(sums, ddof=1) / math.sqrt(seeds))
    g, se_g = np.mean(grads, axis=0), np.std(grads, axis=0, ddof=1) / math.sqrt(seeds)
    ratio = mean_sum / model_sum
    tol = truncation + 4 * se_sum / model_sum
    res.check("SH model vs Mitsuba: sphere mean", abs(ratio - 1), abs(ratio - 1) <= tol,
              f"|ratio - 1| <= {tol:.4f}", "order-4 truncation on these normals (brute force) + 4 MC SE")
    rel_g = np.abs(g - model_grad) / np.abs(model_grad)
    tol_g = truncation + 4 * se_g / np.abs(model_grad)
    res.check("SH model vs Mitsuba: d/d albedo (worst channel)", float(rel_g.max()), bool(np.all(rel_g <= tol_g)),
              f"per channel <= {float(tol_g.max()):.4f}", "order-4 truncation on these normals (brute force) + 4 MC SE")
    res.tables.append(
        "| quantity | Mitsuba | SH image model | relative difference | allowed |\n| --- | --- | --- | --- | --- |\n"
        f"| sum over the sphere | {mean_sum:.4g} | {model_sum:.4g} | {abs(ratio - 1):.3%} | {tol:.3%} |\n"
        + "\n".join(f"| d/d albedo {c} | {g[i]:.4g} | {model_grad[i]:.4g} | {rel_g[i]:.3%} | {tol_g[i]:.3%} |"
                    for i, c in enumerate("RGB")))
    return {"ratio": ratio, "truncation_relative": truncation, "grad_mitsuba": g.tolist(),
            "grad_model": model_grad.tolist(), "grad_relative_error": rel_g.tolist()}
