"""One helper for the README's image grids (``readme_panel.py``, ``readme_sh_sky.py``): titled columns,
labelled rows, written atomically."""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Sequence

import numpy as np


def save_grid(rows: Sequence[tuple[str, Sequence[np.ndarray]]], columns: Sequence[str], out: str,
              cell_width: float = 3.0, started: float | None = None) -> None:
    """Write ``rows`` (a label and its ``(H, W, 3)`` display images in [0, 1]) under ``columns`` to the PNG
    ``out``, each cell ``cell_width`` inches wide with the tallest row's aspect ratio; print the machine and,
    with ``started`` (a ``time.perf_counter()``), the seconds since."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from physrelight import io

    h = max(r[0].shape[0] / r[0].shape[1] for _, r in rows)
    fig, axes = plt.subplots(len(rows), len(columns), squeeze=False,
                             figsize=(cell_width * len(columns), cell_width * h * len(rows) + 0.6))
    for i, (name, row) in enumerate(rows):
        for j, img in enumerate(row):
            ax = axes[i, j]
            ax.imshow(np.clip(img, 0, 1))
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(columns[j], fontsize=9)
            if j == 0:
                ax.set_ylabel(name, fontsize=9)
    fig.tight_layout()
    with io.atomic_path(out, ".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    took = "" if started is None else f" in {time.perf_counter() - started:.1f} s"
    print(f"wrote {out}{took} ({platform.processor() or platform.machine()}, {os.cpu_count()} cores)")
