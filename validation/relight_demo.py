"""The pipeline part of ``physrelight demo``: relight a path-traced scene and a real photo.

A small synthetic outdoor scene (procedural landmark, one tourist view) is path traced with
Mitsuba under a clear-sky source lighting and three targets (low evening sun, a sun-free
hazy sky, the shipped forest HDRI turned 120 degrees). The source photo is relit to each
target with the shipped weights, following the benchmark protocol (docs/bench.md): the
target keeps the source photo's exposure, the networks get the target's SH in the source
photo's units, and the result is compared on the foreground with the path-traced target.
The photo's own lighting, which the quotient divides by, is the relighter's estimate: the decomposition's
(``source_estimate="decomposition"``, the default, as ``RelightOptions``'s) or the sun and sky read from the photo's
sky (``"sky"``: :func:`learned.sky_lighting.read_sky_lighting` through the scene's camera on the scene's sky mask,
the demo's protocol; where the reading falls back, the decomposition's, as ``RelightOptions(source_estimate="sky")``
does). The reading and its sun's error against the path-traced source's go to the metrics.
Methods: ``proposed`` (the default: the shipped neural renderer, a learned gain on the quotient
image), ``quotient`` (the photo times the ratio of target to estimated source shading),
``lambertian_sh`` (the decomposition times the
target SH shading) and ``identity`` (the photo unchanged). A real photo that ships with
scikit-image (``rocket.jpg``) is relit too (no ground truth: for the eye).

The panel shows each relit photo with the target's own sky painted in, as ``physrelight relight`` paints it
(:func:`physrelight.sky_view.target_sky`: the target's sky map seen through the scene's camera, in the photo's
exposure), so the sky says which lighting the foreground was relit to, and beside each method its error
against the path-traced target: ``|relit - target|`` luminance of the display values, one colour scale for
every error map of the panel, with its colour bar. The scores (l1, PSNR, SSIM) are on the foreground only.

Outputs: ``relight_demo.png`` (panel), ``relight_metrics.json``, ``relight_metrics.md``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from physrelight import colour, io, metrics
from physrelight.data import hdri

__all__ = ["METHODS", "PANEL_METHODS", "error_map", "panel_figure", "run", "with_target_sky"]

METHODS = ("proposed", "quotient", "lambertian_sh", "identity")
PANEL_METHODS = ("proposed", "quotient")
"""The methods the panel shows, each with its error map."""


def _chw(x: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32)).permute(2, 0, 1)[None]


def _scene(seed: int, size: int, spp: int, log: Callable[[str], None]) -> dict:
    """Render the scene under the source and the three targets; GT and photo inputs."""
    from synth import cameras, lighting, render, scene
    from synth.photo import metered_ev

    spec = scene.generate_scene(seed)
    cam = cameras.sample_views(spec, 1, seed=seed, width=size, height=size)[0]
    w2c = np.asarray(cam.world_to_camera, dtype=np.float64)
    source = lighting.sunsky(seed, elevation_deg=45.0, azimuth_deg=60.0, turbidity=3.0)
    forest = lighting.hdri(hdri("forest"), azimuth_deg=120.0)
    # The HDRI is in its own units: scale it to the source's DC luminance (the same overall
    # light level), so the target photographed at the source's exposure is not blown out.
    lum = np.asarray(colour.LUMINANCE)
    k = float(source.sh(2)[0] @ lum) / float(forest.sh(2)[0] @ lum)
    lights = {
        "clear sky, sun 45 deg (source)": source,
        "evening sun 8 deg": lighting.evening(seed + 1, elevation_deg=8.0, azimuth_deg=250.0),
        "hazy sky, no sun": lighting.overcast(seed + 2),
        "forest HDRI turned 120 deg": lighting.hdri(hdri("forest"), azimuth_deg=120.0, scale=k),
    }
    out: dict = {"lights": {}, "camera": w2c, "K": np.asarray(cam.K, dtype=np.float64)}
    for k, (name, light) in enumerate(lights.items()):
        log(f"  path tracing {name!r} ({size}x{size}, {spp} spp)")
        mi_scene = render.build_scene(spec, [cam], light, spp=spp, seed=seed)
        if k == 0:
            geo = render.render_geometry(mi_scene, 0, cam, spp=8, seed=seed)
            out["sky"] = geo.sky_mask
            out["foreground"] = ~geo.sky_mask & (np.linalg.norm(geo.normal, axis=-1) > 0.5)
            out["normals"] = geo.normal  # (H, W, 3) camera frame, 0 on sky
        radiance = render.render_radiance(mi_scene, 0, spp=spp, seed=seed + 17 * k)
        out["lights"][name] = {"radiance": radiance, "sh": light.sh(2, w2c), "sky_map": light.sky,
                               "sun_direction": light.sun_direction}
    src = next(iter(out["lights"]))
    out["ev"] = metered_ev(out["lights"][src]["radiance"])
    return out


def with_target_sky(display: torch.Tensor, sky: np.ndarray, sky_map: np.ndarray, K: np.ndarray,
                    world_to_camera: np.ndarray, gain: float) -> torch.Tensor:
    """``(1, 3, H, W)`` display values ``display`` with the target's sky on ``sky (H, W)`` bool: the lat-long
    ``sky_map (h, 2h, 3)`` (world frame, target radiance) seen through the camera (``K (3, 3)``,
    ``world_to_camera (4, 4)``) by :func:`physrelight.sky_view.target_sky`, as ``physrelight relight`` paints a
    target's sky, times the photo's exposure ``gain``, to display values."""
    from physrelight.sky_view import target_sky

    h, w = display.shape[-2:]
    if sky.shape != (h, w):
        raise ValueError(f"sky must have shape {(h, w)}, got {sky.shape}")
    radiance = target_sky(np.asarray(sky_map, dtype=np.float32), K, world_to_camera, h, w)
    painted = colour.to_ldr(radiance.permute(2, 0, 1)[None].float().clamp_min(0) * gain)
    return torch.where(torch.from_numpy(sky)[None, None], painted, display)


def error_map(relit: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """``(H, W)`` ``|relit - target|`` in luminance (Rec. 709 weights) of two ``(1, 3, H, W)`` display images."""
    if relit.shape != target.shape or relit.ndim != 4 or relit.shape[:2] != (1, 3):
        raise ValueError(f"relit and target must both be (1, 3, H, W), got {tuple(relit.shape)}, "
                         f"{tuple(target.shape)}")
    lum = relit.new_tensor(colour.LUMINANCE)[None, :, None, None]
    return ((relit - target) * lum).sum(1)[0].abs()


def _real_photo() -> np.ndarray | None:
    """scikit-image's ``rocket.jpg`` (display values), or None without scikit-image."""
    try:
        from skimage import data
    except ImportError:
        return None
    return data.rocket().astype(np.float32) / 255.0


