"""``physrelight bench --real``: the pipeline on real photos whose lighting is known exactly.

The photos are pinhole crops of real HDR panoramas (:mod:`synth.panorama_crops`): the
panorama is the exact lighting of each crop, its reviewed sky mask gives the true sky, and
another panorama seen through the same camera is the exact relit sky. Per crop:

(a) **sky segmentation** at full resolution: IoU and boundary F (2 px) of the shipped
    segmenter and two baselines (the top third of the rows; pixels brighter than Otsu's
    threshold on the photo's luminance); on crops without sky, the fraction wrongly called sky;
    the shipped mask's stability when the crop comes with another exposure, white balance,
    compression or noise (:data:`real_metrics.CAMERA_VARIANTS`);
(b) **lighting from the photo**: the order-2 estimate's irradiance on the unit sphere
    against the panorama's exact (brute-force) irradiance, scale-invariant (the best single
    gain, :func:`shading_error`), and its level error in stops; baselines the prior's mean
    and, as the ceiling, the panorama's own order-2 truncation; plus cross-view consistency
    (two crops of one panorama, their estimates turned into the world frame);
(c) **the relit sky**: each crop relit to other panoramas (env-map targets); its sky pixels
    against the target seen through the same camera at the output's exposure, l1 and PSNR
    in sRGB over the true sky (every PSNR here capped at 8-bit quantisation, :data:`PSNR_CAP`);
    sky sources: SkyGAN (the pipeline's), the target's order-2
    SH radiance, the photo's own sky kept, and the exact target view (the ceiling with the
    segmenter's mask);
(d) **self-relighting**: the target is the crop's own panorama, so the output should be the
    input: foreground l1, SSIM, PSNR at full resolution, as they are and after each output's best
    single gain (``protocols.display_at_best_gain``: structure apart from level);
(e) **panels** for the eye (``OUT/panels/``).

Protocol. Methods get the photo, the segmenter's sky mask and the target, as the user's
``relight`` does, plus the source lighting's level, as the synthetic bench's protocol does
(``source_lighting``: the crop's camera-frame SH in the photo's linear units). Panoramas are
not calibrated to one another, so each target is scaled to the source's level (equal DC
luminance): the relit photo is what the same camera, metered the same way, would see under
the target; its exact sky is the target's view times that same scale.
"""

from __future__ import annotations

import datetime
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from physrelight.full_resolution import working_resolution
from physrelight.horizon import estimate_pitch
from physrelight.sky_view import fitted_sky, target_sky
from learned.sky_lighting import read_sky_lighting
from learned.source_lighting import grey_world_level
from physrelight import colour, envmap, metrics, panorama, sh

from .methods import to_chw
from .protocols import display_at_best_gain
from .real_metrics import (BOUNDARY_TOLERANCE, CAMERA_VARIANTS, ESTIMATES, GROUND_ALBEDOS, PSNR_CAP, SEGMENTERS,
                           SELF_METHODS, SKY_SOURCES, SPHERE_NORMALS, brightness_sky, camera_variant, dc_luminance,
                           dominant_direction, level_stops, shading_error, sun_angles, sun_errors, targets_for,
                           top_rows_sky)

__all__ = ["ESTIMATES", "PSNR_CAP", "REAL_LEVELS", "SEGMENTERS", "SELF_METHODS", "SKY_SOURCES", "RealLevel",
           "brightness_sky", "level_stops", "more_panoramas", "run_real_bench", "score_crop", "shading_error", "top_rows_sky"]

@dataclass(frozen=True)
class RealLevel:
    """The size of a ``bench --real`` run.

    Attributes:
        name: ``"quick"`` or ``"full"``.
        crops: crops per panorama. targets: target panoramas per crop for (c).
        samples: sub-pixel rays per axis of every view (4: within 0.1 % of 8).
        panels: crops per panorama with a panel (e).
        bootstrap: resamples of every interval.
    """

    name: str
    crops: int
    targets: int
    samples: int = 4
    panels: int = 1
    bootstrap: int = 2000

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


SKY_FOREGROUND = "quotient"
"""The foreground under the relit skies of (c): relight's default method."""
REAL_LEVELS = {"quick": RealLevel("quick", crops=4, targets=2, panels=1, bootstrap=1000),
               "full": RealLevel("full", crops=16, targets=3, panels=4)}


def _display(linear: torch.Tensor) -> torch.Tensor:
    return colour.to_ldr(linear.clamp_min(0.0))


