"""The README's real-photo panel: a photo, its decomposition and two relightings (shipped weights).

    .venv/bin/python scripts/readme_panel.py [--photo PHOTO] [--out docs/images/relight_rocket.png]

Without ``--photo`` it uses scikit-image's ``rocket.jpg`` (a real dusk photo; the test extra
installs scikit-image). Columns: photo | albedo | normals (camera frame, as RGB) | relit to the
shipped forest HDRI | relit to a clear sky with the sun 10 degrees up (both with SkyGAN's sky).
No ground truth: for the eye. The machine and the seconds go to stdout.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ("photo", "albedo", "normals", "relit: forest HDRI", "relit: sun 10 deg, azimuth 60")


def _photo(path: str | None) -> np.ndarray:
    if path is not None:
        from physrelight import io

        return io.read_image(path)
    from skimage import data

    return data.rocket().astype(np.float32) / 255.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--photo", default=None, help="RGB photo (default: scikit-image's rocket.jpg)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "images" / "relight_rocket.png"))
    args = ap.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from learned import Relighter
    from learned.relight_cli import sun_direction
    from physrelight import io

    t0 = time.perf_counter()
    photo = _photo(args.photo)
    relighter = Relighter.load()
    forest = relighter.relight_layers(photo, ROOT / "physrelight" / "data" / "hdri" / "forest.exr")
    low_sun = relighter.relight(photo, sun_direction(10.0, 60.0))
    tiles = [photo, forest["albedo"], forest["normals"], forest["relit"], low_sun]
    fig, axes = plt.subplots(1, len(tiles), figsize=(2.6 * len(tiles), 2.6 * photo.shape[0] / photo.shape[1] + 0.5))
    for ax, img, title in zip(axes, tiles, COLUMNS):
        ax.imshow(np.clip(img, 0, 1))
        ax.set_title(title, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    with io.atomic_path(args.out, ".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    print(f"wrote {args.out} in {time.perf_counter() - t0:.1f} s ({platform.processor() or platform.machine()}, "
          f"{__import__('os').cpu_count()} cores)")


if __name__ == "__main__":
    main()
