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

What follows the network on a real photo (:func:`sky_mask_full_resolution`: the plausibility test, the boundary
decided by colour, the growth by colour) is image processing and lives in :mod:`physrelight.sky_mask`; this module
chains it after the network.
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from physrelight import colour, sky_mask
from physrelight.filters import gaussian_blur
from physrelight.parallel import single_threaded

from . import checkpoint as ckpt
from .data import resize_short_side
from .networks import UNet

__all__ = ["BAND_WORKING_PIXELS", "CLOUD_SKY", "DUSK_SKY", "SEGMENT_RES", "WIDE_AUGMENT", "SkySegmenter", "cloud_sky",
           "dusk_sky", "jpeg_like", "load_sky_segmenter", "photometric_augment", "segment_sky",
           "sky_mask_full_resolution", "sky_probability"]

_LUMA = colour.LUMINANCE


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
        sky_mask.check_rgb_batch(image)
        x = torch.log(image.clamp_min(0) + 1e-3)
        lum = torch.log((image.clamp_min(0) * image.new_tensor(_LUMA).reshape(1, 3, 1, 1)).sum(1, keepdim=True) + 1e-3)
        # Exposure invariance: subtract the image's mean log luminance.
        return self.unet(x - lum.mean(dim=(2, 3), keepdim=True))


def sky_probability(model: SkySegmenter, image: torch.Tensor) -> torch.Tensor:
    """``(B, 3, H, W)`` linear, any size -> sky probability ``(B, 1, H, W)``, computed at the model's resolution."""
    sky_mask.check_rgb_batch(image)
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
    sky_mask.check_rgb_batch(image)
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
            y = gaussian_blur(y, float(u(0.3, 1.0)), radius=2)  # 5 taps at every sigma, as trained
        if wide and float(u(0, 1)) < WIDE_AUGMENT["jpeg"]:
            y = jpeg_like(y, float(u(0.01, 0.04)))
        y = torch.round(y.clamp(0.0, 1.0) * 255.0) / 255.0
        out.append(colour.from_ldr(y[0]).to(image.dtype))
    return torch.stack(out)


def _check_image_and_sky(image: torch.Tensor, sky: torch.Tensor) -> None:
    """``image (B, 3, H, W)`` and its sky ``(B, 1, H, W)`` bool, or a ValueError naming the bad one."""
    sky_mask.check_rgb_batch(image)
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
BAND_WORKING_PIXELS = 6
"""How far (in working pixels) from the upsampled boundary pixels are decided by colour
(:func:`physrelight.sky_mask.refine_sky_boundary`); 0: not at all. Chosen on the training side for the shipped
segmenter (synthetic renders only). Study 22 found 0 better for its real-view segmenter, which was not kept
(worse on data/val5 and on rocket.jpg, docs/experiments/22-sky-mask-real-views.md)."""