def _camera_directions(K: np.ndarray, height: int, width: int) -> torch.Tensor:
    """``(h, w, 3)`` camera-frame unit directions of the pixel centres."""
    return panorama.camera_rays(K, np.eye(3), height, width, 1)[..., 0, :]


def sh_radiance_image(coeffs: np.ndarray, directions: torch.Tensor) -> torch.Tensor:
    """``(1, 3, h, w)`` radiance of order-2 SH ``coeffs (9, 3)`` along ``directions (h, w, 3)``, clamped at 0."""
    y = torch.as_tensor(sh.basis(directions.double(), 2))
    rad = (y @ torch.as_tensor(coeffs, dtype=torch.float64)).clamp_min(0.0)
    return rad.permute(2, 0, 1)[None].float()


# ----------------------------------------------------------------------------- one crop


def score_crop(relighter: Any, crop: Any, targets: Sequence[Any], truth_irradiance: np.ndarray,
               normals: np.ndarray, seed: int = 0) -> dict[str, Any]:
    """Every figure of one crop: (a) segmentation, (b) lighting, (c) relit sky, (d) self-relighting."""
    from .scores import score

    h, w = crop.size
    lin = crop.linear()
    true_sky = torch.from_numpy(crop.sky)[None, None]
    fg = ~true_sky
    out: dict[str, Any] = {"panorama": crop.panorama.name, "group": crop.panorama.group, "index": crop.index,
                           "stratum": crop.stratum, "sky_fraction": float(crop.sky.mean()), "size": [h, w],
                           "camera": {"yaw_deg": crop.yaw_deg, "pitch_deg": crop.pitch_deg, "fov_deg": crop.fov_deg}}
    seconds: dict[str, float] = {}

    # (a) sky segmentation: relight's full-resolution mask, and the 64-px mask it replaced
    t0 = time.perf_counter()
    seg, why = relighter.photo_sky(lin)
    seconds["segmenter"] = time.perf_counter() - t0
    masks = {"segmenter": seg[0, 0].numpy(), "segmenter_64px": relighter.sky_mask(lin)[0, 0].numpy(),
             "top_rows": top_rows_sky(h, w), "brightness": brightness_sky(crop.display())}
    out["segmentation"] = {name: {"iou": metrics.mask_iou(m, crop.sky),
                                  "boundary_f": metrics.boundary_f(m, crop.sky, BOUNDARY_TOLERANCE),
                                  "sky_called": float(m.mean())} for name, m in masks.items()}
    out["no_sky_reason"] = why
    # ... and its stability: the same crop as other camera settings would have stored it
    out["stability"] = {}
    variants = {}  # each camera setting's photo and mask, for (b)'s stability too
    for v, name in enumerate(CAMERA_VARIANTS):
        lin_v = camera_variant(lin, name, seed=seed * 1000 + crop.index * 10 + v)
        seg_v = relighter.photo_sky(lin_v)[0]
        variants[name] = (lin_v, seg_v)
        m = seg_v[0, 0].numpy()
        out["stability"][name] = {"iou": metrics.mask_iou(m, crop.sky),
                                  "boundary_f": metrics.boundary_f(m, crop.sky, BOUNDARY_TOLERANCE),
                                  "sky_called": float(m.mean())}
    pitch = estimate_pitch(seg[0, 0], crop.K)
    out["pitch"] = {"true_deg": crop.pitch_deg, "estimated_deg": pitch, "error_deg": pitch - crop.pitch_deg}

    # (b) lighting, from the decomposition the relighting uses (segmenter's mask: end to end)
    g = crop.gain
    source = crop.lighting_sh(2) * g[None, :]  # camera frame, photo units
    t0 = time.perf_counter()
    full = relighter.relight_full_resolution(lin, seg, torch.from_numpy(source).float(),
                                             source_lighting=torch.from_numpy(source).float(), method="proposed")
    seconds["proposed"] = time.perf_counter() - t0
    work = full["working"]
    dec = {k: work[k] for k in ("albedo", "normals", "shadow", "lighting", "foreground")}
    R = crop.rotation
    cam_normals = normals @ R.T  # n_c = R n_w
    truth = truth_irradiance * g[None, :]
    grey = float(grey_world_level(full["working_image"], work["normals"], work["lighting"], ~full["working_sky"])[0])
    # the sun and sky read from the photo's sky through relight's camera (the crop's field of view, as EXIF gives
    # it; the pitch from the sky's horizon; heading world -Z), as RelightOptions(source_estimate="sky") reads them
    R_est = panorama.level_camera(0.0, pitch)[:3, :3]
    t0 = time.perf_counter()
    reading = read_sky_lighting(lin, seg, crop.K, R_est)
    seconds["sky_reader"] = time.perf_counter() - t0
    read_cam = reading.camera(R_est) if reading.source == "sky" else None
    estimates = {"proposed": work["lighting"][0].double().numpy(),
                 # what the relighter divides by with source_estimate="sky": the reading, else the decomposition's
                 "sky_reader": read_cam[0] if read_cam is not None else work["lighting"][0].double().numpy(),
                 # the same shape at a light meter's level: what a rendered sky is put in (study 36)
                 "grey_world": work["lighting"][0].double().numpy() * grey,
                 "prior_mean": np.asarray(relighter.prior.mean, dtype=np.float64).reshape(9, 3)}
    out["lighting"] = {}
    for name, L in estimates.items():
        E = np.asarray(sh.irradiance(L, cam_normals))
        out["lighting"][name] = {"shading_error": shading_error(E, truth), "level_stops": level_stops(L, source)}
    E2 = np.asarray(sh.irradiance(crop.panorama.sh(2) * g[None, :], normals))
    out["lighting"]["truth_order2"] = {"shading_error": shading_error(E2, truth), "level_stops": 0.0}
    out["sun"] = _sun_figures(reading, R_est, crop, estimates, cam_normals, truth)
    # ... and the estimate's stability: the decomposition of each camera setting's photo, on its own mask (the
    # scale-invariant error: an exposure changes the level only; a colour cast is a change of the light's colour
    # to the photo, so it counts)
    out["lighting_stability"] = {}
    for name, (lin_v, seg_v) in variants.items():
        # the decomposition alone, as relight_full_resolution makes it (no relighting: only its lighting is scored)
        small, small_sky = working_resolution(relighter.denoised(lin_v), seg_v, relighter.res)
        L_v = relighter.decompose_linear(small.float(), small_sky.bool())["lighting"][0].double().numpy()
        out["lighting_stability"][name] = {"shading_error": shading_error(np.asarray(sh.irradiance(L_v, cam_normals)),
                                                                          truth)}
    out["world_sh"] = {name: np.asarray(sh.rotate(L, R.T)).tolist() for name, L in estimates.items()}

    # (d) self-relighting: the target is the source; the output should be the photo. Also after each output's best
    # single gain (display_at_best_gain): its structure apart from its level
    photo_disp = to_chw(crop.display())
    preds, gained, names = [], [], []
    read = {} if read_cam is None else {"read_source": torch.from_numpy(read_cam[0]).float(),
                                         "read_source_sun": torch.from_numpy(read_cam[1]).float()}
    for m in SELF_METHODS[:-1]:
        t0 = time.perf_counter()
        relit = relighter.relight_full_resolution(lin, seg, torch.from_numpy(source).float(),
                                                  source_lighting=torch.from_numpy(source).float(),
                                                  method=m.removesuffix("_known").removesuffix("_sky"), decomposition=dec,
                                                  known_source=m.endswith("_known"),
                                                  **(read if m.endswith("_sky") else {}))["relit"]
        seconds.setdefault(m, time.perf_counter() - t0)
        preds.append(torch.where(fg, _display(relit), photo_disp))
        if bool(fg.any()):
            gained.append(torch.where(fg, display_at_best_gain(relit, photo_disp, lin, fg), photo_disp))
        names.append(m)
    preds.append(photo_disp)
    gained.append(photo_disp)
    names.append("identity")
    if bool(fg.any()):
        def cap(k: str, v: float) -> float:
            return float(min(v, PSNR_CAP) if k == "psnr" else v)

        s = score(preds, [photo_disp] * len(preds), [fg] * len(preds))
        sg = score(gained, [photo_disp] * len(gained), [fg] * len(gained), which=("l1", "ssim", "psnr"))
        out["self"] = {n: {**{k: cap(k, s[k][i]) for k in ("l1", "ssim", "psnr", "ciede2000")},
                           **{f"{k}_at_best_gain": cap(k, sg[k][i]) for k in ("l1", "ssim", "psnr")}}
                       for i, n in enumerate(names)}
    else:
        out["self"] = None

    # (c) the relit sky, against the target seen through the same camera at the output's exposure
    out["sky"] = {}
    dirs = _camera_directions(crop.K, h, w)
    if crop.stratum != "no_sky":
        for tgt in targets:
            L_t = np.asarray(sh.rotate(tgt.sh(2), R))
            k = dc_luminance(source) / dc_luminance(L_t)
            target = torch.from_numpy(L_t * k).float()
            t0 = time.perf_counter()
            res = relighter.relight_full_resolution(lin, seg, target, source_lighting=torch.from_numpy(source).float(),
                                                    method=SKY_FOREGROUND, decomposition=dec)
            relit = res["relit"]
            exact = to_chw(crop.view_of(tgt.env) * k)
            # relight's own sky: the target through the camera as relight has it (the crop's field of
            # view, which its EXIF would give; the pitch estimated from the sky mask; the yaw given)
            estimated = panorama.level_camera(crop.yaw_deg, pitch)
            rendered = target_sky(tgt.env, crop.K, estimated, h, w) * k
            skies = {"target": torch.where(seg, rendered.permute(2, 0, 1)[None].float(), relit),
                     # the sky model fitted to the target's world-frame SH, through relight's estimated camera
                     "fit": torch.where(seg, (fitted_sky(tgt.sh(2) * k, crop.K, estimated, h, w))
                                        .permute(2, 0, 1)[None].float(), relit),
                     "skygan": relighter.paint_sky(relit, seg, res["working"], res["working_sky"], seed=seed),
                     "sh_radiance": torch.where(seg, sh_radiance_image(L_t * k, dirs), relit),
                     "keep": relit,
                     "exact_view": torch.where(seg, exact, relit)}
            seconds.setdefault("relight_and_skies", time.perf_counter() - t0)
            truth_disp = _display(exact)
            out["sky"][tgt.name] = {
                src: {"l1": float(metrics.l1(_display(img), truth_disp, true_sky)),
                      "psnr": min(float(metrics.psnr(_display(img), truth_disp, true_sky)), PSNR_CAP)}
                for src, img in skies.items()}
    out["seconds"] = seconds
    return out


