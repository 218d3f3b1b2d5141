"""Shadows from geometry (issue 26): screen-space sun visibility from true / integrated depth vs ShadowNet.

Stage 1 (validation, data/val5): a grid of ``steps`` x ``thickness`` (x the integration's
``min_cos`` for the integrated depths) for each depth source, scored
by shadow AP (choose by AP) and by the relit l1 of the known-source quotient (choose by l1).
Stage 2 (reporting, data/heldout and data/heldout3), with the settings stage 1 chose:

* AP of ``1 - v`` against the true sun visibility (``shadow.exr < 0.5``), pooled over the
  foreground pixels of every photo, exactly as :func:`learned.evaluate.evaluate` scores ShadowNet
  (same positive class, same :func:`learned.evaluate.average_precision`, chance beside it), for
  (1) true depth, (2) depth integrated from the true normals, (3) depth integrated from the shipped
  decomposition's normals, (4) ShadowNet on the decomposition (``shadownet_ap``). Photos without a
  sun get ``v = 1`` (no sun, no sun shadow); the AP over the photos with a sun is given too.
* relit foreground l1 (the bench's: display values, :func:`validation.bench.scores.score`) on the
  cross-relighting pairs of the known-source quotient (``pair.source_lighting()`` /
  ``pair.target_lighting()``, the decomposition's normals), without shadows, with sun-only shadows
  (source and target) from each depth source, with the true sun visibility (the ceiling), and with
  ShadowNet (``Relighter.relight_linear(method="quotient_shadownet", known_source=True)``).

Run: ``.venv/bin/python docs/experiments/scripts/screen_space_shadow_study.py
--out docs/experiments/results/screen_space_shadow.json`` (1 thread).
"""

from __future__ import annotations

import argparse
import json
import time
from itertools import product
from pathlib import Path

import numpy as np
import torch

from learned import Relighter
from learned.evaluate import average_precision
from physrelight import colour
from physrelight.normal_integration import depth_from_normals
from physrelight.quotient import quotient_relight
from physrelight.screen_space_shadow import sun_visibility
from physrelight.stats import paired_bootstrap
from synth.dataset import SynthDataset
from validation.bench.data import load_dataset
from validation.bench.methods import to_chw
from validation.bench.protocols import cross_pairs
from validation.bench.scores import score

STEPS = (32, 64)
THICKNESS = (0.05, 0.1, 0.2, 0.3)
MIN_COS = (0.05, 0.01, 0.003)  # the integration's grazing cut-off (integrated depth sources only)
SOURCES = ("true_depth", "gt_normals_depth", "est_normals_depth")


