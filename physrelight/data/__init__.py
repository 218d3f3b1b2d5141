"""The data files that ship with :mod:`physrelight`: the outdoor HDRIs and their sky masks.

``physrelight/data/hdri/NAME.exr`` are lat-long environment maps in the layout of DESIGN.md (row 0 = zenith),
``NAME_sky.png`` their sky masks; ``hdri_heldout/`` holds maps never used in training. :func:`hdri` gives the
path of a shipped map by name, so no caller builds the path by hand::

    from physrelight.data import hdri, hdri_names
    hdri("forest")   # Path(".../physrelight/data/hdri/forest.exr")
    hdri_names()     # ("city", "courtyard", "forest", "studio")

``studio`` is indoor: a stress case, never an outdoor score (DESIGN.md).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["DATA_DIR", "HDRI_DIR", "HELDOUT_DIR", "hdri", "hdri_names"]

DATA_DIR = Path(__file__).resolve().parent
"""The package's data folder."""
HDRI_DIR = DATA_DIR / "hdri"
"""The shipped maps (seen in training)."""
HELDOUT_DIR = DATA_DIR / "hdri_heldout"
"""The held-out maps (never seen in training)."""


def hdri_names(heldout: bool = False) -> tuple[str, ...]:
    """The names of the shipped maps, sorted (the held-out ones with ``heldout``): what :func:`hdri` takes."""
    folder = HELDOUT_DIR if heldout else HDRI_DIR
    return tuple(sorted(p.stem for p in folder.glob("*.exr") if p.is_file()))


def hdri(name: str, heldout: bool = False) -> Path:
    """The path of the shipped map ``name`` (e.g. ``"forest"``; a held-out one with ``heldout``), a lat-long
    ``.exr``. Raises ``ValueError`` listing the known names for an unknown one."""
    names = hdri_names(heldout)
    if not isinstance(name, str) or name not in names:
        kind = "held-out HDRI" if heldout else "HDRI"
        raise ValueError(f"unknown {kind} {name!r}; the shipped ones are {', '.join(names)}")
    return (HELDOUT_DIR if heldout else HDRI_DIR) / f"{name}.exr"
