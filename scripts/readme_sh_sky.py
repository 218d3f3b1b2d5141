"""The README's figure of the sky an SH target gets: rocket.jpg relit to order-2 SH (shipped weights).

    .venv/bin/python scripts/readme_sh_sky.py [--out docs/images/rocket_sh_sky.png]

Rows: the SH of the shipped city and forest HDRIs (``sh.project_envmap(envmap.read(...), order=2)``).
Columns: SkyGAN's own sky (``RelightOptions(sky_smooth=0)``, the default before study 31) | the default
(SkyGAN blurred within the mask, ``--sky-source gan``) | the sky model fitted to the SH
(``--sky-source fit``). Everything else is the command line's defaults (``--method proposed --exposure
auto``, field of view 60 degrees, pitch from the sky). No ground truth: for the eye.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from figure_grid import save_grid

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ("SkyGAN's own sky (before)", "default: SkyGAN, smoothed", "--sky-source fit")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "rocket_sh_sky.png"))
    args = ap.parse_args()

    from skimage import data

    from learned import Relighter
    from physrelight import envmap, sh

    t0 = time.perf_counter()
    r = Relighter.load()
    photo = data.rocket()
    rows = []
    for name in ("city", "forest"):
        coeffs = np.asarray(sh.project_envmap(envmap.read(ROOT / "physrelight" / "data" / "hdri" / f"{name}.exr"), 2))
        row = []
        for smooth, source in ((0.0, "gan"), (None, "gan"), (None, "fit")):
            row.append(r.with_options(sky_smooth=smooth).relight(photo, coeffs, method="proposed", exposure="auto",
                                                                 sky_source=source))
        rows.append((f"{name} HDRI's SH", row))
    save_grid(rows, COLUMNS, args.out, started=t0)

if __name__ == "__main__":
    main()
