"""Study 65: the sky reader's fit cost (the best hypothesis's mean robust cost per block, as
``physrelight.sun_from_sky.MAX_FIT_COST`` reads it) on every crop it reads, training side and rooms, beside the
reading's ``quotient`` self-relighting gain from study 64's JSON (run ``64_sun_in_view_seen.py training|indoor``
first, into ``out/64_training.json`` and ``out/64_indoor.json``). Run with the gate off (the costs of the crops
it would remove are the point), as the study did before the gate existed.

    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/65_fit_cost.py
"""

from __future__ import annotations

import json

import torch

import physrelight.sun_from_sky as sfs
from learned import Relighter
from learned.sky_lighting import read_sky_lighting
from physrelight import panorama
from physrelight.horizon import estimate_pitch
from synth.panorama_crops import make_crops, shipped_panoramas
from validation.bench.real import more_panoramas


def main() -> None:
    torch.set_num_threads(1)
    sfs.MAX_FIT_COST = float("inf")  # the gate off
    rel = Relighter.load()
    rec: dict = {}
    fit = sfs._fit

    def recording_fit(blocks, tab, se, sa):  # the first call is the coarse fit over the whole grid
        out = fit(blocks, tab, se, sa)
        if "cost" not in rec:
            best = max(float(out[0].max()), float(out[3]))
            rec["cost"] = -best / (sfs.EFFECTIVE_SAMPLES_PER_SR * blocks.solid_angle)
        return out

    sfs._fit = recording_fit
    prev = {(r["panorama"], r["index"]): r for g in ("training", "indoor") for r in json.load(open(f"out/64_{g}.json"))}
    for group in ("training", "indoor"):
        for pano in [p for p in shipped_panoramas() + more_panoramas() if p.group == group]:
            for c in make_crops(pano, 16, 0, samples=4):
                lin = c.linear()
                seg, _ = rel.photo_sky(lin)
                if not bool(seg.any()) or (group == "training" and c.stratum == "no_sky"):
                    continue
                R_est = panorama.level_camera(0.0, estimate_pitch(seg[0, 0], c.K))[:3, :3]
                rec.clear()
                reading = read_sky_lighting(lin, seg, c.K, R_est)
                if reading.source != "sky":
                    continue
                q = prev.get((pano.name, c.index), {}).get("quotient_psnr", {})
                gain = round(q["with_rule"] - q["today"], 1) if "with_rule" in q else None
                print(json.dumps({"group": group, "panorama": pano.name, "index": c.index,
                                  "fit_cost": round(rec["cost"], 3), "quotient_gain_db": gain}), flush=True)


if __name__ == "__main__":
    main()
