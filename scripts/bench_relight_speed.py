"""Where `physrelight relight` spends its time on a 12-megapixel photo, stage by stage, in seconds and in box passes.

The photo is scikit-image's rocket.jpg enlarged to 4000 x 2669 (``skimage.transform.resize``, order 1, no
anti-aliasing) and saved as a PNG; the target is the forest HDRI (``--sun ELEV AZIM``: a clear sun instead). The
whole command runs in this process (``physrelight.cli.main``, PNG write included) at each ``--threads``; every
stage is timed by wrapping the function that does it (self time: a stage nested in another is not counted twice).
The unit is one 9 x 9 box filter pass over the same photo (``physrelight.guided_filter.box_filter`` on the
``(1, 3, H, W)`` float32 tensor, radius 4), timed in the same run at the same thread count, so the figures in passes
hold on a loaded machine.

    PYTHONPATH=. .venv/bin/python scripts/bench_relight_speed.py --runs 3 --threads 1 2 --json speed.json

The process's allocator is set as ``relight`` sets it (:func:`physrelight.cli_common.keep_freed_memory`) before
anything is timed. The table ends with the process's CPU seconds (user, system: all threads) over each run, which
a loaded machine does not inflate as it does the wall time.

The JSON holds, per thread count, the box pass (median of its timings before and after the runs), the 1-minute load
average before and after, and each stage's median seconds and passes. Results: docs/bench.md, "Speed of relight".

``--profile FILE`` also writes a cProfile of the last run (``python -m pstats FILE``).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
import resource
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

STAGES = ("load weights", "read photo", "sky mask: segmenter", "sky mask: noise", "sky mask: plausibility",
          "sky mask: refinement", "sky mask: growth", "sky mask: monochrome check", "camera", "decomposition",
          "relighting", "transfer to full resolution", "sky view", "exposure", "layers and the rest", "PNG write")


class StageClock:
    """Self time per stage: a wrapped call's time less that of the wrapped calls inside it."""

    def __init__(self) -> None:
        self.totals: dict[str, float] = defaultdict(float)
        self.stack: list[list[Any]] = []

    def wrap(self, fn: Callable, name: str | Callable[[str | None], str]) -> Callable:
        @functools.wraps(fn)
        def timed(*args: Any, **kwargs: Any) -> Any:
            parent = self.stack[-1][0] if self.stack else None
            label = name(parent) if callable(name) else name
            self.stack.append([label, time.perf_counter(), 0.0])
            try:
                return fn(*args, **kwargs)
            finally:
                lab, t0, inner = self.stack.pop()
                dt = time.perf_counter() - t0
                self.totals[lab] += dt - inner
                if self.stack:
                    self.stack[-1][2] += dt
        return timed


@contextlib.contextmanager
def patched(clock: StageClock):
    """Wrap the stages' functions where the pipeline looks them up; restore them after."""
    import learned.relighter as rl
    import learned.sky_segmentation as seg
    import physrelight.guided_filter as gf
    import physrelight.io as pio
    import physrelight.sky_mask as sm

    def in_sky(parent: str | None) -> str:
        # the guided upsampling of the sky's probability is part of bringing the mask to full size
        return "sky mask: refinement" if parent and parent.startswith("sky mask") else (parent or "other")

    spots = [
        (rl.Relighter, "load", "load weights", True),
        (pio, "read_photo", "read photo", False),
        (seg, "sky_mask_full_resolution", "sky mask: segmenter", False),
        (sm, "display_noise_sigma", "sky mask: noise", False),
        (sm, "resized_noise_roughness", "sky mask: noise", False),
        (sm, "log_noise_sigma", "sky mask: noise", False),
        (sm, "plausible_sky", "sky mask: plausibility", False),
        (gf, "guided_upsample", in_sky, False),
        (sm, "refine_sky_boundary", "sky mask: refinement", False),
        (sm, "grow_sky_by_colour", "sky mask: growth", False),
        (sm, "is_monochrome", "sky mask: monochrome check", False),
        (rl, "photo_camera", "camera", False),
        (rl.Relighter, "decompose_linear", "decomposition", False),
        (rl.Relighter, "relight_linear", "relighting", False),
        (rl, "transfer_to_full_resolution", "transfer to full resolution", False),
        (rl, "rendered_sky", "sky view", False),
        (rl, "exposure_gain", "exposure", False),
        (rl.Relighter, "_relight_tensors", "layers and the rest", False),
        (pio, "write_png", "PNG write", False),
    ]
    saved = []
    for owner, attr, name, is_classmethod in spots:
        orig = owner.__dict__[attr] if isinstance(owner, type) else getattr(owner, attr)
        saved.append((owner, attr, orig))
        if is_classmethod:
            setattr(owner, attr, classmethod(clock.wrap(orig.__func__, name)))
        else:
            setattr(owner, attr, clock.wrap(orig, name))
    try:
        yield
    finally:
        for owner, attr, orig in reversed(saved):
            setattr(owner, attr, orig)


def make_photo(path: Path, size: tuple[int, int] = (2669, 4000)) -> Path:
    """rocket.jpg enlarged to ``size (H, W)`` bilinearly without anti-aliasing, saved as an 8-bit PNG."""
    from PIL import Image
    from skimage import data
    from skimage.transform import resize

    big = resize(data.rocket(), size, order=1, anti_aliasing=False, preserve_range=True)
    Image.fromarray(np.clip(np.round(big), 0, 255).astype(np.uint8)).save(path, format="PNG")
    return path


