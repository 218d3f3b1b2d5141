"""Geometry-aware relighting by differentiable path tracing (an upper baseline).

Given one photo (linear radiance) of a scene whose geometry and camera are known, fit the
albedo textures and the lighting (a low-resolution sky map plus the sun's irradiance; the
sun's direction is kept, since Mitsuba's ``prb`` cannot differentiate it) so that the
path-traced render matches the photo, then re-render with the path tracer under a target
lighting. This is the analogue of multi-view relighting methods that reconstruct geometry
first (Philip et al. 2019): what a full physical model buys, and what it costs.

Parameters are optimised with Adam in a projected form: albedo clamped to [0, 1] and
radiance to >= 0 after every step.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from physrelight.camera import Camera

from . import scene as _scene
from .differentiable import DifferentiableRenderer
from .lighting import Lighting


@dataclass
class Fit:
    """Result of :func:`fit`.

    Attributes:
        inputs: fitted renderer inputs (``"texture/<part>"``, ``"sky"``, ``"sun_irradiance"``, ...).
        losses: the photo loss at every step (relative mean squared error).
        seconds: wall time of the optimisation.
    """

    inputs: dict[str, torch.Tensor]
    losses: list[float] = field(default_factory=list)
    seconds: float = 0.0


def photo_loss(render: torch.Tensor, photo: torch.Tensor) -> torch.Tensor:
    """Mean squared error relative to the photo's mean square (scale-free), scalar."""
    return ((render - photo) ** 2).mean() / (photo**2).mean().clamp_min(1e-12)


def fit(renderer: DifferentiableRenderer, photo: torch.Tensor, steps: int = 40, lr: float = 0.05,
        fit_textures: bool = True, fit_sky: bool = True, fit_sun: bool = True, init: dict[str, torch.Tensor] | None = None,
        seed: int = 0, progress: Callable[[int, float], None] | None = None) -> Fit:
    """Fit textures and lighting to a photo by differentiable path tracing.

    Args:
        renderer: the scene and camera of the photo (its initial inputs are the start
            unless ``init`` overrides them).
        photo: ``(H, W, 3)`` linear radiance of the same view.
        steps: Adam steps, each one render + backward at the renderer's spp with a new seed.
        lr: Adam learning rate (relative to the inputs' scale: albedo in [0, 1]; the sky and
            sun are optimised as multiples of their initial mean so one rate fits both).
        fit_textures, fit_sky, fit_sun: which inputs to optimise.
        init: starting values for some inputs (e.g. constant grey textures, a uniform sky).
        seed: first Monte Carlo seed.
        progress: optional callable ``(step, loss)``.
    """
    if photo.shape != (renderer.height, renderer.width, 3):
        raise ValueError(f"photo must have shape {(renderer.height, renderer.width, 3)}, got {tuple(photo.shape)}")
    if not bool(torch.isfinite(photo).all()) or bool((photo < 0).any()):
        raise ValueError("photo must hold finite, non-negative linear radiance")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    start = {**renderer.parameters(), **(init or {})}
    # Radiance is optimised relative to its initial scale so Adam's step size means the same for all.
    scales = {k: max(float(v.abs().mean()), 1e-6) for k, v in start.items() if k in ("sky", "sun_irradiance")}
    free = {}
    for name, value in start.items():
        wanted = (fit_textures and name.startswith("texture/")) or (fit_sky and name == "sky") or \
                 (fit_sun and name == "sun_irradiance")
        if wanted and not (name == "sun_irradiance" and float(value.abs().sum()) == 0.0):
            free[name] = (value / scales.get(name, 1.0)).clone().requires_grad_(True)
    if not free:
        raise ValueError("nothing to optimise")
    opt = torch.optim.Adam(list(free.values()), lr=lr)
    target = photo.to(torch.float32)
    result = Fit(inputs={})
    t0 = time.perf_counter()
    for step in range(steps):
        opt.zero_grad()
        inputs = {**start, **{k: v * scales.get(k, 1.0) for k, v in free.items()}}
        loss = photo_loss(renderer.render(inputs, seed=seed + step), target)
        loss.backward()
        opt.step()
        with torch.no_grad():
            for name, v in free.items():
                v.clamp_(0.0, 1.0) if name.startswith("texture/") else v.clamp_(min=0.0)
        result.losses.append(float(loss.detach()))
        if progress is not None:
            progress(step, result.losses[-1])
    result.seconds = time.perf_counter() - t0
    result.inputs = {**start, **{k: (v * scales.get(k, 1.0)).detach() for k, v in free.items()}}
    return result


def relight(spec: _scene.SceneSpec, camera: Camera, fitted: Fit, target: Lighting, spp: int = 64,
            max_depth: int = 8, seed: int = 0) -> np.ndarray:
    """Path-trace the fitted textures under a target lighting: ``(H, W, 3)`` linear radiance."""
    renderer = DifferentiableRenderer(spec, camera, target, spp=spp, max_depth=max_depth)
    textures = {k: v for k, v in fitted.inputs.items() if k.startswith("texture/")}
    with torch.no_grad():
        return renderer.render(textures, seed=seed).numpy()