def _sun_figures(reading: Any, R_est: np.ndarray, crop: Any, estimates: dict[str, np.ndarray],
                 cam_normals: np.ndarray, truth: np.ndarray) -> dict[str, Any]:
    """The sun's position estimated from a crop against the panorama's (:func:`physrelight.envmap.split_sun`), for
    each of :data:`real_metrics.SUN_ESTIMATES`; each estimate is a direction in the camera's frame, brought into
    the panorama's by the crop's true camera (its yaw known); and the shading error of the sky's reading with each
    ground reflectance of :data:`real_metrics.GROUND_ALBEDOS` (crops it reads)."""
    from learned.sky_lighting import sky_sun_sh

    sun = _panorama_sun(crop.panorama)
    post = reading.posterior
    out: dict[str, Any] = {"source": reading.source, "reason": reading.reason, "sky_kind": post.sky_kind,
                           "posterior": {k: v for k, v in post.summary().items() if k not in ("reason", "sky_kind")},
                           "truth": None, "estimates": {}}
    R = crop.rotation
    cam = {"proposed": dominant_direction(estimates["proposed"]),
           "prior_mean": dominant_direction(estimates["prior_mean"])}
    if reading.source == "sky":
        cam["sky_only"] = R_est @ np.asarray(post.sun_direction, np.float64)
        out["ground_albedo_shading_error"] = {
            f"{a:g}": shading_error(np.asarray(sh.irradiance(np.asarray(sh.rotation(R_est, 2)) @ sky_sun_sh(post, a)[0],
                                                             cam_normals)), truth) for a in GROUND_ALBEDOS}
    cam["sky_reader"] = cam.get("sky_only", cam["proposed"])
    if sun is None:
        return out
    el, az = sun_angles(sun)
    out["truth"] = {"elevation_deg": el, "azimuth_deg": az}
    for name, d in cam.items():
        w = R.T @ d  # camera -> the panorama's world through the true camera
        e_el, e_az = sun_angles(w)
        out["estimates"][name] = {"elevation_deg": e_el, "azimuth_deg": e_az, **sun_errors(w, sun)}
    return out


