"""Study 42: sun shadows from a ground-plane depth (issue 26), chosen on data/val5, read on the held-out sets.

Depth: :func:`ground_depth` of ``42_ground_depth_probe.py`` (the ground is a plane under the camera; objects
are integrated from the decomposition's normals and stand on it). Visibility: study 25's screen-space march
(:func:`physrelight.screen_space_shadow.sun_visibility`), optionally softened, ``1 - a (1 - v)``.

Relit l1 as the bench runs the quotient methods (display values, foreground, the bench's cross pairs; the sun
shaded by its exact clamped cosine, the ratio guided-filtered with radius 3):

* known track (``quotient_known``): the given source lighting; the shadow dims the sun's part in the target
  (target visibility) and in the source (the photo's own sun shadows removed);
* estimated track (``quotient``): the decomposition's lighting at the given source's level; the target's
  sun dimmed by the target visibility only (the estimate has no sun to dim).

``--stage val``: the grid on data/val5 (l1 on the known track chooses; AP beside).
``--stage heldout --setting NAME/THICKNESS/A``: AP and both tracks on data/heldout and data/heldout3, each
against the shipped method without shadow (scene bootstrap of the paired difference), with study 25's
integrated depth and the true depth beside for AP.

Run (1 thread): ``.venv/bin/python docs/experiments/scripts/42_ground_depth_study.py --stage val
--out docs/experiments/results/42_ground_depth_val5.json``
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
probe = importlib.import_module("42_ground_depth_probe")
from screen_space_shadow_study import ap_table  # noqa: E402

from learned import Relighter  # noqa: E402
from physrelight.exposure import exposure_scale  # noqa: E402
from physrelight.quotient import SMOOTH_RADIUS, quotient_relight  # noqa: E402
from physrelight.stats import paired_bootstrap  # noqa: E402
from validation.bench.protocols import cross_pairs  # noqa: E402
from validation.bench.scores import score  # noqa: E402

VARIANTS = {
    "g0.8": dict(ground_cos=0.8), "g0.9": dict(ground_cos=0.9), "g0.95": dict(ground_cos=0.95),
    "g0.95_nocontact": dict(ground_cos=0.95, contact=False), "g0.95_billboard": dict(ground_cos=0.95, integrate=False),
}
THICKNESS = (0.1, 0.2)
BLEND = (0.5, 1.0)
STEPS = 64


def relit(P: probe.GroundPhotos, settings: dict[str, tuple | None], tracks=("known",)) -> dict:
    """Per-pair l1 of each setting (``None`` = no shadow, the shipped method) on each track."""
    pairs = cross_pairs(P.views)
    preds = {(t, k): [] for t in tracks for k in settings}
    targets, masks, scenes = [], [], []
    r = P.relighter
    for p in pairs:
        v = p.view
        ph = P.photo(v, p.source)
        image, sky = p.image(), p.sky()
        dec = ph["decomposition"]
        n = dec["normals"]
        Ls, Lt = p.source_lighting(), p.target_lighting()
        s_sun, t_sun = p.sun_lighting(p.source), p.sun_lighting(p.target)
        fg, tgt = p.foreground(), p.target_display()
        scale = exposure_scale(Lt, dec["lighting"], Ls, fallback=r.prior.mean.reshape(1, 9, 3))[:, None, None]
        for name, setting in settings.items():
            vs = vt = None
            if setting is not None:
                variant, th, a = setting
                vs = P.visibility(v, p.source, "ground_est", (STEPS, th, variant), p.source).float()
                vt = P.visibility(v, p.target, "ground_est", (STEPS, th, variant), p.source).float()
                vs, vt = 1.0 - a * (1.0 - vs), 1.0 - a * (1.0 - vt)
            for track in tracks:
                if track == "known":
                    out = quotient_relight(image, n, Ls * scale, Lt * scale, mask=~sky, source_shadow=vs,
                                           target_shadow=vt, source_sun=s_sun * scale, target_sun=t_sun * scale,
                                           sun_cosine=True, smooth_radius=SMOOTH_RADIUS)
                else:
                    out = quotient_relight(image, n, dec["lighting"], Lt * scale, mask=~sky, target_shadow=vt,
                                           target_sun=t_sun * scale, sun_cosine=True, smooth_radius=SMOOTH_RADIUS)
                out = torch.where(sky, image, out.clamp_min(0.0))
                preds[(track, name)].append(torch.where(fg, p.display(out.float()), tgt))
        targets.append(tgt)
        masks.append(fg)
        scenes.append(v.scene)
    l1 = {k: score(x, targets, masks)["l1"] for k, x in preds.items()}
    res = {"pairs": len(pairs), "scenes": len(set(scenes))}
    for track in tracks:
        base = l1[(track, "none")]
        res[track] = {name: {"l1": float(np.mean(l1[(track, name)])),
                             **({} if name == "none" else paired_bootstrap(l1[(track, name)], base,
                                                                           groups=np.asarray(scenes), seed=0)._asdict())}
                      for name in settings}
    return res, l1


def check_shipped(P: probe.GroundPhotos, l1: dict, tracks) -> dict:
    """The no-shadow rows against the shipped bench methods (must agree: this is the baseline they are)."""
    from validation.bench.methods import build_methods
    methods = build_methods(P.relighter)
    pairs = cross_pairs(P.views)
    out = {}
    for track in tracks:
        m = methods["quotient_known" if track == "known" else "quotient"]
        preds, targets, masks = [], [], []
        for p in pairs[:24]:
            fg, tgt = p.foreground(), p.target_display()
            preds.append(torch.where(fg, p.display(m(p).float()), tgt))
            targets.append(tgt)
            masks.append(fg)
        shipped = score(preds, targets, masks)["l1"]
        out[track] = float(np.max(np.abs(np.asarray(shipped) - np.asarray(l1[(track, "none")][:24]))))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stage", choices=("val", "heldout"), required=True)
    ap.add_argument("--setting", default=None, help="VARIANT/THICKNESS/A chosen on val5 (heldout stage)")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(1)
    probe.GroundPhotos.variants = VARIANTS
    relighter = Relighter.load()
    t0 = time.time()
    result: dict = {"stage": args.stage}
    with torch.no_grad():
        if args.stage == "val":
            P = probe.GroundPhotos("data/val5", relighter)
            settings: dict = {"none": None}
            for variant in VARIANTS:
                for th in THICKNESS:
                    for a in BLEND:
                        settings[f"{variant}/{th}/{a}"] = (variant, th, a)
            res, l1 = relit(P, settings, tracks=("known", "estimated"))
            aps = {}
            for variant in VARIANTS:
                for th in THICKNESS:
                    aps[f"{variant}/{th}"] = ap_table(P, {"ground_est": (STEPS, th, variant)})["ground_est"]["ap_all"]
            chance = ap_table(P, {})["positive_rate_all"]
            best = min((k for k in settings if k != "none"), key=lambda k: res["known"][k]["l1"])
            result.update({"root": "data/val5", "relit": res, "ap": aps, "chance": chance, "chosen_by_known_l1": best,
                           "baseline_vs_shipped_max_abs": check_shipped(P, l1, ("known", "estimated"))})
            for k in settings:
                print(k, " ".join(f"{t} {res[t][k]['l1']:.4f}" + (f" {res[t][k]['diff']:+.4f} [{res[t][k]['lo']:+.4f}, "
                                                                  f"{res[t][k]['hi']:+.4f}]" if k != "none" else "")
                                  for t in ("known", "estimated")), flush=True)
            print("AP", {k: round(x, 3) for k, x in aps.items()}, "chance", round(chance, 3), "chosen", best)
        else:
            variant, th, a = args.setting.split("/")
            setting = (variant, float(th), float(a))
            for root in ("data/heldout", "data/heldout3"):
                P = probe.GroundPhotos(root, relighter)
                res, l1 = relit(P, {"none": None, args.setting: setting}, tracks=("known", "estimated"))
                ap = ap_table(P, {"ground_est": (STEPS, setting[1], variant), "est_normals_depth": (64, 0.1, 0.003),
                                  "true_depth": (64, 0.2, 0.05)})
                result[root] = {"relit": res, "ap": ap, "baseline_vs_shipped_max_abs":
                                check_shipped(P, l1, ("known", "estimated"))}
                print(root, json.dumps({"relit": res, "ap": {k: ap[k]["ap_all"] for k in
                                                             ("ground_est", "est_normals_depth", "true_depth")},
                                        "chance": ap["positive_rate_all"]}, indent=1), flush=True)
    result["seconds"] = time.time() - t0
    Path(args.out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
