"""The synthetic bench's estimated track with the source lighting read from the photo's sky (issue 44), for
docs/experiments/61-sun-in-relighter.md: a bench level's scenes and pairs (``quick``: ``bench --quick``'s own scenes,
rendered here, seeded; ``full``: ``bench --full --data DIR``'s, i.e. every scene of the data folder plus the
generated strata and time-lapse scenes), each learned method of the estimated track as the bench runs it
(``validation.bench.methods.Learned``) and the same with ``read_source`` from
:func:`learned.sky_lighting.read_sky_lighting` on the photo's true sky mask through relight's camera (the view's
intrinsics, the pitch from the sky's horizon): where the sky is informative it replaces the decomposition's lighting,
elsewhere the method is today's to the byte (checked here: the pairs not read score the same).

Per method (``proposed``, ``quotient``) and group of pairs, l1 today and with the sky read, and the difference's 95 %
interval by a scene bootstrap (:func:`physrelight.stats.paired_bootstrap`, scenes resampled, seeded, as
``bench --full-resolution`` gives its differences). ``all`` is the bench's headline set (every cross-relighting pair
with the photo as rendered: ``docs/bench.md``'s 636 pairs on ``data/heldout``). Per source lighting kind: photos
read, the read sun's angle to the true one, l1 on ``all``. Printed, and written as JSON (atomically).

    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/sun_in_relighter_synthetic.py [quick|full] \
        [--data DIR] [--json PATH] [--samples 2000] [--seed 0]
"""

from __future__ import annotations

import argparse
import datetime
import os
import re
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch

from learned import Relighter
from learned.sky_lighting import read_sky_lighting
from physrelight import io, panorama
from physrelight.horizon import estimate_pitch
from physrelight.stats import paired_bootstrap
from validation.bench.methods import Learned
from validation.bench.protocols import VARIANTS, Pair, cross_pairs, informative_pairs, timelapse_pairs
from validation.bench.run import DEFAULT_FULL_DATA, LEVELS, evaluate, gather_views
from validation.bench.scores import MethodRun
from validation.bench.strata import members
from validation.common import machine

RESULTS = Path(__file__).resolve().parents[1] / "results"
METHODS = ("proposed", "quotient")
KINDS = ("sunsky", "evening", "overcast", "hdri")


class SkyRead(Learned):
    """:class:`Learned` with the photo's lighting read from its sky (one reading per source photo).

    ``readings`` may be shared between methods: a reading depends on the photo alone.
    """

    def __init__(self, relighter, method: str, readings: dict[str, Any] | None = None) -> None:
        super().__init__(relighter, method, name=f"{method}_sky")
        self.readings: dict[str, Any] = {} if readings is None else readings

    @staticmethod
    def key(pair: Pair) -> str:
        return f"{pair.view.name}:{pair.source}:{pair.variant}"

    def reading(self, pair: Pair):
        key = self.key(pair)
        if key not in self.readings:
            sky = pair.sky()
            h, w = sky.shape[-2:]
            K = pair.view.K if pair.view.K is not None else panorama.view_intrinsics(60.0, w, h)
            R = panorama.level_camera(0.0, estimate_pitch(sky[0, 0], K))[:3, :3]
            r = read_sky_lighting(pair.image(), sky, K, R)
            self.readings[key] = (r, None if r.source != "sky" else r.camera(R))
        return self.readings[key]

    def __call__(self, pair: Pair) -> torch.Tensor:
        _, cam = self.reading(pair)
        if cam is None:
            return super().__call__(pair)
        image = pair.image()
        return self.relighter.relight_full_resolution(
            image, pair.sky(), pair.target_lighting(), source_lighting=pair.source_lighting(), method=self.method,
            working_res=min(image.shape[-2:]), read_source=torch.from_numpy(cam[0]).float(),
            read_source_sun=torch.from_numpy(cam[1]).float())["relit"]


