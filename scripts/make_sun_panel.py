"""Issue 44's picture: three real crops, each with the sun read from its sky drawn beside the true sun.

    python scripts/make_sun_panel.py [-o docs/images/sun_from_sky_panel.png] [--width PX]

The crops are ``bench --real --full``'s (:func:`synth.panorama_crops.make_crops`: 16 per panorama, seed 0, field of
view 45-75 deg, pitch -5..20 deg), chosen by a rule fixed before any was looked at: the held-out ``sunrise`` and the
first two training-side panoramas, in ``bench --real``'s order, whose sun :func:`physrelight.envmap.split_sun` finds
above the horizon (``city``, ``forest``); of each, the first crop (lowest index) in the ``"sky"`` stratum. Sunrise is
shown, never used to choose anything.

Each crop is read as ``physrelight lighting PHOTO --fov F --pitch P`` reads it with the crop's own camera
(:func:`learned.lighting_cli.estimate_lighting`: the 8-bit photo, the shipped segmenter's sky, the crop's field of
view and pitch given), so the picture shows the sky's reading alone. ``bench --real`` scores the same reading with the
pitch estimated from the sky's horizon, as ``relight`` has it; ``--horizon-pitch`` draws that instead (then the frame
is the horizon's, and the truth is brought into it through the true camera, as the bench does). Columns: the photo | the estimate's env-map preview
(:func:`physrelight.sun_from_sky.lighting_preview`: the MAP sky, its sun as a red ring, the 90 % region in cyan, the
camera's frame in yellow; on a fallback, the decomposition's order-2 lighting and, as an orange ring, its dominant
direction: the sun ``bench --real``'s ``sky_reader`` scores) | the true panorama in the same frame and tone map
(99th-percentile luminance above the horizon to 0.8, sRGB), its sun (``split_sun``) a green cross, drawn on both
previews. Both previews are in the frame the estimate uses: straight ahead of the camera in the middle, level.

``--width`` makes each crop that many pixels wide (at most native; the same cameras): for the test, not the picture.
The PNG is written atomically; the same arguments give the same bytes. Prints each row's figures and the machine.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "images" / "sun_from_sky_panel.png"
CROPS_PER_PANORAMA = 16  # bench --real --full
SEED = 0
DPI = 80
TRAINING_PANORAMAS = 2
TRUE_SUN = (40, 230, 60)
FALLBACK_SUN = (255, 150, 0)


def _preview_pixel(d: np.ndarray, height: int, width: int) -> tuple[float, float]:
    """Column and row of a unit world direction ``d (3,)`` in ``lighting_preview``'s layout (straight ahead, world
    -Z, in the middle; DESIGN.md's rows)."""
    u = (math.atan2(d[0], -d[2]) / (2 * math.pi) + 0.5) % 1.0
    v = math.acos(float(np.clip(d[1], -1.0, 1.0))) / math.pi
    return u * width - 0.5, v * (height - 1)


def _mark(img: np.ndarray, d: np.ndarray, colour: tuple[int, int, int], shape: str) -> np.ndarray:
    """``img (h, w, 3)`` uint8 with a ring or a cross drawn at world direction ``d (3,)`` (wrapped at the seam)."""
    from PIL import Image, ImageDraw

    canvas = Image.fromarray(img)
    draw = ImageDraw.Draw(canvas)
    h, w = img.shape[:2]
    x, y = _preview_pixel(d, h, w)
    for dx in (-w, 0, w):
        cx = x + dx
        if shape == "ring":
            draw.ellipse((cx - 4, y - 4, cx + 4, y + 4), outline=colour, width=2)
        else:  # a cross with a dark outline, readable on sky and on ground
            for c, wd in (((0, 0, 0), 4), (colour, 2)):
                draw.line((cx - 6, y, cx + 6, y), fill=c, width=wd)
                draw.line((cx, y - 6, cx, y + 6), fill=c, width=wd)
    return np.asarray(canvas)


