"""What every stage's command line shares: argparse types and the check for optional extras.

The stage CLIs (``synth.cli``, ``learned.cli``, ``learned.relight_cli``, ``validation.cli``,
``validation.bench.cli``) import from here, never from the entry module
:mod:`physrelight.cli`, which imports them: the shared piece sits one layer below both.
Nothing here imports torch or numpy, so ``physrelight --help`` stays fast.

Extras are read from the installed distribution's own metadata (``pyproject.toml``'s
``[project.optional-dependencies]``), so this module names no package by hand.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import math
import re
from typing import Callable, Sequence

__all__ = ["MissingExtra", "missing_requirements", "positive_int", "positive_number", "require_extras"]

DISTRIBUTION = "physrelight"

# "name[extra,...] >=1.0 ; extra == 'x'" -> name, its extras, the extra it belongs to
_REQUIREMENT = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[([^\]]*)\])?[^;]*(?:;\s*(.*))?$")
_EXTRA_MARKER = re.compile(r"""extra\s*==\s*["']([^"']+)["']""")


def positive_int(text: str) -> int:
    """argparse type: a positive integer, with a one-line error otherwise."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def number_in(lo: float, hi: float, what: str) -> Callable[[str], float]:
    """argparse type: a finite number in ``[lo, hi]`` (``what`` names it in the one-line error)."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not (math.isfinite(v) and lo <= v <= hi):
            raise argparse.ArgumentTypeError(f"{what} must lie in [{lo:g}, {hi:g}], got {text}")
        return v

    return parse


def positive_number(text: str) -> float:
    """argparse type: a finite positive number, with a one-line error otherwise."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text}")
    return v


class MissingExtra(RuntimeError):
    """A subcommand needs an optional extra that is not installed (the message says which)."""


def _requirements() -> list[tuple[str, set[str], str | None]]:
    """``(distribution, its extras, the extra of ours that adds it or None)`` for every requirement."""
    out = []
    for line in importlib.metadata.requires(DISTRIBUTION) or []:
        m = _REQUIREMENT.match(line)
        if m is None:
            continue
        extra = _EXTRA_MARKER.search(m.group(3) or "")
        out.append((m.group(1), {e.strip() for e in (m.group(2) or "").split(",") if e.strip()},
                    extra.group(1) if extra else None))
    return out


def _installed(distribution: str) -> bool:
    try:
        importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


def missing_requirements(extra: str) -> list[str]:
    """Distributions that ``pip install 'physrelight[extra]'`` would add and that are not installed.

    Raises:
        ValueError: ``extra`` is not one of the distribution's extras.
    """
    try:
        reqs = _requirements()
    except importlib.metadata.PackageNotFoundError:
        return []  # run from a source tree that was never installed: nothing to check against
    known = {e for _, _, e in reqs if e is not None}
    if extra not in known:
        raise ValueError(f"unknown extra {extra!r}; {DISTRIBUTION} has {sorted(known)}")
    missing: list[str] = []
    todo, seen = [extra], set()
    while todo:  # an extra may name others ("all" = "physrelight[synth,...]")
        e = todo.pop()
        if e in seen:
            continue
        seen.add(e)
        for name, extras, of in reqs:
            if of != e:
                continue
            if name == DISTRIBUTION:
                todo.extend(extras)
            elif name not in missing and not _installed(name):
                missing.append(name)
    return missing


def require_extras(command: str, extras: Sequence[str], alternative: str = "") -> None:
    """Raise :class:`MissingExtra` naming the first of ``extras`` that is not fully installed.

    Called before a subcommand does any work, so a missing extra costs one line and leaves
    nothing on disk. ``alternative`` is appended (e.g. "or run part 1 alone with --physics-only").
    """
    for extra in extras:
        missing = missing_requirements(extra)
        if missing:
            hint = f"; {alternative}" if alternative else ""
            raise MissingExtra(f"{command} needs the {extra} extra ({', '.join(missing)} not installed): "
                               f"pip install '{DISTRIBUTION}[{extra}]' (in a checkout: pip install -e '.[{extra}]')"
                               f"{hint}")
