"""The data files that ship with :mod:`physrelight`: the HDR panoramas and their sky masks, and one example photo.

``physrelight/data/hdri/NAME.exr`` are lat-long environment maps in the layout of DESIGN.md (row 0 = zenith),
``NAME_sky.png`` their sky masks; ``hdri_heldout/`` holds maps never used in training; ``hdri_more/`` the fifteen
cleaned CC0 panoramas of issue 43 (``pm_*.exr``, 512 x 256; their kinds in ``kinds.json``; a ``pm_NAME_sky.png``
beside each outdoor one whose mask was reviewed). :func:`hdri` gives the path of a map by name, so no caller builds
the path by hand::

    from physrelight.data import hdri, hdri_kind, hdri_names
    hdri("forest")                                   # Path(".../physrelight/data/hdri/forest.exr")
    hdri_names()                                     # ("city", "courtyard", "forest", "studio")
    hdri_names(collection="more", kind="outdoor")    # ("pm_city", "pm_dawn", ..., "pm_venice")
    hdri("pm_sky", collection="more")                # Path(".../physrelight/data/hdri_more/pm_sky.exr")
    hdri_kind("studio")                              # "indoor"

``studio`` and the ``indoor`` maps of ``hdri_more`` are indoor: stress cases and no-sky negatives, never an
outdoor score (DESIGN.md). ``pm_bridge`` is a ``walkway`` (a covered glass walkway): neither.

``photos/rocket.jpg`` is a real outdoor photo to try things on (public domain; ``photos/LICENSE.txt``):
:func:`example_photo` gives its path.
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

__all__ = ["COLLECTIONS", "DATA_DIR", "HDRI_DIR", "HELDOUT_DIR", "KINDS", "MORE_DIR", "PHOTO_DIR", "example_photo",
           "hdri", "hdri_kind", "hdri_names", "hdri_sky_mask"]

DATA_DIR = Path(__file__).resolve().parent
"""The package's data folder."""
HDRI_DIR = DATA_DIR / "hdri"
"""The shipped maps (seen in training)."""
HELDOUT_DIR = DATA_DIR / "hdri_heldout"
"""The held-out maps (never seen in training)."""
MORE_DIR = DATA_DIR / "hdri_more"
"""The fifteen cleaned CC0 panoramas of issue 43 (training side; their kinds in ``kinds.json``)."""
COLLECTIONS = ("shipped", "heldout", "more")
"""The folders :func:`hdri` reads: :data:`HDRI_DIR`, :data:`HELDOUT_DIR`, :data:`MORE_DIR`."""
KINDS = ("outdoor", "indoor", "walkway")
"""What a map shows: an outdoor place with sky, a room (no sky), or a covered walkway (neither)."""
_SHIPPED_INDOOR = ("studio",)
_FOLDERS = {"shipped": HDRI_DIR, "heldout": HELDOUT_DIR, "more": MORE_DIR}
PHOTO_DIR = DATA_DIR / "photos"
"""The example photo and its licence note."""


def _collection(heldout: bool, collection: str | None) -> str:
    if collection is None:
        return "heldout" if heldout else "shipped"
    if collection not in COLLECTIONS:
        raise ValueError(f"collection must be one of {', '.join(COLLECTIONS)}, got {collection!r}")
    if heldout and collection != "heldout":
        raise ValueError(f"heldout=True names the held-out collection; it cannot be combined with {collection!r}")
    return collection


@lru_cache(maxsize=None)
def _more_kinds() -> dict[str, str]:
    kinds = json.loads((MORE_DIR / "kinds.json").read_text())
    bad = {n: k for n, k in kinds.items() if k not in KINDS}
    if bad:  # a damaged data file, not the caller's fault: say which entry
        raise ValueError(f"{MORE_DIR / 'kinds.json'}: unknown kinds {bad}; known: {', '.join(KINDS)}")
    return kinds


def _kind_of(name: str, collection: str) -> str:
    if collection == "more":
        return _more_kinds()[name]
    return "indoor" if name in _SHIPPED_INDOOR else "outdoor"


def hdri_names(heldout: bool = False, collection: str | None = None, kind: str | None = None) -> tuple[str, ...]:
    """The names of the maps of one collection, sorted: what :func:`hdri` takes.

    Args:
        heldout: the held-out maps (the same as ``collection="heldout"``; kept for the callers before issue 43).
        collection: one of :data:`COLLECTIONS`; None: ``"shipped"`` (or ``"heldout"`` with ``heldout``).
        kind: only the maps of this kind (:data:`KINDS`); None: every map.
    """
    coll = _collection(heldout, collection)
    if kind is not None and kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    names = sorted(p.stem for p in _FOLDERS[coll].glob("*.exr") if p.is_file())
    return tuple(n for n in names if kind is None or _kind_of(n, coll) == kind)


def hdri(name: str, heldout: bool = False, collection: str | None = None) -> Path:
    """The path of the map ``name`` (e.g. ``"forest"``; a held-out one with ``heldout``; ``"pm_sky"`` with
    ``collection="more"``), a lat-long ``.exr``. Raises ``ValueError`` listing the known names for an unknown one."""
    coll = _collection(heldout, collection)
    names = hdri_names(collection=coll)
    if not isinstance(name, str) or name not in names:
        what = {"shipped": "HDRI", "heldout": "held-out HDRI", "more": "HDRI of hdri_more"}[coll]
        raise ValueError(f"unknown {what} {name!r}; the shipped ones are {', '.join(names)}")
    return _FOLDERS[coll] / f"{name}.exr"


def hdri_kind(name: str, heldout: bool = False, collection: str | None = None) -> str:
    """What the map ``name`` shows, one of :data:`KINDS` (``studio`` and the rooms of ``hdri_more``: indoor)."""
    coll = _collection(heldout, collection)
    hdri(name, collection=coll)  # the same refusal for an unknown name
    return _kind_of(name, coll)


def hdri_sky_mask(name: str, heldout: bool = False, collection: str | None = None) -> Path | None:
    """The reviewed sky mask ``NAME_sky.png`` beside the map ``name`` (white = sky), or None where the map has
    none (an outdoor map of ``hdri_more`` whose mask could not be made trustworthy; rooms have none)."""
    p = hdri(name, heldout, collection).with_name(f"{name}_sky.png")
    return p if p.is_file() else None


def example_photo() -> Path:
    """The path of the shipped example photo: ``photos/rocket.jpg``, a 640 x 427 sRGB JPEG of a rocket on its pad
    at dusk, under a deep-blue sky (SpaceX, public domain; scikit-image's ``rocket.jpg``, byte for byte), for
    ``physrelight.io.read_image`` or ``physrelight relight``."""
    return PHOTO_DIR / "rocket.jpg"
