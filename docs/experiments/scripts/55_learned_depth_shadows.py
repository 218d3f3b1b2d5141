"""Study 55: sun shadows from a depth network trained on the self-supervised data's MVS depth.

    .venv/bin/python docs/experiments/scripts/55_learned_depth_shadows.py train --out runs/s55_depth
    .venv/bin/python docs/experiments/scripts/55_learned_depth_shadows.py val --net runs/s55_depth/depth.pt \
        --out docs/experiments/results/55_val5.json
    .venv/bin/python docs/experiments/scripts/55_learned_depth_shadows.py heldout --net runs/s55_depth/depth.pt \
        --setting learned/THICKNESS/A --out docs/experiments/results/55_heldout.json

The network (``UNet(3, 1, 16, 3)`` on the metered photo, log depth up to an offset) is trained with the
scale-invariant log loss over the valid, non-sky MVS pixels of ``data/train``'s train split (self-supervised
keys only). Shadows and scores: study 42's (``42_ground_depth_study.relit``, ``ap_table``), the learned depth in
place of the ground-plane depth.
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
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parent))

from learned.networks import UNet, metered  # noqa: E402

STEPS_TRAIN, BATCH, LR = 3000, 16, 1e-3


def si_log_loss(pred: torch.Tensor, mvs: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Scale-invariant log error (lambda 1) per photo over ``valid``, averaged over the batch."""
    d = torch.where(valid, pred - torch.log(mvs.clamp_min(1e-6)), torch.zeros_like(pred))
    n = valid.flatten(1).sum(1).clamp_min(1)
    m1 = d.flatten(1).sum(1) / n
    m2 = (d * d).flatten(1).sum(1) / n
    return (m2 - m1 * m1).mean()


def load_split(root: str, split: str) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    from synth.dataset import SynthDataset
    from learned.data import load_photo

    ds = SynthDataset(root, split=split)
    ims, deps, vals = [], [], []
    for scene in ds.scenes:
        rec = ds.record(scene)
        views = rec["views"] if isinstance(rec["views"], int) else len(rec["views"])
        for view in range(views):
            for light in range(rec["num_lights"]):
                p = load_photo(ds, scene, view, light, 64)
                d = p["depth"]
                ims.append(p["image"])
                deps.append(d)
                vals.append(torch.isfinite(d) & (d > 0) & ~p["sky"])
    return torch.stack(ims), torch.stack(deps).nan_to_num(0.0, 0.0, 0.0), torch.stack(vals)


def predict_log_depth(net: torch.nn.Module, image: torch.Tensor) -> torch.Tensor:
    return net(metered(image.float()).clamp(0.0, 8.0))


def train(out: Path) -> None:
    torch.manual_seed(0)
    torch.set_num_threads(2)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    X, D, V = load_split("data/train", "train")
    Xv, Dv, Vv = load_split("data/train", "val")
    print(f"train {len(X)} photos, val {len(Xv)}; valid share {float(V.float().mean()):.3f} ({time.time() - t0:.0f} s)",
          flush=True)
    net = UNet(3, 1, width=16, depth=3)
    opt = torch.optim.Adam(net.parameters(), lr=LR)
    rng = np.random.default_rng(0)
    log = []
    for step in range(STEPS_TRAIN):
        idx = torch.from_numpy(rng.integers(len(X), size=BATCH))
        x, d, v = X[idx].clone(), D[idx].clone(), V[idx].clone()
        flip = torch.from_numpy(rng.random(BATCH) < 0.5)
        x[flip], d[flip], v[flip] = x[flip].flip(-1), d[flip].flip(-1), v[flip].flip(-1)
        x = x * torch.from_numpy(2.0 ** rng.uniform(-1, 1, BATCH)).float()[:, None, None, None]
        loss = si_log_loss(predict_log_depth(net, x), d, v)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if (step + 1) % 250 == 0:
            with torch.no_grad():
                net.eval()
                lv = float(si_log_loss(predict_log_depth(net, Xv), Dv, Vv))
                net.train()
            log.append({"step": step + 1, "train": float(loss), "val": lv, "seconds": time.time() - t0})
            print(log[-1], flush=True)
    torch.save(net.state_dict(), out / "depth.pt")
    (out / "log.json").write_text(json.dumps(log, indent=1))


