"""Sky segmentation: a small UNet trained on synthetic renders with photometric augmentation.

The paper segments the sky with a pretrained PSPNet; no pretrained weights can be
downloaded here, so a small :class:`learned.networks.UNet` (3 -> 1 logits) is trained on
the synthetic photos and their sky masks (``physrelight train segmentation``,
:mod:`learned.train_sky`). Real photos differ from the renders in exposure, white
balance, tone curve, noise and compression, so training images go through
:func:`photometric_augment` first. The relighting also accepts a user mask instead.

The network sees ``log(image + 1e-3)`` minus the image's mean log luminance, so a global
exposure change does not change its input. :func:`segment_sky` runs it at its training
resolution (short side ``res``, aspect kept) and upsamples the probability to the
input's size.
"""

from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from physrelight import colour

from . import checkpoint as ckpt
from .data import resize_short_side
from .networks import UNet

__all__ = ["SkySegmenter", "load_sky_segmenter", "photometric_augment", "segment_sky", "sky_probability"]

_LUMA = colour.LUMINANCE


def _check_image(image: torch.Tensor, name: str = "image") -> None:
    if not isinstance(image, torch.Tensor) or image.ndim != 4 or image.shape[1] != 3:
        got = tuple(image.shape) if isinstance(image, torch.Tensor) else type(image).__name__
        raise ValueError(f"{name} must be a tensor of shape (B, 3, H, W), got {got}")
    if image.shape[-1] < 1 or image.shape[-2] < 1:
        raise ValueError(f"{name} must be non-empty, got {tuple(image.shape)}")


class SkySegmenter(nn.Module):
    """Linear image ``(B, 3, H, W)`` -> sky logits ``(B, 1, H, W)``.

    Args:
        width: UNet width (first-level channels).
        depth: UNet depth.
        res: the resolution it is trained at (:func:`segment_sky` resizes to it).
    """

    def __init__(self, width: int = 8, depth: int = 3, res: int = 64) -> None:
        super().__init__()
        if isinstance(res, bool) or not isinstance(res, int) or res < 8:
            raise ValueError(f"res must be an integer >= 8, got {res!r}")
        self.width, self.depth, self.res = width, depth, res
        self.unet = UNet(3, 1, width, depth)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """``(B, 3, H, W)`` linear -> ``(B, 1, H, W)`` logits (sky > 0)."""
        _check_image(image)
        x = torch.log(image.clamp_min(0) + 1e-3)
        lum = torch.log((image.clamp_min(0) * image.new_tensor(_LUMA).reshape(1, 3, 1, 1)).sum(1, keepdim=True) + 1e-3)
        # Exposure invariance: subtract the image's mean log luminance.
        return self.unet(x - lum.mean(dim=(2, 3), keepdim=True))


def sky_probability(model: SkySegmenter, image: torch.Tensor) -> torch.Tensor:
    """``(B, 3, H, W)`` linear, any size -> sky probability ``(B, 1, H, W)``, computed at the model's resolution."""
    _check_image(image)
    h, w = image.shape[-2:]
    param = next(model.parameters())
    x = resize_short_side(image.to(param.dtype), model.res)
    with torch.no_grad():
        p = torch.sigmoid(model(x))
    if p.shape[-2:] != (h, w):
        p = F.interpolate(p, size=(h, w), mode="bilinear", align_corners=False)
    return p.to(image.dtype)


def segment_sky(model: SkySegmenter, image: torch.Tensor, threshold: float = 0.5) -> torch.Tensor:
    """Sky mask of linear images.

    Args:
        model: a :class:`SkySegmenter` (e.g. :func:`load_sky_segmenter`).
        image: ``(B, 3, H, W)`` linear RGB (e.g. ``physrelight.colour.from_ldr`` of a photo), any size.
        threshold: probability above which a pixel is sky, in (0, 1).

    Returns:
        ``(B, 1, H, W)`` bool, True on sky.
    """
    if not (isinstance(threshold, (int, float)) and 0.0 < float(threshold) < 1.0):
        raise ValueError(f"threshold must be a number in (0, 1), got {threshold!r}")
    return sky_probability(model, image) > float(threshold)


def load_sky_segmenter(path: str | Path) -> SkySegmenter:
    """A :class:`SkySegmenter` from an exported ``sky_segmentation`` safetensors file (eval mode)."""
    tensors, meta = ckpt.load_weights(path)
    if meta.get("kind") != "sky_segmentation":
        raise ValueError(f"{str(path)!r} holds {meta.get('kind')!r} weights, not a sky segmenter")
    model = SkySegmenter(int(meta["width"]), int(meta["depth"]), int(meta["res"]))
    # Training keeps the segmenter under the name "seg" of a ModuleDict.
    model.load_state_dict({k[4:]: v for k, v in tensors.items() if k.startswith("seg.")} or tensors)
    return model.eval()


def _blur(x: torch.Tensor, sigma: float) -> torch.Tensor:
    """Separable Gaussian blur of ``(1, C, H, W)`` (5 taps, replicate border)."""
    t = torch.arange(-2, 3, dtype=x.dtype)
    k = torch.exp(-0.5 * (t / sigma) ** 2)
    k = k / k.sum()
    c = x.shape[1]
    x = F.pad(x, (2, 2, 2, 2), mode="replicate")
    x = F.conv2d(x, k.reshape(1, 1, 1, 5).expand(c, 1, 1, 5).contiguous(), groups=c)
    return F.conv2d(x, k.reshape(1, 1, 5, 1).expand(c, 1, 5, 1).contiguous(), groups=c)


def photometric_augment(image: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """Re-photograph linear images with a random camera: what a real photo might look like, linearised.

    Per image: exposure ``2 ** U(-1.5, 1.5)``; white balance gains ``exp(U(-0.15, 0.15))``
    per channel (green 1); a response curve ``clip(x, 0, 1) ** (1 / U(1.6, 2.8))`` blended
    half of the time with a smoothstep S-curve (weight ``U(0, 0.5)``); Gaussian noise of
    standard deviation ``U(0, 0.03)`` in display values; half of the time a JPEG-like
    softening (Gaussian blur ``sigma U(0.3, 1.0)``); 8-bit quantisation. The result is
    linearised with the sRGB curve, as a user's photo would be (the true curve is unknown).

    Args:
        image: ``(B, 3, H, W)`` linear RGB.
        generator: the source of randomness (same state, same output).

    Returns:
        ``(B, 3, H, W)`` linear RGB.
    """
    _check_image(image)
    out = []
    g = generator

    def u(lo: float, hi: float, n: int = 1) -> torch.Tensor:
        return lo + (hi - lo) * torch.rand(n, generator=g, dtype=torch.float64)

    for x in image:
        x = x.double()[None]
        ev = u(-1.5, 1.5)
        wb = torch.exp(u(-0.15, 0.15, 3))
        wb = wb / wb[1]
        y = (x * 2.0 ** ev * wb.reshape(1, 3, 1, 1)).clamp(0.0, 1.0) ** (1.0 / float(u(1.6, 2.8)))
        if float(u(0, 1)) < 0.5:
            t = float(u(0.0, 0.5))
            y = (1 - t) * y + t * (3 * y**2 - 2 * y**3)
        sigma = float(u(0.0, 0.03))
        y = y + sigma * torch.randn(y.shape, generator=g, dtype=torch.float64)
        if float(u(0, 1)) < 0.5:
            y = _blur(y, float(u(0.3, 1.0)))
        y = torch.round(y.clamp(0.0, 1.0) * 255.0) / 255.0
        out.append(colour.from_ldr(y[0]).to(image.dtype))
    return torch.stack(out)
