"""Study 55, addendum: the sun-shadow AP of the MVS depth itself (the network's training target), its holes filled
by repeated 3 x 3 means of log depth, beside the true depth.

    .venv/bin/python docs/experiments/scripts/55_mvs_depth_ceiling.py data/val5 data/heldout data/heldout3
"""
import importlib
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
torch.set_num_threads(2)
study = importlib.import_module("42_ground_depth_study")
probe = study.probe
from learned import Relighter
from synth.dataset import to_chw

def fill_holes(d):
    """Fill invalid pixels by repeated 3x3 mean of valid neighbours (in log depth)."""
    v = torch.isfinite(d) & (d > 0)
    x = torch.where(v, torch.log(d.clamp_min(1e-6)), torch.zeros_like(d))
    w = v.double()
    x = x.double()
    for _ in range(200):
        if bool(w.bool().all()): break
        s = torch.nn.functional.avg_pool2d(x * w, 3, 1, 1, count_include_pad=False)
        c = torch.nn.functional.avg_pool2d(w, 3, 1, 1, count_include_pad=False)
        new = c > 0
        x = torch.where(w.bool(), x, torch.where(new, s / c.clamp_min(1e-12), x))
        w = torch.where(new | w.bool(), torch.ones_like(w), w)
    return torch.exp(x)

class MVSPhotos(probe.GroundPhotos):
    def depth(self, v, source, min_cos, light):
        if source != "ground_est":
            return super().depth(v, source, min_cos, light)
        key = (v.name, "mvs")
        if key not in self._depth:
            d = self.ds.load(v.scene, v.view, None, keys=("mvs_depth",))["mvs_depth"]
            self._depth[key] = fill_holes(to_chw(d)[None].double())
        ph = self.photo(v, light)
        return self._depth[key], ph["normals"], ~ph["sky"]

probe.GroundPhotos.variants = {"mvs": {}}
r = Relighter.load()
for root in sys.argv[1:]:
    P = MVSPhotos(root, r)
    with torch.no_grad():
        t = study.ap_table(P, {"ground_est": (64, 0.2, "mvs"), "true_depth": (64, 0.2, 0.05)})
    print(root, "mvs (holes filled)", round(t["ground_est"]["ap_all"], 3), "true", round(t["true_depth"]["ap_all"], 3),
          "chance", round(t["positive_rate_all"], 3))