def _sky_reading(lin: torch.Tensor, sky: np.ndarray, K: np.ndarray, w2c: np.ndarray,
                 true_sun: np.ndarray | None) -> tuple[dict, dict]:
    """The photo's lighting read from its sky (:func:`learned.sky_lighting.read_sky_lighting`) through the scene's
    camera: ``(relight_full_resolution``'s ``read_source``/``read_source_sun`` keywords (empty on a fallback), the
    reading as JSON, with the MAP sun's angle to the path-traced source's ``true_sun (3,)`` world direction)``."""
    import math

    from learned.sky_lighting import read_sky_lighting

    reading = read_sky_lighting(lin, torch.from_numpy(sky), K, w2c)
    post = reading.posterior
    info: dict = {"source": reading.source, "reason": reading.reason, "sky_kind": post.sky_kind,
                  "credible_area_sr": float(post.credible_area_sr), "sun_world": None, "sun_error_deg": None}
    if not post.has_sun:
        return {}, info
    d = np.asarray(post.sun_direction, dtype=np.float64)
    info["sun_world"] = [float(x) for x in d]
    if true_sun is not None:
        info["sun_error_deg"] = math.degrees(math.acos(float(np.clip(d @ np.asarray(true_sun), -1.0, 1.0))))
    if reading.source != "sky":
        return {}, info
    sh_c, sun_c = reading.camera(w2c)
    return {"read_source": torch.from_numpy(sh_c).float(), "read_source_sun": torch.from_numpy(sun_c).float()}, info


