"""SkyGAN: a SPADE (GauGAN-style) generator that paints the sky behind a relit foreground.

The paper's last step: noise + the sky mask + the relit foreground -> a sky consistent
with the foreground, composited with the mask (Park et al. 2019, two classes: sky and
foreground). Beyond the paper the generator is also conditioned on the *target lighting*
(order-2 radiance SH ``(B, 9, 3)`` in the camera frame), so the sky can follow the
requested lighting; whether it does is measured by :func:`learned.train_sky.sky_follows_lighting`
(``docs/experiments/18-skygan.md``).

Units. The lighting may come at any overall scale (photo units, decomposition units).
Everything is divided by ``s = Y00 * lum(L00)``, the mean radiance over the sphere of the
lighting's DC term (``lum`` = Rec. 709 luminance, ``Y00 = 0.282095``): a sky pixel is a
sample of the environment map whose projection the SH is, so ``sky / s`` is a
scale-free quantity (about 1 for a uniform sky). The network sees the foreground as
``log(fg / s + 0.01)``, the SH as ``L / lum(L00)`` (DC luminance 1, colour and shape
kept) tiled per pixel, and predicts ``log(sky / s)``; the output is ``s * exp(.)``, in the
units of the lighting and foreground given.

Architecture (:class:`SkyGenerator`): the condition map ``c`` (sky mask 1, log
foreground outside the sky 3, pixel coordinates 2, tiled SH 27 = 33 channels) drives the
SPADE normalisation of every block: ``GroupNorm(x)`` without affine parameters, then
``* (1 + gamma(c)) + beta(c)`` with ``gamma, beta`` 3x3 convolutions of a shared 3x3
convolution of ``c`` resized to the block's resolution. The input is a noise vector
``z`` (tiled) and a low-resolution noise map, at 1/8 of the image size, with ``c``
downsampled; four SPADE residual blocks (three x2 upsamplings) reach full resolution.
GroupNorm rather than BatchNorm: the output does not depend on the batch.
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from physrelight import colour
from physrelight.filters import gaussian_blur

from . import checkpoint as ckpt

__all__ = ["SMOOTH_SIGMA", "SkyGenerator", "condition_map", "generate_sky", "lighting_scale", "load_sky_generator", "smooth_sky",
           "sky_noise", "COND_CHANNELS"]

Y00 = 0.282095
LUMA = colour.LUMINANCE
COND_CHANNELS = 1 + 3 + 2 + 27
LOG_EPS = 0.01


def _groups(c: int) -> int:
    for g in (8, 4, 2, 1):
        if c % g == 0:
            return g
    return 1


def check_inputs(foreground: torch.Tensor, sky: torch.Tensor, lighting: torch.Tensor) -> None:
    """ValueError naming the first bad shape/type among ``foreground (B,3,H,W)``, ``sky (B,1,H,W)``
    bool and ``lighting (B,9,3)``."""
    if not isinstance(foreground, torch.Tensor) or foreground.ndim != 4 or foreground.shape[1] != 3:
        got = tuple(foreground.shape) if isinstance(foreground, torch.Tensor) else type(foreground).__name__
        raise ValueError(f"foreground must be a tensor of shape (B, 3, H, W), got {got}")
    b, _, h, w = foreground.shape
    if not isinstance(sky, torch.Tensor) or sky.shape != (b, 1, h, w):
        got = tuple(sky.shape) if isinstance(sky, torch.Tensor) else type(sky).__name__
        raise ValueError(f"sky must be a bool tensor of shape ({b}, 1, {h}, {w}), got {got}")
    if sky.dtype != torch.bool:
        raise ValueError(f"sky must be a bool tensor, got dtype {sky.dtype}")
    if not isinstance(lighting, torch.Tensor) or lighting.shape != (b, 9, 3):
        got = tuple(lighting.shape) if isinstance(lighting, torch.Tensor) else type(lighting).__name__
        raise ValueError(f"lighting must be a tensor of shape ({b}, 9, 3), got {got}")
    if not bool(torch.isfinite(lighting).all()) or not bool(torch.isfinite(foreground).all()):
        raise ValueError("foreground and lighting must be finite")


def lighting_scale(lighting: torch.Tensor) -> torch.Tensor:
    """``(B, 9, 3)`` -> ``(B, 1, 1, 1)``: ``s = Y00 * lum(L00)``, the DC term's mean radiance.

    Raises:
        ValueError: a lighting whose DC luminance is not positive (no light to scale by).
    """
    luma = lighting.new_tensor(LUMA)
    dc = (lighting[:, 0, :] * luma).sum(-1)
    if bool((dc <= 0).any()):
        raise ValueError(f"lighting DC luminance must be positive, got {dc.tolist()}")
    return (Y00 * dc).reshape(-1, 1, 1, 1)


def condition_map(foreground: torch.Tensor, sky: torch.Tensor, lighting: torch.Tensor) -> torch.Tensor:
    """The SPADE condition ``(B, 33, H, W)``: mask, log foreground / s (0 on sky), x/y in [-1, 1], SH tiled."""
    b, _, h, w = foreground.shape
    s = lighting_scale(lighting)
    m = sky.to(foreground.dtype)
    fg = torch.log(foreground.clamp_min(0) / s + LOG_EPS) * (1 - m)
    ys = torch.linspace(1.0, -1.0, h, dtype=foreground.dtype)  # +1 at the top: camera y up
    xs = torch.linspace(-1.0, 1.0, w, dtype=foreground.dtype)
    coords = torch.stack(torch.meshgrid(ys, xs, indexing="ij"))[None].expand(b, 2, h, w)
    sh = (lighting / (s / Y00).reshape(-1, 1, 1)).reshape(b, 27, 1, 1).expand(b, 27, h, w).to(foreground.dtype)
    return torch.cat([m, fg, coords, sh], 1)


class SPADE(nn.Module):
    """``GroupNorm(x) * (1 + gamma(c)) + beta(c)``, ``c`` resized (area) to ``x``'s size."""

    def __init__(self, channels: int, hidden: int) -> None:
        super().__init__()
        self.norm = nn.GroupNorm(_groups(channels), channels, affine=False)
        self.shared = nn.Sequential(nn.Conv2d(COND_CHANNELS, hidden, 3, padding=1), nn.ReLU(inplace=True))
        self.gamma = nn.Conv2d(hidden, channels, 3, padding=1)
        self.beta = nn.Conv2d(hidden, channels, 3, padding=1)

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        if c.shape[-2:] != x.shape[-2:]:
            c = F.adaptive_avg_pool2d(c, x.shape[-2:])
        a = self.shared(c)
        return self.norm(x) * (1 + self.gamma(a)) + self.beta(a)


