"""Panels for docs/experiments/61-sun-in-relighter.md: crops of the training panoramas (bench --real --full's crops,
seed 0) relit with RelightOptions(source_estimate="decomposition") and ("sky"), for the eye.

Each row: the photo | relit to its own panorama (today) | the same with the sky's reading | relit to TARGET (today)
| the same with the sky's reading. relight_layers with the crop's true camera, the segmenter's mask, method proposed.

    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/sun_in_relighter_look.py out/look
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from learned import Relighter
from synth.panorama_crops import make_crops, shipped_panoramas

CROPS = (("forest", 14), ("city", 4), ("city", 14))
TARGET = "courtyard"  # no sun: a soft, sunless light


def main(out: Path) -> None:
    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    pans = {p.name: p for p in shipped_panoramas()}
    base = Relighter.load()
    rows = []
    for name, index in CROPS:
        crop = make_crops(pans[name], 16, 0, fov_range=(45.0, 75.0), samples=4)[index]
        kw = dict(world_to_camera=crop.world_to_camera, fov_deg=crop.fov_deg, method="proposed", exposure="keep")
        row = [crop.photo / 255.0]
        for target in (pans[name].env, pans[TARGET].env):
            for option in ("decomposition", "sky"):
                layers = base.with_options(source_estimate=option).relight_layers(crop.photo, target, **kw)
                row.append(layers["relit"])
                if option == "sky":
                    r = layers.sky_lighting
                    said = r.reason if r.source != "sky" else (
                        f"sun {r.posterior.elevation_deg:.0f} up, {r.posterior.azimuth_deg:.0f} from ahead")
                    print(f"{name} {index} -> {'self' if target is pans[name].env else TARGET}: {r.source}, {said}")
        rows.append(np.concatenate([np.clip(np.asarray(x, np.float64), 0, 1) for x in row], 1))
        h = max(r.shape[0] for r in rows)
    w = max(r.shape[1] for r in rows)
    canvas = np.ones((sum(r.shape[0] for r in rows), w, 3))
    y = 0
    for r in rows:
        canvas[y: y + r.shape[0], : r.shape[1]] = r
        y += r.shape[0]
    Image.fromarray(np.round(canvas * 255).astype(np.uint8)).save(out / "sun_in_relighter_crops.png")
    print(out / "sun_in_relighter_crops.png", h)


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/look"))
