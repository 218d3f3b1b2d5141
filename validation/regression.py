"""Regression scenes: tiny renders whose derived figures are pinned with statistical tolerances.

Three hand-made scenes (32 x 32 px, fixed seeds) each give a handful of figures: mean
radiance (luminance) per region, the lighting's camera-frame SH coefficients, shadow
coverage and the shadow-free loss with and without the shadow. Every figure carries its
standard error, measured from independent renders (or 0 for deterministic figures). A
test compares a fresh measurement with the pinned one:

    |now - pinned| <= 5 sqrt(se_now^2 + se_pinned^2) + quantum

where ``quantum`` is 1e-9 relative for deterministic figures and one pixel's share for
pixel counts. A change that shifts the physics or a convention (frames, exposure, SH
ordering, the shadow definition) therefore fails with a message naming the figure;
a new noise realisation does not.

Re-pin (after a deliberate change, say why in the commit)::

    .venv/bin/python -m validation.regression --pin tests/validation/regression_pins.json
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any, Callable

import numpy as np

from physrelight import io
from synth import lighting as _lighting
from synth import render as _render

from . import scenes
from .common import LUMINANCE
from .shadow_loss import paper_loss

Figure = tuple[float, float, str]
"""``(value, standard error, kind)`` with kind ``"stat"``, ``"exact"`` or ``"count:N"``."""

RENDERS = 4
SPP = 32
SIGMAS = 5.0


def _region_means(runs: np.ndarray, regions: dict[str, np.ndarray]) -> dict[str, Figure]:
    """Mean luminance per region, standard error over the K renders."""
    lum = runs @ LUMINANCE  # (K, H, W)
    out: dict[str, Figure] = {}
    for name, sel in regions.items():
        if not sel.any():
            raise RuntimeError(f"regression region {name!r} is empty: the scene or camera changed")
        per = lum[:, sel].mean(axis=1)
        out[f"radiance/{name}"] = (float(per.mean()), float(per.std(ddof=1) / math.sqrt(len(per))), "stat")
    return out


def _coverage(shadows: list[np.ndarray], sel: np.ndarray, name: str) -> dict[str, Figure]:
    """Share of ``sel`` pixels with shadow < 0.5, from independent shadow renders."""
    shares = [float((s[sel] < 0.5).mean()) for s in shadows]
    se = float(np.std(shares, ddof=1) / math.sqrt(len(shares)))
    return {f"shadow_coverage/{name}": (float(np.mean(shares)), se, f"count:{int(sel.sum())}")}


def _sh(light: _lighting.Lighting, cam: Any) -> dict[str, Figure]:
    c = light.sh(2, np.asarray(cam.world_to_camera, dtype=np.float64))
    return {f"sh/L{i}_{'rgb'[ch]}": (float(c[i, ch]), 0.0, "exact") for i in range(9) for ch in range(3)}


def _render_set(spec: Any, cam: Any, light: _lighting.Lighting, seed: int) -> tuple[Any, np.ndarray, list[Any]]:
    scene = _render.build_scene(spec, [cam], light, spp=SPP)
    geo = _render.render_geometry(scene, 0, cam, spp=16, seed=seed)
    runs = scenes.radiance_runs(scene, 0, SPP, [seed + 10 + k for k in range(RENDERS)])
    lits = [_render.render_lit(scene, 0, light, spp=1, shadow_spp=64, seed=seed + 50 + k) for k in range(2)]
    return geo, runs, lits


def _losses(geo: Any, runs: np.ndarray, shadow: np.ndarray, light: _lighting.Lighting, cam: Any,
            mask: np.ndarray) -> dict[str, Figure]:
    """The paper's loss per render, with s = shadow and s = 1 (mean and standard error over renders)."""
    from .scenes import BankView

    e = float(light.params["exposure_scale"])
    v = BankView(scene_seed=0, view_index=0, lighting_name=light.kind, camera=cam, light=light,
                 albedo=geo.albedo.astype(np.float64), albedo_sem=np.zeros(geo.albedo.shape),
                 normal=geo.normal.astype(np.float64), sky=geo.sky_mask,
                 coverage=geo.coverage.astype(np.float64), normal_world=np.zeros(geo.normal.shape),
                 spread=np.zeros(geo.sky_mask.shape), full=runs, direct=runs, sun_visibility=shadow,
                 direct_ratio=shadow, direct_ratio_sem=np.zeros(shadow.shape), irradiance=np.zeros(geo.normal.shape),
                 exposure=e)
    out: dict[str, Figure] = {}
    for name, s in (("with_shadow", shadow), ("without_shadow", None)):
        per = np.array([paper_loss(r * e, s, v, mask) for r in runs])
        out[f"loss/{name}"] = (float(per.mean()), float(per.std(ddof=1) / math.sqrt(len(per))), "stat")
    return out


