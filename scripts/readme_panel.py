"""The README's real-photo panel: real photos relit by `physrelight relight`'s defaults (shipped weights).

    .venv/bin/python scripts/readme_panel.py [--out docs/images/relight_rocket.png]

Rows: scikit-image's ``rocket.jpg`` (a real dusk photo; the test extra installs scikit-image) and
three crops of the held-out panorama ``sunrise.exr`` (bench --real's crops 0, 5 and 10 of 16,
seed 0), each as an 8-bit photo. Columns: input | relit to the shipped forest HDRI | to a low clear
sun (10 degrees up, 60 to the right) | to an overcast sky. Every relighting is what the command line
gives with its defaults (``--method proposed --exposure auto``, the target's own sky, the field of
view 60 degrees for the rocket and the crop's own for the crops, the pitch estimated from the sky).
No ground truth: for the eye. The machine and the seconds go to stdout.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
from figure_grid import save_grid

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ("input", "relit: forest HDRI", "relit: sun 10 deg up, 60 right", "relit: overcast")
CROPS = (0, 5, 10)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "relight_rocket.png"))
    args = ap.parse_args()

    from skimage import data

    from learned import Relighter
    from learned.relight_cli import sun_direction
    from physrelight import envmap
    from synth.panorama_crops import HELDOUT_DIR, load_panorama, make_crops

    t0 = time.perf_counter()
    relighter = Relighter.load()
    pano = load_panorama(HELDOUT_DIR / "sunrise.exr", "heldout")
    crops = make_crops(pano, 16, seed=0)
    inputs = [("rocket.jpg", data.rocket(), 60.0)] + [(f"sunrise crop {i}", crops[i].photo, crops[i].fov_deg)
                                                      for i in CROPS]
    forest = envmap.read(ROOT / "physrelight" / "data" / "hdri" / "forest.exr")
    targets = [(forest, {}), (sun_direction(10.0, 60.0), {}), (sun_direction(45.0, 0.0), {"sky": "overcast"})]
    rows = []
    for name, photo, fov in inputs:
        row = [photo.astype(np.float32) / 255.0]
        for target, kw in targets:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                row.append(relighter.relight(photo, target, method="proposed", exposure="auto", fov_deg=fov, **kw))
        rows.append((name, row))
    save_grid(rows, COLUMNS, args.out, started=t0)

if __name__ == "__main__":
    main()
