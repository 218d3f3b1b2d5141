"""Study 47 probe: the growth's gate (``GROW_CHI2``) on study 40's lattice composites JPEG-compressed at quality 85
(4:2:0), beside the uncompressed set and the plain training crops (``real_crop_scores.score_mask_variants``).

    .venv/bin/python docs/experiments/scripts/47_jpeg_lattice_probe.py -o docs/experiments/results/47_training.json
    .venv/bin/python docs/experiments/scripts/47_jpeg_lattice_probe.py --heldout --only 11.34 --only CHOSEN \
        -o docs/experiments/results/47_sunrise.json
"""
from __future__ import annotations

import argparse
import importlib
import io as pyio
import json
import sys
from pathlib import Path

import numpy as np
import torch
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_crop_scores import score_mask_variants  # noqa: E402

from learned import Relighter  # noqa: E402
from physrelight import colour  # noqa: E402

lattice = importlib.import_module("40_lattice_sky_probe")
masks = importlib.import_module("46_growth_gate_probe").masks  # the shipped mask with each gate
SETTINGS = ("11.34", "16.27", "21.11", "30")
QUALITY = 85


def jpeg(lin: torch.Tensor, quality: int = QUALITY) -> torch.Tensor:
    """``(1, 3, H, W)`` linear photo through an 8-bit sRGB JPEG at ``quality`` (Pillow, 4:2:0) and back."""
    disp = (colour.to_ldr(lin[0].clamp_min(0.0)).clamp(0, 1) * 255 + 0.5).to(torch.uint8).permute(1, 2, 0).numpy()
    buf = pyio.BytesIO()
    Image.fromarray(disp).save(buf, format="JPEG", quality=quality, subsampling="4:2:0")
    back = np.asarray(Image.open(pyio.BytesIO(buf.getvalue())).convert("RGB"), dtype=np.float32) / 255.0
    return colour.from_ldr(torch.from_numpy(back).permute(2, 0, 1)[None])


def jpeg_composite(crop, seed: int):
    comp, truth, cover = lattice.composite(crop, seed)
    return jpeg(comp), truth, cover


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true")
    ap.add_argument("--only", action="append", default=[], help="settings (the first is the reference)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = Relighter.load().sky_segmenter
    settings = tuple(args.only) or SETTINGS
    out = {"jpeg_quality": QUALITY}
    out["jpeg"] = score_mask_variants(lambda lin: masks(model, lin, settings), settings, args.heldout, jpeg_composite)
    if not args.heldout:
        print("-- uncompressed (study 46's set) --", flush=True)
        out["plain_png"] = score_mask_variants(lambda lin: masks(model, lin, settings), settings, False,
                                               lattice.composite)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
