"""The synthetic bench's estimated track with the source lighting read from the photo's sky (issue 44), for
docs/experiments/61-sun-in-relighter.md: ``bench --quick``'s own scenes and pairs (rendered here, seeded), each learned
method of the estimated track as the bench runs it (``validation.bench.methods.Learned``) and the same with
``read_source`` from :func:`learned.sky_lighting.read_sky_lighting` on the photo's true sky mask through relight's
camera (the view's intrinsics, the pitch from the sky's horizon): where the sky is informative it replaces the
decomposition's lighting, elsewhere the method is today's to the byte.

    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/sun_in_relighter_synthetic.py [quick|full]
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch

from learned import Relighter
from learned.sky_lighting import read_sky_lighting
from physrelight import panorama
from physrelight.horizon import estimate_pitch
from validation.bench.methods import Learned
from validation.bench.protocols import VARIANTS, cross_pairs, informative_pairs, timelapse_pairs
from validation.bench.run import LEVELS, evaluate, gather_views


class SkyRead(Learned):
    """:class:`Learned` with the photo's lighting read from its sky (one reading per source photo)."""

    def __init__(self, relighter, method: str) -> None:
        super().__init__(relighter, method, name=f"{method}_sky")
        self.readings: dict[str, object] = {}

    def reading(self, pair):
        key = f"{pair.view.name}:{pair.source}:{pair.variant}"
        if key not in self.readings:
            sky = pair.sky()
            h, w = sky.shape[-2:]
            K = pair.view.K if pair.view.K is not None else panorama.view_intrinsics(60.0, w, h)
            R = panorama.level_camera(0.0, estimate_pitch(sky[0, 0], K))[:3, :3]
            r = read_sky_lighting(pair.image(), sky, K, R)
            self.readings[key] = (r, None if r.source != "sky" else r.camera(R))
        return self.readings[key]

    def __call__(self, pair) -> torch.Tensor:
        _, cam = self.reading(pair)
        if cam is None:
            return super().__call__(pair)
        image = pair.image()
        return self.relighter.relight_full_resolution(
            image, pair.sky(), pair.target_lighting(), source_lighting=pair.source_lighting(), method=self.method,
            working_res=min(image.shape[-2:]), read_source=torch.from_numpy(cam[0]).float(),
            read_source_sun=torch.from_numpy(cam[1]).float())["relit"]


def main(level_name: str = "quick") -> None:
    torch.set_num_threads(1)
    level = LEVELS[level_name]
    t0 = time.perf_counter()
    views, info = gather_views(level, None, print)
    variant_views = [v.name for v in views if v.view == 0 and v.group != "timelapse"][: level.variant_views]
    cross, _ = informative_pairs(cross_pairs(views, VARIANTS, variant_views))
    tl, _ = informative_pairs(timelapse_pairs(views))
    pairs = cross + tl
    print(f"{len(views)} views, {len(pairs)} pairs ({time.perf_counter() - t0:.0f} s)")
    relighter = Relighter.load()
    for method in ("proposed", "quotient"):
        base = evaluate(method, Learned(relighter, method), pairs)
        sky = SkyRead(relighter, method)
        read = evaluate(sky.name, sky, pairs)
        readings = [r for r, _ in sky.readings.values()]
        n_read = sum(r.source == "sky" for r in readings)
        used = [i for i, p in enumerate(pairs) if sky.reading(p)[1] is not None]
        print(f"{method}: photos read {n_read} of {len(readings)}, pairs read {len(used)} of {len(pairs)}")
        groups = {"all pairs": None, "cross pairs": list(range(len(cross))),
                  "time-lapse pairs": list(range(len(cross), len(pairs))), "pairs read": used}
        for title, idx in groups.items():
            b, r = base.mean(idx), read.mean(idx)
            print(f"  {title}: l1 {b['l1']:.4f} -> {r['l1']:.4f}, at best gain {b['gain_l1']:.4f} -> "
                  f"{r['gain_l1']:.4f}")
        kinds = {}
        for r in readings:
            kinds[r.source if r.source == "sky" else r.reason.split(":")[0].split("(")[0].strip()] = \
                kinds.get(r.source if r.source == "sky" else r.reason.split(":")[0].split("(")[0].strip(), 0) + 1
        print("  readings:", kinds)
    print(f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "quick")