def true_preview(env: np.ndarray, pano_to_frame: np.ndarray, height: int, width: int) -> np.ndarray:
    """``(height, width, 3)`` uint8: the panorama ``env (H, 2H, 3)`` turned by ``pano_to_frame (3, 3)`` into the
    preview's frame and layout, tone-mapped as ``lighting_preview`` does (99th-percentile luminance above the
    horizon to 0.8, the sRGB curve)."""
    from physrelight import envmap
    from physrelight.colour import LUMINANCE, linear_to_srgb

    small = np.asarray(envmap.downsample(env.astype(np.float64), height))  # filtered before the bilinear turn
    turned = np.asarray(envmap.rotate(small, pano_to_frame), dtype=np.float64)
    if turned.shape[:2] != (height, width):
        raise ValueError(f"the preview is {height} x {width}, the turned map {turned.shape[:2]}")
    turned = np.roll(turned, width // 2, axis=1)  # straight ahead in the middle, as lighting_preview
    d = np.roll(envmap.directions(height, width), width // 2, axis=1)
    lum = turned @ np.asarray(LUMINANCE)
    white = float(np.percentile(lum[d[..., 1] > 0], 99.0))
    img = np.asarray(linear_to_srgb(np.clip(turned * (0.8 / white if white > 0 else 1.0), 0.0, 1.0)))
    return np.round(img * 255).astype(np.uint8)


def choose_crops(width: int | None = None) -> list[Any]:
    """The three crops by the rule (module docstring): sunrise's, then the two training panoramas'."""
    from synth.panorama_crops import make_crop, make_crops, shipped_panoramas
    from validation.bench.real import _panorama_sun, more_panoramas

    shipped = shipped_panoramas()
    # bench --real's order: the shipped training maps, the more ones, (rooms), the held-out
    training = [p for p in shipped if p.group == "training"] + [p for p in more_panoramas() if p.group == "training"]
    sunny = [p for p in training if _panorama_sun(p) is not None][:TRAINING_PANORAMAS]
    heldout = [p for p in shipped if p.group == "heldout" and _panorama_sun(p) is not None]
    out = []
    for pano in heldout[:1] + sunny:
        crop = next(c for c in make_crops(pano, CROPS_PER_PANORAMA, SEED) if c.stratum == "sky")
        if width is not None:  # the same camera, smaller (the test's size)
            crop = make_crop(pano, crop.index, crop.yaw_deg, crop.pitch_deg, crop.fov_deg,
                             np.random.default_rng(SEED + crop.index), width=width)
        out.append(crop)
    return out


def panel_row(relighter: Any, crop: Any, horizon_pitch: bool = False) -> dict[str, Any]:
    """One crop read as ``physrelight lighting`` reads it (the crop's pitch given, or with ``horizon_pitch`` the
    horizon's): its photo, both previews and the figures."""
    from learned.lighting_cli import estimate_lighting
    from physrelight import envmap
    from physrelight.panorama import level_camera
    from validation.bench.real import _panorama_sun
    from validation.bench.real_metrics import dominant_direction, sun_angles, sun_errors

    record, preview = estimate_lighting(relighter, crop.display(), fov_deg=crop.fov_deg, fov_source="given",
                                          pitch_deg=None if horizon_pitch else crop.pitch_deg)
    R_est = level_camera(0.0, record["camera"]["pitch_deg"])[:3, :3]  # the estimate's frame: heading world -Z
    to_frame = R_est.T @ crop.rotation  # the panorama's world -> the estimate's frame, through the true camera
    true_sun = to_frame @ _panorama_sun(crop.panorama)
    if record["sun"] is not None:
        est = envmap.direction_from_angles(record["sun"]["elevation_deg"], record["sun"]["azimuth_deg"])
    else:  # bench --real's sky_reader on a fallback: the decomposition's dominant direction
        est = R_est.T @ dominant_direction(np.asarray(record["sh_camera"]))
        preview = _mark(preview, est, FALLBACK_SUN, "ring")
    h, w = preview.shape[:2]
    truth = _mark(true_preview(crop.panorama.env, to_frame, h, w), est,
                  (255, 40, 40) if record["sun"] is not None else FALLBACK_SUN, "ring")
    truth = _mark(truth, true_sun, TRUE_SUN, "cross")
    preview = _mark(preview, true_sun, TRUE_SUN, "cross")
    e_el, e_az = sun_angles(est)
    t_el, t_az = sun_angles(true_sun)
    return {"name": crop.name, "group": crop.panorama.group, "photo": crop.display(), "preview": preview,
            "truth": truth, "source": record["source"], "reason": record["reason"], "sky_kind": record["sky_kind"],
            "area_sr": record["sun_spread"]["credible_area_sr"],
            "pitch": (record["camera"]["pitch_deg"], crop.pitch_deg), "fov": crop.fov_deg,
            "horizon_pitch": horizon_pitch,
            "estimate": (e_el, e_az), "truth_angles": (t_el, t_az), **sun_errors(est, true_sun)}


def _short(reason: str) -> str:
    """The fallback's reason cut to what fits under a preview."""
    if "not where" in reason:
        return "a sun, but not where (90% region > pi sr)"
    if "blown out" in reason:
        return "the sky is blown out"
    return reason if len(reason) <= 45 else reason[:44] + "..."


def save_panel(rows: list[dict[str, Any]], out: str | os.PathLike) -> None:
    """Write the rows as one PNG, atomically (matplotlib, Agg, re-encoded by Pillow without metadata: the same rows,
    the same bytes)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    from physrelight import io

    cols = ("the photo (8-bit)", "read from its sky (physrelight lighting)", "the panorama (truth)")
    fig, axes = plt.subplots(len(rows), 3, squeeze=False, figsize=(9.0, 2.3 * len(rows) + 0.6),
                             gridspec_kw={"width_ratios": [1.5, 2.0, 2.0]})
    for i, r in enumerate(rows):
        if r["source"] == "sky":
            said = (f"sky read: sun {r['estimate'][0]:.0f} deg up, azimuth {r['estimate'][1]:+.0f}\n"
                    f"{r['sky_kind']}, 90% region {r['area_sr']:.2f} sr")
        else:
            said = (f"fallback: {_short(r['reason'])}\n"
                    f"dominant direction {r['estimate'][0]:.0f} deg up, azimuth {r['estimate'][1]:+.0f}")
        pitch = (f"pitch {r['pitch'][1]:.1f} (horizon's {r['pitch'][0]:.1f})" if r["horizon_pitch"]
                 else f"pitch {r['pitch'][1]:.1f} (both given)")
        texts = (f"fov {r['fov']:.0f} deg, {pitch}",
                 said,
                 f"true sun {r['truth_angles'][0]:.0f} deg up, azimuth {r['truth_angles'][1]:+.0f}\n"
                 f"estimate off by {r['angle_deg']:.0f} deg (azimuth {r['azimuth_error_deg']:.0f})")
        for j, (img, text) in enumerate(zip((r["photo"], r["preview"], r["truth"]), texts)):
            ax = axes[i, j]
            ax.imshow(img if img.dtype == np.uint8 else np.clip(img, 0, 1), interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_xlabel(text, fontsize=7)
            if i == 0:
                ax.set_title(cols[j], fontsize=9)
        axes[i, 0].set_ylabel(f"{r['name']}\n({'held out' if r['group'] == 'heldout' else r['group']})", fontsize=9)
    fig.suptitle("red ring: the sun read from the sky (orange: a fallback's, the decomposition's dominant direction); "
                 "green cross: the true sun\ncyan: the 90% credible region; yellow: the camera's frame; "
                 "straight ahead in the middle, azimuth growing to the right", fontsize=8, y=0.995)
    fig.tight_layout(rect=(0, 0, 1, 0.965))
    buf = BytesIO()
    fig.savefig(buf, dpi=DPI, format="png", metadata={"Software": None})
    plt.close(fig)
    buf.seek(0)
    # RGB (no alpha) at zlib's best: the photos' noise makes the PNG large, and the picture must stay < 300 KB
    with Image.open(buf) as im, io.atomic_path(out, ".png") as tmp:
        im.convert("RGB").save(tmp, format="PNG", optimize=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", default=str(OUT), help="the PNG to write (default: %(default)s)")
    ap.add_argument("--width", type=int, default=None, help="each crop this many pixels wide (default: native)")
    ap.add_argument("--horizon-pitch", action="store_true",
                    help="read with the pitch estimated from the sky's horizon (bench --real's way), not the crop's")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default: 1)")
    args = ap.parse_args(argv)
    if Path(args.output).suffix.lower() != ".png":
        print(f"make_sun_panel: error: the output must be a .png file, got {args.output!r}", file=sys.stderr)
        return 2
    if Path(args.output).is_dir():
        print(f"make_sun_panel: error: the output {args.output!r} is a folder", file=sys.stderr)
        return 2
    if args.width is not None and args.width < 16:
        print(f"make_sun_panel: error: --width must be at least 16 pixels, got {args.width}", file=sys.stderr)
        return 2
    if args.threads < 1:
        print(f"make_sun_panel: error: --threads must be at least 1, got {args.threads}", file=sys.stderr)
        return 2
    import torch

    from learned import Relighter

    torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    try:
        crops = choose_crops(args.width)
    except ValueError as err:  # e.g. --width wider than a crop's native size
        print(f"make_sun_panel: error: {err}", file=sys.stderr)
        return 2
    relighter = Relighter.load()
    rows = [panel_row(relighter, c, args.horizon_pitch) for c in crops]
    save_panel(rows, args.output)
    for r in rows:
        print(f"{r['name']:10s} {r['group']:8s} {r['source']:8s} est {r['estimate'][0]:5.1f} up {r['estimate'][1]:+7.1f} "
              f"az | true {r['truth_angles'][0]:5.1f} up {r['truth_angles'][1]:+7.1f} az | angle {r['angle_deg']:5.1f} "
              f"az {r['azimuth_error_deg']:5.1f} el {r['elevation_error_deg']:4.1f} | pitch {r['pitch'][0]:.1f} "
              f"(true {r['pitch'][1]:.1f}) | {r['sky_kind']} {r['reason']}")
    print(f"wrote {args.output} in {time.perf_counter() - t0:.1f} s "
          f"({platform.processor() or platform.machine()}, {os.cpu_count()} cores, {args.threads} torch thread(s))")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
