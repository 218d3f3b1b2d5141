"""Seconds per 256 x 256 image at one thread for the whole Relighter.relight call (sky mask, target sky, exposure):
a crop of rocket.jpg relit to a sun, median of 5 after a warm-up, for proposed and quotient.

    .venv/bin/python docs/experiments/scripts/29_relight_speed.py
"""
import time, os, numpy as np, torch, warnings
from skimage import data
from learned import Relighter
torch.set_num_threads(1)
r = Relighter.load(); photo = data.rocket()[100:356, 200:456]
from learned.relight_cli import sun_direction
t = sun_direction(20.0, 30.0)
for m in ("proposed", "quotient"):
    ts = []
    for i in range(6):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r.relight(photo, t, method=m, exposure="auto")
        ts.append(time.perf_counter() - t0)
    print(m, "median of 5 after a warm-up:", round(float(np.median(ts[1:])), 3), "s", "load", os.getloadavg())
