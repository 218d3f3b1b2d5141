"""The pipeline part of ``physrelight demo``: relight a path-traced scene and a real photo.

A small synthetic outdoor scene (procedural landmark, one tourist view) is path traced with
Mitsuba under a clear-sky source lighting and three targets (low evening sun, a sun-free
hazy sky, the shipped forest HDRI turned 120 degrees). The source photo is relit to each
target with the shipped weights, following the benchmark protocol (docs/bench.md): the
target keeps the source photo's exposure, the networks get the target's SH in the source
photo's units, and the result is compared on the foreground with the path-traced target.
Methods: ``proposed`` (the default: the shipped neural renderer, a learned gain on the quotient
image), ``quotient`` (the photo times the ratio of target to estimated source shading),
``lambertian_sh`` (the decomposition times the
target SH shading) and ``identity`` (the photo unchanged). A real photo that ships with
scikit-image (``rocket.jpg``) is relit too (no ground truth: for the eye).

Outputs: ``relight_demo.png`` (panel), ``relight_metrics.json``, ``relight_metrics.md``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from physrelight import colour, io, metrics

__all__ = ["METHODS", "run"]

METHODS = ("proposed", "quotient", "lambertian_sh", "identity")
HDRI_DIR = Path(__file__).resolve().parents[1] / "physrelight" / "data" / "hdri"


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
    forest = lighting.hdri(HDRI_DIR / "forest.exr", azimuth_deg=120.0)
    # The HDRI is in its own units: scale it to the source's DC luminance (the same overall
    # light level), so the target photographed at the source's exposure is not blown out.
    lum = np.asarray(colour.LUMINANCE)
    k = float(source.sh(2)[0] @ lum) / float(forest.sh(2)[0] @ lum)
    lights = {
        "clear sky, sun 45 deg (source)": source,
        "evening sun 8 deg": lighting.evening(seed + 1, elevation_deg=8.0, azimuth_deg=250.0),
        "hazy sky, no sun": lighting.overcast(seed + 2),
        "forest HDRI turned 120 deg": lighting.hdri(HDRI_DIR / "forest.exr", azimuth_deg=120.0, scale=k),
    }
    out: dict = {"lights": {}, "camera": w2c}
    for k, (name, light) in enumerate(lights.items()):
        log(f"  path tracing {name!r} ({size}x{size}, {spp} spp)")
        mi_scene = render.build_scene(spec, [cam], light, spp=spp, seed=seed)
        if k == 0:
            geo = render.render_geometry(mi_scene, 0, cam, spp=8, seed=seed)
            out["sky"] = geo.sky_mask
            out["foreground"] = ~geo.sky_mask & (np.linalg.norm(geo.normal, axis=-1) > 0.5)
        radiance = render.render_radiance(mi_scene, 0, spp=spp, seed=seed + 17 * k)
        out["lights"][name] = {"radiance": radiance, "sh": light.sh(2, w2c)}
    src = next(iter(out["lights"]))
    out["ev"] = metered_ev(out["lights"][src]["radiance"])
    return out


def _real_photo() -> np.ndarray | None:
    """scikit-image's ``rocket.jpg`` (display values), or None without scikit-image."""
    try:
        from skimage import data
    except ImportError:
        return None
    return data.rocket().astype(np.float32) / 255.0


def run(out_dir: str | Path, size: int = 96, spp: int = 64, seed: int = 7, log: Callable[[str], None] = print) -> dict:
    """Run the pipeline demo; write the panel and metrics into ``out_dir``; return the metrics."""
    from learned import Relighter

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
    fg = torch.from_numpy(sc["foreground"])[None, None].float()
    relighter = Relighter.load()

    log("[2/3] relighting with the shipped weights, compared with path tracing")
    results: dict = {"seed": seed, "size": size, "spp": spp, "source": names[0], "targets": {}}
    rows = []
    for name in names[1:]:
        target = colour.to_ldr(_chw(sc["lights"][name]["radiance"] * gain))
        preds = {"identity": photo}
        seconds = {"identity": 0.0}
        for method in ("proposed", "quotient", "lambertian_sh"):
            t = time.perf_counter()
            relit = relighter.relight_full_resolution(
                lin, sky, torch.from_numpy(sc["lights"][name]["sh"] * gain).float(),
                source_lighting=torch.from_numpy(src["sh"] * gain).float(), method=method)["relit"]
            preds[method] = colour.to_ldr(relit.clamp_min(0))
            seconds[method] = time.perf_counter() - t
        entry = {}
        for method in METHODS:
            p = preds[method]
            entry[method] = {"l1": float(metrics.l1(p, target, fg)), "psnr": float(metrics.psnr(p, target, fg)),
                             "ssim": float(metrics.ssim(p, target, fg)), "seconds": seconds[method]}
        results["targets"][name] = entry
        rows.append((name, [photo, target, preds["proposed"], preds["quotient"]]))

    log("[3/3] a real photo (scikit-image's rocket.jpg), no ground truth")
    real = _real_photo()
    real_row = None
    if real is not None:
        forest = relighter.relight(real, HDRI_DIR / "forest.exr", method="proposed", exposure="auto")
        from learned.relight_cli import sun_direction

        low_sun = relighter.relight(real, sun_direction(10.0, 60.0), method="proposed", exposure="auto")
        real_row = [real, forest, low_sun]
        results["real_photo"] = {"name": "skimage rocket.jpg", "shape": list(real.shape),
                                 "targets": ["forest HDRI", "clear sky, sun 10 deg, azimuth 60 deg"]}
    _panel(out / "relight_demo.png", names[0], rows, real_row)
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


def _panel(path: Path, source: str, rows: list, real_row: list | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = ["photo (source)", "path-traced target", "proposed (default)", "quotient"]
    n = len(rows) + (1 if real_row is not None else 0)
    fig, axes = plt.subplots(n, 4, figsize=(2.4 * 4, 2.5 * n), squeeze=False)
    for r, (name, imgs) in enumerate(rows):
        for c, img in enumerate(imgs):
            axes[r, c].imshow(img[0].permute(1, 2, 0).numpy())
            if r == 0:
                axes[r, c].set_title(cols[c], fontsize=8)
        axes[r, 0].set_ylabel(name, fontsize=7)
    if real_row is not None:
        titles = ["rocket.jpg", "relit: forest HDRI", "relit: sun 10 deg", ""]
        for c in range(4):
            if c < len(real_row):
                axes[-1, c].imshow(np.clip(real_row[c], 0, 1))
            axes[-1, c].set_xlabel(titles[c], fontsize=8)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    if real_row is not None:
        axes[-1, 3].axis("off")
    fig.suptitle(f"Relighting a path-traced scene ({source}) with the shipped weights", fontsize=9)
    fig.tight_layout()
    with io.atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)

