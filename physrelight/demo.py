"""``physrelight demo``: relight a textured Lambertian sphere between real outdoor HDRIs.

What it shows with the physics core alone (no network yet): a "photo" of a sphere under
one shipped HDRI is rendered exactly (brute-force irradiance per pixel); its lighting is
solved from the photo (:func:`physrelight.image_model.solve_lighting`) at SH orders 2
and 4; the albedo is recovered by dividing the photo by that shading; and the sphere is
relit with each target HDRI's SH. The result is compared with the exact render under the
target, so the panel shows what the SH model costs: the ceiling of any SH relighting.

Outputs in the output folder: ``demo.png`` (panel), ``metrics.json``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from physrelight import colour, envmap, image_model, io, metrics, sh
from physrelight.data import hdri


def sphere_normals(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Orthographic unit sphere filling the image: camera-frame normals ``(H, W, 3)`` and mask ``(H, W)``.

    The camera sits on +z looking at the origin with world Y up, so camera frame = world frame.
    """
    c = (np.arange(size) + 0.5) / size * 2 - 1
    v, u = np.meshgrid(c, c, indexing="ij")
    r2 = u**2 + v**2
    mask = r2 < 0.98
    n = np.zeros((size, size, 3))
    n[mask] = np.stack([u[mask], -v[mask], np.sqrt(1 - r2[mask])], axis=-1)
    return n, mask


