"""Speed of the synthetic-data pipeline (not a test: reports medians on a noisy machine).

    .venv/bin/python scripts/bench_synth.py [--res 128] [--spp 64] [--repeats 3] [--json out/bench_synth.json]

Renders the same scenes (4 views x 3 lightings: sunsky, overcast, hdri) with the full
writer (ground truth, photos, EXR/PNG files) and with a bare ``mi.render`` of the same
Mitsuba scene (path tracer only), after one warm-up run that fills Dr.Jit's kernel cache.
Reports view-lightings per minute, the overhead ratio, and the cost split per phase.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from physrelight import io
from synth import writer
from synth.backend import load_mitsuba


def bare_render_seconds(config: writer.SynthConfig, index: int) -> float:
    """Seconds of ``mi.render`` alone for every view x lighting of scene ``index``."""
    from synth import render

    mi = load_mitsuba()
    _, spec, views, lights = writer.scene_inputs(config, index)
    total = 0.0
    for light in lights:
        mscene = render.build_scene(spec, views, light, config.spp, config.max_depth)
        for vi in range(len(views)):
            t = time.perf_counter()
            np.array(mi.render(mscene, sensor=vi, spp=config.spp, seed=vi))
            total += time.perf_counter() - t
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--res", type=int, default=128)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--scenes", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    config = writer.SynthConfig(scenes=args.scenes, views=4, lights=3, res=args.res, spp=args.spp,
                                kinds=("sunsky", "overcast", "hdri"))
    units = config.scenes * config.views * config.lights

    runs, splits, bare = [], [], []
    for rep in range(args.repeats + 1):  # the first run warms the kernel cache
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            writer.write_dataset(tmp, config, progress=False)
            elapsed = time.perf_counter() - t
            split: dict[str, float] = {}
            for p in Path(tmp).glob("scene_*/timing.json"):
                for k, v in io.read_json(p).items():
                    split[k] = split.get(k, 0.0) + v
        b = sum(bare_render_seconds(config, i) for i in range(config.scenes))
        if rep:
            runs.append(elapsed)
            splits.append(split)
            bare.append(b)
    total = statistics.median(runs)
    bare_s = statistics.median(bare)
    split = {k: statistics.median(s[k] for s in splits) for k in splits[0]}
    result = {
        "config": config.to_json(),
        "view_lightings_per_minute": 60.0 * units / total,
        "seconds_per_view_lighting": total / units,
        "bare_mi_render_seconds_per_view_lighting": bare_s / units,
        "overhead_ratio": total / bare_s,
        "split_seconds_per_view_lighting": {k: v / units for k, v in sorted(split.items())},
        "repeats": args.repeats,
    }
    print(f"{units} view-lightings per run at {args.res}x{args.res}, {args.spp} spp, median of {args.repeats}")
    print(f"  view-lightings per minute      {result['view_lightings_per_minute']:8.1f}")
    print(f"  pipeline s / view-lighting     {result['seconds_per_view_lighting']:8.3f}")
    print(f"  bare mi.render s / view-light  {result['bare_mi_render_seconds_per_view_lighting']:8.3f}")
    print(f"  overhead ratio                 {result['overhead_ratio']:8.2f}")
    for k, v in result["split_seconds_per_view_lighting"].items():
        print(f"  {k:<30} {v:8.3f} s")
    if args.json:
        io.write_json(args.json, result)


if __name__ == "__main__":
    main()
