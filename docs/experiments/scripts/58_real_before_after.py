"""Issue 43: `bench --real`'s figures before and after the fifteen more panoramas, from one run's real.json.

    python docs/experiments/scripts/58_real_before_after.py out/bench_real_more/real.json

The shipped panoramas' crops and targets do not depend on the other panoramas scored (checked: the 20 crops of a
`--quick` run at 9121540 equal, figure for figure, the same crops of a run with hdri_more), so "before" is the
run restricted to city, courtyard, forest (training), studio (indoor) and sunrise; "after" is all of it. Each figure
is the mean with the bench's 95 % interval (panoramas, then crops: `physrelight.stats.hierarchical_bootstrap`,
2000 resamples, seed 0).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))

from physrelight.stats import hierarchical_bootstrap  # noqa: E402

BEFORE = {"city", "courtyard", "forest", "studio", "sunrise"}


def iv(crops: list[dict], get) -> str:
    vals = [(get(c), c["panorama"]) for c in crops]
    vals = [(v, g) for v, g in vals if v is not None and np.isfinite(v)]
    if not vals:
        return "n/a"
    mi = hierarchical_bootstrap([v for v, _ in vals], [g for _, g in vals], samples=2000, seed=0)
    return f"{mi.mean:.3f} [{mi.lo:.3f}, {mi.hi:.3f}]"


def table(report: dict) -> list[str]:
    groups = {p["name"]: p["group"] for p in report["panoramas"]}
    rows = []

    def both(label, group, stratum, get):
        cells = []
        for keep in (lambda n: n in BEFORE, lambda n: True):
            cs = [c for c in report["crops"] if groups[c["panorama"]] == group and c["stratum"] == stratum
                  and keep(c["panorama"])]
            cells.append(iv(cs, get) if cs else "n/a")
        rows.append(f"| {label} | {cells[0]} | {cells[1]} |")

    def count(label, group, stratum, pred):
        cells = []
        for keep in (lambda n: n in BEFORE, lambda n: True):
            cs = [c for c in report["crops"] if groups[c["panorama"]] == group and c["stratum"] == stratum
                  and keep(c["panorama"])]
            cells.append(f"{sum(pred(c) for c in cs)} of {len(cs)} ({len({c['panorama'] for c in cs})} panoramas)")
        rows.append(f"| {label} | {cells[0]} | {cells[1]} |")

    seg = lambda k: (lambda c: c["segmentation"]["segmenter"][k])  # noqa: E731
    for g, name in (("training", "training"), ("heldout", "sunrise")):
        both(f"sky mask IoU, {name} crops with sky", g, "sky", seg("iou"))
        both(f"sky mask boundary F, {name} crops with sky", g, "sky", seg("boundary_f"))
    count("training crops with sky declined", "training", "sky", lambda c: bool(c["no_sky_reason"]))
    both("indoor crops: share of the image called sky", "indoor", "no_sky", seg("sky_called"))
    count("indoor crops called sky at all", "indoor", "no_sky", lambda c: c["segmentation"]["segmenter"]["sky_called"] > 0)
    for src, what in (("exact_view", "true camera, relight's mask"), ("target", "estimated camera and mask")):
        for g, name in (("training", "training"), ("heldout", "sunrise")):
            both(f"relit sky PSNR dB ({what}), {name}", g, "sky",
                 lambda c, s=src: float(np.mean([t[s]["psnr"] for t in c["sky"].values()])) if c["sky"] else None)
    for est in ("proposed", "prior_mean"):
        for g, name in (("training", "training"), ("heldout", "sunrise")):
            both(f"`{est}` shading error, {name}", g, "sky", lambda c, e=est: c["lighting"][e]["shading_error"])
    return ["| figure | before (shipped panoramas) | after (with hdri_more) |", "| --- | ---: | ---: |"] + rows


if __name__ == "__main__":
    print("\n".join(table(json.loads(Path(sys.argv[1]).read_text()))))
