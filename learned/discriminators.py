"""Multiscale PatchGAN discriminators, the least-squares GAN loss and feature matching.

Shared by the neural renderer (the paper's multiscale LSGAN on the foreground) and SkyGAN
(pix2pixHD / GauGAN-style 2-scale PatchGAN with feature matching). No pretrained VGG can
be downloaded here, so feature matching on the discriminator's own features stands in
for the paper's perceptual loss.

Shapes: images ``(B, C, H, W)``; each scale's discriminator returns its intermediate
feature maps and, last, a ``(B, 1, h, w)`` map of patch scores (real -> 1, fake -> 0).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["PatchDiscriminator", "MultiscaleDiscriminator", "lsgan_loss", "feature_matching_loss"]


class PatchDiscriminator(nn.Module):
    """A PatchGAN: ``layers`` stride-2 4x4 convolutions (LeakyReLU 0.2; GroupNorm after the
    first, which behaves the same in train and eval), then a 3x3 convolution to one score per patch.

    Args:
        in_channels: input channels.
        width: channels of the first layer (doubled per layer, capped at ``8 * width``).
        layers: stride-2 layers (receptive field grows as ``~ 2**layers * 4`` pixels).
    """

    def __init__(self, in_channels: int, width: int = 16, layers: int = 3) -> None:
        super().__init__()
        if not (isinstance(in_channels, int) and in_channels >= 1):
            raise ValueError(f"in_channels must be a positive integer, got {in_channels!r}")
        if not (isinstance(width, int) and width >= 1) or not (isinstance(layers, int) and layers >= 1):
            raise ValueError(f"width and layers must be positive integers, got {width!r}, {layers!r}")
        blocks: list[nn.Module] = []
        cin = in_channels
        for i in range(layers):
            cout = min(width * 2 ** i, 8 * width)
            norm: nn.Module = nn.GroupNorm(min(8, cout), cout) if i > 0 and cout % min(8, cout) == 0 else nn.Identity()
            blocks.append(nn.Sequential(nn.Conv2d(cin, cout, 4, stride=2, padding=1), norm, nn.LeakyReLU(0.2, True)))
            cin = cout
        blocks.append(nn.Conv2d(cin, 1, 3, padding=1))
        self.blocks = nn.ModuleList(blocks)
        self.in_channels = in_channels

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """``(B, C, H, W)`` -> feature maps of every layer, the last being the ``(B, 1, h, w)`` scores."""
        if x.ndim != 4 or x.shape[1] != self.in_channels:
            raise ValueError(f"discriminator input must be (B, {self.in_channels}, H, W), got {tuple(x.shape)}")
        feats = []
        for b in self.blocks:
            x = b(x)
            feats.append(x)
        return feats


class MultiscaleDiscriminator(nn.Module):
    """``scales`` PatchGANs, scale ``k`` seeing the input average-pooled ``2**k`` times
    (coarse scales judge global consistency, fine ones texture)."""

    def __init__(self, in_channels: int, width: int = 16, layers: int = 3, scales: int = 2) -> None:
        super().__init__()
        if not (isinstance(scales, int) and scales >= 1):
            raise ValueError(f"scales must be a positive integer, got {scales!r}")
        self.nets = nn.ModuleList(PatchDiscriminator(in_channels, width, layers) for _ in range(scales))

    def forward(self, x: torch.Tensor) -> list[list[torch.Tensor]]:
        """``(B, C, H, W)`` -> per scale, the list of feature maps (scores last)."""
        out = []
        for k, net in enumerate(self.nets):
            out.append(net(x if k == 0 else F.avg_pool2d(x, 2 ** k, ceil_mode=True)))
        return out


def lsgan_loss(outputs: list[list[torch.Tensor]], real: bool) -> torch.Tensor:
    """Least-squares GAN loss (Mao et al. 2017) summed over scales: mean ``(D - 1)^2`` for
    ``real`` targets, mean ``D^2`` for fake ones."""
    target = 1.0 if real else 0.0
    return sum(((feats[-1] - target) ** 2).mean() for feats in outputs)


def feature_matching_loss(fake: list[list[torch.Tensor]], real: list[list[torch.Tensor]]) -> torch.Tensor:
    """Mean L1 between the discriminator's features of fake and real inputs (scores excluded),
    averaged over layers and summed over scales; the real features are treated as constants."""
    if len(fake) != len(real):
        raise ValueError(f"fake and real come from different discriminators ({len(fake)} vs {len(real)} scales)")
    total = fake[0][0].new_zeros(())
    for f_s, r_s in zip(fake, real):
        layers = list(zip(f_s[:-1], r_s[:-1]))
        total = total + sum((f - r.detach()).abs().mean() for f, r in layers) / max(len(layers), 1)
    return total