def sky_mask_full_resolution(model: SkySegmenter, image: torch.Tensor,
                             res: int | tuple[int, ...] | None = SEGMENT_RES,
                             eps: float = 1e-2, threshold: float = 0.5,
                             band: int = BAND_WORKING_PIXELS,
                             refine: str = sky_mask.REFINEMENT,
                             grow: float | None = None) -> tuple[torch.Tensor, list[str]]:
    """The sky of real photos at full resolution, and a reason per photo when there is none.

    The segmenter runs with its short side at ``res`` (:data:`SEGMENT_RES`; several sizes: the mean of
    its probabilities at each, brought bilinearly to the largest); its mask keeps only a
    plausible sky (:func:`physrelight.sky_mask.plausible_sky`, at that resolution); the kept sky's probability is
    brought to full size by the guided filter on the photo's log luminance
    (:func:`physrelight.guided_filter.guided_upsample`), so the boundary follows the photo's
    edges, and thresholded at ``threshold``; pixels within ``band`` working pixels of the boundary
    are then decided by colour (:func:`physrelight.sky_mask.refine_sky_boundary`, :data:`BAND_WORKING_PIXELS`); with
    ``grow``, sky-coloured pixels near the mask are added last (:func:`physrelight.sky_mask.grow_sky_by_colour`).

    Args:
        image: ``(B, 3, H, W)`` linear photos.
        res: the working short side, or a tuple of them (a multi-scale mean; the largest is the
            working size); None: the photo's own (no resizing).
        eps: the guided filter's regulariser (log-luminance units squared).
        threshold: the sky probability above which a working pixel is sky, in (0, 1).
        band: working pixels near the boundary decided by colour (:func:`physrelight.sky_mask.refine_sky_boundary`);
            0: none.
        grow: how far from the mask, as a fraction of the short side, sky-coloured pixels are
            added (:func:`physrelight.sky_mask.grow_sky_by_colour`, gated at
            :data:`physrelight.sky_mask.GROW_MAX_SPREAD`); None: :data:`physrelight.sky_mask.GROW_REACH` (0: none).

    Returns:
        ``(sky (B, 1, H, W) bool, reasons)``: ``reasons[b]`` is ``""`` when photo ``b`` has a
        plausible sky, else one line saying why not (its mask is then empty).
    """
    from physrelight.guided_filter import guided_upsample

    sky_mask.check_rgb_batch(image)
    sizes = (res,) if res is None or not isinstance(res, tuple) else res
    if not sizes or any(r is not None and (isinstance(r, bool) or not isinstance(r, int) or r < 8) for r in sizes) \
            or (len(sizes) > 1 and None in sizes):
        raise ValueError(f"res must be an integer >= 8, a non-empty tuple of them, or None, got {res!r}")
    if not (isinstance(threshold, (int, float)) and 0.0 < float(threshold) < 1.0):
        raise ValueError(f"threshold must be a number in (0, 1), got {threshold!r}")
    if isinstance(band, bool) or not isinstance(band, int) or band < 0:
        raise ValueError(f"band must be an integer >= 0, got {band!r}")
    if refine not in sky_mask.REFINEMENTS:
        raise ValueError(f"refine must be one of {sky_mask.REFINEMENTS}, got {refine!r}")
    grow = sky_mask.GROW_REACH if grow is None else grow
    if isinstance(grow, bool) or not isinstance(grow, (int, float)) or not 0.0 <= float(grow) <= 1.0:
        raise ValueError(f"grow must be a number in [0, 1], got {grow!r}")
    reach = int(round(float(grow) * min(image.shape[-2:])))
    param = next(model.parameters())
    smalls = [image.to(param.dtype) if r is None else resize_short_side(image.to(param.dtype), r) for r in sizes]
    small = max(smalls, key=lambda x: x.shape[-2] * x.shape[-1])
    with torch.no_grad(), single_threaded():  # a working-size network: one thread (physrelight.parallel)
        # Several sizes: the coarse run sees the scene whole, the fine one keeps thin structures.
        prob = torch.stack([F.interpolate(torch.sigmoid(model(x)), size=small.shape[-2:], mode="bilinear",
                                          align_corners=False) if x.shape[-2:] != small.shape[-2:]
                            else torch.sigmoid(model(x)) for x in smalls]).mean(0)
    masks, reasons = [], []
    for b in range(image.shape[0]):
        lum = (image[b: b + 1] * image.new_tensor(_LUMA)[None, :, None, None]).sum(1, keepdim=True)  # full size
        noise_var = None
        if sky_mask.SMOOTHNESS_NOISE_AWARE and sky_mask.SMOOTHNESS_NOISE_AT_OWN_SIZE:
            # the noise is read off the photo as it came, and carried through the resizing to the working size
            sigma_d = sky_mask.display_noise_sigma(lum[0, 0])
            lum_small = (small[b] * small.new_tensor(_LUMA)[:, None, None]).sum(0)
            gain = sky_mask.resized_noise_roughness(tuple(image.shape[-2:]), tuple(small.shape[-2:]))
            noise_var = gain * sky_mask.log_noise_sigma(lum_small, sigma_d.to(lum_small.dtype)) ** 2
        kept, why = sky_mask.plausible_sky(prob[b, 0] > threshold, small[b], noise_var)
        reasons.append(why)
        p = (prob[b, 0] * kept)[None, None]  # the rejected parts' probability is 0
        if not bool(kept.any()):
            masks.append(torch.zeros(1, 1, *image.shape[-2:], dtype=torch.bool))
            continue
        guide = torch.log(lum.clamp_min(1e-3)).to(p.dtype)
        up = guided_upsample(guide, p.to(guide.dtype), eps=eps) > threshold
        if band > 0:
            width = max(1, band * round(image.shape[-2] / small.shape[-2]))
            up = sky_mask.refine_sky_boundary(up, image[b: b + 1], width, refine)
        masks.append(sky_mask.grow_sky_by_colour(up, image[b: b + 1], reach, max_spread=sky_mask.GROW_MAX_SPREAD))
    return torch.cat(masks), reasons
