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

import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from physrelight import colour

from . import checkpoint as ckpt
from .data import resize_short_side
from .networks import UNet

__all__ = ["CLOUD_SKY", "DUSK_SKY", "SEGMENT_RES", "WIDE_AUGMENT", "SkySegmenter", "cloud_sky", "dusk_sky", "grow_sky_by_colour", "is_monochrome", "jpeg_like", "label_components", "load_sky_segmenter", "photometric_augment", "plausible_sky",
           "refine_sky_boundary", "segment_sky", "sky_colour_model", "sky_mask_full_resolution", "sky_probability"]

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


WIDE_AUGMENT = {"ev": 2.0, "wb": 0.3, "gamma": (1.4, 3.0), "noise": 0.04, "dusk": 0.3, "jpeg": 0.5}
"""The wider camera of ``photometric_augment(..., wide=True)``: exposure +-2 EV, white balance
``exp(U(-0.3, 0.3))``, response exponent ``1 / U(1.4, 3.0)``, noise up to 0.04, a dusk tint on 30 %
of the photos and an 8 x 8 block-DCT quantisation (JPEG-like) on half of them."""


def _dct_matrix(n: int = 8, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """``(n, n)`` orthonormal DCT-II matrix (rows: frequencies)."""
    k = torch.arange(n, dtype=dtype)[:, None]
    i = torch.arange(n, dtype=dtype)[None, :]
    d = torch.cos(math.pi * (2 * i + 1) * k / (2 * n)) * math.sqrt(2.0 / n)
    d[0] /= math.sqrt(2.0)
    return d


def jpeg_like(y: torch.Tensor, step: float) -> torch.Tensor:
    """Quantise ``y (1, C, H, W)`` display values in 8 x 8 DCT blocks, as JPEG does: coefficient
    ``(u, v)`` to multiples of ``step * (1 + (u + v) / 2)`` (coarser at high frequencies); blocks
    cut at the border are padded by replication and cropped back."""
    if y.ndim != 4:
        raise ValueError(f"y must have shape (1, C, H, W), got {tuple(y.shape)}")
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step!r}")
    h, w = y.shape[-2:]
    ph, pw = (-h) % 8, (-w) % 8
    x = F.pad(y, (0, pw, 0, ph), mode="replicate") if ph or pw else y
    c, hh, ww = x.shape[1:]
    blocks = x.reshape(c, hh // 8, 8, ww // 8, 8).permute(0, 1, 3, 2, 4)  # (C, by, bx, 8, 8)
    d = _dct_matrix(8, y.dtype)
    coeff = d @ blocks @ d.T
    f = torch.arange(8, dtype=y.dtype)
    q = step * (1.0 + 0.5 * (f[:, None] + f[None, :]))
    back = d.T @ (torch.round(coeff / q) * q) @ d
    return back.permute(0, 1, 3, 2, 4).reshape(1, c, hh, ww)[..., :h, :w]


def photometric_augment(image: torch.Tensor, generator: torch.Generator, wide: bool = False) -> torch.Tensor:
    """Re-photograph linear images with a random camera: what a real photo might look like, linearised.

    Per image: exposure ``2 ** U(-1.5, 1.5)``; white balance gains ``exp(U(-0.15, 0.15))``
    per channel (green 1); a response curve ``clip(x, 0, 1) ** (1 / U(1.6, 2.8))`` blended
    half of the time with a smoothstep S-curve (weight ``U(0, 0.5)``); Gaussian noise of
    standard deviation ``U(0, 0.03)`` in display values; half of the time a JPEG-like
    softening (Gaussian blur ``sigma U(0.3, 1.0)``); 8-bit quantisation. The result is
    linearised with the sRGB curve, as a user's photo would be (the true curve is unknown).

    With ``wide`` the ranges are :data:`WIDE_AUGMENT`'s (a dusk tint, warm or purple, multiplies
    red by ``exp(U(0, 0.6))`` and blue by ``exp(U(-0.6, 0.2))``; the JPEG-like step is :func:`jpeg_like`
    with a step ``U(0.01, 0.04)``): real photos of every sky, not only our renders' cameras.

    Args:
        image: ``(B, 3, H, W)`` linear RGB.
        generator: the source of randomness (same state, same output).
        wide: the wider camera (False: the draws and ranges above, unchanged).

    Returns:
        ``(B, 3, H, W)`` linear RGB.
    """
    _check_image(image)
    out = []
    g = generator

    def u(lo: float, hi: float, n: int = 1) -> torch.Tensor:
        return lo + (hi - lo) * torch.rand(n, generator=g, dtype=torch.float64)

    ev_r, wb_r, gamma_r, noise_r = (WIDE_AUGMENT["ev"], WIDE_AUGMENT["wb"], WIDE_AUGMENT["gamma"],
                                    WIDE_AUGMENT["noise"]) if wide else (1.5, 0.15, (1.6, 2.8), 0.03)
    for x in image:
        x = x.double()[None]
        ev = u(-ev_r, ev_r)
        wb = torch.exp(u(-wb_r, wb_r, 3))
        wb = wb / wb[1]
        if wide and float(u(0, 1)) < WIDE_AUGMENT["dusk"]:
            wb = wb * torch.exp(torch.cat([u(0.0, 0.6), torch.zeros(1, dtype=torch.float64), u(-0.6, 0.2)]))
        y = (x * 2.0 ** ev * wb.reshape(1, 3, 1, 1)).clamp(0.0, 1.0) ** (1.0 / float(u(*gamma_r)))
        if float(u(0, 1)) < 0.5:
            t = float(u(0.0, 0.5))
            y = (1 - t) * y + t * (3 * y**2 - 2 * y**3)
        sigma = float(u(0.0, noise_r))
        y = y + sigma * torch.randn(y.shape, generator=g, dtype=torch.float64)
        if float(u(0, 1)) < 0.5:
            y = _blur(y, float(u(0.3, 1.0)))
        if wide and float(u(0, 1)) < WIDE_AUGMENT["jpeg"]:
            y = jpeg_like(y, float(u(0.01, 0.04)))
        y = torch.round(y.clamp(0.0, 1.0) * 255.0) / 255.0
        out.append(colour.from_ldr(y[0]).to(image.dtype))
    return torch.stack(out)


def _check_image_and_sky(image: torch.Tensor, sky: torch.Tensor) -> None:
    """``image (B, 3, H, W)`` and its sky ``(B, 1, H, W)`` bool, or a ValueError naming the bad one."""
    _check_image(image)
    if sky.shape != (image.shape[0], 1, *image.shape[-2:]) or sky.dtype != torch.bool:
        raise ValueError(f"sky must be a bool tensor of shape {(image.shape[0], 1, *image.shape[-2:])}, got "
                         f"{sky.dtype} {tuple(sky.shape)}")


DUSK_SKY = {"probability": 0.3, "stops": (-3.0, -0.5), "red": (-0.5, 0.0), "blue": (0.0, 0.3)}
"""The dusk-sky draw of :func:`dusk_sky`: how often, how many stops darker, and the log gains of red and blue."""


def dusk_sky(image: torch.Tensor, sky: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """Darken and blue the sky of some photos: a dusk sky behind a lit foreground.

    Our panoramas and most renders have a sky brighter than everything under it; at dusk and at
    night the sky is darker than a lit foreground (scikit-image's rocket.jpg). With probability
    ``DUSK_SKY["probability"]`` a photo's sky pixels are multiplied by ``2 ** U(-3, -0.5)`` and by
    red and blue gains ``exp(U(-0.5, 0))`` and ``exp(U(0, 0.3))`` (linear values, before the camera
    of :func:`photometric_augment`); the foreground is kept.

    Args:
        image: ``(B, 3, H, W)`` linear. sky: ``(B, 1, H, W)`` bool. generator: the draws.

    Returns:
        ``(B, 3, H, W)`` linear.
    """
    _check_image_and_sky(image, sky)
    d = DUSK_SKY
    out = image.clone()
    for b in range(image.shape[0]):
        r = torch.rand(4, generator=generator, dtype=torch.float64)
        if float(r[0]) >= d["probability"]:
            continue
        lo, hi = d["stops"]
        gain = 2.0 ** (lo + (hi - lo) * float(r[1]))
        red = math.exp(d["red"][0] + (d["red"][1] - d["red"][0]) * float(r[2]))
        blue = math.exp(d["blue"][0] + (d["blue"][1] - d["blue"][0]) * float(r[3]))
        g = image.new_tensor([gain * red, gain, gain * blue]).reshape(3, 1, 1)
        out[b] = torch.where(sky[b], image[b] * g, image[b])
    return out


CLOUD_SKY = {"probability": 0.5, "cover": (0.15, 0.85), "stops": (-3.0, 1.0), "horizon": 0.5, "stretch": (1.0, 3.0)}
"""The cloud draw of :func:`cloud_sky`: how often, the share of the sky covered, the clouds' brightness in stops
against the sky's mean, how often they gather towards the bottom of the sky, and their horizontal stretch."""


def _fractal_noise(h: int, w: int, stretch: float, generator: torch.Generator) -> torch.Tensor:
    """``(H, W)`` zero-mean, unit-variance noise with structure at several scales: four octaves of Gaussian
    noise on coarse grids (3 ... 24 rows, and ``stretch`` times fewer columns than square cells would need:
    clouds seen towards the horizon are flattened), each brought up bilinearly, weighted 1, 1/2, 1/4, 1/8."""
    f = torch.zeros(h, w, dtype=torch.float64)
    for k in range(4):
        gh = 3 * 2 ** k
        gw = max(2, int(round(gh * w / (stretch * max(h, 1)))))
        g = torch.randn(1, 1, gh + 1, gw + 1, generator=generator, dtype=torch.float64)
        f += 0.5 ** k * F.interpolate(g, size=(h, w), mode="bilinear", align_corners=True)[0, 0]
    return (f - f.mean()) / f.std().clamp_min(1e-12)


def cloud_sky(image: torch.Tensor, sky: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """Put clouds in the sky of some photos: dark cloud banks at dusk, grey or white clouds by day.

    Our renders' skies are sky models and panoramas seen at 64 px: clear gradients, so the segmenter
    takes a textured band of dark cloud along the horizon for land (scikit-image's rocket.jpg). With
    probability ``CLOUD_SKY["probability"]`` a photo's sky pixels get a cloud layer (linear values, before
    the camera of :func:`photometric_augment`): coverage ``alpha = sigmoid((f - t) / s)`` of a fractal
    noise ``f`` (:func:`_fractal_noise`), its threshold ``t`` the noise's quantile leaving a share
    ``U(0.15, 0.85)`` covered, softness ``s ~ U(0.05, 0.5)``; half of the time the cover gathers towards
    the bottom of the sky (``alpha`` times ``(row / H) ** U(0.5, 3)`` over its largest value on the sky). The cloud's
    colour is the sky's mean luminance times ``2 ** U(-3, 1)`` (a dark bank to a sunlit white), its
    chromaticity between neutral and the sky's own (``U(0, 1)``), shaded within by ``exp(0.25 g)`` of a second
    noise ``g``. The foreground and the mask are kept: clouds are sky.

    Args:
        image: ``(B, 3, H, W)`` linear. sky: ``(B, 1, H, W)`` bool. generator: the draws.

    Returns:
        ``(B, 3, H, W)`` linear.
    """
    _check_image_and_sky(image, sky)
    d = CLOUD_SKY
    h, w = image.shape[-2:]
    out = image.clone()
    luma = image.new_tensor(_LUMA).double()

    def u(lo: float, hi: float) -> float:
        return lo + (hi - lo) * float(torch.rand(1, generator=generator, dtype=torch.float64))

    for b in range(image.shape[0]):
        # every draw is made for every photo, so that one photo's sky does not shift the next one's clouds
        draw = u(0.0, 1.0)
        cover, soft, stops, tint = u(*d["cover"]), u(0.05, 0.5), u(*d["stops"]), u(0.0, 1.0)
        gather, power, stretch = u(0.0, 1.0) < d["horizon"], u(0.5, 3.0), u(*d["stretch"])
        f = _fractal_noise(h, w, stretch, generator)
        g = _fractal_noise(h, w, stretch, generator)
        m = sky[b, 0]
        if draw >= d["probability"] or int(m.sum()) < 4:
            continue
        x = image[b].double()
        t = torch.quantile(f[m], 1.0 - cover)
        alpha = torch.sigmoid((f - t) / soft)
        if gather:
            rows = ((torch.arange(h, dtype=torch.float64) + 0.5) / h)[:, None] ** power
            alpha = alpha * rows / rows.expand(h, w)[m].max()
        mean_rgb = x[:, m].mean(1)
        lum = float((mean_rgb * luma).sum())
        if lum <= 0:
            continue
        chroma = (1.0 - tint) + tint * mean_rgb / lum  # luminance 1: neutral, or the sky's own colour
        cloud = lum * 2.0 ** stops * chroma[:, None, None] * torch.exp(0.25 * g)[None]
        mixed = (1.0 - alpha)[None] * x + alpha[None] * cloud
        out[b] = torch.where(m, mixed.to(image.dtype), image[b])
    return out


# ----------------------------------------------------------------------------- real photos: full-resolution mask


SEGMENT_RES = 128
"""Short side the segmenter runs at on a real photo: the shipped segmenter's training size. Chosen by
leave-one-panorama-out on the training panoramas' crops (study 22: 128 px against the photo's own
size, mean IoU 0.575 against 0.548), never on the held-out panorama."""
COLOUR_MIN_BLUE_OVER_RED = 0.85
"""A sky's median blue/red at least this (blue, grey or white). (Study 22's real-view segmenter needed
0.9 to refuse the mottled studio backdrop of scikit-image's astronaut, blue/red 0.859 under it; that
segmenter was not kept, and under the shipped one the backdrop is refused at 0.85.)"""
SMOOTHNESS_MAX_RATIO = 0.5
SMOOTHNESS_NOISE_AWARE = True
"""Whether :func:`plausible_sky`'s smoothness test takes each pixel's expected noise out of the roughness
(:func:`sky_roughness`; docs/experiments/50-noise-aware-smoothness.md). False: the plain roughness, as before."""
SMOOTHNESS_NOISE_AT_OWN_SIZE = True
"""Whether that noise is read off the photo at its own size and carried through the resizing to the working size
(:func:`resized_noise_roughness`), rather than read off the working image, where an enlarged small photo's noise is
spread over neighbouring pixels and mostly missed (study 50, round 2)."""
MIN_SKY_FRACTION = 0.01
BAND_WORKING_PIXELS = 6
"""How far (in working pixels) from the upsampled boundary pixels are decided by colour
(:func:`refine_sky_boundary`); 0: not at all. Chosen on the training side for the shipped segmenter
(synthetic renders only). Study 22 found 0 better for its real-view segmenter, which was not kept
(worse on data/val5 and on rocket.jpg, docs/experiments/22-sky-mask-real-views.md)."""


REFINEMENTS = ("local", "gauss")
"""How :func:`refine_sky_boundary` decides a band pixel: ``"local"``, the nearer of the two sides'
local mean colours; ``"gauss"``, the likelier under each side's local diagonal Gaussian (mean and
variance of log RGB)."""
REFINEMENT = "gauss"
VARIANCE_FLOOR = 1e-3
"""Floor of a side's local variance of log RGB in ``"gauss"`` (about 3 % noise)."""
MIN_SURE_SHARE = 0.125
"""The least share of :func:`refine_sky_boundary`'s window that a side's sure pixels must fill for that side's
*local* statistics; below it the side's statistics over the whole photo stand in (0: any sure pixel in the
window will do, as before study 44). An object narrower than the band has no sure pixels of its own, and a
Gaussian of the few unrelated ones near it, at the variance floor, lost rocket.jpg's body to the sky
(docs/experiments/44-band-statistics-from-enough-pixels.md: training crops +0.009, lattices +0.024, sunrise
+0.022 in mean IoU/F)."""


MONOCHROME_TOLERANCE = 3.0 / 255.0
"""A display pixel counts as coloured when its channels spread by more than this (JPEG's chroma noise on a
grey photo stays under it)."""
MONOCHROME_MAX_SHARE = 0.005
"""A photo is monochrome when no more than this share of its pixels is coloured."""


def is_monochrome(image: torch.Tensor) -> bool:
    """Whether a linear photo ``(1, 3, H, W)`` has no colour: a black-and-white photo stored as RGB.

    The sky mask leans on the sky's colour (the segmenter was trained on colour photos; the band and the
    growth compare colours), so on such a photo it takes white walls and pale objects for sky: scikit-image's
    ``camera`` (the cameraman, its three channels equal) loses a white tower and part of the camcorder to it.
    :meth:`learned.relighter.Relighter.relight_layers` says so in a warning. A tinted monochrome (sepia) has
    colour by this test.
    """
    _check_image(image)
    d = colour.to_ldr(image[0].clamp_min(0.0))
    spread = d.amax(0) - d.amin(0)
    return float((spread > MONOCHROME_TOLERANCE).float().mean()) <= MONOCHROME_MAX_SHARE


def label_components(mask: torch.Tensor) -> torch.Tensor:
    """8-connected component labels of ``mask (H, W)`` bool: ``(H, W)`` int64, 0 off the mask, each
    component's label its largest flat index + 1 (max-label propagation, a few hundred passes at 128 px)."""
    if mask.ndim != 2:
        raise ValueError(f"mask must have shape (H, W), got {tuple(mask.shape)}")
    h, w = mask.shape
    lab = torch.where(mask, torch.arange(1, h * w + 1, dtype=torch.float64).reshape(h, w), torch.zeros(h, w,
                                                                                                   dtype=torch.float64))
    m = mask.to(torch.float64)
    for _ in range(h * w):
        new = F.max_pool2d(lab[None, None], 3, stride=1, padding=1)[0, 0] * m
        if torch.equal(new, lab):
            break
        lab = new
    return lab.to(torch.int64)


def _roughness(lum: torch.Tensor) -> torch.Tensor:
    """``(H, W)`` std of log luminance over 3 x 3 pixels (border windows cut at the image)."""
    from physrelight.guided_filter import box_filter

    ly = torch.log(lum.clamp_min(1e-4))[None, None]
    m = box_filter(ly, 1)
    return (box_filter(ly * ly, 1) - m * m).clamp_min(0).sqrt()[0, 0]


def log_noise_sigma(lum: torch.Tensor, sigma_d: float | torch.Tensor | None = None) -> torch.Tensor:
    """The photo's noise at each pixel of linear luminance ``lum (H, W)``, in log luminance: ``(H, W)``.

    Noise in a stored photo (the sensor's after the camera's curve, JPEG's) is about even in *display* values, so
    in log luminance it is larger where the photo is darker: ``sigma_d / (d display / d log lum)``, with
    ``sigma_d`` the noise of the display luminance (given, or the noise floor of ``lum``'s:
    :func:`physrelight.denoise.noise_sigma`) and the slope of :func:`physrelight.colour.to_ldr` taken
    numerically. Where the display clips the slope is 0 and the noise infinite (a clipped patch has no noise left
    to see).
    """
    y = lum.clamp_min(1e-4)
    if sigma_d is None:
        sigma_d = display_noise_sigma(y)
    h = 1e-3  # central difference in log luminance
    slope = (colour.to_ldr(y * math.exp(h)) - colour.to_ldr(y * math.exp(-h))) / (2.0 * h)
    return torch.where(slope > 0, sigma_d / slope.clamp_min(1e-12), torch.full_like(y, math.inf))


def display_noise_sigma(lum: torch.Tensor) -> torch.Tensor:
    """The noise floor (:func:`physrelight.denoise.noise_sigma`) of the display luminance of linear ``lum (H, W)``:
    a 0-d tensor, in display values."""
    from physrelight.denoise import noise_sigma

    return noise_sigma(colour.to_ldr(lum.clamp_min(1e-4))[None, None])[0, 0]


def resized_noise_roughness(size: tuple[int, int], working: tuple[int, int]) -> float:
    """The expected squared 3 x 3 roughness (variance over 9 pixels) of unit white noise at ``size (H, W)`` once
    resized to ``working (h, w)`` as :func:`learned.data.resize_short_side` does: 8/9 without resizing.

    Enlarged bilinearly, each noise sample spreads over its neighbours, so a small photo's noise looks smoother at
    the working size than it is, and the noise floor read there misses most of it (study 50: a third). Measured on
    seeded noise (patches of at most 1024 x 1024 at the same scale, about 65k resized samples: ~1 %), so the same
    sizes give the same number.
    """
    if tuple(size) == tuple(working):
        return 8.0 / 9.0
    from physrelight.guided_filter import box_filter

    ph, pw = min(size[0], 1024), min(size[1], 1024)
    oh, ow = max(3, round(ph * working[0] / size[0])), max(3, round(pw * working[1] / size[1]))
    # enough draws for about 65k resized samples (mean known to ~1 %), at most 8M noise samples (~0.3 s)
    draws = max(1, min(math.ceil(65536 / (oh * ow)), (8 << 20) // (ph * pw)))
    g = torch.Generator().manual_seed(0)
    n = torch.randn(draws, 1, ph, pw, generator=g, dtype=torch.float64)
    if oh * ow < ph * pw:
        y = F.interpolate(n, size=(oh, ow), mode="area")
    else:
        y = F.interpolate(n, size=(oh, ow), mode="bilinear", align_corners=False)
    m = box_filter(y, 1)
    var = (box_filter(y * y, 1) - m * m)[:, 0, 1:-1, 1:-1]
    return float(var.mean())


def sky_roughness(lum: torch.Tensor, noise_aware: bool = True, noise_var: torch.Tensor | None = None) -> torch.Tensor:
    """``(H, W)`` roughness of linear luminance ``lum (H, W)`` for :func:`plausible_sky`'s smoothness test.

    The standard deviation of log luminance over 3 x 3 pixels; with ``noise_aware``, less the photo's noise:
    ``sqrt(max(r^2 - v, 0))``, ``v (H, W)`` the squared roughness the noise alone would give (``noise_var``; by
    default ``8/9 s^2`` with ``s`` from :func:`log_noise_sigma`, 8/9 being the expected 3 x 3 variance, over 9 and
    not 8, of unit white noise). Without it a small noisy photo's sky is as rough as its foreground and refused
    (study 50: rocket.jpg at 160 px with 2 % noise); a photo without noise keeps the plain roughness.
    """
    r = _roughness(lum)
    if not noise_aware:
        return r
    if noise_var is None:
        noise_var = (8.0 / 9.0) * log_noise_sigma(lum) ** 2
    return (r * r - noise_var).clamp_min(0.0).sqrt()


def plausible_sky(mask: torch.Tensor, image: torch.Tensor,
                  noise_var: torch.Tensor | None = None) -> tuple[torch.Tensor, str]:
    """Keep the parts of a sky mask that are a sky, and say why when none is.

    A sky component (8-connected, of ``mask (H, W)`` bool on linear ``image (3, H, W)``) is kept
    when it touches the top border, or when it is as bright as the top-touching sky (median
    luminance at least half of it) and as blue (blue/red at least 0.9 of it): sky between towers
    or branches. The kept sky is then judged a sky when it covers at least 1 % of the photo, is
    sky-coloured (median blue/red >= :data:`COLOUR_MIN_BLUE_OVER_RED`: blue, grey or white, not a warm
    wall, a face or a cup) and smooth (median 3 x 3 roughness of log luminance, less the photo's noise, at most half the
    foreground's: :func:`sky_roughness`; ``noise_var (H, W)``, the squared roughness the photo's noise alone
    gives at each pixel, when the caller knows it better than ``image`` shows, as for a resized photo).

    Returns:
        ``(kept (H, W) bool, reason)``; ``reason`` is ``""`` for a plausible sky, else one line
        saying why there is none (then ``kept`` is all False).
    """
    lum = (image * image.new_tensor(_LUMA)[:, None, None]).sum(0)
    lab = label_components(mask)
    top = set(lab[0][lab[0] > 0].tolist())
    if not top:
        return torch.zeros_like(mask), "no sky region touches the top of the photo"
    top_mask = torch.isin(lab, torch.tensor(sorted(top)))
    ratio = image[2] / image[0].clamp_min(1e-4)
    ref_lum, ref_ratio = float(lum[top_mask].median()), float(ratio[top_mask].median())
    kept = top_mask.clone()
    for c in torch.unique(lab[(lab > 0) & ~top_mask]).tolist():
        sel = lab == c
        if float(lum[sel].median()) >= 0.5 * ref_lum and float(ratio[sel].median()) >= 0.9 * ref_ratio:
            kept |= sel
    frac = float(kept.float().mean())
    if frac < MIN_SKY_FRACTION:
        return torch.zeros_like(mask), f"the sky found covers {100 * frac:.1f} % of the photo"
    colour_ratio = float(ratio[kept].median())
    if colour_ratio < COLOUR_MIN_BLUE_OVER_RED:
        return torch.zeros_like(mask), (f"the region found at the top is not sky-coloured (blue/red {colour_ratio:.3f}, "
                                        f"a sky has >= {COLOUR_MIN_BLUE_OVER_RED})")
    rough = sky_roughness(lum, SMOOTHNESS_NOISE_AWARE, noise_var)
    fg = ~kept
    if bool(fg.any()):
        r_sky, r_fg = float(rough[kept].median()), float(rough[fg].median())
        if r_sky > SMOOTHNESS_MAX_RATIO * r_fg:
            return torch.zeros_like(mask), (f"the region found at the top is as textured as the rest "
                                            f"(roughness {r_sky:.3f} vs {r_fg:.3f}): not a sky")
    return kept, ""


def sky_mask_full_resolution(model: SkySegmenter, image: torch.Tensor,
                             res: int | tuple[int, ...] | None = SEGMENT_RES,
                             eps: float = 1e-2, threshold: float = 0.5,
                             band: int = BAND_WORKING_PIXELS,
                             refine: str = REFINEMENT,
                             grow: float | None = None) -> tuple[torch.Tensor, list[str]]:
    """The sky of real photos at full resolution, and a reason per photo when there is none.

    The segmenter runs with its short side at ``res`` (:data:`SEGMENT_RES`; several sizes: the mean of
    its probabilities at each, brought bilinearly to the largest); its mask keeps only a
    plausible sky (:func:`plausible_sky`, at that resolution); the kept sky's probability is
    brought to full size by the guided filter on the photo's log luminance
    (:func:`physrelight.guided_filter.guided_upsample`), so the boundary follows the photo's
    edges, and thresholded at ``threshold``; pixels within ``band`` working pixels of the boundary
    are then decided by colour (:func:`refine_sky_boundary`, :data:`BAND_WORKING_PIXELS`); with ``grow``,
    sky-coloured pixels near the mask are added last (:func:`grow_sky_by_colour`).

    Args:
        image: ``(B, 3, H, W)`` linear photos.
        res: the working short side, or a tuple of them (a multi-scale mean; the largest is the
            working size); None: the photo's own (no resizing).
        eps: the guided filter's regulariser (log-luminance units squared).
        threshold: the sky probability above which a working pixel is sky, in (0, 1).
        band: working pixels near the boundary decided by colour (:func:`refine_sky_boundary`);
            0: none.
        grow: how far from the mask, as a fraction of the short side, sky-coloured pixels are
            added (:func:`grow_sky_by_colour`, gated at :data:`GROW_MAX_SPREAD`); None:
            :data:`GROW_REACH` (0: none).

    Returns:
        ``(sky (B, 1, H, W) bool, reasons)``: ``reasons[b]`` is ``""`` when photo ``b`` has a
        plausible sky, else one line saying why not (its mask is then empty).
    """
    from physrelight.guided_filter import guided_upsample

    _check_image(image)
    sizes = (res,) if res is None or not isinstance(res, tuple) else res
    if not sizes or any(r is not None and (isinstance(r, bool) or not isinstance(r, int) or r < 8) for r in sizes) \
            or (len(sizes) > 1 and None in sizes):
        raise ValueError(f"res must be an integer >= 8, a non-empty tuple of them, or None, got {res!r}")
    if not (isinstance(threshold, (int, float)) and 0.0 < float(threshold) < 1.0):
        raise ValueError(f"threshold must be a number in (0, 1), got {threshold!r}")
    if isinstance(band, bool) or not isinstance(band, int) or band < 0:
        raise ValueError(f"band must be an integer >= 0, got {band!r}")
    if refine not in REFINEMENTS:
        raise ValueError(f"refine must be one of {REFINEMENTS}, got {refine!r}")
    grow = GROW_REACH if grow is None else grow
    if isinstance(grow, bool) or not isinstance(grow, (int, float)) or not 0.0 <= float(grow) <= 1.0:
        raise ValueError(f"grow must be a number in [0, 1], got {grow!r}")
    reach = int(round(float(grow) * min(image.shape[-2:])))
    param = next(model.parameters())
    smalls = [image.to(param.dtype) if r is None else resize_short_side(image.to(param.dtype), r) for r in sizes]
    small = max(smalls, key=lambda x: x.shape[-2] * x.shape[-1])
    with torch.no_grad():
        # Several sizes: the coarse run sees the scene whole, the fine one keeps thin structures.
        prob = torch.stack([F.interpolate(torch.sigmoid(model(x)), size=small.shape[-2:], mode="bilinear",
                                          align_corners=False) if x.shape[-2:] != small.shape[-2:]
                            else torch.sigmoid(model(x)) for x in smalls]).mean(0)
    masks, reasons = [], []
    for b in range(image.shape[0]):
        lum = (image[b: b + 1] * image.new_tensor(_LUMA)[None, :, None, None]).sum(1, keepdim=True)  # full size
        noise_var = None
        if SMOOTHNESS_NOISE_AWARE and SMOOTHNESS_NOISE_AT_OWN_SIZE:
            # the noise is read off the photo as it came, and carried through the resizing to the working size
            sigma_d = display_noise_sigma(lum[0, 0])
            lum_small = (small[b] * small.new_tensor(_LUMA)[:, None, None]).sum(0)
            gain = resized_noise_roughness(tuple(image.shape[-2:]), tuple(small.shape[-2:]))
            noise_var = gain * log_noise_sigma(lum_small, sigma_d.to(lum_small.dtype)) ** 2
        kept, why = plausible_sky(prob[b, 0] > threshold, small[b], noise_var)
        reasons.append(why)
        p = (prob[b, 0] * kept)[None, None]  # the rejected parts' probability is 0
        if not bool(kept.any()):
            masks.append(torch.zeros(1, 1, *image.shape[-2:], dtype=torch.bool))
            continue
        guide = torch.log(lum.clamp_min(1e-3)).to(p.dtype)
        up = guided_upsample(guide, p.to(guide.dtype), eps=eps) > threshold
        if band > 0:
            width = max(1, band * round(image.shape[-2] / small.shape[-2]))
            up = refine_sky_boundary(up, image[b: b + 1], width, refine)
        masks.append(grow_sky_by_colour(up, image[b: b + 1], reach, max_spread=GROW_MAX_SPREAD))
    return torch.cat(masks), reasons


_DILATE_POOL_MAX = 16


def _dilate(mask: torch.Tensor, r: int) -> torch.Tensor:
    """``mask (B, 1, H, W)`` bool dilated by a ``(2r+1)^2`` square. A small ``r`` by two separable max pools;
    a wide one (the colour band of a large photo: hundreds of pixels) by the window's count of mask pixels
    (a pixel is in the dilation when its window holds any), whose summed-area tables cost the same at any
    ``r`` (a max pool's cost grows with it). Counts are integers, exact in float64."""
    from physrelight.guided_filter import box_filter

    r = min(r, max(mask.shape[-2:]))
    if r > _DILATE_POOL_MAX:
        return box_filter(mask.to(torch.float64), r) > 0
    m = F.max_pool2d(mask.float(), (1, 2 * r + 1), stride=1, padding=(0, r))
    return F.max_pool2d(m, (2 * r + 1, 1), stride=1, padding=(r, 0)) > 0.5


def _boundary_band(sky: torch.Tensor, band: int) -> torch.Tensor:
    """``(B, 1, H, W)`` bool: the pixels within a ``(2 band + 1)^2`` square of both sky and non-sky,
    ``_dilate(sky, band) & _dilate(~sky, band)``. A wide band reads both from one window count of the sky:
    the window holds sky when its count is above 0 and non-sky when below the window's size (integer counts,
    exact in float64), so one summed-area pass serves where two were run."""
    from physrelight.guided_filter import box_filter

    r = min(band, max(sky.shape[-2:]))
    if r > _DILATE_POOL_MAX:
        share = box_filter(sky.to(torch.float64), r)
        return (share > 0) & (share < 1)
    return _dilate(sky, band) & _dilate(~sky, band)


def refine_sky_boundary(sky: torch.Tensor, image: torch.Tensor, band: int, refine: str = REFINEMENT,
                        min_share: float | None = None) -> torch.Tensor:
    """Decide the pixels near a sky boundary by colour, at full resolution.

    A mask brought up from a working resolution is right away from its boundary and wrong
    within a band as wide as a working pixel or two: a lattice tower or a branch is thinner
    than that. Within ``band`` pixels of the boundary each pixel goes to the side whose local
    mean colour (log RGB, averaged over the sure pixels of that side within ``4 band``, or over
    all of them where none is that near) it is nearer to; elsewhere the mask stays. A step edge
    between two flat colours is kept exactly.

    Args:
        sky: ``(1, 1, H, W)`` bool. image: ``(1, 3, H, W)`` linear. band: pixels.
        min_share: a side's local statistics need its sure pixels to fill this share of the window, else its
            statistics over the whole photo are used (:data:`MIN_SURE_SHARE` when None).

    Returns:
        ``(1, 1, H, W)`` bool.
    """
    min_share = MIN_SURE_SHARE if min_share is None else float(min_share)
    if not 0.0 <= min_share < 1.0:
        raise ValueError(f"min_share must lie in [0, 1), got {min_share!r}")
    near = _boundary_band(sky, band)
    if not bool(near.any()):
        return sky
    x = torch.log(image.clamp_min(1e-4))
    sure_sky, sure_fg = (sky & ~near).to(x.dtype), (~sky & ~near).to(x.dtype)
    if float(sure_sky.sum()) == 0 or float(sure_fg.sum()) == 0:
        return sky
    r = 4 * band
    if refine == "local":
        d_sky = ((x - _local_mean(sure_sky, x, r, min_share)) ** 2).sum(1, keepdim=True)
        d_fg = ((x - _local_mean(sure_fg, x, r, min_share)) ** 2).sum(1, keepdim=True)
    else:
        # "gauss": a diagonal Gaussian per side, so a smooth sky does not claim a varied foreground's outliers
        d_sky, d_fg = _local_gaussian_nll(x, sure_sky, r, min_share), _local_gaussian_nll(x, sure_fg, r, min_share)
    return torch.where(near, d_sky < d_fg, sky)


def _local_moments(w: torch.Tensor, planes: list[torch.Tensor], r: int, min_share: float = 0.0) -> list[torch.Tensor]:
    """The weighted means of each of ``planes`` (``(1, C_k, H, W)`` each) over the pixels of weight ``w (1, 1, H, W)``
    (not all zero) within ``r`` of each pixel, from one box filter of the weight and every plane; where those
    pixels fill no more than ``min_share`` of the window (none, at 0), over all of them."""
    from physrelight.guided_filter import box_filter

    weighted = [p * w for p in planes]
    sums = box_filter(torch.cat([w, *weighted], 1), r)
    n = sums[:, :1]
    local, total = n > min_share, float(w.sum())
    out, k = [], 1
    for p in weighted:
        c = p.shape[1]
        out.append(torch.where(local, sums[:, k: k + c] / n.clamp_min(1e-12), p.sum((2, 3), keepdim=True) / total))
        k += c
    return out


def _local_mean(w: torch.Tensor, v: torch.Tensor, r: int, min_share: float = 0.0) -> torch.Tensor:
    """``(1, C, H, W)`` mean of ``v (1, C, H, W)`` over the pixels of weight ``w (1, 1, H, W)`` (not all
    zero) within ``r`` of each pixel; where they fill no more than ``min_share`` of that window (none, at 0),
    over all of them (:func:`_local_moments`)."""
    return _local_moments(w, [v], r, min_share)[0]


def _local_gaussian_nll(x: torch.Tensor, w: torch.Tensor, r: int, min_share: float = 0.0) -> torch.Tensor:
    """``(1, 1, H, W)`` negative log-likelihood (times 2, up to a constant) of each pixel of ``x (1, C, H, W)``
    under the diagonal Gaussian of the pixels ``w`` near it (:func:`_local_moments` of ``x`` and ``x^2`` in one
    box filter; variance floor :data:`VARIANCE_FLOOR`)."""
    mu, ex2 = _local_moments(w, [x, x * x], r, min_share)
    var = (ex2 - mu * mu).clamp_min(0) + VARIANCE_FLOOR
    return ((x - mu) ** 2 / var + torch.log(var)).sum(1, keepdim=True)


def _local_gaussian_nll_at(x: torch.Tensor, w: torch.Tensor, r: int, index: torch.Tensor) -> torch.Tensor:
    """:func:`_local_gaussian_nll` at the flat pixel indices ``index (N,)`` only: ``(N,)`` float64.

    The windows' sums are read from summed-area tables (four look-ups per pixel), so the cost does not grow with
    ``r`` and the statistics are computed only where they are asked for (the growth asks at its few candidates,
    while a window of ``4 * reach`` spans most of a large photo). The tables are float64, built one plane at a time
    (each about 0.2 GB for a 24-megapixel photo). ``x (1, C, H, W)``, ``w (1, 1, H, W)``."""
    from physrelight.guided_filter import cumsum

    c, h, wd = x.shape[1], x.shape[-2], x.shape[-1]
    iy, ix = index // wd, index % wd
    y0, y1 = (iy - r).clamp_min(0), (iy + r + 1).clamp_max(h)
    x0, x1 = (ix - r).clamp_min(0), (ix + r + 1).clamp_max(wd)
    xd, wt = x[0].to(torch.float64), w[0, 0].to(torch.float64)

    def window_sums(plane: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The sums of ``plane (H, W)`` over the windows of ``index``, and over the whole image."""
        sat = F.pad(cumsum(plane, 0).cumsum(1), (1, 0, 1, 0))
        return sat[y1, x1] - sat[y0, x1] - sat[y1, x0] + sat[y0, x0], sat[-1, -1]

    n, n_all = window_sums(wt)
    near = n > 0
    out = torch.zeros(index.numel(), dtype=torch.float64)
    for ch in range(c):
        s1, t1 = window_sums(xd[ch] * wt)
        s2, t2 = window_sums(xd[ch] * xd[ch] * wt)
        mu = torch.where(near, s1 / n.clamp_min(1e-12), t1 / n_all)
        var = (torch.where(near, s2 / n.clamp_min(1e-12), t2 / n_all) - mu * mu).clamp_min(0) + VARIANCE_FLOOR
        out += (xd[ch].flatten()[index] - mu) ** 2 / var + torch.log(var)
    return out


GROW_REACH = 0.1
"""How far from the mask (a fraction of the photo's short side) :func:`sky_mask_full_resolution` lets
:func:`grow_sky_by_colour` add sky-coloured pixels; 0: not at all. The segmenter draws a lattice tower, power
lines or bare branches solid at its working size; the growth finds the sky between the bars. Chosen by study 40
(docs/experiments/40-sky-through-lattices.md) on the training panoramas' crops with composited lattices (mean of
IoU and boundary F +0.020 [+0.009, +0.033]); on the crops without lattices it changes the mean by -0.001 (study
28, round 3); on the held-out sunrise crops (real pylons), read once: IoU 0.903 -> 0.916, boundary F 0.702 ->
0.717. ``relight --sky-grow 0`` turns it off."""
GROW_CHI2 = 11.34
"""A grown pixel's colour must lie within this squared Mahalanobis distance of the smooth sky model
(chi-square with 3 degrees of freedom at 0.99)."""
GROW_MAX_SPREAD = 0.1
"""The sky model's largest spread (log RGB, per channel) at which :func:`sky_mask_full_resolution`'s
growth adds anything: wider, and the mask it was fitted to holds façade or foliage (study 28, round 3:
neutral on the training crops at reach 0.05; rocket.jpg's dusk sky fits within it)."""
GROW_ERODE = 2
"""Pixels within this many pixels of the mask's boundary are left out of the sky model's fit."""
_GROW_MAX_FIT = 20000


def _sky_basis(h: int, w: int, dtype: torch.dtype, order: int = 2,
               box: tuple[float, float, float, float] | None = None) -> torch.Tensor:
    """``(K, H, W)`` monomials of pixel centres up to ``order`` (1: 1, u, v; 2: also u^2, uv, v^2),
    u and v centred and scaled by the longer side, and clamped to ``box = (u0, u1, v0, v1)``."""
    s = float(max(h, w))
    v = ((torch.arange(h, dtype=dtype) + 0.5 - h / 2) / s)[:, None].expand(h, w)
    u = ((torch.arange(w, dtype=dtype) + 0.5 - w / 2) / s)[None, :].expand(h, w)
    if box is not None:
        u, v = u.clamp(box[0], box[1]), v.clamp(box[2], box[3])
    terms = [torch.ones_like(u), u, v] + ([u * u, u * v, v * v] if order == 2 else [])
    return torch.stack(terms)


def sky_colour_model(sky: torch.Tensor, image: torch.Tensor, order: int = 2,
                     clamp: bool = True) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
    """The smooth model of a sky's colour that :func:`grow_sky_by_colour` fits: per channel, log RGB as a
    polynomial of degree ``order`` in the pixel position, least squares over the mask's pixels at least
    ``GROW_ERODE`` px inside it, refitted once without the 3-sigma outliers.

    Args:
        sky: ``(1, 1, H, W)`` bool. image: ``(1, 3, H, W)`` linear. order: 1 or 2.
        clamp: evaluate the model only inside the fitted pixels' bounding box (no extrapolation).

    Returns:
        ``(x, pred, sigma)``: the photo's log RGB ``(3, H, W)`` and the model's prediction ``(3, H, W)`` (float64),
        and its spread per channel ``(3,)`` (the residuals' MAD scaled to a standard deviation, at least
        ``sqrt(VARIANCE_FLOOR)``); None when fewer than 64 pixels lie inside the mask, it covers everything, or
        fewer than 16 survive the outlier test.
    """
    h, w = sky.shape[-2:]
    x = torch.log(image.clamp_min(1e-4)).to(torch.float64)[0]  # (3, H, W)
    sure = ~_dilate(~sky, GROW_ERODE)[0, 0]
    if int(sure.sum()) < 64 or bool(sure.all()):
        return None
    idx = torch.nonzero(sure.flatten()).squeeze(1)
    basis = _sky_basis(h, w, torch.float64, order)
    if clamp:
        uv = basis[1:3].reshape(2, -1)[:, idx]
        box = (float(uv[0].min()), float(uv[0].max()), float(uv[1].min()), float(uv[1].max()))
        basis = _sky_basis(h, w, torch.float64, order, box)
    if idx.numel() > _GROW_MAX_FIT:  # an even, deterministic subsample keeps the fit cheap
        idx = idx[torch.linspace(0, idx.numel() - 1, _GROW_MAX_FIT).round().long()]
    a = basis.reshape(basis.shape[0], -1)[:, idx].T  # (N, K)
    y = x.reshape(3, -1)[:, idx].T  # (N, 3)
    keep = torch.ones(a.shape[0], dtype=torch.bool)
    for _ in range(2):
        coef = torch.linalg.lstsq(a[keep], y[keep]).solution  # (K, 3)
        res = y - a @ coef
        med = res[keep].median(0).values
        sigma = (1.4826 * (res[keep] - med).abs().median(0).values).clamp_min(math.sqrt(VARIANCE_FLOOR))
        keep = ((res - med).abs() <= 3 * sigma).all(1)
        if int(keep.sum()) < 16:
            return None
    return x, torch.einsum("khw,kc->chw", basis, coef) + med[:, None, None], sigma


def grow_sky_by_colour(sky: torch.Tensor, image: torch.Tensor, reach: int, chi2: float = GROW_CHI2,
                       order: int = 2, clamp: bool = True, max_spread: float | None = None) -> torch.Tensor:
    """Add the pixels that have the sky's colour where the sky would be, near the mask.

    A working-resolution segmenter sees a lattice tower or a tree's crown as solid; the sky
    between its bars or leaves is too far inside for :func:`refine_sky_boundary`'s band. A clear
    or overcast sky's log RGB varies smoothly across a photo, so it is modelled per channel as a
    polynomial in the pixel position, fitted by least squares to the mask's pixels away from its
    boundary (twice, the second time without the fit's 3-sigma outliers; the spread per channel is
    the residuals' MAD scaled to a standard deviation, at least ``sqrt(VARIANCE_FLOOR)``). A
    non-sky pixel within ``reach`` pixels of the mask becomes sky when its colour is within
    squared Mahalanobis distance ``chi2`` of the model's prediction at its position, and likelier
    under it than under the local Gaussian of the surrounding non-sky pixels (as in
    :func:`refine_sky_boundary`'s ``"gauss"``). A dark bar or a lit wall is far from the sky's
    colour; a blue wall is nearer its own surroundings. Nothing is removed. With ``clamp``, the model is
    not extrapolated: a pixel outside the fitted pixels' bounding box gets the prediction at the
    box's nearest point (a quadratic fitted to a sky at the top would otherwise dive toward a grey
    road below it).

    Args:
        sky: ``(1, 1, H, W)`` bool. image: ``(1, 3, H, W)`` linear. reach: pixels, >= 0.
        chi2: the squared Mahalanobis gate, > 0. order: the polynomial's degree, 1 or 2.
        clamp: evaluate the model only inside the fitted pixels' bounding box.
        max_spread: when the model's spread in log RGB exceeds this in any channel, the mask it was
            fitted to is not a clean sky (a façade or foliage taken for sky) and nothing is added;
            None: no such check.

    Returns:
        ``(1, 1, H, W)`` bool, a superset of ``sky``.
    """
    if sky.ndim != 4 or sky.shape[:2] != (1, 1):
        raise ValueError(f"sky must have shape (1, 1, H, W), got {tuple(sky.shape)}")
    if image.ndim != 4 or image.shape[:2] != (1, 3) or image.shape[-2:] != sky.shape[-2:]:
        raise ValueError(f"image must have shape (1, 3, {sky.shape[-2]}, {sky.shape[-1]}), got {tuple(image.shape)}")
    if isinstance(reach, bool) or not isinstance(reach, int) or reach < 0:
        raise ValueError(f"reach must be an integer >= 0, got {reach!r}")
    if not chi2 > 0:
        raise ValueError(f"chi2 must be > 0, got {chi2!r}")
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    if reach == 0:
        return sky
    h, w = sky.shape[-2:]
    cand = (_dilate(sky, reach) & ~sky)[0, 0]
    if not bool(cand.any()):
        return sky
    model = sky_colour_model(sky, image, order, clamp)
    if model is None:
        return sky
    x, pred, sigma = model
    if max_spread is not None and float(sigma.max()) > max_spread:
        return sky
    maha = (((x - pred) / sigma[:, None, None]) ** 2).sum(0)
    d_sky = maha + 2 * torch.log(sigma).sum()
    # only the candidates with the sky's colour need the local Gaussian of the non-sky pixels around them (a
    # candidate is itself non-sky, so it is always defined there)
    ask = torch.nonzero((cand & (maha < chi2)).flatten()).squeeze(1)
    grow = torch.zeros(h * w, dtype=torch.bool)
    if ask.numel():
        d_fg = _local_gaussian_nll_at(x[None], (~sky).to(torch.float64), max(4, 4 * reach), ask)
        grow[ask] = d_sky.flatten()[ask] < d_fg
    return sky | grow.reshape(1, 1, h, w)