def box_pass(photo: Path, runs: int) -> float:
    """Median seconds of one 9 x 9 box filter over the photo's ``(1, 3, H, W)`` float32 tensor."""
    from physrelight.guided_filter import box_filter
    from PIL import Image

    x = torch.from_numpy(np.asarray(Image.open(photo), dtype=np.float32) / 255.0).permute(2, 0, 1)[None].contiguous()
    box_filter(x, 4)  # warm-up
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        box_filter(x, 4)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


DEFAULT_TARGET = ("--env", "physrelight/data/hdri/forest.exr")


def relight_once(photo: Path, out: Path, threads: int, profile: Path | None = None,
                 target: tuple[str, ...] = DEFAULT_TARGET) -> dict[str, float]:
    """One `physrelight relight` in this process (``target``: the target's arguments): seconds per stage, and
    ``"total"``."""
    from physrelight.cli import main

    clock = StageClock()
    argv = ["relight", str(photo), *target, "--threads", str(threads), "--quiet", "-o", str(out)]
    prof = None
    if profile is not None:
        import cProfile

        prof = cProfile.Profile()
    with patched(clock), contextlib.redirect_stdout(sys.stderr):
        ru0 = resource.getrusage(resource.RUSAGE_SELF)
        t0 = time.perf_counter()
        if prof is not None:
            prof.enable()
        rc = main(argv)
        if prof is not None:
            prof.disable()
        total = time.perf_counter() - t0
        ru1 = resource.getrusage(resource.RUSAGE_SELF)
    if rc != 0:
        raise SystemExit(f"relight failed with status {rc}")
    if prof is not None:
        prof.dump_stats(str(profile))
    stages = dict(clock.totals)
    stages["other (CLI, checks)"] = total - sum(stages.values())
    stages["total"] = total
    # CPU seconds of the process (all threads) over the run: on a loaded machine the wall time includes waiting
    stages["cpu user"], stages["cpu system"] = ru1.ru_utime - ru0.ru_utime, ru1.ru_stime - ru0.ru_stime
    return stages


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=3, help="runs per thread count (median reported)")
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    p.add_argument("--photo", help="the photo (default: rocket.jpg enlarged to 4000 x 2669 in a temporary folder)")
    p.add_argument("--keep-output", help="copy the last relit PNG here")
    p.add_argument("--json", help="write the table as JSON here")
    p.add_argument("--profile", help="write a cProfile of the last run here")
    p.add_argument("--sun", nargs=2, type=float, metavar=("ELEV", "AZIM"),
                   help="relight to a clear sun (relight --sun) instead of the forest HDRI")
    args = p.parse_args()
    target = DEFAULT_TARGET if args.sun is None else ("--sun", *(f"{x:g}" for x in args.sun))
    with tempfile.TemporaryDirectory() as tmp:
        photo = Path(args.photo) if args.photo else make_photo(Path(tmp) / "rocket_4000x2669.png")
        out = Path(tmp) / "relit.png"
        result: dict[str, Any] = {"photo": str(args.photo or "rocket.jpg enlarged to 4000 x 2669"),
                                  "target": list(target),
                                  "cpu": _cpu(), "runs": args.runs, "threads": {}}
        try:
            from physrelight.cli_common import keep_freed_memory

            # the allocator as `relight` sets it, before the unit too: the box pass is timed as the command's
            # process would run it
            keep_freed_memory()
        except ImportError:  # the code before it (a "before" run): the allocator as it was
            pass
        for threads in args.threads:
            torch.set_num_threads(threads)
            load0 = os.getloadavg()[0]
            unit = box_pass(photo, max(3, args.runs))
            runs = [relight_once(photo, out, threads, target=target) for _ in range(args.runs)]
            if args.profile:
                relight_once(photo, out, threads, Path(f"{args.profile}.t{threads}"), target=target)
            unit_after = box_pass(photo, max(3, args.runs))
            box = statistics.median([unit, unit_after])
            names = [s for s in (*STAGES, "other (CLI, checks)", "total", "cpu user", "cpu system")
                     if any(s in r for r in runs)]
            table = {s: statistics.median([r.get(s, 0.0) for r in runs]) for s in names}
            result["threads"][str(threads)] = {
                "box_pass_s": box, "box_pass_before_after_s": [unit, unit_after],
                "load_average_1min": [load0, os.getloadavg()[0]], "stages_s": table,
                "stages_passes": {s: v / box for s, v in table.items()}, "totals_s": [r["total"] for r in runs]}
            print(f"\n--threads {threads}: box pass {box:.3f} s (before {unit:.3f}, after {unit_after:.3f}); "
                  f"load {load0:.2f} -> {os.getloadavg()[0]:.2f}; median of {args.runs}")
            print(f"{'stage':32s} {'seconds':>8s} {'passes':>8s}")
            for s, v in table.items():
                print(f"{s:32s} {v:8.3f} {v / box:8.1f}")
        if args.keep_output:
            Path(args.keep_output).write_bytes(out.read_bytes())
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2, sort_keys=True) + "\n")


def _cpu() -> str:
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return f"{line.split(':', 1)[1].strip()}, {os.cpu_count()} cores"
    return f"{os.cpu_count()} cores"


if __name__ == "__main__":
    main()
