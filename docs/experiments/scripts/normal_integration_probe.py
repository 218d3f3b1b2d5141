"""Probe: what limits depth integrated from the *true* normals as a sun-shadow caster? (issue 26, study 25)

On the first 24 views of data/val5: shadow AP on the photos with a sun (positive class
``shadow.exr < 0.5``, foreground pixels pooled, :func:`learned.evaluate.average_precision`) of
:func:`physrelight.screen_space_shadow.sun_visibility` (64 steps, thickness 0.2) from (a) the true depth,
(b) :func:`physrelight.normal_integration.depth_from_normals` at several ``min_cos``, (c) the same
re-solved with Cauchy weights on the edge residuals (iteratively reweighted, letting the surface tear
where the normals are not integrable), and the mean |log depth error| after the best scale.

Run: ``.venv/bin/python docs/experiments/scripts/normal_integration_probe.py``
"""

from __future__ import annotations

import numpy as np
import torch

from learned.evaluate import average_precision
from physrelight import normal_integration as NI
from physrelight.screen_space_shadow import sun_visibility
from synth.dataset import SynthDataset, to_chw
from validation.bench.data import load_dataset


def irls(n: torch.Tensor, K: torch.Tensor, mask: torch.Tensor, min_cos: float, rounds: int = 5,
         sigma: float = 0.05) -> torch.Tensor:
    """Depth (geometric mean 1 on ``mask``) from Cauchy-reweighted integration."""
    p, q, conf = NI.log_depth_gradients(n, K[None], min_cos)
    gx, wx, gy, wy = NI._edges(p, q, conf, mask)
    zeta = NI._solve(p, q, conf, mask, 2000, 1e-7, 1e-8, 4)
    for _ in range(rounds):
        rx = zeta[..., 1:] - zeta[..., :-1] - gx
        ry = zeta[..., 1:, :] - zeta[..., :-1, :] - gy
        wx2, wy2 = wx / (1 + (rx / sigma) ** 2), wy / (1 + (ry / sigma) ** 2)
        ridge = 1e-8 * torch.cat([wx2.flatten(1), wy2.flatten(1)], 1).mean(1).reshape(-1, 1, 1, 1) * torch.ones_like(zeta)
        zeta = NI._cg(wx2, wy2, NI._rhs(gx, wx2, gy, wy2), ridge, zeta, 2000, 1e-7)
    m = mask.double()
    return torch.where(mask, torch.exp(zeta - (zeta * m).sum() / m.sum()), torch.zeros_like(zeta))


def main() -> None:
    torch.set_num_threads(1)
    views = load_dataset("data/val5", with_physical=False)[:24]
    ds = SynthDataset("data/val5", split="all", mode="full")
    variants = ("true", "ls_0.05", "ls_0.01", "ls_0.003", "irls_0.05")
    scores = {k: [] for k in variants}
    labels, errors = [], {k: [] for k in variants[1:]}
    for v in views:
        rec = ds.record(v.scene)
        d = ds.load(v.scene, v.view, None, keys=("depth", "K", "world_to_camera"))
        R, fg = d["world_to_camera"][:3, :3], v.foreground()
        mask = torch.from_numpy(fg)[None, None]
        n, K, true = to_chw(v.normal)[None].double(), torch.from_numpy(d["K"]), to_chw(d["depth"])[None].double()
        depths = {"true": true, "irls_0.05": irls(n, K, mask, 0.05)}
        for mc in (0.05, 0.01, 0.003):
            depths[f"ls_{mc}"] = NI.depth_from_normals(n, K, mask, min_cos=mc)
        for k in variants[1:]:
            lr = np.log(depths[k][0, 0].numpy()[fg]) - np.log(true[0, 0].numpy()[fg])
            errors[k].append(np.abs(lr - lr.mean()).mean())
        for li, light in enumerate(rec["lights"]):
            if light["sun_direction"] is None:
                continue
            sun = torch.from_numpy(R @ np.asarray(light["sun_direction"]))[None]
            labels.append(v.shadow[li][fg] < 0.5)
            for k, dep in depths.items():
                vis = sun_visibility(dep, K, sun, normals=n, mask=None if k == "true" else mask, steps=64, thickness=0.2)
                scores[k].append(1.0 - vis[0, 0].numpy()[fg])
    y = np.concatenate(labels)
    print(f"chance {y.mean():.3f}")
    for k in variants:
        err = f", mean |log depth error| {np.mean(errors[k]):.3f}" if k in errors else ""
        print(f"{k}: AP (sun photos) {average_precision(np.concatenate(scores[k]), y):.3f}{err}")


if __name__ == "__main__":
    main()
