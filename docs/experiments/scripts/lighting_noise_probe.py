"""How much should the lighting step trust the network's layers? (docs/experiments/06-run-d.md)

``map_relative`` (:func:`physrelight.image_model.solve_lighting_map`, ``relative=True``) takes the image
model's residual as Gaussian at ``noise`` times the image's rms, with ``noise = 1`` in the shipped step.
For each ``--noise`` value, run :func:`learned.evaluate.evaluate` with each photo's lighting re-solved
at that noise from an inverse network's own albedo, normals and shadow, and report its
``lighting_shading_err`` (the scale-invariant shading error against the true lighting on the true
normals, as in ``train evaluate``); ``inf`` is the prior's mean shape at the fitted level. Prints JSON.

    .venv/bin/python docs/experiments/scripts/lighting_noise_probe.py --data data/train640 --split val --images 96
"""

from __future__ import annotations

import argparse
import json
import math

import torch

from learned.evaluate import evaluate
from learned.lighting import load_prior
from learned.objectives import decompose_and_solve
from learned.networks import load_inverse
from physrelight import image_model


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
    results = {}
    for noise in args.noise:
        def decompose(image: torch.Tensor, sky: torch.Tensor, noise: float = noise) -> dict[str, torch.Tensor]:
            out = decompose_and_solve(net, image, sky, prior)
            # A very large noise is the prior's mean shape; 1e6 stands for infinity in the closed form.
            out["lighting"] = image_model.solve_lighting_map(
                image, out["albedo"], out["normals"], (~sky).to(image.dtype), prior, shadow=out["shadow"],
                noise=min(noise, 1e6), relative=True).to(image.dtype)
            return out

        m = evaluate(decompose, args.data, args.split, args.res, prior, max_images=args.images)
        results[str(noise)] = m["lighting_shading_err"]
    print(json.dumps({"images": int(m["images"]), "lighting_shading_err": results}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