def run(out_dir: str | Path, size: int = 96, spp: int = 64, seed: int = 7, log: Callable[[str], None] = print,
        source_estimate: str = "decomposition") -> dict:
    """Run the pipeline demo; write the panel and metrics into ``out_dir``; return the metrics.

    ``source_estimate``: the photo's own lighting on the estimated track (:data:`learned.relight_options.SOURCE_ESTIMATES`,
    as :attr:`learned.relight_options.RelightOptions.source_estimate`): ``"decomposition"`` (the default) or
    ``"sky"``.
    """
    from learned import Relighter
    from learned.relight_options import SOURCE_ESTIMATES

    if source_estimate not in SOURCE_ESTIMATES:
        raise ValueError(f"source_estimate must be one of {SOURCE_ESTIMATES}, got {source_estimate!r}")

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    log("[1/3] a synthetic scene, path traced under four lightings")
    sc = _scene(seed, size, spp, log)
    gain = 2.0 ** sc["ev"]
    names = list(sc["lights"])
    src = sc["lights"][names[0]]
    photo = colour.to_ldr(_chw(src["radiance"] * gain))  # what the user has: an LDR photo
    lin = colour.from_ldr(photo)
    sky = torch.from_numpy(sc["sky"])[None, None]
    K, w2c = sc["K"], sc["camera"]
    fg = torch.from_numpy(sc["foreground"])[None, None].float()
    relighter = Relighter.load().with_options(source_estimate=source_estimate)

    log("[2/3] relighting with the shipped weights, compared with path tracing")
    results: dict = {"seed": seed, "size": size, "spp": spp, "source": names[0], "source_estimate": source_estimate,
                     "targets": {}}
    read: dict = {}
    if source_estimate == "sky":
        read, results["sky_reading"] = _sky_reading(lin, sc["sky"], K, w2c, src["sun_direction"])
        r = results["sky_reading"]
        log(f"  the photo's lighting: {'read from its sky' if r['source'] == 'sky' else 'fallback: ' + r['reason']}"
            + ("" if r["sun_error_deg"] is None else f" (its sun {r['sun_error_deg']:.1f} deg from the true one)"))
    rows = []
    for name in names[1:]:
        target = colour.to_ldr(_chw(sc["lights"][name]["radiance"] * gain))
        preds = {"identity": photo}
        seconds = {"identity": 0.0}
        for method in ("proposed", "quotient", "lambertian_sh"):
            t = time.perf_counter()
            relit = relighter.relight_full_resolution(
                lin, sky, torch.from_numpy(sc["lights"][name]["sh"] * gain).float(),
                source_lighting=torch.from_numpy(src["sh"] * gain).float(), method=method, **read)["relit"]
            preds[method] = colour.to_ldr(relit.clamp_min(0))
            seconds[method] = time.perf_counter() - t
        entry = {}
        for method in METHODS:
            p = preds[method]
            entry[method] = {"l1": float(metrics.l1(p, target, fg)), "psnr": float(metrics.psnr(p, target, fg)),
                             "ssim": float(metrics.ssim(p, target, fg)), "seconds": seconds[method]}
        results["targets"][name] = entry
        shown = {m: with_target_sky(preds[m], sc["sky"], sc["lights"][name]["sky_map"], K, w2c, gain)
                 for m in PANEL_METHODS}
        rows.append((name, photo, target, [(m, shown[m], error_map(shown[m], target)) for m in PANEL_METHODS]))

    log("[3/3] a real photo (scikit-image's rocket.jpg), no ground truth")
    real = _real_photo()
    real_row = None
    if real is not None:
        forest = relighter.relight(real, hdri("forest"), method="proposed", exposure="auto")
        from learned.relight_cli import sun_direction

        low_sun = relighter.relight(real, sun_direction(10.0, 60.0), method="proposed", exposure="auto")
        real_row = [real, forest, low_sun]
        results["real_photo"] = {"name": "skimage rocket.jpg", "shape": list(real.shape),
                                 "targets": ["forest HDRI", "clear sky, sun 10 deg, azimuth 60 deg"]}
    _panel(out / "relight_demo.png", names[0], rows, real_row, source_estimate)
    results["seconds"] = time.perf_counter() - t0
    io.write_json(out / "relight_metrics.json", results)
    lines = ["| target | method | l1 | PSNR dB | SSIM |", "| --- | --- | ---: | ---: | ---: |"]
    for name, entry in results["targets"].items():
        for method in METHODS:
            m = entry[method]
            lines.append(f"| {name} | {method} | {m['l1']:.4f} | {m['psnr']:.2f} | {m['ssim']:.3f} |")
    with io.atomic_path(out / "relight_metrics.md") as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    for ln in lines:
        log(ln)
    log(f"wrote {out / 'relight_demo.png'} and relight_metrics.json/.md in {results['seconds']:.1f} s")
    return results