def sun_direction(sh_rgb: np.ndarray) -> np.ndarray | None:
    """Unit direction ``(3,)`` (the SH's frame: x, y, z) of a sun's order-2 SH ``(9, 3)`` from its band 1
    (``(L11, L1-1, L10)`` is proportional to ``(x, y, z)`` for a delta, DESIGN.md's ordering), luminance-weighted;
    None when it carries no light (no sun above the horizon)."""
    lum = np.asarray(sh_rgb, dtype=np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    d = np.array([lum[3], lum[1], lum[2]])
    n = float(np.linalg.norm(d))
    return d / n if n > 1e-12 else None


def reading_kind(r) -> str:
    """``"sky"`` or the fallback's reason up to its first colon or parenthesis (its kind, without numbers)."""
    # the reason's words without its figures (parenthesised) and its detail (after a colon), to count by kind
    return r.source if r.source == "sky" else re.sub(r"\s*\([^)]*\)", "", r.reason.split(":")[0]).strip()


def compare(base: MethodRun, read: MethodRun, pairs: Sequence[Pair], idx: Sequence[int], samples: int,
            seed: int) -> dict[str, Any] | None:
    """l1 (and l1 at best gain) today and with the sky read on ``pairs[idx]``, the difference (read - today) with its
    scene-bootstrap 95 % interval; None for an empty group."""
    idx = list(idx)
    if not idx:
        return None
    b, r = base.mean(idx), read.mean(idx)
    d = paired_bootstrap(read.values["l1"][idx], base.values["l1"][idx], [pairs[i].view.scene for i in idx],
                         samples=samples, seed=seed)
    return {"pairs": len(idx), "scenes": d.groups, "l1_today": b["l1"], "l1_sky": r["l1"], "l1_diff": d.diff,
            "l1_diff_lo": d.lo, "l1_diff_hi": d.hi, "gain_l1_today": b["gain_l1"], "gain_l1_sky": r["gain_l1"]}


def photos_by_kind(pairs: Sequence[Pair], readings: dict[str, Any]) -> dict[str, Any]:
    """Per source lighting kind, over the source photos as rendered (no variant): how many were read, the fallbacks'
    reasons, and the read sun's angle to the true one (degrees, in the view's camera frame; photos whose true
    lighting has a sun above the horizon)."""
    photos: dict[str, Pair] = {}
    for p in pairs:
        if not p.variant:
            photos.setdefault(SkyRead.key(p), p)
    out: dict[str, Any] = {}
    for key, p in photos.items():
        kind = p.view.lights[p.source].kind
        e = out.setdefault(kind, {"photos": 0, "read": 0, "readings": {}, "sun_error_deg": []})
        r, cam = readings[key]
        e["photos"] += 1
        e["read"] += cam is not None
        k = reading_kind(r)
        e["readings"][k] = e["readings"].get(k, 0) + 1
        truth = sun_direction(p.view.sun_sh[p.source])
        if cam is not None and truth is not None:
            est = sun_direction(cam[1])
            if est is not None:
                e["sun_error_deg"].append(float(np.degrees(np.arccos(np.clip(est @ truth, -1.0, 1.0)))))
    for e in out.values():
        errs = e.pop("sun_error_deg")
        e["sun_error_deg"] = ({"photos": len(errs), "median": float(np.median(errs)),
                               "p90": float(np.percentile(errs, 90))} if errs else None)
    return out


def run(level_name: str, data: str | None, samples: int, seed: int, command: str) -> dict[str, Any]:
    torch.set_num_threads(1)
    level = LEVELS[level_name]
    t0 = time.perf_counter()
    load_before = os.getloadavg()
    views, info = gather_views(level, data, print)
    variant_views = [v.name for v in views if v.view == 0 and v.group != "timelapse"][: level.variant_views]
    cross, _ = informative_pairs(cross_pairs(views, VARIANTS, variant_views))
    tl, _ = informative_pairs(timelapse_pairs(views))
    pairs = cross + tl
    print(f"{len(views)} views, {len(pairs)} pairs ({time.perf_counter() - t0:.0f} s)", flush=True)
    relighter = Relighter.load()
    readings: dict[str, Any] = {}
    bench_all = members(pairs)["all"]
    result: dict[str, Any] = {
        "format": "physrelight-sun-in-relighter-synthetic", "command": command, "level": level_name,
        "data": info.get("data"), "data_scenes": info.get("data_scenes"), "views": len(views),
        "pairs": {"every": len(pairs), "cross": len(cross), "all": len(bench_all), "timelapse": len(tl)},
        "bootstrap": {"samples": samples, "seed": seed, "level": 0.95, "unit": "scene",
                      "function": "physrelight.stats.paired_bootstrap"},
        "methods": {}}
    for method in METHODS:
        base = evaluate(method, Learned(relighter, method), pairs, lambda m: print(m, flush=True))
        sky = SkyRead(relighter, method, readings)
        read = evaluate(sky.name, sky, pairs, lambda m: print(m, flush=True))
        failures = base.failures + read.failures
        if failures or base.nonfinite or read.nonfinite:
            raise RuntimeError(f"{method}: {len(failures)} failures, {base.nonfinite + read.nonfinite} non-finite "
                               f"outputs: {failures[:3]}")
        used = [i for i, p in enumerate(pairs) if sky.reading(p)[1] is not None]
        unused = sorted(set(range(len(pairs))) - set(used))
        # the fallback is today's method to the byte: the pairs not read must score exactly the same
        fallback_diff = float(np.abs(read.values["l1"][unused] - base.values["l1"][unused]).max()) if unused else 0.0
        groups = {"every": range(len(pairs)), "all": bench_all, "cross": range(len(cross)),
                  "timelapse": range(len(cross), len(pairs)), "read": used,
                  "all_read": sorted(set(used) & set(bench_all))}
        by_kind = {k: [i for i in bench_all if pairs[i].view.lights[pairs[i].source].kind == k] for k in KINDS}
        entry = {"groups": {g: compare(base, read, pairs, ix, samples, seed) for g, ix in groups.items()},
                 "all_by_source_kind": {k: compare(base, read, pairs, ix, samples, seed)
                                        for k, ix in by_kind.items() if ix},
                 "fallback_pairs_max_abs_l1_diff": fallback_diff,
                 "seconds_per_image_median": {"today": float(np.median(base.seconds)),
                                              "sky": float(np.median(read.seconds))}}
        result["methods"][method] = entry
        n_read = sum(cam is not None for _, cam in readings.values())
        print(f"{method}: photos read {n_read} of {len(readings)}, pairs read {len(used)} of {len(pairs)}; "
              f"pairs not read identical: {fallback_diff == 0.0}", flush=True)
        for g, e in entry["groups"].items():
            if e is not None:
                print(f"  {g} ({e['pairs']} pairs, {e['scenes']} scenes): l1 {e['l1_today']:.4f} -> {e['l1_sky']:.4f} "
                      f"(diff {e['l1_diff']:+.4f} [{e['l1_diff_lo']:+.4f}, {e['l1_diff_hi']:+.4f}]), at best gain "
                      f"{e['gain_l1_today']:.4f} -> {e['gain_l1_sky']:.4f}", flush=True)
        for k, e in entry["all_by_source_kind"].items():
            print(f"  all, source {k} ({e['pairs']} pairs): l1 {e['l1_today']:.4f} -> {e['l1_sky']:.4f} "
                  f"(diff {e['l1_diff']:+.4f} [{e['l1_diff_lo']:+.4f}, {e['l1_diff_hi']:+.4f}])", flush=True)
    kinds: dict[str, int] = {}
    for r, _ in readings.values():
        kinds[reading_kind(r)] = kinds.get(reading_kind(r), 0) + 1
    result["readings"] = {"photos": len(readings), "read": sum(cam is not None for _, cam in readings.values()),
                          "kinds": kinds, "by_source_kind": photos_by_kind(pairs, readings)}
    print("readings:", kinds)
    for k, e in result["readings"]["by_source_kind"].items():
        s = e["sun_error_deg"]
        print(f"  {k}: read {e['read']} of {e['photos']} photos as rendered {e['readings']}"
              + (f", sun error median {s['median']:.1f} deg, p90 {s['p90']:.1f} ({s['photos']} photos)" if s else ""))
    result["seconds"] = round(time.perf_counter() - t0, 1)
    result["machine"] = {**machine(), "torch_threads": torch.get_num_threads(),
                         "load_average_before": [round(x, 2) for x in load_before],
                         "load_average_after": [round(x, 2) for x in os.getloadavg()]}
    result["date"] = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    print(f"{result['seconds']:.0f} s")
    return result


def _fail(message: str) -> None:
    """Bad input: one line on stderr, exit status 2."""
    print(f"sun_in_relighter_synthetic: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("level", nargs="?", default="quick", choices=sorted(LEVELS))
    parser.add_argument("--data", default=None, help="a synth folder, as `bench --data` takes it (full: default "
                        f"{DEFAULT_FULL_DATA}; quick: its first scenes instead of the generated ones)")
    parser.add_argument("--json", default=None, help="where to write the figures (default: docs/experiments/results/"
                        "61_sun_in_relighter_<level>[_<data folder>].json)")
    parser.add_argument("--samples", type=int, default=2000, help="bootstrap resamples (default 2000)")
    parser.add_argument("--seed", type=int, default=0, help="the bootstrap's seed (default 0)")
    args = parser.parse_args(argv)
    data = DEFAULT_FULL_DATA if args.data is None and LEVELS[args.level].base is None else args.data
    if data is not None and not (Path(data) / "manifest.json").is_file():
        _fail(f"no synth dataset at {data!r} (manifest.json missing): render it as docs/learned.md says")
    if args.samples < 1:
        _fail(f"--samples must be >= 1, got {args.samples}")
    out = Path(args.json) if args.json else RESULTS / (
        f"61_sun_in_relighter_{args.level}" + (f"_{Path(data).name}" if data is not None else "") + ".json")
    command = "docs/experiments/scripts/sun_in_relighter_synthetic.py " + " ".join(sys.argv[1:] if argv is None
                                                                                 else argv)
    result = run(args.level, data, args.samples, args.seed, command.strip())
    io.write_json(out, result)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
