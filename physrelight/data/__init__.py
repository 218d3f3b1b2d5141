"""The data files that ship with :mod:`physrelight`: the outdoor HDRIs and their sky masks, and one example photo.

``physrelight/data/hdri/NAME.exr`` are lat-long environment maps in the layout of DESIGN.md (row 0 = zenith),
``NAME_sky.png`` their sky masks; ``hdri_heldout/`` holds maps never used in training. :func:`hdri` gives the
path of a shipped map by name, so no caller builds the path by hand::

    from physrelight.data import hdri, hdri_names
    hdri("forest")   # Path(".../physrelight/data/hdri/forest.exr")
    hdri_names()     # ("city", "courtyard", "forest", "studio")

``studio`` is indoor: a stress case, never an outdoor score (DESIGN.md).

``photos/rocket.jpg`` is a real outdoor photo to try things on (public domain; ``photos/LICENSE.txt``):
:func:`example_photo` gives its path.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["DATA_DIR", "HDRI_DIR", "HELDOUT_DIR", "PHOTO_DIR", "example_photo", "hdri", "hdri_names"]

DATA_DIR = Path(__file__).resolve().parent
"""The package's data folder."""
HDRI_DIR = DATA_DIR / "hdri"
"""The shipped maps (seen in training)."""
HELDOUT_DIR = DATA_DIR / "hdri_heldout"
"""The held-out maps (never seen in training)."""
PHOTO_DIR = DATA_DIR / "photos"
"""The example photo and its licence note."""


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


def example_photo() -> Path:
    """The path of the shipped example photo: ``photos/rocket.jpg``, a 640 x 427 sRGB JPEG of a rocket launch
    under a clear blue sky (SpaceX, public domain; scikit-image's ``rocket.jpg``, byte for byte), for
    ``physrelight.io.read_image`` or ``physrelight relight``."""
    return PHOTO_DIR / "rocket.jpg"
