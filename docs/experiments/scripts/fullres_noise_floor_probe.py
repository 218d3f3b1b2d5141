"""How much of the 256-px relit l1 is the path tracer's noise in the target?

The study (`physrelight bench --full-resolution`) scores 256-px outputs against 256-px path-traced targets
rendered at 64 spp, and the 64-px working result against those targets box-downsampled (16 pixels averaged:
a quarter of the noise). This probe re-scores the same outputs, on the scenes of a second render of the same
folder at 4x the samples (`--spp 256`: half the noise; same seed, so the same scenes, cameras, lightings and
G-buffers, checked), against both targets. With l1 = l1_0 + c sigma^2 for noise small against the error,
l1_0 ~ (4 l1(256 spp) - l1(64 spp)) / 3 is the noise-free extrapolation.

Usage: .venv/bin/python docs/experiments/scripts/fullres_noise_floor_probe.py data/heldout256 data/heldout256_spp256
"""

from __future__ import annotations

import json
import sys

import numpy as np
import torch

from learned import Relighter
from physrelight.full_resolution import working_resolution
from physrelight import colour, metrics
from synth.dataset import SynthDataset
from validation.bench import full_resolution as fr
from validation.bench.data import load_dataset
from validation.bench.methods import to_chw
from validation.bench.protocols import cross_pairs, informative_pairs


def main(data: str, ref: str) -> None:
    torch.set_num_threads(1)
    lo, hi = SynthDataset(data, split="all", mode="full"), SynthDataset(ref, split="all", mode="full")
    scenes = hi.scenes
    for s in scenes:  # the same scenes and G-buffers (only the path tracer's samples differ)
        for v in range(len(hi.record(s)["views"])):
            a = lo.load(s, v, None, ("sky_mask", "normal", "depth"))
            b = hi.load(s, v, None, ("sky_mask", "normal", "depth"))
            assert all(np.array_equal(a[k], b[k]) for k in a), (s, v)
    views = [v for v in load_dataset(data, max_scenes=len(scenes), with_physical=False)]
    pairs, _ = informative_pairs(cross_pairs(views))
    relighter = Relighter.load()
    depth = {v.name: to_chw(lo.load(v.scene, v.view, None, ("depth",))["depth"]) for v in views}
    rows = []
    for p in pairs:
        rad = hi.load(p.view.scene, p.view.view, p.target, ("radiance",))["radiance"]
        lin = to_chw(rad).double() * torch.as_tensor(p.gain)[None, :, None, None]
        t_ref = colour.to_ldr(lin.clamp_min(0).float()).double()
        t_ref_lo = colour.to_ldr(fr.box_down(lin.clamp_min(0), 4).float()).double()
        t, t_lo = p.target_display().double(), fr.low_res_target(p, 4).double()
        fg = p.foreground()
        fg_lo = fr.low_res_foreground(fg, 4)
        image, sky = p.image(), p.sky()
        small, small_sky = working_resolution(image, sky, 64)
        dec = {"small": relighter.decompose_linear(small, small_sky), "full": relighter.decompose_linear(image, sky)}
        for method in fr.METHODS:
            outs = fr.relight_variants(relighter, image, sky, p.target_lighting(), p.source_lighting(), method, 64, dec)
            r = {"key": p.key, "scene": p.view.scene, "method": method}
            w = p.display(outs["working"]).double()
            r["working_64spp"], r["working_256spp"] = (float(metrics.l1(w, x, fg_lo)) for x in (t_lo, t_ref_lo))
            for c in ("bilinear", "guided", "fast_guided", "direct"):
                d = p.display(outs[c]).double()
                r[f"{c}_64spp"], r[f"{c}_256spp"] = (float(metrics.l1(d, x, fg)) for x in (t, t_ref))
                r[f"halo_{c}_64spp"], r[f"halo_{c}_256spp"] = (
                    float(metrics.edge_band_l1(d, x, depth[p.view.name], fg, k=fr.HALO_K)) for x in (t, t_ref))
            rows.append(r)
        p.release()
    out = {"pairs": len(pairs), "scenes": list(scenes)}
    for method in fr.METHODS:
        rs = [r for r in rows if r["method"] == method]
        m = {}
        for c in ("working", "bilinear", "guided", "fast_guided", "direct", "halo_bilinear", "halo_guided",
                  "halo_fast_guided", "halo_direct"):
            a = float(np.mean([r[f"{c}_64spp"] for r in rs]))
            b = float(np.mean([r[f"{c}_256spp"] for r in rs]))
            m[c] = {"64spp": round(a, 5), "256spp": round(b, 5), "extrapolated": round((4 * b - a) / 3, 5)}
        m["guided - working"] = {k: round(m["guided"][k] - m["working"][k], 5) for k in m["guided"]}
        m["bilinear - working"] = {k: round(m["bilinear"][k] - m["working"][k], 5) for k in m["guided"]}
        out[method] = m
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main(*sys.argv[1:3])