def sphere_on_ground() -> dict[str, Figure]:
    """A sphere on a grey ground under a 40-degree sun: lit and dark sides, lit and shadowed ground."""
    light = _lighting.sunsky(3, elevation_deg=40.0, azimuth_deg=30.0, turbidity=3.0, resolution=32)
    cam = scenes.view([0.3, 2.2, 4.5], [0.0, 1.0, 0.0], size=32, fov=60.0)
    geo, runs, lits = _render_set(scenes.sphere_spec(with_ground=True), cam, light, seed=11)
    nw = scenes.world_normals(geo.normal, cam)
    full = (geo.coverage >= 1 - 1e-6) & ~geo.sky_mask
    sphere = full & (nw[..., 1] < 0.999)  # the ground's normal is exactly +Y
    ground = full & ~sphere
    vis = np.mean([l.sun_visibility for l in lits], axis=0)
    cos = nw @ light.sun_direction
    regions = {"sphere_lit": sphere & (cos > 0.3), "sphere_dark": sphere & (cos < -0.1),
               "ground_lit": ground & (vis > 0.999), "ground_shadow": ground & (vis < 0.001)}
    out = _region_means(runs, regions)
    out.update(_coverage([l.sun_visibility for l in lits], ground, "ground"))
    out.update(_sh(light, cam))
    out.update(_losses(geo, runs, vis, light, cam, full))
    return out


def box_evening() -> dict[str, Figure]:
    """A box under a low sun seen from above: its long shadow on the ground."""
    light = _lighting.evening(0, elevation_deg=15.0, azimuth_deg=90.0, resolution=32)
    cam = scenes.view([0.0, 12.0, 0.01], [0.0, 0.0, 0.0], size=32, fov=60.0)
    geo, runs, lits = _render_set(scenes.box_spec(), cam, light, seed=23)
    nw = scenes.world_normals(geo.normal, cam)
    full = (geo.coverage >= 1 - 1e-6) & ~geo.sky_mask
    top = full & (geo.albedo[..., 1] < 0.35)  # the red box (green albedo 0.2) vs the grey ground (0.5)
    ground = full & ~top & (nw[..., 1] > 0.999)
    vis = np.mean([l.sun_visibility for l in lits], axis=0)
    regions = {"box_top": top, "ground_lit": ground & (vis > 0.999), "ground_shadow": ground & (vis < 0.001)}
    out = _region_means(runs, regions)
    out.update(_coverage([l.sun_visibility for l in lits], ground, "ground"))
    out.update(_losses(geo, runs, vis, light, cam, full))
    return out


