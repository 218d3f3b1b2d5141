"""Study 56, addendum: the shipped mask on upward-looking crops of the training panoramas (pitch 15-35 deg, seed 1,
16 per panorama, crops with sky): does the held-out failure (deep upper sky called land) occur on the training side?

    .venv/bin/python docs/experiments/scripts/56_upward_training_crops.py
"""
import sys, numpy as np, torch, torch.nn.functional as F
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_crop_scores import crop_panoramas
from synth.panorama_crops import make_crops
from learned import Relighter
from physrelight.full_resolution import resize_short_side
from learned.sky_segmentation import SEGMENT_RES, sky_mask_full_resolution
from physrelight import metrics
torch.set_num_threads(2)
seg = Relighter.load().sky_segmenter
_, panos = crop_panoramas(False)
for pano in panos:
    rows = []
    for c in make_crops(pano, 16, 1, fov_range=(45.0, 75.0), pitch_range=(15.0, 35.0), samples=4):
        t = c.sky > 0.5
        if t.mean() < 0.01: continue
        lin = c.linear()
        m = sky_mask_full_resolution(seg, lin)[0][0, 0].numpy()
        rows.append((metrics.mask_iou(m, t), metrics.boundary_f(m, t, 2.0), int((t & ~m).sum()), int((~t & m).sum()), float(t.mean())))
    a = np.array(rows)
    print(pano.name, len(rows), 'IoU %.3f F %.3f missed %d false %d skyfrac %.2f' % (a[:,0].mean(), a[:,1].mean(), a[:,2].sum(), a[:,3].sum(), a[:,4].mean()))
