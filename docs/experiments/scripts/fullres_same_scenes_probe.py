"""Is a 256-px synth folder the same scenes, views and lightings as a 64-px one of the same seed?

Compares, per scene of both folders: the camera poses and intrinsics (K scaled by 256/64), the lighting
records, the photo parameters (exposure is metered from the render: it may move a little), the sky masks
(256 majority-downsampled vs 64), and the path-traced radiance box-downsampled 256 -> 64 against the
64-px render. The radiance difference mixes two renders' Monte-Carlo noise: its per-pixel spread gives
an estimate of the 256-px render's own noise (see the printout), the floor under any l1 against it.

Usage: .venv/bin/python docs/experiments/scripts/fullres_same_scenes_probe.py data/heldout data/heldout256
"""

from __future__ import annotations

import json
import sys

import numpy as np
import torch

from physrelight import colour
from synth.dataset import SynthDataset
from synth.photo import photo_gain


def main(lo_root: str, hi_root: str) -> None:
    lo, hi = SynthDataset(lo_root, split="all", mode="full"), SynthDataset(hi_root, split="all", mode="full")
    rows = []
    for scene in hi.scenes:
        rl, rh = lo.record(scene), hi.record(scene)
        f = rh["views"][0]["width"] / rl["views"][0]["width"]
        pose = max(float(np.abs(np.asarray(a["world_to_camera"]) - np.asarray(b["world_to_camera"])).max())
                   for a, b in zip(rl["views"], rh["views"]))
        K = max(float(np.abs(np.asarray(a["K"])[:2] * f - np.asarray(b["K"])[:2]).max() / f)
                for a, b in zip(rl["views"], rh["views"]))
        kinds = [(a["kind"], b["kind"]) for a, b in zip(rl["lights"], rh["lights"])]
        sun = max((float(np.abs(np.asarray(a["sun_direction"]) - np.asarray(b["sun_direction"])).max())
                   if a["sun_direction"] is not None else 0.0) for a, b in zip(rl["lights"], rh["lights"]))
        sh = max(float(np.abs(np.asarray(a["sh"]["world"]["2"]) - np.asarray(b["sh"]["world"]["2"])).max())
                 for a, b in zip(rl["lights"], rh["lights"]))
        for v in range(len(rh["views"])):
            skl = lo.load(scene, v, None, ("sky_mask",))["sky_mask"] > 0.5
            skh = torch.from_numpy(hi.load(scene, v, None, ("sky_mask",))["sky_mask"].astype(np.float32))
            skh = (torch.nn.functional.avg_pool2d(skh[None, None], int(f))[0, 0] >= 0.5).numpy()
            for li in range(len(rh["lights"])):
                a = lo.load(scene, v, li, ("radiance", "photo_params"))
                b = hi.load(scene, v, li, ("radiance", "photo_params"))
                down = torch.nn.functional.avg_pool2d(torch.from_numpy(b["radiance"]).permute(2, 0, 1)[None],
                                                      int(f))[0].permute(1, 2, 0).numpy()
                fg = ~skl & ~skh
                g = photo_gain(a["photo_params"])  # display units of the 64-px photo
                disp = lambda x: colour.to_ldr(np.clip(x * g, 0, None))  # noqa: E731
                d = disp(down) - disp(a["radiance"])
                rel = (down - a["radiance"]) / np.maximum(a["radiance"], 1e-3)
                rows.append({"scene": scene, "view": v, "light": li, "pose": pose, "K": K, "kinds_equal":
                             all(x == y for x, y in kinds), "sun": sun, "sh": sh,
                             "sky_agree": float((skl == skh).mean()),
                             "ev_lo": a["photo_params"]["ev"], "ev_hi": b["photo_params"]["ev"],
                             "display_l1_fg": float(np.abs(d[fg]).mean()),
                             "display_mean_diff_fg": float(d[fg].mean()),
                             "display_rms_fg": float(np.sqrt(np.mean(d[fg] ** 2))),
                             "rel_rms_fg": float(np.sqrt(np.mean(rel[fg] ** 2))),
                             "rel_median_abs_fg": float(np.median(np.abs(rel[fg])))})
    keys = ("pose", "K", "sun", "sh")
    print(json.dumps({k: max(r[k] for r in rows) for k in keys}, indent=1))
    print("kinds equal:", all(r["kinds_equal"] for r in rows), " scenes:", len(hi.scenes), " images:", len(rows))
    print("sky agreement (256 majority-downsampled vs 64): min %.4f mean %.4f" % (
        min(r["sky_agree"] for r in rows), np.mean([r["sky_agree"] for r in rows])))
    ev = np.array([r["ev_hi"] - r["ev_lo"] for r in rows])
    print("photo exposure 256 - 64 (EV): mean %+.3f, max |.| %.3f" % (ev.mean(), np.abs(ev).max()))
    l1 = np.array([r["display_l1_fg"] for r in rows])
    md = np.array([r["display_mean_diff_fg"] for r in rows])
    print("display l1 (fg) box(256) vs 64: mean %.4f median %.4f max %.4f; mean signed %+.4f" % (
        l1.mean(), np.median(l1), l1.max(), md.mean()))
    rms = np.array([r["display_rms_fg"] for r in rows])
    print("display rms (fg) box(256) vs 64: mean over images %.4f (= sqrt(var64 + var256 / 16) per pixel)" % rms.mean())
    rr = np.array([r["rel_median_abs_fg"] for r in rows])
    print("median |relative radiance difference| (fg): mean over images %.4f" % rr.mean())


if __name__ == "__main__":
    main(*sys.argv[1:3])
