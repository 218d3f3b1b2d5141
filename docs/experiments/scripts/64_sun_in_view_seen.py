"""Study 64: the sky reader with and without the rule that a sun in the frame must be seen there
(:func:`physrelight.sun_from_sky.unseen_in_frame`), crop by crop.

For every crop of ``bench --real --full`` (16 per panorama, seed 0) of the training-side panoramas (``training``) or
the rooms (``indoor``), read as ``bench --real`` reads it (the segmenter's mask, relight's camera: the crop's field of
view, the pitch from the sky's horizon): the reading without the rule (``unseen_in_frame`` replaced by one that rules
nothing out) and with it; where either reads a sun on an outdoor crop, the ``quotient`` self-relighting PSNR of the
foreground today (the decomposition's lighting) and with each reading. ``rocket``: ``physrelight lighting``'s reading
of the example photo, both ways. Never the held-out panorama. Prints one JSON line per crop; writes the list.

    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/64_sun_in_view_seen.py training out/64_training.json
    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/64_sun_in_view_seen.py indoor out/64_indoor.json
    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/64_sun_in_view_seen.py rocket out/64_rocket.json
"""

from __future__ import annotations

import json
import math
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch

import physrelight.sun_from_sky as sfs
from learned import Relighter
from learned.sky_lighting import read_sky_lighting
from physrelight import metrics, panorama
from physrelight.horizon import estimate_pitch
from synth.panorama_crops import make_crops, shipped_panoramas
from validation.bench.methods import to_chw
from validation.bench.real import _display, _panorama_sun, more_panoramas


@contextmanager
def rule_off():
    """The reader as it was before the rule: no direction is ruled out (the check the reader builds per photo,
    :func:`physrelight.sun_from_sky._seen_check`, replaced by one that rules nothing out)."""
    kept = sfs._seen_check
    sfs._seen_check = lambda *a, **k: (lambda directions: np.zeros(len(np.asarray(directions).reshape(-1, 3)), bool))
    try:
        yield
    finally:
        sfs._seen_check = kept


def summary(reading, R_est: np.ndarray, truth_rotation: np.ndarray | None, sun: np.ndarray | None) -> dict:
    p = reading.posterior
    out = {"source": reading.source, "kind": p.sky_kind, "reason": reading.reason[:90]}
    if p.has_sun:
        out.update(elevation_deg=p.elevation_deg, azimuth_deg=p.azimuth_deg, area_sr=round(p.credible_area_sr, 3))
        if sun is not None and truth_rotation is not None:
            d = truth_rotation.T @ (R_est @ np.asarray(p.sun_direction))
            out["error_deg"] = round(math.degrees(math.acos(float(np.clip(d @ sun, -1, 1)))), 1)
    return out


def self_psnr(rel: Relighter, crop, lin, seg, readings: dict) -> dict:
    """``quotient`` self-relighting PSNR of the foreground: today's, and with each reading that has a sun."""
    photo = to_chw(crop.display())
    fg = ~torch.from_numpy(crop.sky)[None, None]
    src = torch.from_numpy(crop.lighting_sh(2) * crop.gain[None, :]).float()
    full = rel.relight_full_resolution(lin, seg, src, source_lighting=src, method="quotient")
    dec = {k: full["working"][k] for k in ("albedo", "normals", "shadow", "lighting", "foreground")}
    out = {}
    for name, (reading, R_est) in {"today": (None, None), **readings}.items():
        kw = {}
        if reading is not None:
            if reading.source != "sky":
                continue
            sh_c, sun_c = reading.camera(R_est)
            kw = {"read_source": torch.from_numpy(sh_c).float(), "read_source_sun": torch.from_numpy(sun_c).float()}
        relit = rel.relight_full_resolution(lin, seg, src, source_lighting=src, method="quotient",
                                            decomposition=dec, **kw)["relit"]
        out[name] = round(min(float(metrics.psnr(torch.where(fg, _display(relit), photo), photo, fg)), 50.0), 2)
    return out


def crops_rows(rel: Relighter, group: str) -> list[dict]:
    panos = [p for p in shipped_panoramas() + more_panoramas() if p.group == group]
    rows = []
    for pano in panos:
        sun = _panorama_sun(pano)
        for c in make_crops(pano, 16, 0, samples=4):
            lin = c.linear()
            seg, _ = rel.photo_sky(lin)
            if not bool(seg.any()):
                continue
            R_est = panorama.level_camera(0.0, estimate_pitch(seg[0, 0], c.K))[:3, :3]
            with rule_off():
                before = read_sky_lighting(lin, seg, c.K, R_est)
            after = read_sky_lighting(lin, seg, c.K, R_est)
            row = {"panorama": pano.name, "index": c.index,
                   "without_rule": summary(before, R_est, c.rotation, sun),
                   "with_rule": summary(after, R_est, c.rotation, sun)}
            if pano.outdoor and "sky" in (before.source, after.source):
                row["quotient_psnr"] = self_psnr(rel, c, lin, seg, {"without_rule": (before, R_est),
                                                                     "with_rule": (after, R_est)})
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def rocket_rows(rel: Relighter) -> list[dict]:
    from learned.lighting_cli import estimate_lighting
    from physrelight import io
    from physrelight.data import example_photo

    img = io.read_photo(example_photo()).image
    rows = []
    for name, ctx in (("without_rule", rule_off), ("with_rule", None)):
        if ctx is None:
            rec, _ = estimate_lighting(rel, img, fov_deg=60.0, fov_source="default")
        else:
            with ctx():
                rec, _ = estimate_lighting(rel, img, fov_deg=60.0, fov_source="default")
        rows.append({"way": name, **{k: rec[k] for k in ("source", "reason", "sun", "sky_kind", "sun_spread")}})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def main(argv: list[str]) -> int:
    if len(argv) != 2 or argv[0] not in ("training", "indoor", "rocket"):
        print("usage: 64_sun_in_view_seen.py training|indoor|rocket OUT.json", file=sys.stderr)
        return 2
    torch.set_num_threads(1)
    rel = Relighter.load()
    rows = rocket_rows(rel) if argv[0] == "rocket" else crops_rows(rel, argv[0])
    out = Path(argv[1])
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(rows, indent=1))
    tmp.replace(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
