"""The figures of ``bench --real`` that its run and its report share: names, the scale-invariant
shading error, the level in stops, the sky baselines and the choice of target panoramas."""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from physrelight import colour

__all__ = ["BOUNDARY_TOLERANCE", "CAMERA_VARIANTS", "ESTIMATES", "GROUND_ALBEDOS", "PSNR_CAP", "SEGMENTERS",
           "SELF_METHODS", "SKY_SOURCES", "SPHERE_NORMALS", "SUN_ESTIMATES", "TOP_ROWS_FRACTION", "brightness_sky",
           "camera_variant", "dc_luminance", "dominant_direction", "level_stops", "shading_error", "sun_angles",
           "sun_error_summary", "sun_errors", "targets_for", "top_rows_sky"]

SEGMENTERS = ("segmenter", "segmenter_64px", "top_rows", "brightness")
ESTIMATES = ("proposed", "sky_reader", "grey_world", "prior_mean", "truth_order2")
"""(b)'s lighting estimates: the decomposition's (``proposed``), the sky's reading where it is informative and the
decomposition's elsewhere (``sky_reader``: what ``RelightOptions(source_estimate="sky")`` divides by), the
decomposition's at a light meter's level, the prior's mean, the truth's order-2 truncation."""
SKY_SOURCES = ("target", "fit", "skygan", "sh_radiance", "keep", "exact_view")
SELF_METHODS = ("quotient_known", "quotient", "quotient_sky", "proposed", "proposed_sky", "lambertian_sh",
                "shadownet_lambertian", "identity")
"""(d)'s methods; ``*_sky``: the method on the estimated track with the photo's lighting read from its sky where it
says something (``RelightOptions(source_estimate="sky")``)."""
SUN_ESTIMATES = ("sky_reader", "sky_only", "proposed", "prior_mean")
"""The sun's position from: the sky's posterior's MAP where it is informative, else the decomposition's
(``sky_reader``, what the relighter uses); the sky's MAP on the crops where it is informative only (``sky_only``);
the dominant direction of the decomposition's order-2 lighting (``proposed``, today's estimate); the dominant
direction of the lighting prior's mean (``prior_mean``: a fixed guess in the camera's frame, 2.3 deg from its up axis)."""
GROUND_ALBEDOS = (0.0, 0.1, 0.2, 0.3)
"""The ground reflectances tried below the sky's reading (``learned.sky_lighting.sky_sun_sh``) on the crops it reads."""
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


def dominant_direction(coeffs: np.ndarray) -> np.ndarray:
    """``(3,)`` unit direction of an order-2 lighting's band 1 in luminance (``coeffs (9, 3)``, DESIGN.md order
    ``[Y00, y, z, x, ...]``): where its light comes from most. A zero band gives +Y."""
    c = np.asarray(coeffs, np.float64) @ np.asarray(colour.LUMINANCE)
    d = np.array([c[3], c[1], c[2]])
    n = float(np.linalg.norm(d))
    return d / n if n > 0 else np.array([0.0, 1.0, 0.0])


def sun_angles(direction: np.ndarray) -> tuple[float, float]:
    """``(elevation_deg, azimuth_deg)`` of a world direction ``(3,)`` (Y up; azimuth as
    :func:`physrelight.envmap.direction_from_angles`: 0 = -Z, 90 = +X)."""
    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    return math.degrees(math.asin(float(np.clip(d[1], -1.0, 1.0)))), math.degrees(math.atan2(d[0], -d[2]))


def sun_errors(estimate: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """The errors of an estimated sun direction against the true one (world ``(3,)`` each): ``azimuth_error_deg``
    (absolute, the shorter way round, 0-180), ``elevation_error_deg`` (absolute), ``angle_deg`` (between the two)."""
    e_el, e_az = sun_angles(estimate)
    t_el, t_az = sun_angles(truth)
    a, b = np.asarray(estimate, np.float64), np.asarray(truth, np.float64)
    cos = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))
    return {"azimuth_error_deg": abs((e_az - t_az + 180.0) % 360.0 - 180.0),
            "elevation_error_deg": abs(e_el - t_el), "angle_deg": math.degrees(math.acos(float(np.clip(cos, -1, 1))))}


def sun_error_summary(errors: Sequence[dict[str, float]]) -> dict[str, Any] | None:
    """Median and 90th percentile (linear interpolation, ``numpy.percentile``) of each of :func:`sun_errors`'
    figures over crops, with their count; None without crops."""
    if not errors:
        return None
    out: dict[str, Any] = {"crops": len(errors)}
    for k in ("azimuth_error_deg", "elevation_error_deg", "angle_deg"):
        v = np.array([e[k] for e in errors], np.float64)
        out[k] = {"median": float(np.median(v)), "p90": float(np.percentile(v, 90))}
    return out


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
