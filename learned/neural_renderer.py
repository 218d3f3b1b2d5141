"""The paper's neural renderer: a UNet that turns a decomposition and a target lighting into a relit photo.

Input: 14 channels per pixel (:func:`renderer_inputs`), in this order

====  ========  ==========================================================================
idx   name      what
====  ========  ==========================================================================
0-2   albedo    the inverse network's albedo, ``(B, 3, H, W)`` in [0, 1]
3-5   normals   its unit normals, camera frame ``(B, 3, H, W)``
6-8   shading   target Lambertian shading ``shading(n; L_target) = E / pi``, ``(B, 3, H, W)``
9     shadow    ShadowNet's shadow for the target lighting, ``(B, 1, H, W)`` in [0, 1]
10    sky       the sky mask as 0/1, ``(B, 1, H, W)``
11-13 residual  ``image - albedo * shading(n; L_source) * shadow_source``: what the
                decomposition could not explain (texture detail, specularity, the
                source's cast shadows it missed), ``(B, 3, H, W)``
====  ========  ==========================================================================

Every channel but the sky mask is zeroed on sky pixels (the decomposition means nothing
there and the sky is pasted back from the photo afterwards).

Output: linear RGB ``(B, 3, H, W)``, >= 0. The UNet does not paint the image from scratch:
it predicts a per-pixel log-gain ``g`` and an additive term ``r`` on top of the Lambertian
render with the target shadow, ``x = albedo * shading * shadow * exp(g) + 0.1 r``, mapped to
``>= 0`` by a smooth positive unit (identity above ``tau``, ``tau * exp(x / tau - 1)``
below). The head starts near ``g = r = 0`` (small weights, zero bias), so an untrained
renderer gives "ShadowNet + Lambertian SH" relighting and training learns the corrections
(texture the albedo lost via ``r``, shadow and shading errors via ``g``). With
``additive=False`` (the shipped weights) only the gain is used: ``r`` is in absolute units
and showed as colour casts in dark targets, a gain scales with the target's brightness.

``base="quotient"`` (issue 26: a renderer on top of the physical core) adds three channels,
14-16, the quotient relighting ``image * S(n; L_target) / S(n; L_source)``
(:func:`physrelight.quotient.quotient_relight`, ratio smoothed as the ``quotient`` method does),
and the gain acts on it instead: ``x = quotient * exp(g)``. The untrained renderer is then the
quotient method, and relighting a photo to its own lighting starts from the photo itself.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from physrelight import image_model

from . import checkpoint as ckpt
from .networks import UNet

__all__ = ["BASES", "CHANNELS", "NeuralRenderer", "lambertian_relit", "load_renderer", "positive", "render_relit",
           "renderer_inputs"]

CHANNELS = ("albedo_r", "albedo_g", "albedo_b", "normal_x", "normal_y", "normal_z", "shading_r", "shading_g",
            "shading_b", "shadow", "sky", "residual_r", "residual_g", "residual_b")

BASES = ("lambertian", "quotient")
"""What the renderer's gain multiplies: the shadowed Lambertian render of the decomposition, or the
quotient relighting of the photo (then 3 more input channels)."""

_TAU = 1e-3  # below this (linear radiance) the output unit bends smoothly towards 0


def positive(x: torch.Tensor, tau: float = _TAU) -> torch.Tensor:
    """``x`` for ``x >= tau``, ``tau * exp(x / tau - 1)`` below: >= 0, continuous with slope 1 at ``tau``."""
    return torch.where(x >= tau, x, tau * torch.exp(torch.clamp(x, max=tau) / tau - 1.0))


def _check(x: torch.Tensor, channels: int, name: str, like: tuple[int, int, int] | None) -> None:
    if not isinstance(x, torch.Tensor) or x.ndim != 4 or x.shape[1] != channels:
        shape = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
        raise ValueError(f"{name} must be a torch tensor of shape (B, {channels}, H, W), got {shape}")
    if like is not None and (x.shape[0], *x.shape[2:]) != like:
        raise ValueError(f"{name} has shape {tuple(x.shape)}, expected batch and size (B, H, W) = {like}")


def _check_lighting(x: torch.Tensor, name: str, batch: int) -> None:
    if not isinstance(x, torch.Tensor) or tuple(x.shape) != (batch, 9, 3):
        shape = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
        raise ValueError(f"{name} must have shape ({batch}, 9, 3), got {shape}")


def renderer_inputs(image: torch.Tensor, sky: torch.Tensor, albedo: torch.Tensor, normals: torch.Tensor,
                    source_shadow: torch.Tensor, source_lighting: torch.Tensor, target_lighting: torch.Tensor,
                    target_shadow: torch.Tensor, quotient: torch.Tensor | None = None) -> torch.Tensor:
    """The renderer's 14 input channels (order in the module docstring), 17 with ``quotient``.

    Args:
        image: ``(B, 3, H, W)`` linear photo.
        sky: ``(B, 1, H, W)`` bool, True on sky.
        albedo, normals: ``(B, 3, H, W)`` the decomposition of ``image``.
        source_shadow: ``(B, 1, H, W)`` the decomposition's shadow of ``image``.
        source_lighting: ``(B, 9, 3)`` the decomposition's lighting (camera-frame SH).
        target_lighting: ``(B, 9, 3)`` camera-frame SH in the decomposition's units.
        target_shadow: ``(B, 1, H, W)`` ShadowNet on ``target_lighting``.
        quotient: ``(B, 3, H, W)`` the quotient relighting of ``image`` to ``target_lighting``
            (for a ``base="quotient"`` renderer), or None.

    Returns:
        ``(B, 14, H, W)``, or ``(B, 17, H, W)`` with ``quotient``.

    Raises:
        ValueError: a tensor of the wrong shape (the message names it and its shape).
    """
    _check(image, 3, "image", None)
    like = (image.shape[0], *image.shape[2:])
    _check(sky, 1, "sky", like)
    if sky.dtype != torch.bool:
        raise ValueError(f"sky must be a bool tensor, got dtype {sky.dtype}")
    for t, c, name in ((albedo, 3, "albedo"), (normals, 3, "normals"), (source_shadow, 1, "source_shadow"),
                       (target_shadow, 1, "target_shadow")):
        _check(t, c, name, like)
    _check_lighting(source_lighting, "source_lighting", image.shape[0])
    _check_lighting(target_lighting, "target_lighting", image.shape[0])
    fg = (~sky).to(image.dtype)
    shading = image_model.shading(normals, target_lighting.to(image.dtype))
    residual = image_model.residual(image, albedo, normals, source_lighting.to(image.dtype), source_shadow)
    parts = [albedo * fg, normals * fg, shading * fg, target_shadow * fg, 1.0 - fg, residual * fg]
    if quotient is not None:
        _check(quotient, 3, "quotient", like)
        parts.append(quotient * fg)
    return torch.cat(parts, 1)


class NeuralRenderer(nn.Module):
    """UNet on the 14 channels (17 for ``base="quotient"``) -> relit linear RGB (see the module docstring).

    Args:
        width: UNet width (first-level channels).
        depth: UNet depth (downsamplings).
        additive: use the additive term ``r``; False = gain only, ``x = base * exp(g)``
            (every correction then scales with the target's brightness).
        base: what the gain multiplies (:data:`BASES`): ``"lambertian"``, the shadowed
            Lambertian render (the paper's, and the shipped weights'); ``"quotient"``, the
            quotient relighting given as channels 14-16.
    """

    def __init__(self, width: int = 16, depth: int = 3, additive: bool = True, base: str = "lambertian") -> None:
        super().__init__()
        if base not in BASES:
            raise ValueError(f"base must be one of {BASES}, got {base!r}")
        self.width, self.depth, self.additive, self.base = width, depth, bool(additive), base
        self.in_channels = 14 if base == "lambertian" else 17
        self.unet = UNet(self.in_channels, 6, width, depth)
        with torch.no_grad():
            # Start at g = r = 0 (the ShadowNet + Lambertian render) with small head weights,
            # so every layer gets a gradient from the first step.
            self.unet.head.weight.mul_(0.01)
            self.unet.head.bias.zero_()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, 14, H, W)`` (``(B, 17, H, W)`` for ``base="quotient"``) from :func:`renderer_inputs`
        -> ``(B, 3, H, W)`` linear RGB >= 0."""
        out = self._head(x)
        albedo, shading, shadow = x[:, 0:3], x[:, 6:9], x[:, 9:10]
        base = albedo * shading * shadow if self.base == "lambertian" else x[:, 14:17]
        gain = torch.exp(out[:, 0:3].clamp(-8.0, 8.0))
        return positive(base * gain + 0.1 * out[:, 3:6]) if self.additive else positive(base * gain)

    def gain(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, 3, H, W)`` the learned gain ``exp(g)`` alone, for input ``x`` as in :meth:`forward`
        (a gain-only renderer's output is ``positive(base * gain(x))``)."""
        return torch.exp(self._head(x)[:, 0:3].clamp(-8.0, 8.0))

    def _head(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, 6, H, W)`` the UNet's output (log-gain ``g``, additive ``r``) for input ``x``."""
        _check(x, self.in_channels, "renderer input", None)
        # Radiance spans decades: the network sees shading and residual on a compressed
        # (signed log) scale; the raw values enter only through ``base`` and ``r``.
        feats = [x[:, 0:6], _slog(x[:, 6:9]), x[:, 9:11], _slog(x[:, 11:14])]
        if self.base == "quotient":
            feats.append(_slog(x[:, 14:17]))
        return self.unet(torch.cat(feats, 1))


def _slog(x: torch.Tensor) -> torch.Tensor:
    """Signed log compression ``sign(x) log(1 + |x| / 0.05)``: linear near 0, logarithmic beyond."""
    return torch.sign(x) * torch.log1p(x.abs() / 0.05)


def lambertian_relit(decomposition: dict[str, torch.Tensor], target: torch.Tensor,
                     target_shadow: torch.Tensor | None = None) -> torch.Tensor:
    """``albedo * shading(n; target) [* target_shadow]``, ``(B, 3, H, W)`` (the baselines)."""
    return image_model.render(decomposition["albedo"], decomposition["normals"], target, target_shadow)


def render_relit(renderer: NeuralRenderer, image: torch.Tensor, sky: torch.Tensor,
                 decomposition: dict[str, torch.Tensor], target: torch.Tensor,
                 target_shadow: torch.Tensor, quotient: torch.Tensor | None = None) -> torch.Tensor:
    """Relight a decomposed photo with the neural renderer.

    Args:
        renderer: a :class:`NeuralRenderer`.
        image: ``(B, 3, H, W)`` linear photo.
        sky: ``(B, 1, H, W)`` bool.
        decomposition: from :func:`learned.objectives.decompose_and_solve`: ``albedo``,
            ``normals``, ``shadow``, ``lighting`` ``(B, 9, 3)``.
        target: ``(B, 9, 3)`` camera-frame SH in the decomposition's units.
        target_shadow: ``(B, 1, H, W)`` ShadowNet on ``target``.
        quotient: ``(B, 3, H, W)`` the quotient relighting of ``image`` to ``target``; needed by
            a ``base="quotient"`` renderer, refused by a ``"lambertian"`` one.

    Returns:
        ``(B, 3, H, W)`` linear relit photo; sky pixels are the input's, bit for bit.
    """
    if (renderer.base == "quotient") != (quotient is not None):
        raise ValueError(f"a {renderer.base!r} renderer {'needs' if renderer.base == 'quotient' else 'takes no'} "
                         "quotient image")
    for key in ("albedo", "normals", "shadow", "lighting"):
        if key not in decomposition:
            raise ValueError(f"decomposition lacks {key!r} (have {sorted(decomposition)})")
    x = renderer_inputs(image, sky, decomposition["albedo"], decomposition["normals"], decomposition["shadow"],
                        decomposition["lighting"], target, target_shadow, quotient)
    return torch.where(sky, image, renderer(x))


def load_renderer(path: str | Path) -> NeuralRenderer:
    """A :class:`NeuralRenderer` from weights exported by ``physrelight train export-renderer``
    (safetensors with ``kind = "renderer"``, ``width``, ``depth``, ``additive`` and, when not the
    Lambertian one, ``base`` in its metadata), in eval mode."""
    tensors, meta = ckpt.load_weights(path)
    if meta.get("kind") != "renderer":
        raise ValueError(f"{str(path)!r} holds {meta.get('kind')!r} weights, not a neural renderer")
    net = NeuralRenderer(int(meta["width"]), int(meta["depth"]), meta.get("additive", "1") == "1",
                         meta.get("base", "lambertian"))
    net.load_state_dict(tensors)
    return net.eval()