def panel_figure(source: str, rows: list, real_row: list | None, source_estimate: str = "decomposition"):
    """The demo's panel as a matplotlib figure.

    Args:
        source: the source lighting's name (the title).
        source_estimate: the photo's own lighting the relighter used (the title).
        rows: one per target, ``(name, photo, target, [(method, relit, error), ...])``: ``(1, 3, H, W)`` display
            images (the relit ones with the target's sky) and ``(H, W)`` error maps (:func:`error_map`).
        real_row: ``[photo, relit, relit]`` ``(H, W, 3)`` of the real photo, or None.

    Returns:
        The figure: per target row the photo, the target, then each method and its error map, all error maps on
        one colour scale (0 to the largest 99th percentile of them) with one colour bar.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = [m for m, _, _ in rows[0][3]] if rows else list(PANEL_METHODS)
    ncols = 2 + 2 * len(methods)
    cols = ["photo (source)", "path-traced target"]
    for m in methods:
        cols += [f"{m}{' (default)' if m == 'proposed' else ''}", f"|{m} - target|"]
    errors = [e for _, _, _, ms in rows for _, _, e in ms]
    vmax = max([float(torch.quantile(e.flatten().float(), 0.99)) for e in errors] + [1e-3])
    n = len(rows) + (1 if real_row is not None else 0)
    fig, axes = plt.subplots(n, ncols, figsize=(1.9 * ncols + 0.6, 2.0 * n + 0.4), squeeze=False)
    im = None
    for r, (name, photo, target, ms) in enumerate(rows):
        imgs = [("rgb", photo), ("rgb", target)]
        for _, relit, err in ms:
            imgs += [("rgb", relit), ("err", err)]
        for c, (kind, img) in enumerate(imgs):
            ax = axes[r, c]
            if kind == "rgb":
                ax.imshow(img[0].permute(1, 2, 0).clamp(0, 1).numpy())
            else:
                im = ax.imshow(img.numpy(), cmap="magma", vmin=0.0, vmax=vmax)
            if r == 0:
                ax.set_title(cols[c], fontsize=7)
        axes[r, 0].set_ylabel(name, fontsize=7)
    if real_row is not None:
        titles = ["rocket.jpg", "relit: forest HDRI", "relit: sun 10 deg"]
        for c in range(ncols):
            if c < len(real_row):
                axes[-1, c].imshow(np.clip(real_row[c], 0, 1))
                axes[-1, c].set_xlabel(titles[c], fontsize=7)
            else:
                axes[-1, c].axis("off")
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"Relighting a path-traced scene ({source}) with the shipped weights, the photo's own lighting "
                 f"from {'its sky' if source_estimate == 'sky' else 'the decomposition'}; the relit photos get the "
                 "target's sky as physrelight relight paints it", fontsize=8)
    fig.tight_layout(rect=(0, 0, 0.93, 1))
    if im is not None:
        cax = fig.add_axes((0.945, 0.35, 0.012, 0.4))
        bar = fig.colorbar(im, cax=cax)
        bar.set_label("|relit - target| luminance (display)", fontsize=7)
        bar.ax.tick_params(labelsize=6)
    return fig


def _panel(path: Path, source: str, rows: list, real_row: list | None, source_estimate: str) -> None:
    import matplotlib.pyplot as plt

    fig = panel_figure(source, rows, real_row, source_estimate)
    with io.atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