def sphere_overcast() -> dict[str, Figure]:
    """The sphere on the ground under a sun-free sky: soft occlusion near the contact."""
    light = _lighting.overcast(5, elevation_deg=40.0, azimuth_deg=60.0, turbidity=9.0, resolution=32)
    cam = scenes.view([0.3, 2.2, 4.5], [0.0, 1.0, 0.0], size=32, fov=60.0)
    geo, runs, lits = _render_set(scenes.sphere_spec(with_ground=True), cam, light, seed=37)
    nw = scenes.world_normals(geo.normal, cam)
    full = (geo.coverage >= 1 - 1e-6) & ~geo.sky_mask
    sphere = full & (nw[..., 1] < 0.999)
    ground = full & ~sphere
    ratio = np.mean([l.direct_shadow for l in lits], axis=0)
    regions = {"sphere_top": sphere & (nw[..., 1] > 0.5), "sphere_bottom": sphere & (nw[..., 1] < -0.2),
               "ground": ground}
    out = _region_means(runs, regions)
    ratios = [float(l.direct_shadow[ground].mean()) for l in lits]
    out["direct_ratio/ground_mean"] = (float(np.mean(ratios)), float(np.std(ratios, ddof=1) / math.sqrt(2)), "stat")
    out.update(_sh(light, cam))
    out.update(_losses(geo, runs, ratio, light, cam, full))
    return out


SCENES: dict[str, Callable[[], dict[str, Figure]]] = {
    "sphere_on_ground_sunsky": sphere_on_ground,
    "box_evening": box_evening,
    "sphere_on_ground_overcast": sphere_overcast,
}


def measure(names: list[str] | None = None) -> dict[str, dict[str, Figure]]:
    """``{scene: {figure: (value, se, kind)}}`` for the named (default: all) regression scenes."""
    return {n: SCENES[n]() for n in (names or list(SCENES))}


def tolerance(pinned: Figure, now: Figure) -> float:
    """Allowed ``|now - pinned|`` (see the module docstring)."""
    value, se, kind = pinned
    tol = SIGMAS * math.hypot(se, now[1])
    if kind == "exact":
        tol += 1e-9 * max(abs(value), 1e-3)
    elif kind.startswith("count:"):
        tol += 1.0 / max(1, int(kind.split(":")[1]))
    return tol


def compare(pinned: dict[str, dict[str, Figure]], now: dict[str, dict[str, Figure]]) -> list[str]:
    """Messages, one per figure that moved (or vanished) beyond its tolerance; empty when all hold."""
    problems = []
    for scene, figs in pinned.items():
        for name, p in figs.items():
            if scene not in now or name not in now[scene]:
                problems.append(f"{scene}: figure {name} is no longer measured")
                continue
            n = now[scene][name]
            tol = tolerance(tuple(p), tuple(n))  # type: ignore[arg-type]
            if not abs(n[0] - p[0]) <= tol:
                problems.append(f"{scene}: figure {name} moved: pinned {p[0]:.6g} +- {p[1]:.2g}, now {n[0]:.6g} "
                                f"+- {n[1]:.2g} (allowed +-{tol:.2g}, {p[2]} figure)")
    return problems


def load(path: str | Path) -> dict[str, dict[str, Figure]]:
    """The pinned figures in ``path`` (written by :func:`pin`), by scene and name."""
    data = io.read_json(path)
    return {s: {k: (float(v[0]), float(v[1]), str(v[2])) for k, v in figs.items()} for s, figs in data["scenes"].items()}


def pin(path: str | Path) -> None:
    """Measure every regression scene and write the pins."""
    io.write_json(path, {"format": "physrelight-regression-pins", "version": 1,
                         "rule": "|now - pinned| <= 5 sqrt(se_now^2 + se_pinned^2) + quantum",
                         "scenes": {s: {k: list(v) for k, v in figs.items()} for s, figs in measure().items()}})


def main(argv: list[str] | None = None) -> int:
    """``python -m validation.regression``: ``--pin`` measures and writes the pins, ``--check`` compares a fresh
    measurement with them (exit status 1 when a figure moved)."""
    p = argparse.ArgumentParser(prog="python -m validation.regression", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pin", metavar="JSON", help="measure and write the pins to JSON")
    p.add_argument("--check", metavar="JSON", help="measure and compare with the pins in JSON")
    args = p.parse_args(argv)
    if args.pin:
        pin(args.pin)
        print(f"pinned -> {args.pin}")
    if args.check:
        problems = compare(load(args.check), measure())
        print("\n".join(problems) or "all regression figures hold")
        return 1 if problems else 0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