def photos_class(net_path: str):
    study = importlib.import_module("42_ground_depth_study")
    probe = study.probe
    net = UNet(3, 1, width=16, depth=3)
    net.load_state_dict(torch.load(net_path, weights_only=True))
    net.eval()

    class LearnedDepthPhotos(probe.GroundPhotos):
        """Study 42's cache, its ``ground_est`` depth replaced by the network's (per photo)."""

        def depth(self, v, source, min_cos, light):
            if source != "ground_est":
                return super().depth(v, source, min_cos, light)
            ph = self.photo(v, light)
            key = (v.name, "learned", light)
            if key not in self._depth:
                with torch.no_grad():
                    self._depth[key] = torch.exp(predict_log_depth(net, ph["image"])).double()
            return self._depth[key], ph["normals"], ~ph["sky"]

    return study, LearnedDepthPhotos


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("stage", choices=("train", "val", "heldout"))
    ap.add_argument("--out", required=True)
    ap.add_argument("--net", default=None)
    ap.add_argument("--setting", default=None)
    args = ap.parse_args()
    if args.stage == "train":
        train(Path(args.out))
        return
    torch.set_num_threads(1)
    from learned import Relighter

    study, P_cls = photos_class(args.net)
    study.probe.GroundPhotos.variants = {"learned": {}}
    relighter = Relighter.load()
    t0 = time.time()
    result: dict = {"stage": args.stage}
    with torch.no_grad():
        if args.stage == "val":
            P = P_cls("data/val5", relighter)
            settings: dict = {"none": None}
            for th in (0.1, 0.2):
                for a in (0.5, 1.0):
                    settings[f"learned/{th}/{a}"] = ("learned", th, a)
            res, l1 = study.relit(P, settings, tracks=("known", "estimated"))
            aps = {f"learned/{th}": study.ap_table(P, {"ground_est": (64, th, "learned")})["ground_est"]["ap_all"]
                   for th in (0.1, 0.2)}
            chance = study.ap_table(P, {})["positive_rate_all"]
            best = min((k for k in settings if k != "none"), key=lambda k: res["known"][k]["l1"])
            result.update({"root": "data/val5", "relit": res, "ap": aps, "chance": chance, "chosen_by_known_l1": best})
            for k in settings:
                print(k, " ".join(f"{t} {res[t][k]['l1']:.4f}" + (f" {res[t][k]['diff']:+.4f} [{res[t][k]['lo']:+.4f}, "
                                                                  f"{res[t][k]['hi']:+.4f}]" if k != "none" else "")
                                  for t in ("known", "estimated")), flush=True)
            print("AP", {k: round(x, 3) for k, x in aps.items()}, "chance", round(chance, 3), "chosen", best)
        else:
            _, th, a = args.setting.split("/")
            setting = ("learned", float(th), float(a))
            for root in ("data/heldout", "data/heldout3"):
                P = P_cls(root, relighter)
                res, l1 = study.relit(P, {"none": None, args.setting: setting}, tracks=("known", "estimated"))
                apt = study.ap_table(P, {"ground_est": (64, float(th), "learned"), "est_normals_depth": (64, 0.1, 0.003),
                                         "true_depth": (64, 0.2, 0.05)})
                result[root] = {"relit": res, "ap": apt}
                print(root, json.dumps({"relit": res, "ap": {k: apt[k]["ap_all"] for k in
                                                             ("ground_est", "est_normals_depth", "true_depth", "shadownet")},
                                        "chance": apt["positive_rate_all"]}, indent=1), flush=True)
    result["seconds"] = time.time() - t0
    Path(args.out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