def sphere_albedo(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A faintly veined stone albedo ``(H, W, 3)`` in [0.45, 0.75], smooth over the surface.

    Low contrast on purpose: the panel is about shading, the texture only shows that the
    albedo survives the round trip.
    """
    x, y, z = normals[..., 0], normals[..., 1], normals[..., 2]
    vein = 0.5 + 0.5 * np.sin(7 * x + 3 * np.sin(5 * y) + 2 * z)
    base = np.array([0.75, 0.70, 0.62])
    dark = np.array([0.55, 0.50, 0.45])
    alb = dark + (base - dark) * vein[..., None]
    return np.where(mask[..., None], alb, 0.0)


def exact_shading(env: np.ndarray, normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``E(n) / pi`` by brute force at every masked pixel, ``(H, W, 3)``."""
    out = np.zeros(normals.shape)
    out[mask] = envmap.irradiance_reference(env, normals[mask]) / math.pi
    return out


def _chw(x: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(np.moveaxis(x, -1, 0)))[None]


def run(out_dir: str | Path, source: str = "city", targets: tuple[str, ...] = ("forest", "courtyard"),
        size: int = 80, log: Callable[[str], None] = print) -> dict:
    """Run the demo and write ``demo.png`` and ``metrics.json`` into ``out_dir``.

    Args:
        out_dir: output folder (created).
        source: shipped HDRI the photo is lit by.
        targets: shipped HDRIs to relight to (the source turned by 120 degrees is added).
        size: sphere image size in pixels.
        log: where progress lines go.

    Returns:
        The metrics dictionary written to ``metrics.json``.
    """
    from physrelight import rotations  # local: only the demo needs it

    paths = {name: hdri(name) for name in (source, *targets)}  # an unknown name: ValueError listing the known
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    normals, mask = sphere_normals(size)
    albedo = sphere_albedo(normals, mask)
    maps = {name: envmap.read(path) for name, path in paths.items()}
    turned = f"{source} turned 120 deg"
    maps[turned] = envmap.rotate(maps[source], rotations.about_y(120.0)).astype(np.float32)
    target_names = [*targets, turned]

    log(f"[1/3] exact photo of the sphere under {source!r} ({int(mask.sum())} pixels, brute force)")
    photo = albedo * exact_shading(maps[source], normals, mask)
    photo_ldr = colour.to_ldr(_chw(photo), math.log2(0.18 / float(photo[mask].mean())))
    n_t, m_t, p_t = _chw(normals), _chw(mask[..., None].astype(np.float64)), _chw(photo)

    rows = []
    results: dict = {"source": source, "size": size, "targets": {}}
    for k, name in enumerate(target_names, start=1):
        log(f"[2/3] target {k}/{len(target_names)}: {name!r}: exact render and SH relighting")
        exact = albedo * exact_shading(maps[name], normals, mask)
        ev = math.log2(0.18 / float(exact[mask].mean()))  # one exposure per target, shared by all
        relit = {}
        for order in (2, 4):
            src_sh = image_model.solve_lighting(p_t, _chw(albedo), n_t, m_t, order=order)
            src_shading = image_model.shading(n_t, src_sh)
            albedo_hat = torch.where(src_shading > 1e-8, p_t / src_shading.clamp_min(1e-8), torch.zeros_like(p_t))
            tgt_sh = torch.from_numpy(sh.project_envmap(maps[name], order))
            relit[order] = albedo_hat * image_model.shading(n_t, tgt_sh)
        ldr = lambda x: colour.to_ldr(x if isinstance(x, torch.Tensor) else _chw(x), ev)  # noqa: E731
        gt = ldr(exact)
        entry = {"ev": ev}
        for order, img in relit.items():
            pred = ldr(img)
            entry[f"order{order}"] = {
                "psnr": metrics.psnr(pred, gt, m_t), "ssim": metrics.ssim(pred, gt, m_t),
                "delta_e2000": metrics.delta_e2000(pred, gt, m_t),
                "linear_rel_error": float((img - _chw(exact)).abs()[m_t.expand_as(img) > 0].mean() / exact[mask].mean()),
            }
            entry[f"order{order}"] = {k2: float(v) for k2, v in entry[f"order{order}"].items()}
        results["targets"][name] = entry
        rows.append((name, photo_ldr, ldr(relit[2]), ldr(relit[4]), gt, (relit[2] - _chw(exact)).abs().sum(1) / 3))

    log("[3/3] writing demo.png and metrics.json")
    _panel(out / "demo.png", source, rows)
    results["seconds"] = time.perf_counter() - t0
    io.write_json(out / "metrics.json", results)
    log(f"{'target':<24} {'order':>5} {'PSNR dB':>8} {'SSIM':>6} {'dE2000':>7}")
    for name, entry in results["targets"].items():
        for order in (2, 4):
            m = entry[f"order{order}"]
            log(f"{name:<24} {order:>5} {m['psnr']:>8.2f} {m['ssim']:>6.3f} {m['delta_e2000']:>7.2f}")
    log(f"wrote {out / 'demo.png'} and {out / 'metrics.json'} in {results['seconds']:.1f} s")
    return results


def panel_figure(source: str, rows: list) -> Any:
    """The panel as a matplotlib figure: one row per target, photo | order 2 | order 4 | exact | error map."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = [f"photo ({source})", "SH order 2 relit", "SH order 4 relit", "exact target", "|order 2 - exact|"]
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(2.2 * len(cols), 2.3 * len(rows)), squeeze=False)
    for r, (name, *imgs, err) in enumerate(rows):
        for c, img in enumerate(imgs):
            axes[r, c].imshow(img[0].permute(1, 2, 0).numpy())
        vmax = float(err.max()) or 1.0
        shown = axes[r, 4].imshow(err[0].numpy(), cmap="magma", vmin=0, vmax=vmax)
        # each row has its own scale, so each gets its own bar (linear radiance, mean over RGB)
        bar = fig.colorbar(shown, ax=axes[r, 4], fraction=0.046, pad=0.04)
        bar.ax.tick_params(labelsize=6)
        bar.set_label("linear radiance", fontsize=6)
        axes[r, 0].set_ylabel(name, fontsize=8)
        for c in range(len(cols)):
            axes[r, c].set_xticks([])
            axes[r, c].set_yticks([])
            if r == 0:
                axes[r, c].set_title(cols[c], fontsize=8)
    fig.suptitle("Relighting a Lambertian sphere through SH vs exact irradiance", fontsize=9)
    fig.tight_layout()
    return fig


def _panel(path: Path, source: str, rows: list) -> None:
    import matplotlib.pyplot as plt

    fig = panel_figure(source, rows)
    with io.atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
