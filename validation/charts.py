"""Matplotlib (Agg) charts with a title, labelled axes and a footnote naming the machine
and the command that produced them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .common import Context, machine_line  # noqa: E402


def figure(width: float = 7.5, height: float = 4.2, ncols: int = 1) -> tuple[Any, Any]:
    """A new figure and its axes (one row of ``ncols``)."""
    fig, axes = plt.subplots(1, ncols, figsize=(width, height), squeeze=False)
    return fig, (axes[0, 0] if ncols == 1 else axes[0])


def save(fig: Any, ctx: Context, name: str, title: str) -> str:
    """Title the figure, add the machine/command footnote, write ``charts/NAME.png``.

    Returns:
        The path relative to the report folder (for markdown links).
    """
    fig.suptitle(title, fontsize=11)
    foot = f"{machine_line(ctx.machine)}  |  {ctx.command}"
    fig.text(0.01, 0.005, foot, fontsize=6.5, color="0.35", ha="left", va="bottom")
    fig.tight_layout(rect=(0, 0.035, 1, 0.96))
    path = Path(ctx.chart_dir) / f"{name}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return f"charts/{name}.png"
