"""Turn path-traced HDR radiance into an internet-photo-like LDR image.

A tourist photo is not radiance: the camera meters the scene, picks an exposure, applies
a white balance and a tone curve, and often JPEG-compresses. The learned pipeline trains
on such photos (it must linearise them itself), so the synthetic photos carry the same
nuisances, drawn from a seeded generator and recorded so they can be undone in checks.
"""

from __future__ import annotations

import io as _io
import math
from dataclasses import asdict, dataclass

import numpy as np

from physrelight import colour

CURVES = ("srgb", "gamma2.2", "filmic")


@dataclass(frozen=True)
class PhotoParams:
    """The nuisances of one photo.

    Attributes:
        ev: exposure in stops applied to radiance (``radiance * 2**ev``).
        wb_gains: ``(3,)`` per-channel white-balance gains, green = 1.
        curve: camera response (:data:`physrelight.colour.RESPONSE_CURVES`).
        noise_sigma: std of additive Gaussian sensor noise in linear exposed units.
        jpeg_quality: JPEG quality of the round trip, or None for none.
    """

    ev: float
    wb_gains: tuple[float, float, float]
    curve: str
    noise_sigma: float
    jpeg_quality: int | None

    def to_json(self) -> dict:
        d = asdict(self)
        d["wb_gains"] = list(self.wb_gains)
        return d


def metered_ev(radiance: np.ndarray, key: float = 0.18) -> float:
    """Exposure that maps the image's log-average luminance to ``key`` (Reinhard's key).

    A camera meters the whole frame, sky included; the log average keeps the sun's
    specular glints from dominating.
    """
    y = radiance @ np.asarray(colour.LUMINANCE)
    log_avg = math.exp(float(np.mean(np.log(np.maximum(y, 1e-6)))))
    return math.log2(key / max(log_avg, 1e-12))


def sample_photo_params(rng: np.random.Generator, radiance: np.ndarray, jpeg_probability: float = 0.5) -> PhotoParams:
    """Draw photo nuisances: metered exposure +- 0.7 EV, white balance +- 6 %, a curve, noise, JPEG."""
    ev = metered_ev(radiance) + float(rng.uniform(-0.7, 0.7))
    gains = np.exp(rng.normal(0.0, 0.06, size=3))
    gains /= gains[1]
    curve = str(rng.choice(CURVES))
    noise = float(rng.uniform(0.0, 0.01))
    quality = int(rng.integers(60, 96)) if rng.random() < jpeg_probability else None
    return PhotoParams(ev=ev, wb_gains=tuple(float(g) for g in gains), curve=curve,
                       noise_sigma=noise, jpeg_quality=quality)


def photo_gain(params: PhotoParams | dict) -> np.ndarray:
    """``(3,)`` ``2**ev * wb_gains``: radiance (and radiance SH) -> the photo's linear units.

    ``params`` is a :class:`PhotoParams` or its JSON record (``photo_params`` in a dataset).
    """
    if isinstance(params, PhotoParams):
        ev, gains = params.ev, params.wb_gains
    else:
        ev, gains = params["ev"], params["wb_gains"]
    return (2.0 ** float(ev)) * np.asarray(gains, dtype=np.float64)


def make_photo(radiance: np.ndarray, params: PhotoParams, rng: np.random.Generator) -> np.ndarray:
    """Render the LDR photo ``uint8 (H, W, 3)`` from linear radiance ``(H, W, 3)``."""
    if radiance.ndim != 3 or radiance.shape[-1] != 3:
        raise ValueError(f"radiance must have shape (H, W, 3), got {radiance.shape}")
    if not np.all(np.isfinite(radiance)):
        raise ValueError("radiance holds NaN or inf")
    # Exposure then white balance, in this order: the same bytes as every dataset written so far.
    exposed = np.clip(radiance, 0, None) * (2.0**params.ev) * np.asarray(params.wb_gains)
    if params.noise_sigma > 0:
        exposed = np.clip(exposed + rng.normal(0.0, params.noise_sigma, size=exposed.shape), 0, None)
    ldr = colour.to_ldr(exposed, 0.0, params.curve)
    u8 = np.clip(np.round(ldr * 255.0), 0, 255).astype(np.uint8)
    if params.jpeg_quality is not None:
        from PIL import Image

        buf = _io.BytesIO()
        Image.fromarray(u8).save(buf, format="JPEG", quality=params.jpeg_quality)
        buf.seek(0)
        with Image.open(buf) as im:
            u8 = np.asarray(im.convert("RGB")).copy()
    return u8
