"""Study 49: the sky's colour test (``COLOUR_MIN_BLUE_OVER_RED``) on the training crops as is and under warm casts,
the lattice set, the crops without sky, the studio (indoor) crops and scikit-image's indoor photos.

    .venv/bin/python docs/experiments/scripts/49_colour_threshold_probe.py -o docs/experiments/results/49_threshold_training.json
    .venv/bin/python docs/experiments/scripts/49_colour_threshold_probe.py --heldout --only 0.85 --only CHOSEN \
        -o docs/experiments/results/49_threshold_sunrise.json
"""
from __future__ import annotations

import argparse
import importlib
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_crop_scores import bench_crops, score_mask_variants  # noqa: E402

from learned import Relighter  # noqa: E402
from learned import sky_segmentation as ss  # noqa: E402
from physrelight import colour  # noqa: E402
from synth.panorama_crops import shipped_panoramas  # noqa: E402

lattice = importlib.import_module("40_lattice_sky_probe")
SETTINGS = ("0.85", "0.75", "0.65", "0.55")
CASTS = {"as is": None, "mild warm": (1.1, 1.0, 0.9), "warm": (1.25, 1.0, 0.75)}


def cast(lin: torch.Tensor, gains) -> torch.Tensor:
    """A white-balance cast, through 8-bit sRGB as a camera would store it."""
    if gains is None:
        return lin
    d = colour.to_ldr((lin * torch.tensor(gains)[None, :, None, None]).clamp_min(0.0)).clamp(0, 1)
    return colour.from_ldr(torch.round(d * 255) / 255)


def masks_with(model, lin: torch.Tensor, settings) -> dict[str, tuple[np.ndarray, str]]:
    out = {}
    for s in settings:
        ss.COLOUR_MIN_BLUE_OVER_RED = float(s)
        m, why = ss.sky_mask_full_resolution(model, lin)
        out[s] = (m[0, 0].numpy(), why[0])
    ss.COLOUR_MIN_BLUE_OVER_RED = 0.85
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true")
    ap.add_argument("--only", action="append", default=[])
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = Relighter.load().sky_segmenter
    settings = tuple(args.only) or SETTINGS
    out: dict = {"settings": list(settings)}
    for name, gains in CASTS.items():
        if args.heldout and name == "warm":
            continue
        print(f"-- {name} --", flush=True)
        out[name] = score_mask_variants(lambda lin: {s: m for s, (m, _) in masks_with(model, cast(lin, gains), settings).items()},
                                        settings, args.heldout, lattice.composite if name == "as is" else None)
    if not args.heldout:
        studio = [p for p in shipped_panoramas() if p.name == "studio"]
        called = {s: [] for s in settings}
        for _, crop in bench_crops(studio):
            for s, (m, _) in masks_with(model, crop.linear(), settings).items():
                called[s].append(float(m.mean()))
        out["studio_sky_called"] = {s: float(np.mean(v)) for s, v in called.items()}
        print("studio sky called:", {s: round(v, 4) for s, v in out["studio_sky_called"].items()}, flush=True)
        import skimage.data as data

        indoor = {"astronaut": data.astronaut(), "coffee": data.coffee(), "chelsea": data.chelsea(),
                  "motorcycle": data.stereo_motorcycle()[0]}
        out["indoor_refused"] = {}
        for name, img in indoor.items():
            lin = colour.from_ldr(torch.from_numpy(np.ascontiguousarray(img)).permute(2, 0, 1)[None].float() / 255)
            res = masks_with(model, lin, settings)
            out["indoor_refused"][name] = {s: bool(why) and not m.any() for s, (m, why) in res.items()}
        print("indoor photos refused:", out["indoor_refused"], flush=True)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
