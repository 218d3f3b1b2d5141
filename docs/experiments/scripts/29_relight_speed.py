"""Seconds per 256 x 256 image at one thread for the whole Relighter.relight call (sky mask, target sky, exposure):
a crop of rocket.jpg relit to a sun, median of 5 after a warm-up, for proposed and quotient.

    .venv/bin/python docs/experiments/scripts/29_relight_speed.py
    .venv/bin/python docs/experiments/scripts/29_relight_speed.py --sh   (study 33: the city HDRI's SH instead, a
        new target each call so the fitted sky model's sun is fitted every time)
"""
import os
import sys
import time
import warnings

import numpy as np
import torch
from skimage import data

from learned import Relighter
from learned.relight_cli import sun_direction
from physrelight import envmap, sh

torch.set_num_threads(1)
r = Relighter.load()
photo = data.rocket()[100:356, 200:456]
use_sh = "--sh" in sys.argv[1:]
L = np.asarray(sh.project_envmap(envmap.read("physrelight/data/hdri/city.exr"), 2)) if use_sh else None
for m in ("proposed", "quotient"):
    ts = []
    for i in range(6):
        t = L * (1.0 + 1e-9 * (i + 10 * (m == "quotient"))) if use_sh else sun_direction(20.0, 30.0)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r.relight(photo, t, method=m, exposure="auto")
        ts.append(time.perf_counter() - t0)
    print(m, "median of 5 after a warm-up:", round(float(np.median(ts[1:])), 3), "s", "load", os.getloadavg())