class SPADEResBlock(nn.Module):
    """SPADE -> LeakyReLU -> conv, twice, plus a (1x1 when the width changes) shortcut."""

    def __init__(self, cin: int, cout: int, hidden: int) -> None:
        super().__init__()
        self.n1, self.c1 = SPADE(cin, hidden), nn.Conv2d(cin, cout, 3, padding=1)
        self.n2, self.c2 = SPADE(cout, hidden), nn.Conv2d(cout, cout, 3, padding=1)
        self.skip = nn.Conv2d(cin, cout, 1, bias=False) if cin != cout else nn.Identity()

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        y = self.c1(F.leaky_relu(self.n1(x, c), 0.2))
        y = self.c2(F.leaky_relu(self.n2(y, c), 0.2))
        return self.skip(x) + y


class SkyGenerator(nn.Module):
    """Noise + condition map -> ``log(sky / s)`` ``(B, 3, H, W)`` (see the module docstring).

    Args:
        width: channels of the full-resolution block; the blocks at 1/8, 1/4, 1/2 have
            ``4, 3, 2`` times as many.
        z_dim: length of the noise vector.
        noise_channels: channels of the 1/8-resolution noise map.
        hidden: channels of SPADE's shared convolution.
    """

    def __init__(self, width: int = 8, z_dim: int = 16, noise_channels: int = 4, hidden: int = 16) -> None:
        super().__init__()
        for name, v in (("width", width), ("z_dim", z_dim), ("noise_channels", noise_channels), ("hidden", hidden)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        self.width, self.z_dim, self.noise_channels, self.hidden = width, z_dim, noise_channels, hidden
        chans = [4 * width, 3 * width, 2 * width, width]
        self.stem = nn.Conv2d(z_dim + noise_channels + COND_CHANNELS, chans[0], 3, padding=1)
        self.blocks = nn.ModuleList(
            SPADEResBlock(chans[max(i - 1, 0)], chans[i], hidden) for i in range(4))
        self.head = nn.Conv2d(chans[-1], 3, 3, padding=1)

    def forward(self, cond: torch.Tensor, z: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """``cond (B, 33, H, W)``, ``z (B, z_dim)``, ``noise (B, noise_channels, ceil(H/8), ceil(W/8))``
        -> ``log(sky / s)`` ``(B, 3, H, W)``."""
        if cond.ndim != 4 or cond.shape[1] != COND_CHANNELS:
            raise ValueError(f"cond must have shape (B, {COND_CHANNELS}, H, W), got {tuple(cond.shape)}")
        b, _, h, w = cond.shape
        sizes = [(math.ceil(h / 2**k), math.ceil(w / 2**k)) for k in (3, 2, 1, 0)]
        if z.shape != (b, self.z_dim):
            raise ValueError(f"z must have shape ({b}, {self.z_dim}), got {tuple(z.shape)}")
        if noise.shape != (b, self.noise_channels, *sizes[0]):
            raise ValueError(f"noise must have shape ({b}, {self.noise_channels}, {sizes[0][0]}, {sizes[0][1]}), "
                             f"got {tuple(noise.shape)}")
        c0 = F.adaptive_avg_pool2d(cond, sizes[0])
        x = self.stem(torch.cat([z[:, :, None, None].expand(b, self.z_dim, *sizes[0]), noise, c0], 1))
        for i, blk in enumerate(self.blocks):
            if x.shape[-2:] != sizes[i]:
                x = F.interpolate(x, size=sizes[i], mode="bilinear", align_corners=False)
            x = blk(x, cond)
        # Bounded log output: exp stays finite whatever the weights (sky/s in [e^-6, e^6]).
        return 6.0 * torch.tanh(self.head(F.leaky_relu(x, 0.2)) / 6.0)


def sky_noise(generator: SkyGenerator, batch: int, height: int, width: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The noise of ``seed``: ``z (B, z_dim)``, ``noise (B, C, ceil(H/8), ceil(W/8))``.

    Each image ``i`` draws from its own ``torch.Generator`` seeded with ``(seed, i)``, so
    an image's noise does not depend on the batch it is in.
    """
    hs, ws = math.ceil(height / 8), math.ceil(width / 8)
    zs, ns = [], []
    for i in range(batch):
        g = torch.Generator().manual_seed((int(seed) * 1_000_003 + i) % (2**63 - 1))
        zs.append(torch.randn(generator.z_dim, generator=g))
        ns.append(torch.randn(generator.noise_channels, hs, ws, generator=g))
    return torch.stack(zs), torch.stack(ns)


def generate_sky(generator: SkyGenerator, foreground: torch.Tensor, sky: torch.Tensor, lighting: torch.Tensor,
                 seed: int = 0) -> torch.Tensor:
    """Paint the sky: foreground outside the mask, a generated sky inside.

    Args:
        generator: a :class:`SkyGenerator` (e.g. :func:`load_sky_generator`).
        foreground: ``(B, 3, H, W)`` linear relit image (sky pixels are ignored).
        sky: ``(B, 1, H, W)`` bool, True on sky.
        lighting: ``(B, 9, 3)`` camera-frame radiance SH of the target lighting, in the
            foreground's units or any overall scale (the output is in the units of
            ``lighting``: ``s * exp(G)`` with ``s = Y00 * lum(L00)``).
        seed: the noise; same seed, same output.

    Returns:
        ``(B, 3, H, W)`` linear image; foreground pixels are returned bit for bit.

    Raises:
        ValueError: bad shapes or dtypes, non-finite values, lighting without positive DC luminance.
    """
    check_inputs(foreground, sky, lighting)
    b, _, h, w = foreground.shape
    lighting = lighting.to(foreground.dtype)
    z, noise = sky_noise(generator, b, h, w, seed)
    param = next(generator.parameters())
    with torch.no_grad():
        cond = condition_map(foreground.to(param.dtype), sky, lighting.to(param.dtype))
        log_sky = generator(cond, z.to(param.dtype), noise.to(param.dtype))
        out = (lighting_scale(lighting.to(param.dtype)) * torch.exp(log_sky)).to(foreground.dtype)
    return torch.where(sky, out, foreground)


def load_sky_generator(path: str | Path) -> SkyGenerator:
    """A :class:`SkyGenerator` from an exported ``sky_gan`` safetensors file (eval mode)."""
    tensors, meta = ckpt.load_weights(path)
    if meta.get("kind") != "sky_gan":
        raise ValueError(f"{str(path)!r} holds {meta.get('kind')!r} weights, not a sky_gan generator")
    import json

    cfg = json.loads(meta["config"])
    gen = SkyGenerator(int(cfg["width"]), int(cfg.get("z_dim", 16)), int(cfg.get("noise_channels", 4)),
                       int(cfg.get("hidden", 16)))
    state = {k[2:]: v for k, v in tensors.items() if k.startswith("g.")} or tensors
    gen.load_state_dict(state)
    return gen.eval()


SMOOTH_SIGMA = 1.0 / 8.0
"""The Gaussian that :func:`smooth_sky` blurs SkyGAN's sky by, a fraction of the photo's short side. Chosen
by study 31's third round on the training panoramas' crops (``docs/experiments/31-sky-fitted-to-sh.md``):
SkyGAN's blotches are detail it cannot place (a photo's sky through the camera is not what SkyGAN saw), and
blurring them away scored higher than the blotches (10.09 against 9.68 dB)."""
_SMOOTH_FULL_SIZE = 256


def smooth_sky(sky_image: torch.Tensor, sky: torch.Tensor, sigma: float = SMOOTH_SIGMA) -> torch.Tensor:
    """``sky_image (B, 3, H, W)`` blurred within the mask ``sky (B, 1, H, W)`` bool by a Gaussian of
    ``sigma`` times the short side (normalised convolution: foreground pixels neither give nor take).

    Photos with a short side above 256 px are blurred at that size and brought back bilinearly (the
    result varies on the scale of sigma, so nothing is lost; an exact blur of sigma 375 px on a 12 MP
    photo would be 200 GMAC). Outside the mask the result is ``sky_image``'s blurred neighbours too: composite it.
    """
    if sky_image.ndim != 4 or sky_image.shape[1] != 3:
        raise ValueError(f"sky_image must have shape (B, 3, H, W), got {tuple(sky_image.shape)}")
    if sky.shape != (sky_image.shape[0], 1, *sky_image.shape[-2:]):
        raise ValueError(f"sky must have shape {(sky_image.shape[0], 1, *sky_image.shape[-2:])}, got {tuple(sky.shape)}")
    if not (isinstance(sigma, (int, float)) and sigma > 0):
        raise ValueError(f"sigma must be a positive fraction of the short side, got {sigma!r}")
    w = sky.to(sky_image.dtype)
    num, den = sky_image * w, w
    size = sky_image.shape[-2:]
    k = _SMOOTH_FULL_SIZE / min(size)
    if k < 1:
        small = (max(1, round(size[0] * k)), max(1, round(size[1] * k)))
        num, den = F.interpolate(num, size=small, mode="area"), F.interpolate(den, size=small, mode="area")
    s = float(sigma) * min(num.shape[-2:])
    out = gaussian_blur(num, s) / gaussian_blur(den, s).clamp_min(1e-6)
    if k < 1:
        out = F.interpolate(out, size=size, mode="bilinear", align_corners=False)
    return out
