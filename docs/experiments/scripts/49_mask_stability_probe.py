"""Study 49 probe: how stable is relight's sky mask when the photo's exposure, white balance, compression or noise
change? The training panoramas' crops of ``bench --real --full`` (seed 0), each perturbed, the shipped mask scored
against the true sky (mean of IoU and boundary F over the crops with sky; sky called on crops without sky).

    .venv/bin/python docs/experiments/scripts/49_mask_stability_probe.py -o docs/experiments/results/49_training.json
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
from learned import sky_segmentation as ss  # noqa: E402
from physrelight import colour  # noqa: E402

lattice = importlib.import_module("40_lattice_sky_probe")


def _to8(lin: torch.Tensor) -> np.ndarray:
    return (colour.to_ldr(lin[0].clamp_min(0.0)).clamp(0, 1) * 255 + 0.5).to(torch.uint8).permute(1, 2, 0).numpy()


def _from8(a: np.ndarray) -> torch.Tensor:
    return colour.from_ldr(torch.from_numpy(a.astype(np.float32) / 255.0).permute(2, 0, 1)[None])


def perturb(lin: torch.Tensor, name: str) -> torch.Tensor:
    """The photo as another camera setting or file would have given it (8-bit sRGB in and out)."""
    if name == "as is":
        return lin
    if name.startswith("EV"):
        return _from8(_to8(lin * 2.0 ** float(name[2:])))
    if name == "warm WB":
        return _from8(_to8(lin * torch.tensor([1.25, 1.0, 0.75])[None, :, None, None]))
    if name == "cool WB":
        return _from8(_to8(lin * torch.tensor([0.8, 1.0, 1.3])[None, :, None, None]))
    if name.startswith("JPEG"):
        buf = pyio.BytesIO()
        Image.fromarray(_to8(lin)).save(buf, format="JPEG", quality=int(name[4:]), subsampling="4:2:0")
        return _from8(np.asarray(Image.open(pyio.BytesIO(buf.getvalue())).convert("RGB")))
    if name == "noise 2%":
        g = torch.Generator().manual_seed(int(lin.shape[-1] * 1000 + lin.shape[-2]))
        d = colour.to_ldr(lin.clamp_min(0.0)) + 0.02 * torch.randn(lin.shape, generator=g)
        return colour.from_ldr(d.clamp(0, 1))
    raise ValueError(name)


SETTINGS = ("as is", "EV-2", "EV-1", "EV+1", "EV+2", "warm WB", "cool WB", "JPEG50", "noise 2%")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = Relighter.load().sky_segmenter

    def masks(lin: torch.Tensor) -> dict[str, np.ndarray]:
        return {s: ss.sky_mask_full_resolution(model, perturb(lin, s))[0][0, 0].numpy() for s in SETTINGS}

    out = score_mask_variants(masks, SETTINGS, False, lattice.composite)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
