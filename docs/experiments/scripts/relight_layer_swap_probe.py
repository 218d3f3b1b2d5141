"""Which layer of a decomposition makes its Lambertian relighting better or worse (docs/experiments/12-checkpoint-averaging-havg.md)?

Two weights folders A and B decompose the same held-out photos; ``lambertian_sh`` (``albedo * shading(n;
target)``, the target scaled into the decomposition's units by its own lighting's DC, ``Relighter.relight_linear``)
is scored four ways on every relighting case of ``train evaluate-relight``: A alone, B alone, A's albedo and
lighting with B's normals, B's albedo and lighting with A's normals. Albedo and lighting travel together because
they share one unknown scale. With ``lambertian_sh`` the estimated lighting enters only through its DC level,
so what is left is the albedo's pattern and the level of albedo x lighting; ``a_level`` / ``b_level`` score A's
and B's relit images each rescaled by the one scalar that gives its foreground the target's median level
(linear, unclipped target pixels): what remains of a gap there is not the level (an oracle: it reads the
target). ``a_shading`` / ``b_shading`` need no oracle: the target is scaled by the ratio of the foreground's
summed luminance of shading under the estimated source lighting to that under the given source lighting (both
on the estimated normals) instead of the ratio of DC levels, i.e. the level the decomposition explains the photo
with. Prints JSON: each variant's mean l1 / SSIM / PSNR / CIEDE2000, and each variant
minus A, paired over the same cases, with the scene-bootstrap interval of ``evaluate-relight``.

    .venv/bin/python docs/experiments/scripts/relight_layer_swap_probe.py --data data/heldout12 --a learned/weights \
        --b runs/pipeline_havg_w --json docs/experiments/results/relight_layer_swap_heldout12.json
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch

from learned.relight_eval import case_batches, relight_cases, relit_scores
from learned.relighter import Relighter
from physrelight import colour, image_model, io
from physrelight.stats import paired_bootstrap
from synth.dataset import SynthDataset

VARIANTS = ("a", "b", "a_with_b_normals", "b_with_a_normals", "a_level", "b_level", "a_shading", "b_shading")


def shading_matched_relit(dec: dict[str, torch.Tensor], image: torch.Tensor, sky: torch.Tensor,
                          target: torch.Tensor, source: torch.Tensor) -> torch.Tensor:
    """``lambertian_sh`` with the target ``(B, 9, 3)`` scaled by sum_fg lum(shading(n, L_est)) /
    sum_fg lum(shading(n, L_source)) over the decomposition's foreground; ``(B, 3, H, W)`` linear."""
    n, fg = dec["normals"], dec["foreground"].float()
    lum = torch.tensor(colour.LUMINANCE, dtype=n.dtype)[None, :, None, None]
    est = (image_model.shading(n, dec["lighting"]) * lum).sum(1, keepdim=True)
    src = (image_model.shading(n, source.to(n.dtype)) * lum).sum(1, keepdim=True)
    scale = (est * fg).sum((1, 2, 3)) / (src * fg).sum((1, 2, 3)).clamp_min(1e-9)
    relit = image_model.render(dec["albedo"], n, target.to(n.dtype) * scale[:, None, None], torch.ones_like(fg))
    return torch.where(sky, image, relit.clamp_min(0))


def level_matched(relit: torch.Tensor, target_ldr: torch.Tensor, fg: torch.Tensor) -> torch.Tensor:
    """``relit (B, 3, H, W)`` (linear) times, per image, the median over foreground pixels with an unclipped
    target of (target luminance / relit luminance), the target linearised from ``target_ldr`` (sRGB)."""
    lum = lambda x: x.mean(dim=1)  # noqa: E731 (a grey level is enough for one scalar per image)
    t = lum(colour.srgb_to_linear(target_ldr))
    q = lum(relit)
    ok = fg[:, 0] & (target_ldr.amax(dim=1) < 1.0) & (q > 1e-6)
    scale = torch.stack([torch.median(t[i][ok[i]] / q[i][ok[i]]) if bool(ok[i].any()) else relit.new_tensor(1.0)
                         for i in range(relit.shape[0])])
    return relit * scale[:, None, None, None]


def swap_probe(data: str, a: Relighter, b: Relighter, res: int = 64, batch_size: int = 16) -> dict:
    """Scores of the four ``lambertian_sh`` variants over ``data``'s relighting cases (all splits)."""
    ds = SynthDataset(data, split="all", mode="full")
    cases = relight_cases(ds)
    if not cases:
        raise ValueError(f"{data!r} has no relighting cases (needs >= 2 lightings)")
    acc: dict[str, dict[str, list[np.ndarray]]] = {v: {} for v in VARIANTS}
    scenes: list[str] = []
    for batch, batch_scenes, _ in case_batches(ds, cases, res, batch_size):  # evaluate-relight's cases
        if not batch_scenes:
            continue
        scenes += batch_scenes
        image, sky = batch["image"].float(), batch["sky"].bool()
        with torch.no_grad():
            da, db = a.decompose_linear(image, sky), b.decompose_linear(image, sky)
            decs = {"a": (a, da), "b": (b, db), "a_with_b_normals": (a, {**da, "normals": db["normals"]}),
                    "b_with_a_normals": (b, {**db, "normals": da["normals"]})}
            for name, (relighter, dec) in decs.items():
                out = relighter.relight_linear(image, sky, batch["target_sh"], batch["source_sh"],
                                               method="lambertian_sh", decomposition=dec)
                relit = {name: out["relit"].clamp_min(0)}
                if name in ("a", "b"):
                    relit[f"{name}_level"] = torch.where(sky, relit[name], level_matched(
                        relit[name], batch["target_ldr"], batch["fg"].bool()))
                    relit[f"{name}_shading"] = shading_matched_relit(dec, image, sky, batch["target_sh"].float(),
                                                                     batch["source_sh"].float())
                for n, x in relit.items():
                    for k, v in relit_scores(colour.to_ldr(x), batch["target_ldr"], batch["fg"]).items():
                        acc[n].setdefault(k, []).append(v)
    per = {v: {k: np.concatenate(x) for k, x in acc[v].items()} for v in VARIANTS}
    result: dict = {v: {k: float(np.mean(x)) for k, x in per[v].items()} for v in VARIANTS}
    result["cases"] = float(len(scenes))
    result["minus_a"] = {v: {k: paired_bootstrap(per[v][k], per["a"][k], groups=scenes)._asdict() for k in per[v]}
                         for v in VARIANTS[1:4]}
    for v in ("level", "shading"):
        result[f"b_{v}_minus_a_{v}"] = {k: paired_bootstrap(per[f"b_{v}"][k], per[f"a_{v}"][k], groups=scenes)._asdict()
                                        for k in per[f"b_{v}"]}
        result[f"a_{v}_minus_a"] = {k: paired_bootstrap(per[f"a_{v}"][k], per["a"][k], groups=scenes)._asdict()
                                    for k in per["a"]}
    return result


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="held-out synth dataset (ground truth)")
    p.add_argument("--a", required=True, help="weights folder A (the reference)")
    p.add_argument("--b", required=True, help="weights folder B")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--json", default=None)
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    result = swap_probe(args.data, Relighter.load(args.a), Relighter.load(args.b))
    print(json.dumps(result, indent=1))
    if args.json:
        io.write_json(args.json, result)


if __name__ == "__main__":
    main()