_SUNS: dict[str, np.ndarray | None] = {}


def _panorama_sun(pano: Any) -> np.ndarray | None:
    """The panorama's sun (world ``(3,)``) when :func:`physrelight.envmap.split_sun` finds one above the horizon."""
    key = str(pano.path)
    if key not in _SUNS:
        d = envmap.split_sun(pano.env).direction
        _SUNS[key] = None if d is None or d[1] <= 0 else np.asarray(d, np.float64)
    return _SUNS[key]


# ----------------------------------------------------------------------------- the run


def more_panoramas() -> list[Any]:
    """The panoramas of ``physrelight/data/hdri_more`` (issue 43) that ``bench --real`` scores by default: every
    ``outdoor`` map with a reviewed sky mask (``training``: the lighting prior and the segmenter may see them) and
    every room (``indoor``: no sky, a negative). Not pm_forest (no trustworthy mask) nor pm_bridge (a walkway)."""
    from physrelight import data
    from synth.panorama_crops import load_panorama

    out = []
    for name in data.hdri_names(collection="more"):
        kind = data.hdri_kind(name, collection="more")
        if kind == "walkway" or data.hdri_sky_mask(name, collection="more") is None:
            continue
        out.append(load_panorama(data.hdri(name, collection="more"), "training" if kind == "outdoor" else "indoor"))
    return out


