"""The figures of ``bench --real`` that its run and its report share: names, the scale-invariant
shading error, the level in stops, the sky baselines and the choice of target panoramas."""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from physrelight import colour

__all__ = ["BOUNDARY_TOLERANCE", "CAMERA_VARIANTS", "ESTIMATES", "PSNR_CAP", "SEGMENTERS", "SELF_METHODS",
           "SKY_SOURCES", "SPHERE_NORMALS", "TOP_ROWS_FRACTION", "brightness_sky", "camera_variant", "dc_luminance",
           "level_stops", "shading_error", "targets_for", "top_rows_sky"]

SEGMENTERS = ("segmenter", "segmenter_64px", "top_rows", "brightness")
ESTIMATES = ("proposed", "grey_world", "prior_mean", "truth_order2")
SKY_SOURCES = ("target", "fit", "skygan", "sh_radiance", "keep", "exact_view")
SELF_METHODS = ("quotient_known", "quotient", "proposed", "lambertian_sh", "shadownet_lambertian", "identity")
BOUNDARY_TOLERANCE = 2.0
SPHERE_NORMALS = 256
TOP_ROWS_FRACTION = 1.0 / 3.0
CAMERA_VARIANTS = ("-1 EV", "+1 EV", "warm cast", "cool cast", "JPEG 50", "noise 2 %")
"""The other camera settings (a)'s stability table gives the same crop: exposure one stop down / up, a white
balance cast (red x 1.1, blue x 0.9 and the reverse), JPEG at quality 50 (4:2:0) and Gaussian noise of 2 % of
white in the display values (docs/experiments/49-sky-mask-stability.md)."""
PSNR_CAP = 10.0 * math.log10(12.0 * 255.0**2)
"""58.9 dB: an 8-bit picture's own quantisation error (uniform, 1/255 wide); a PSNR above it means
"exact to 8 bits", and capping it keeps means finite when a sky is rendered exactly."""


def camera_variant(linear: Any, name: str, seed: int = 0) -> Any:
    """The linear photo ``(1, 3, H, W)`` as another camera setting would have stored it (8-bit sRGB in and out),
    one of :data:`CAMERA_VARIANTS`; ``seed`` draws the noise (the same seed, the same bytes)."""
    import io

    import torch
    from PIL import Image

    def quantise(display: torch.Tensor) -> np.ndarray:  # (3, H, W) display values -> (H, W, 3) uint8
        return (display.clamp(0, 1) * 255 + 0.5).to(torch.uint8).permute(1, 2, 0).numpy()

    def to8(x: torch.Tensor) -> np.ndarray:
        return quantise(colour.to_ldr(x[0].clamp_min(0.0)))

    def from8(a: np.ndarray) -> torch.Tensor:
        return colour.from_ldr(torch.from_numpy(a.astype(np.float32) / 255.0).permute(2, 0, 1)[None])

    gains = {"-1 EV": (0.5, 0.5, 0.5), "+1 EV": (2.0, 2.0, 2.0), "warm cast": (1.1, 1.0, 0.9),
             "cool cast": (0.9, 1.0, 1.1)}
    if name in gains:
        return from8(to8(linear * torch.tensor(gains[name], dtype=linear.dtype)[None, :, None, None]))
    if name == "JPEG 50":
        buf = io.BytesIO()
        Image.fromarray(to8(linear)).save(buf, format="JPEG", quality=50, subsampling="4:2:0")
        return from8(np.asarray(Image.open(io.BytesIO(buf.getvalue())).convert("RGB")))
    if name == "noise 2 %":
        g = torch.Generator().manual_seed(int(seed))
        noisy = colour.to_ldr(linear.clamp_min(0.0)) + 0.02 * torch.randn(linear.shape, generator=g)
        return from8(quantise(noisy[0]))
    raise ValueError(f"camera variant must be one of {CAMERA_VARIANTS}, got {name!r}")


def shading_error(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Scale-invariant relative error ``min_a ||a E_hat - E|| / ||E||`` of ``(N, 3)`` irradiances.

    One gain for all channels, so a wrong colour counts and a wrong level (the albedo-lighting
    ambiguity, the camera's exposure) does not. 1 for an estimate that is all zero.
    """
    e, t = np.asarray(estimate, np.float64).ravel(), np.asarray(truth, np.float64).ravel()
    den = float(e @ e)
    a = float(e @ t) / den if den > 0 else 0.0
    return float(np.linalg.norm(a * e - t) / max(np.linalg.norm(t), 1e-300))


def dc_luminance(coeffs: np.ndarray) -> float:
    """The luminance of an SH lighting's DC term, ``coeffs (9, 3)``: its level."""
    return float(np.asarray(coeffs)[0] @ np.asarray(colour.LUMINANCE))


def level_stops(estimate: np.ndarray, truth: np.ndarray) -> float:
    """``log2`` of the DC luminance of ``estimate`` over ``truth`` ``(9, 3)`` (clipped at +-10 stops)."""
    num, den = dc_luminance(estimate), dc_luminance(truth)
    if num <= 0:
        return -10.0
    return float(np.clip(math.log2(num / den), -10.0, 10.0))


def top_rows_sky(height: int, width: int, fraction: float = TOP_ROWS_FRACTION) -> np.ndarray:
    """Baseline sky: the top ``fraction`` of the rows (the horizon on the upper third line)."""
    out = np.zeros((height, width), dtype=bool)
    out[: int(round(fraction * height))] = True
    return out


def brightness_sky(display: np.ndarray) -> np.ndarray:
    """Baseline sky: pixels whose luminance (display values) is above Otsu's threshold."""
    y = np.asarray(display, np.float64) @ np.asarray(colour.LUMINANCE)
    hist, edges = np.histogram(y, bins=256, range=(0.0, 1.0))
    p = hist / max(hist.sum(), 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(p)
    m0 = np.cumsum(p * centres)
    between = (m0[-1] * w0 - m0) ** 2 / np.maximum(w0 * (1.0 - w0), 1e-12)
    return y > edges[int(np.argmax(between)) + 1]


def targets_for(pano: Any, panoramas: Sequence[Any], n: int, index: int) -> list[Any]:
    """``n`` outdoor target panoramas other than ``pano``, cycling with the crop's index."""
    others = [p for p in panoramas if p.name != pano.name and p.outdoor]
    if not others:
        return []
    return [others[(index + k) % len(others)] for k in range(min(n, len(others)))]
