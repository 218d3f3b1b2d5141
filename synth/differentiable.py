"""Mitsuba renders as torch functions: differentiable w.r.t. albedo textures, sky map and sun.

A :class:`DifferentiableRenderer` holds one Mitsuba scene (``llvm_ad_rgb``; a clear
``RuntimeError`` without it) with the ``prb`` integrator (path replay backpropagation:
constant memory in path length) and exposes

``render(inputs, seed) -> (H, W, 3) torch tensor``

where ``inputs`` maps parameter names to torch tensors (missing ones keep the scene's
values and get no gradient):

* ``"texture/<part>"`` -- ``(S, S, 3)`` albedo texture of a part's material (parts that
  share a material share one texture, listed under the first part's name);
* ``"sky"`` -- ``(H, W, 3)`` lat-long radiance in our layout (the wrapped halo columns
  Mitsuba's ``envmap`` stores are added here, so gradients of both copies of an edge
  column reach the same texel);
* ``"sun_irradiance"`` -- ``(3,)``; ``"sun_direction"`` -- ``(3,)`` towards the sun
  (normalised here). The direction is an input but not differentiable: ``prb`` samples
  emitters detached (Mitsuba raises "not attached to the AD graph"), so a tensor that
  requires grad is refused with a ``ValueError``. A sun in the sky map is differentiable.

PRB replays the scene in the adjoint pass, so call ``backward`` on a render's result
before the next :meth:`render` changes the scene's parameters (as in any optimisation
loop: render, loss, backward, step).

The adjoint pass uses its own random numbers (``seed_grad = seed + 2**20``; Mitsuba
refuses equal seeds), so a gradient is an unbiased Monte Carlo estimate of the derivative
of the expected image; a central finite difference with a fixed primal seed is another
(the estimate is smooth in the inputs for fixed random numbers), and the two agree within
their standard errors (``tests/synth/test_differentiable.py``). Russian roulette is
disabled (``rr_depth`` above ``max_depth``) because it would make the estimate a
discontinuous function of albedo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from physrelight.camera import Camera

from . import cameras as _cameras
from . import scene as _scene
from .backend import load_mitsuba
from .lighting import Lighting

TEXTURE_SUFFIX = ".bsdf.reflectance.data"
GRADIENT_SEED_OFFSET = 1 << 20


class DifferentiableRenderer:
    """A scene, one camera and one lighting, rendered as a differentiable torch function.

    Args:
        spec: the scene (geometry and initial textures).
        camera: the view.
        lighting: initial lighting (its sky resolution fixes the ``"sky"`` input's shape;
            a sun is always present as an emitter, with zero irradiance if the lighting
            has none, so it can be optimised).
        spp: samples per pixel of each render.
        max_depth: path length (2 = direct light only).
    """

    def __init__(self, spec: _scene.SceneSpec, camera: Camera, lighting: Lighting, spp: int = 16,
                 max_depth: int = 3) -> None:
        self.mi = load_mitsuba(differentiable=True)
        import drjit as dr

        self._dr = dr
        if spp < 1 or max_depth < 1:
            raise ValueError(f"spp and max_depth must be >= 1, got {spp}, {max_depth}")
        emitters = lighting.mitsuba_emitters(self.mi)
        if "sun" not in emitters:
            emitters["sun"] = {"type": "directional", "direction": [0.0, -1.0, 0.0],
                               "irradiance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
        d = {"type": "scene", **_scene.to_mitsuba(spec, self.mi), **emitters,
             "integrator": {"type": "prb", "max_depth": int(max_depth), "rr_depth": int(max_depth) + 1},
             "view": _cameras.to_mitsuba_sensor(camera, spp, self.mi)}
        self.scene = self.mi.load_dict(d)
        self.params = self.mi.traverse(self.scene)
        self.spp = int(spp)
        self.width, self.height = camera.width, camera.height
        self._texture_keys = {k[: -len(TEXTURE_SUFFIX)]: k for k in sorted(self.params.keys())
                              if k.endswith(TEXTURE_SUFFIX)}
        sun = lighting.sun_direction if lighting.has_sun else np.array([0.0, 1.0, 0.0])
        self._initial: dict[str, torch.Tensor] = {
            **{f"texture/{n}": torch.tensor(np.array(self.params[k])) for n, k in self._texture_keys.items()},
            "sky": torch.tensor(np.array(self.params["sky.data"])[:, 1:-1]),
            "sun_irradiance": torch.tensor(np.asarray(lighting.sun_irradiance, dtype=np.float32)),
            "sun_direction": torch.tensor(np.asarray(sun, dtype=np.float32)),
        }
        self._sun_now = np.asarray(sun, dtype=np.float64)
        self._wrapped = dr.wrap(source="torch", target="drjit")(self._render_drjit)

    @property
    def texture_names(self) -> list[str]:
        """Parts whose texture is an input (``"texture/<name>"``)."""
        return list(self._texture_keys)

    def parameters(self) -> dict[str, torch.Tensor]:
        """The scene's initial inputs (copies): every name :meth:`render` accepts."""
        return {k: v.clone() for k, v in self._initial.items()}

    def _check(self, inputs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        out = {}
        for name, value in inputs.items():
            if name not in self._initial:
                raise ValueError(f"unknown input {name!r}; known: {sorted(self._initial)}")
            if not isinstance(value, torch.Tensor):
                raise ValueError(f"input {name!r} must be a torch tensor, got {type(value).__name__}")
            want = tuple(self._initial[name].shape)
            if tuple(value.shape) != want:
                raise ValueError(f"input {name!r} must have shape {want}, got {tuple(value.shape)}")
            if not bool(torch.isfinite(value.detach()).all()):
                raise ValueError(f"input {name!r} holds NaN or inf")
            if name == "sun_direction" and value.requires_grad:
                raise ValueError("gradients w.r.t. the sun direction are not available: Mitsuba's prb "
                                 "integrator samples emitters detached; pass a tensor without requires_grad "
                                 "(or put the sun into the differentiable sky map)")
            out[name] = value.to(torch.float32)
        return out

    def render(self, inputs: dict[str, torch.Tensor] | None = None, seed: int = 0, spp: int | None = None) -> torch.Tensor:
        """Path-traced image ``(H, W, 3)`` (linear radiance) as a differentiable torch function.

        Args:
            inputs: parameter name -> tensor (see the module doc); others stay as built.
            seed: Monte Carlo seed of the primal and adjoint passes.
            spp: samples per pixel (default: the constructor's).
        """
        given = self._check(inputs or {})
        full = {**{k: v for k, v in self._initial.items()}, **given}
        names = sorted(full)
        sky = full["sky"]
        full["sky"] = torch.cat([sky[:, -1:], sky, sky[:, :1]], dim=1)  # Mitsuba's wrapped halo columns
        return self._wrapped([full[n] for n in names], names, int(seed), int(spp or self.spp))

    def _render_drjit(self, values: list[Any], names: list[str], seed: int, spp: int) -> Any:
        mi, dr = self.mi, self._dr
        p = self.params
        for name, value in zip(names, values):
            if name.startswith("texture/"):
                p[self._texture_keys[name[len("texture/"):]]] = value
            elif name == "sky":
                p["sky.data"] = value
            elif name == "sun_irradiance":
                p["sun.irradiance.value"] = mi.Color3f(*[dr.gather(mi.Float, value.array, i) for i in range(3)])
            elif name == "sun_direction":
                s = np.asarray(value.numpy(), dtype=np.float64).ravel()
                s = s / max(np.linalg.norm(s), 1e-12)
                if not np.allclose(s, self._sun_now, atol=1e-7):
                    up = [1.0, 0.0, 0.0] if abs(s[1]) > 0.99 else [0.0, 1.0, 0.0]
                    # The directional emitter propagates along its local +z: from the sun into the scene.
                    p["sun.to_world"] = mi.Transform4f().look_at(origin=[0.0, 0.0, 0.0], target=(-s).tolist(), up=up)
                    self._sun_now = s
        p.update()
        # Mitsuba insists on independent primal and adjoint random numbers (unbiased gradients).
        return mi.render(self.scene, p, spp=spp, seed=seed, seed_grad=seed + GRADIENT_SEED_OFFSET)


@dataclass(frozen=True)
class GradientCheck:
    """AD vs central finite difference of ``sum(W * image)`` along one direction of an input.

    Attributes:
        name: the input.
        ad: mean directional derivative from the adjoint pass over the seeds.
        fd: mean central finite difference (fixed primal seed per pair) over the seeds.
        standard_error: combined standard error of ``ad - fd``.
        seeds: number of seeds of each estimate.
    """

    name: str
    ad: float
    fd: float
    standard_error: float
    seeds: int

    @property
    def z(self) -> float:
        """``(ad - fd) / standard_error``: Student-t with about ``2 (seeds - 1)`` dof under agreement."""
        return (self.ad - self.fd) / max(self.standard_error, 1e-30)

    @property
    def relative_error(self) -> float:
        return abs(self.ad - self.fd) / max(abs(self.fd), 1e-30)


def gradient_check(renderer: DifferentiableRenderer, name: str, step: float, seeds: int = 6, seed: int = 0) -> GradientCheck:
    """Compare the adjoint gradient with a central finite difference along a random direction.

    Both are unbiased estimates of the derivative of the expected ``sum(W * image)`` (``W``
    fixed random weights): the finite difference because, for fixed random numbers, the
    estimate is a polynomial of degree <= ``max_depth - 1`` in the albedo and linear in the
    emitted radiance, so central differences are exact up to float round-off. Their
    difference is judged against its standard error over ``seeds`` independent seeds.

    Args:
        renderer: the scene.
        name: an input of :meth:`DifferentiableRenderer.render`.
        step: finite-difference step along the unit direction (in the input's units).
        seeds: independent seeds per estimate (>= 2).
        seed: seeds the direction and the weights.
    """
    if seeds < 2:
        raise ValueError(f"seeds must be >= 2 to estimate a standard error, got {seeds}")
    g = torch.Generator().manual_seed(seed)
    x0 = renderer.parameters()[name]
    v = torch.randn(x0.shape, generator=g)
    v = v / v.norm()
    w = torch.rand(renderer.height, renderer.width, 3, generator=g)
    ad, fd = [], []
    for s in range(seeds):
        x = x0.clone().requires_grad_(True)
        (renderer.render({name: x}, seed=100 + s) * w).sum().backward()
        ad.append(float((x.grad * v).sum()))
        with torch.no_grad():
            hi = (renderer.render({name: x0 + step * v}, seed=200 + s) * w).sum()
            lo = (renderer.render({name: x0 - step * v}, seed=200 + s) * w).sum()
        fd.append(float(hi - lo) / (2 * step))
    se = math.sqrt(np.var(ad, ddof=1) / seeds + np.var(fd, ddof=1) / seeds)
    return GradientCheck(name=name, ad=float(np.mean(ad)), fd=float(np.mean(fd)), standard_error=se, seeds=seeds)
