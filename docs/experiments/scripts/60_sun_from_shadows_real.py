"""Study 60: the shadow and shading cues (physrelight.sun_from_shadows) and their combination with the sky and the
prior (physrelight.sun_estimate) on real photos: pinhole crops of the training side's panoramas whose sun
envmap.split_sun finds (city 47.9 deg, forest 19.5 deg up; pm_sky is a sky over a mirror-like ground, so it is left
out), cut looking down at the ground (pitch -25 to -5 deg) and level (pitch -8 to 8 deg, so that the sky speaks too),
60 deg wide, 8 yaws round the circle each, plus the shipped example photo (no known sun). Never the held-out sunrise (it scores bench --real).

Normals are the shipped decomposition's (``Relighter.decompose_linear`` at its working resolution, bilinearly
upsampled to the crop's); the sky mask is the panorama's reviewed one seen through the crop; the camera is known.

    .venv/bin/python docs/experiments/scripts/60_sun_from_shadows_real.py \\
        -o docs/experiments/results/60_sun_from_shadows_real.json --figure docs/images/60_sun_from_shadows_real.png
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
import torch


def _err(a: float | None, b: float) -> float | None:
    return None if a is None else round(abs((a - b + 180.0) % 360.0 - 180.0), 1)


def _normals(relighter, lin: torch.Tensor, sky: torch.Tensor) -> np.ndarray:
    from physrelight.full_resolution import working_resolution

    small, small_sky = working_resolution(lin, sky, relighter.res)
    with torch.no_grad():
        n = relighter.decompose_linear(small, small_sky)["normals"]
    up = torch.nn.functional.interpolate(n, size=lin.shape[-2:], mode="bilinear", align_corners=False)
    up = up / up.norm(dim=1, keepdim=True).clamp_min(1e-6)
    return up[0].double().numpy()


def _panel(display: np.ndarray, segments, text: list[str], scale: int = 2):
    from PIL import Image, ImageDraw

    im = Image.fromarray((np.clip(display, 0, 1) * 255).astype(np.uint8))
    im = im.resize((im.width * scale, im.height * scale), Image.NEAREST)
    d = ImageDraw.Draw(im)
    for s in segments:
        (x0, y0), (x1, y1) = (s.endpoints_px + 0.5) * scale
        d.line((x0, y0, x1, y1), fill=(255, 40, 40) if s.sun_azimuth_deg is not None else (40, 170, 255), width=2)
    canvas = Image.new("RGB", (im.width, im.height + 12 * len(text) + 4), "white")
    canvas.paste(im, (0, 0))
    d = ImageDraw.Draw(canvas)
    for k, line in enumerate(text):
        d.text((3, im.height + 2 + 12 * k), line, fill=(0, 0, 0))
    return canvas


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", required=True)
    parser.add_argument("--figure", default=None)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    from learned import Relighter
    from physrelight import colour, data, envmap, io
    from physrelight.horizon import estimate_pitch
    from physrelight.panorama import level_camera, view_intrinsics
    from physrelight.sun_estimate import estimate_sun
    from physrelight.sun_from_shadows import shading_likelihood, shadow_likelihood, shadow_segments
    from physrelight.sun_from_sky import estimate_sun_from_sky
    from synth.panorama_crops import load_panorama, make_crop

    relighter = Relighter.load()
    rng = np.random.default_rng(args.seed)
    rows, panels = [], []
    t0 = time.time()
    for name, (p_lo, p_hi) in (("city", (-25.0, -5.0)), ("forest", (-25.0, -5.0)), ("city", (-8.0, 8.0)),
                                ("forest", (-8.0, 8.0))):
        pano = load_panorama(data.hdri(name), "training")
        split = envmap.split_sun(pano.env)
        s = split.direction
        sun_el = math.degrees(math.asin(s[1]))
        sun_az = math.degrees(math.atan2(s[0], -s[2])) % 360.0
        start = float(rng.uniform(0, 360))
        for k in range(8):
            yaw, pitch = (start + 45.0 * k) % 360.0, float(rng.uniform(p_lo, p_hi))
            crop = make_crop(pano, k, yaw, pitch, 60.0, rng)
            disp = crop.display().astype(np.float64)
            lin = crop.linear()
            sky = torch.from_numpy(crop.sky)[None, None]
            normals = _normals(relighter, lin, sky)
            K, T = crop.K, crop.world_to_camera
            sky_post = estimate_sun_from_sky(disp, crop.sky, K, T)
            shadows = shadow_likelihood(disp, crop.sky, K, T, normals=normals)
            shading = shading_likelihood(disp, normals, crop.sky, K, T)
            both = estimate_sun(disp, crop.sky, normals, K, T)
            rel = (sun_az - yaw + 180.0) % 360.0 - 180.0
            m = np.exp(shading.log_likelihood[0])
            right = float(m[np.sin(np.radians(shading.azimuths_deg - yaw)) > 0].sum() / m.sum())
            row = {"crop": f"{name}/{'down' if p_hi < 0 else 'level'}/{k}", "yaw_deg": round(yaw, 1), "pitch_deg": round(pitch, 1),
                   "size": list(crop.size), "sky_share": round(float(crop.sky.mean()), 3),
                   "sun": {"elevation_deg": round(sun_el, 1), "world_azimuth_deg": round(sun_az, 1),
                           "relative_azimuth_deg": round(rel, 1)},
                   "sky": {"has_sun": sky_post.has_sun, "azimuth_error_deg": _err(sky_post.world_azimuth_deg, sun_az),
                           "kind": sky_post.sky_kind, "mass_within_20": round(float(sky_post.azimuth_marginal()[
                               np.array([_err(a, sun_az) <= 20 for a in sky_post.azimuths_deg])].sum()), 3)},
                   "shadows": {"spoke": shadows.spoke, "segments": shadows.observations, "anchored": shadows.anchored,
                               "azimuth_error_deg": _err(shadows.azimuth_deg, sun_az),
                               "axis_error_deg": None if shadows.azimuth_deg is None else round(min(
                                   _err(shadows.azimuth_deg, sun_az), _err(shadows.azimuth_deg + 180.0, sun_az)), 1)},
                   "shading": {"spoke": shading.spoke, "detail": shading.detail, "right_share": round(right, 3),
                               "sun_on_right": rel > 0},
                   "combined": {"has_sun": both.has_sun, "cues": list(both.cues),
                                "azimuth_error_deg": _err(both.world_azimuth_deg, sun_az),
                                "azimuth_std_deg": round(both.azimuth_std_deg, 1), "covers_90": both.covers(s),
                                "mass_within_20": round(float(both.azimuth_marginal()[np.array(
                                    [_err(a, sun_az) <= 20 for a in both.azimuths_deg])].sum()), 3)},
                   "fixed_guess_error_deg": _err(yaw + 180.0, sun_az)}
            rows.append(row)
            print(json.dumps(row))
            segs = shadow_segments(disp, crop.sky, K, T, normals=normals)
            panels.append(_panel(disp, segs, [
                f"{row['crop']} sun {rel:+.0f} rel, {sun_el:.0f} up",
                f"sky {row['sky']['azimuth_error_deg']} shadows {row['shadows']['azimuth_error_deg']}"
                f" ({shadows.anchored}/{shadows.observations}) all {row['combined']['azimuth_error_deg']}"]))
    # the shipped example photo: no known sun; camera as relight has it (60 deg, pitch from the sky's horizon)
    img = io.read_image(data.example_photo())
    disp = np.asarray(img, dtype=np.float64)
    lin = colour.from_ldr(torch.from_numpy(disp).permute(2, 0, 1)[None].float())
    sky_t, _ = relighter.photo_sky(lin)
    h, w = disp.shape[:2]
    K = view_intrinsics(60.0, w, h)
    pitch = estimate_pitch(sky_t[0, 0], K)
    T = level_camera(0.0, pitch)
    normals = _normals(relighter, lin, sky_t)
    skym = sky_t[0, 0].numpy()
    shadows = shadow_likelihood(disp, skym, K, T, normals=normals)
    shading = shading_likelihood(disp, normals, skym, K, T)
    both = estimate_sun(disp, skym, normals, K, T)
    rocket = {"crop": "rocket.jpg", "pitch_deg": round(pitch, 1), "size": [h, w],
              "shadows": {"spoke": shadows.spoke, "detail": shadows.detail, "azimuth_deg": shadows.azimuth_deg},
              "shading": {"spoke": shading.spoke, "detail": shading.detail},
              "combined": {"has_sun": both.has_sun, "cues": list(both.cues), "reason": both.reason,
                           "azimuth_deg": both.azimuth_deg, "elevation_deg": both.elevation_deg,
                           "sky_kind": both.sky_kind}}
    print(json.dumps(rocket))
    segs = shadow_segments(disp, skym, K, T, normals=normals)
    rocket_panel = _panel(disp[::2, ::2], [], [f"rocket: {shadows.detail}", f"{shading.detail[:90]}"], scale=1)

    def stats(key: str, sub: str = "azimuth_error_deg") -> dict:
        v = np.array([r[key][sub] for r in rows if r[key].get(sub) is not None], dtype=float)
        if not len(v):
            return {"n": 0}
        return {"n": int(len(v)), "median": round(float(np.median(v)), 1),
                "p90": round(float(np.percentile(v, 90)), 1), "within_20": int((v <= 20).sum())}

    def mass(key: str) -> float:
        return round(float(np.mean([r[key]["mass_within_20"] for r in rows])), 3)

    summary = {"sky": stats("sky"), "shadows": stats("shadows"), "shadows_axis": stats("shadows", "axis_error_deg"),
               "combined": stats("combined"), "sky_mass_within_20_mean": mass("sky"),
               "combined_mass_within_20_mean": mass("combined"),
               "combined_covers_90": int(sum(r["combined"]["covers_90"] for r in rows)),
               "fixed_guess": {"median": float(np.median([r["fixed_guess_error_deg"] for r in rows]))},
               "shading_side_right": int(sum((r["shading"]["right_share"] > 0.5) == r["shading"]["sun_on_right"]
                                             for r in rows if r["shading"]["spoke"])),
               "shading_spoke": int(sum(r["shading"]["spoke"] for r in rows))}
    out = {"study": 60, "command": "docs/experiments/scripts/60_sun_from_shadows_real.py", "seed": args.seed,
           "seconds": round(time.time() - t0, 1), "crops": rows, "rocket": rocket, "summary": summary}
    from physrelight.io import atomic_path

    with atomic_path(args.output, ".json") as tmp:
        tmp.write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(summary))
    if args.figure:
        from PIL import Image

        cols = 4
        pw = max(p.width for p in panels)
        ph = max(p.height for p in panels)
        n_rows = math.ceil(len(panels) / cols)
        sheet = Image.new("RGB", (cols * pw, n_rows * ph + rocket_panel.height), "white")
        for i, p in enumerate(panels):
            sheet.paste(p, ((i % cols) * pw, (i // cols) * ph))
        sheet.paste(rocket_panel, (0, n_rows * ph))
        with atomic_path(args.figure, ".png") as tmp:
            sheet.quantize(colors=128, method=Image.Quantize.MEDIANCUT).save(tmp, optimize=True)


if __name__ == "__main__":
    main()