def run_real_bench(level: RealLevel, hdri_dir: str | Path | None, out_dir: str | Path, command: str,
                   threads: int = 2, progress: Callable[[str], None] = print, weights: str | Path | None = None,
                   seed: int = 0, fov_range: tuple[float, float] = (45.0, 75.0)) -> dict[str, Any]:
    """Run ``bench --real`` at ``level`` and write ``real.md``, ``real.json``, ``charts/`` and ``panels/``.

    Args:
        hdri_dir: a folder of lat-long ``.exr``/``.hdr`` panoramas (scored as group ``"user"``,
            masks by the procedure unless ``NAME_sky.png`` lies beside a map), or None: the
            shipped panoramas (training side, studio apart, held-out sunrise) and :func:`more_panoramas`
            (five more outdoor maps on the training side, eight rooms beside studio).
        weights: the learned methods' weights folder (None: the shipped ones).
        seed: crops, photo noise and SkyGAN's noise.
        fov_range: the crops' horizontal field of view range in degrees.

    Returns:
        real.json's content.
    """
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    from learned import Relighter
    from synth.panorama_crops import folder_panoramas, make_crops, shipped_panoramas

    from ..common import machine
    from .real_report import write_real_report

    t_start = time.perf_counter()
    if hdri_dir is not None:
        panoramas = folder_panoramas(hdri_dir)
        pool_of: dict[str, list[Any]] = {}
    else:
        shipped, more = shipped_panoramas(), more_panoramas()
        # the shipped panoramas keep the target pool of every earlier run (their figures stay comparable with
        # docs/experiments/bench-history.md); the new ones are relit to every outdoor map
        pool_of = {p.name: shipped for p in shipped}
        panoramas = ([p for p in shipped if p.group == "training"] + [p for p in more if p.group == "training"]
                     + [p for p in shipped if p.group == "indoor"] + [p for p in more if p.group == "indoor"]
                     + [p for p in shipped if p.group == "heldout"])
    relighter = Relighter.load(weights)
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    load_before = os.getloadavg()
    try:
        normals = sh.fibonacci_sphere(SPHERE_NORMALS)
        target_pool = panoramas
        if sum(p.outdoor for p in panoramas) < 2:  # one user map: relight it to the shipped outdoor ones
            target_pool = panoramas + [p for p in shipped_panoramas() if p.group == "training"]
        results: list[dict[str, Any]] = []
        crops_by_pano: dict[str, list[Any]] = {}
        for pano in panoramas:
            t0 = time.perf_counter()
            truth = np.asarray(envmap.irradiance_reference(pano.env.astype(np.float64), normals))
            crops = make_crops(pano, level.crops, seed, fov_range=fov_range, samples=level.samples)
            crops_by_pano[pano.name] = crops
            for c in crops:
                pool = pool_of.get(pano.name, target_pool)
                results.append(score_crop(relighter, c, targets_for(pano, pool, level.targets, c.index), truth,
                                          normals, seed))
            progress(f"{pano.name} ({pano.group}): {len(crops)} crops scored in {time.perf_counter() - t0:.0f} s")
        report = {
            "format": "physrelight-bench-real", "version": 1, "command": command, "level": level.to_json(),
            "seed": seed, "fov_range": list(fov_range),
            "machine": {**machine(), "torch_threads": threads,
                        "load_average_before": [round(x, 2) for x in load_before],
                        "load_average_after": [round(x, 2) for x in os.getloadavg()],
                        "shared": "the machine is shared with other jobs: timings are medians and indicative"},
            "date": datetime.datetime.now().isoformat(timespec="seconds"),
            "weights": "learned/weights" if weights is None else str(weights),
            "panoramas": [{"name": p.name, "group": p.group, "mask": p.mask_source, "file": str(p.path),
                           "size": list(p.env.shape[:2]), "sky_fraction": float(p.sky.mean())} for p in panoramas],
            "crops": results,
        }
        report["seconds"] = round(time.perf_counter() - t_start, 1)
        return write_real_report(out_dir, report, relighter, crops_by_pano, target_pool, level, progress)
    finally:
        torch.set_num_threads(before)
