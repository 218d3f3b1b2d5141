"""How much should the lighting step trust the network's layers? (docs/learned.md, seventh rule's outcome)

``map_relative`` (:func:`physrelight.image_model.solve_lighting_map`, ``relative=True``) takes the image
model's residual as Gaussian at ``noise`` times the image's rms, with ``noise = 1`` in the shipped step.
For each ``--noise`` value, re-solve each photo's lighting from an inverse network's own albedo,
normals and shadow and report the mean scale-invariant shading error against the true lighting on the
true normals (:func:`learned.evaluate.shading_error`, the ``lighting_shading_err`` of ``train
evaluate``); ``inf`` is the prior's mean shape at the fitted level. Prints JSON.

    .venv/bin/python scripts/lighting_noise_probe.py --data data/train640 --split val --images 96
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import torch

from learned.data import load_photo
from learned.evaluate import load_ground_truth, shading_error
from learned.lighting import load_prior
from learned.objectives import decompose_and_solve
from learned.train import load_inverse
from physrelight import image_model
from synth.dataset import SynthDataset


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, help="synth dataset with ground truth")
    ap.add_argument("--split", default="val")
    ap.add_argument("--images", type=int, default=96, help="photos, evenly spread over the split")
    ap.add_argument("--weights", default="learned/weights/inverse.safetensors", help="inverse network")
    ap.add_argument("--noise", type=float, nargs="+", default=[0.5, 1, 2, 4, 8, 16, math.inf])
    ap.add_argument("--res", type=int, default=64, help="resolution the network runs at (default: 64)")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    net = load_inverse(args.weights).eval()
    prior = load_prior()
    ds = SynthDataset(args.data, split=args.split, mode="full")
    items = ds.items
    if not items:
        raise SystemExit(f"lighting_noise_probe: {args.data!r} has no photos in split {args.split!r}")
    idx = np.linspace(0, len(items) - 1, min(args.images, len(items))).round().astype(int)
    errs: dict[float, list[float]] = {k: [] for k in args.noise}
    for i in idx:
        it = items[i]
        photo = load_photo(ds, it.scene, it.view, it.light, args.res)
        image, sky = photo["image"][None], photo["sky"][None]
        gt = load_ground_truth(ds, it.scene, it.view, it.light, image.shape[-1])
        fg = ~sky[0] & (gt["normal"].norm(dim=0, keepdim=True) > 0.5)
        if int(fg.sum()) == 0:
            continue
        with torch.no_grad():
            out = decompose_and_solve(net, image, sky, prior)
            mask = (~sky).to(image.dtype)
            for k in args.noise:
                # A very large noise is the prior's mean shape; 1e6 stands for infinity in the closed form.
                lighting = image_model.solve_lighting_map(image, out["albedo"], out["normals"], mask, prior,
                                                          shadow=out["shadow"], noise=min(k, 1e6), relative=True)
                errs[k].append(shading_error(lighting[0].float(), gt["lighting"], gt["normal"], fg))
    print(json.dumps({"images": len(errs[args.noise[0]]),
                      "lighting_shading_err": {str(k): float(np.mean(v)) for k, v in errs.items()}}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
