"""Study 54 probe: the sky mask of black-and-white photos, shipped and with only the top-joined sky and no growth.

    .venv/bin/python docs/experiments/scripts/54_monochrome_mask_probe.py -o docs/experiments/results/54_training.json
    .venv/bin/python docs/experiments/scripts/54_monochrome_mask_probe.py --heldout -o docs/experiments/results/54_sunrise.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_crop_scores import score_mask_variants  # noqa: E402

from learned import Relighter  # noqa: E402
from learned import sky_segmentation as ss  # noqa: E402
from physrelight import colour  # noqa: E402

SETTINGS = ("shipped", "top_only_no_growth")
_PLAUSIBLE = ss.plausible_sky


def _top_only(mask, image, noise_var=None):
    kept, why = _PLAUSIBLE(mask, image, noise_var)
    if why:
        return kept, why
    lab = ss.label_components(kept)
    top = sorted(set(lab[0][lab[0] > 0].tolist()))
    return torch.isin(lab, torch.tensor(top)), ""


def masks(model, lin: torch.Tensor) -> dict[str, np.ndarray]:
    grey = (lin * lin.new_tensor(colour.LUMINANCE)[None, :, None, None]).sum(1, keepdim=True).expand_as(lin)
    assert ss.is_monochrome(grey.contiguous())
    out = {"shipped": ss.sky_mask_full_resolution(model, grey.contiguous())[0][0, 0].numpy()}
    ss.plausible_sky = _top_only
    try:
        out["top_only_no_growth"] = ss.sky_mask_full_resolution(model, grey.contiguous(), grow=0.0)[0][0, 0].numpy()
    finally:
        ss.plausible_sky = _PLAUSIBLE
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--heldout", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = Relighter.load().sky_segmenter
    out = score_mask_variants(lambda lin: masks(model, lin), SETTINGS, args.heldout)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