class Photos:
    """Per view of a synth folder: true depth, K, camera-frame sun direction per lighting, depth
    integrated from the true normals; per photo the decomposition (normals, lighting, ShadowNet) and
    the depth integrated from its normals; visibilities, all computed once."""

    def __init__(self, root: str, relighter: Relighter) -> None:
        self.root, self.relighter = root, relighter
        self.views = load_dataset(root, with_physical=False)
        self.ds = SynthDataset(root, split="all", mode="full")
        self._view: dict[str, dict] = {}
        self._photo: dict[tuple[str, int], dict] = {}
        self._depth: dict[tuple, torch.Tensor] = {}
        self._vis: dict[tuple, torch.Tensor] = {}
        self.seconds_integration: list[float] = []
        self.seconds_visibility: list[float] = []

    def view(self, v) -> dict:
        if v.name not in self._view:
            rec = self.ds.record(v.scene)
            d = self.ds.load(v.scene, v.view, None, keys=("depth", "K", "world_to_camera"))
            R = d["world_to_camera"][:3, :3]
            suns = [None if l["sun_direction"] is None else torch.from_numpy(R @ np.asarray(l["sun_direction"]))[None]
                    for l in rec["lights"]]
            self._view[v.name] = {"depth": to_chw(d["depth"]).double(), "K": torch.from_numpy(d["K"]), "suns": suns,
                                  "fg": torch.from_numpy(v.foreground())[None, None],
                                  "normal": to_chw(v.normal).double()}
        return self._view[v.name]

    def photo(self, v, light: int) -> dict:
        """The decomposition of photo (view, light), its image as Pair.image() linearises it."""
        key = (v.name, light)
        if key not in self._photo:
            image = colour.from_ldr(to_chw(v.photo[light]).clamp(0.0, 1.0))
            sky = torch.from_numpy(np.ascontiguousarray(v.sky))[None, None]
            out = self.relighter.decompose_linear(image, sky)
            sn = self.relighter.shadow_net(out["normals"], out["lighting"])  # as learned/evaluate.py scores it
            self._photo[key] = {"image": image, "sky": sky, "normals": out["normals"].double(),
                                "shadownet": sn, "decomposition": out}
        return self._photo[key]

    def depth(self, v, source: str, min_cos: float, light: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """``(depth, normals for the attached-shadow test, mask)`` of a depth source; ``light`` is the
        photo whose decomposition the estimate comes from."""
        vd = self.view(v)
        if source == "true_depth":
            return vd["depth"], vd["normal"], None
        key = (v.name, source, min_cos, light if source == "est_normals_depth" else -1)
        if source == "gt_normals_depth":
            normals, mask = vd["normal"], vd["fg"]
        else:
            ph = self.photo(v, light)
            normals, mask = ph["normals"], ~ph["sky"]
        if key not in self._depth:
            t0 = time.perf_counter()
            self._depth[key] = depth_from_normals(normals, vd["K"], mask, min_cos=min_cos)
            self.seconds_integration.append(time.perf_counter() - t0)
        return self._depth[key], normals, mask

    def visibility(self, v, light: int, source: str, setting: tuple, photo_light: int) -> torch.Tensor:
        """``(1, 1, H, W)`` sun visibility of lighting ``light`` of view ``v`` (ones without a sun) from a
        depth source; ``photo_light``: the photo the estimated depth comes from."""
        steps, thickness, min_cos = setting
        sun = self.view(v)["suns"][light]
        if sun is None:
            return torch.ones_like(self.view(v)["depth"])
        key = (v.name, light, source, setting, photo_light if source == "est_normals_depth" else -1)
        if key not in self._vis:
            depth, normals, mask = self.depth(v, source, min_cos, photo_light)
            t0 = time.perf_counter()
            self._vis[key] = sun_visibility(depth, self.view(v)["K"], sun, mask=mask, normals=normals, steps=steps,
                                            thickness=thickness)
            self.seconds_visibility.append(time.perf_counter() - t0)
        return self._vis[key]


def ap_table(P: Photos, settings: dict[str, tuple]) -> dict:
    """Shadow AP per depth source and ShadowNet's, pooled over foreground pixels (all photos, sun photos)."""
    scores = {k: [] for k in (*settings, "shadownet")}
    labels, has_sun = [], []
    for v in P.views:
        vd = P.view(v)
        fg = vd["fg"][0, 0]
        for light in range(v.num_lights):
            ph = P.photo(v, light)
            labels.append(v.shadow[light][fg.numpy()] < 0.5)
            has_sun.append(np.full(int(fg.sum()), vd["suns"][light] is not None))
            for src, setting in settings.items():
                vis = P.visibility(v, light, src, setting, light)
                scores[src].append((1.0 - vis[0, 0][fg]).numpy())
            scores["shadownet"].append((1.0 - ph["shadownet"][0, 0][fg]).double().numpy())
    y, sun = np.concatenate(labels), np.concatenate(has_sun)
    out = {"positive_rate_all": float(y.mean()), "positive_rate_sun": float(y[sun].mean()),
           "pixels_all": int(y.size), "pixels_sun": int(sun.sum())}
    for k, s in scores.items():
        s = np.concatenate(s)
        out[k] = {"ap_all": average_precision(s, y), "ap_sun": average_precision(s[sun], y[sun]),
                  "predicted_shadow_rate": float((s > 0.5).mean())}
    return out


def relit_l1(P: Photos, settings: dict[str, tuple], with_shadownet: bool = True) -> dict:
    """Per-pair l1 of the known-source quotient variants on the cross pairs."""
    pairs = cross_pairs(P.views)
    names = ["no_shadow", "true_visibility", *settings, *[f"{s}_target_only" for s in settings]]
    if with_shadownet:
        names += ["shadownet", "quotient_relight_linear"]
    preds = {k: [] for k in names}
    targets, masks, scenes = [], [], []
    for p in pairs:
        v = p.view
        ph = P.photo(v, p.source)
        image, sky = p.image(), p.sky()
        Ls, Lt = p.source_lighting(), p.target_lighting()
        sun_s = torch.from_numpy((v.sun_sh[p.source] * p.gain[None, :]).astype(np.float32))[None]
        sun_t = torch.from_numpy((v.sun_sh[p.target] * p.gain[None, :]).astype(np.float32))[None]
        n = ph["normals"].float()
        fg, tgt = p.foreground(), p.target_display()

        def put(name: str, relit: torch.Tensor) -> None:
            relit = torch.where(sky, image, relit.clamp_min(0.0))
            preds[name].append(torch.where(fg, p.display(relit.float()), tgt))

        put("no_shadow", quotient_relight(image, n, Ls, Lt, mask=~sky))
        true_s, true_t = to_chw(v.shadow[p.source]), to_chw(v.shadow[p.target])
        put("true_visibility", quotient_relight(image, n, Ls, Lt, mask=~sky, source_shadow=true_s,
                                                target_shadow=true_t, source_sun=sun_s, target_sun=sun_t))
        for src, setting in settings.items():
            vs = P.visibility(v, p.source, src, setting, p.source).float()
            vt = P.visibility(v, p.target, src, setting, p.source).float()
            put(src, quotient_relight(image, n, Ls, Lt, mask=~sky, source_shadow=vs, target_shadow=vt,
                                      source_sun=sun_s, target_sun=sun_t))
            put(f"{src}_target_only", quotient_relight(image, n, Ls, Lt, mask=~sky, target_shadow=vt, target_sun=sun_t))
        if with_shadownet:
            r = P.relighter
            put("shadownet", r.relight_linear(image, sky, Lt, source_lighting=Ls, method="quotient_shadownet",
                                              decomposition=ph["decomposition"], known_source=True)["relit"])
            put("quotient_relight_linear", r.relight_linear(image, sky, Lt, source_lighting=Ls, method="quotient",
                                                            decomposition=ph["decomposition"], known_source=True)["relit"])
        targets.append(tgt)
        masks.append(fg)
        scenes.append(v.scene)
    l1 = {k: score(x, targets, masks)["l1"] for k, x in preds.items()}
    out = {"pairs": len(pairs), "scenes": len(set(scenes)), "mean_l1": {k: float(np.mean(x)) for k, x in l1.items()}}
    out["vs_no_shadow"] = {k: paired_bootstrap(x, l1["no_shadow"], groups=np.asarray(scenes), seed=0)._asdict()
                           for k, x in l1.items() if k != "no_shadow"}
    return out


def choose(P: Photos) -> dict:
    """The val5 grid: AP and relit l1 of every setting (steps, thickness, min_cos) of every depth source."""
    grid: dict[str, dict] = {}
    for steps, th, mc in product(STEPS, THICKNESS, MIN_COS):
        setting = (steps, th, mc)
        sources = SOURCES if mc == MIN_COS[0] else SOURCES[1:]  # true depth does not integrate
        settings = {s: setting for s in sources}
        ap = ap_table(P, settings)
        l1 = relit_l1(P, settings, with_shadownet=False)
        name = f"{steps}/{th}/{mc}"
        grid[name] = {"ap": {s: ap[s]["ap_all"] for s in sources}, "ap_sun": {s: ap[s]["ap_sun"] for s in sources},
                      "l1": {s: l1["mean_l1"][s] for s in sources}, "l1_no_shadow": l1["mean_l1"]["no_shadow"]}
        print(f"val5 {name}: AP " + " ".join(f"{s} {ap[s]['ap_all']:.3f}" for s in sources)
              + " | l1 " + " ".join(f"{s} {l1['mean_l1'][s]:.4f}" for s in sources)
              + f" (none {l1['mean_l1']['no_shadow']:.4f})", flush=True)

    def parse(g: str) -> tuple:
        a, b, c = g.split("/")
        return int(a), float(b), float(c)

    best_ap = {s: max((g for g in grid if s in grid[g]["ap"]), key=lambda g: grid[g]["ap"][s]) for s in SOURCES}
    best_l1 = {s: min((g for g in grid if s in grid[g]["l1"]), key=lambda g: grid[g]["l1"][s]) for s in SOURCES}
    return {"grid": grid, "by_ap": {s: parse(g) for s, g in best_ap.items()},
            "by_l1": {s: parse(g) for s, g in best_l1.items()}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--val", default="data/val5")
    ap.add_argument("--heldout", nargs="+", default=["data/heldout", "data/heldout3"])
    ap.add_argument("--out", default="docs/experiments/results/screen_space_shadow.json")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    relighter = Relighter.load()
    t0 = time.time()
    with torch.no_grad():
        val = Photos(args.val, relighter)
        chosen = choose(val)
        print("chosen by AP", chosen["by_ap"], "by l1", chosen["by_l1"], flush=True)
        result = {"val": {"root": args.val, **chosen}, "heldout": {}}
        for root in args.heldout:
            P = Photos(root, relighter)
            aps = ap_table(P, chosen["by_ap"])
            l1 = relit_l1(P, chosen["by_l1"])
            result["heldout"][root] = {"ap": aps, "relit_l1": l1,
                                       "integration_ms_median_64px": 1000 * float(np.median(P.seconds_integration)),
                                       "visibility_ms_median_64px": 1000 * float(np.median(P.seconds_visibility))}
            print(root, json.dumps({"ap": aps, "l1": l1["mean_l1"]}, indent=1), flush=True)
    result["seconds"] = time.time() - t0
    result["threads"] = args.threads
    Path(args.out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
