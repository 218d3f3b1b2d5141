"""Study 56 (a diagnosis, nothing chosen): where the shipped sky mask falls short on the held-out sunrise crops.

Per crop of ``bench --real --full`` (seed 0): IoU, boundary F, the true sky missed and the land called sky (pixels),
and the segmenter's own miss: true-sky pixels whose working-size probability (brought to the crop's size) is under
1/2. Also the same counts on the training panoramas' crops.

    .venv/bin/python docs/experiments/scripts/56_sunrise_mask_shortfall.py -o docs/experiments/results/56_shortfall.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_crop_scores import bench_crops, crop_panoramas  # noqa: E402

from learned import Relighter  # noqa: E402
from physrelight.full_resolution import resize_short_side  # noqa: E402
from learned.sky_segmentation import SEGMENT_RES, sky_mask_full_resolution  # noqa: E402
from physrelight import metrics  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--out", required=True)
    args = ap.parse_args()
    torch.set_num_threads(1)
    seg = Relighter.load().sky_segmenter
    out: dict = {}
    for heldout in (True, False):
        group, panos = crop_panoramas(heldout)
        rows = []
        counts: dict[str, int] = {}
        for pano, c in bench_crops(panos):
            i = counts.get(pano.name, 0)
            counts[pano.name] = i + 1
            t = c.sky > 0.5
            if t.mean() < 0.01:
                continue
            lin = c.linear()
            m = sky_mask_full_resolution(seg, lin)[0][0, 0].numpy()
            small = resize_short_side(lin, SEGMENT_RES)
            with torch.no_grad():
                p = torch.sigmoid(seg(small))
            p = F.interpolate(p, size=lin.shape[-2:], mode="bilinear", align_corners=False)[0, 0].numpy()
            rows.append({"panorama": pano.name, "crop": i, "pitch_deg": c.pitch_deg, "sky_fraction": float(t.mean()),
                         "iou": metrics.mask_iou(m, t), "boundary_f": metrics.boundary_f(m, t, 2.0),
                         "missed_px": int((t & ~m).sum()), "false_px": int((~t & m).sum()),
                         "segmenter_missed_px": int((t & (p < 0.5)).sum()), "pixels": int(t.size)})
        out[group] = rows
        missed = sum(r["missed_px"] for r in rows)
        false = sum(r["false_px"] for r in rows)
        print(f"{group}: {len(rows)} crops, missed {missed} px, false {false} px, segmenter's own miss "
              f"{sum(r['segmenter_missed_px'] for r in rows)} px")
        for r in sorted(rows, key=lambda r: -r["missed_px"])[:6]:
            print("  ", {k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()})
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
