"""What every stage's command line shares: argparse types, the check for optional extras, and the checks of
output paths, memory and inputs that every subcommand makes before it does any work.

The stage CLIs (``synth.cli``, ``learned.cli``, ``learned.relight_cli``, ``validation.cli``,
``validation.bench.cli``) import from here, never from the entry module
:mod:`physrelight.cli`, which imports them: the shared piece sits one layer below both.
Nothing here imports torch or numpy, so ``physrelight --help`` stays fast.

Output paths (:func:`check_output_file`, :func:`check_output_folder`, :func:`check_outputs`): a subcommand names
its output arguments with ``set_defaults(output_files=(...), output_folders=(...))`` and the entry module checks them
after parsing, before the handler runs: a folder where a file goes, a file where a folder goes, or a place that does
not take new files is one line and exit 2, not a traceback after minutes of work. Writability is probed by making
(and at once removing) a temporary file in the nearest existing folder: ``os.access`` says yes to root everywhere,
even in ``/proc``.

Extras are read from the installed distribution's own metadata (``pyproject.toml``'s
``[project.optional-dependencies]``), so this module names no package by hand.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import math
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Callable, Sequence

__all__ = ["MEMORY_FRACTION", "SETUP_COMMAND", "MissingExtra", "MissingSetup", "available_memory",
           "check_fits_in_memory", "check_not_input", "check_output_file", "check_output_folder", "check_outputs",
           "finite_number", "keep_freed_memory", "missing_requirements", "number_in", "positive_int",
           "positive_number", "require_extras"]

MEMORY_FRACTION = 0.5
"""The share of the available memory one run may plan to hold (:func:`check_fits_in_memory`): the rest is the
process's own (torch, Mitsuba's JIT) and the other programs'."""

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


def finite_number(what: str) -> Callable[[str], float]:
    """argparse type: any finite number (``what`` names it in the one-line error for text, nan or inf)."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"{what} must be a finite number, got {text}")
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


SETUP_COMMAND = "bash scripts/setup.sh"
"""The checkout's set-up script: system libraries (libllvm19 for Mitsuba's llvm_ad_rgb), the venv, the extras."""


class MissingSetup(RuntimeError):
    """The machine lacks a system piece that :data:`SETUP_COMMAND` installs (the message says which and how):
    the entry module reports it as one line, exit 2."""


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


# ----------------------------------------------------------------------------- outputs, inputs, memory


def _nearest_existing(path: Path) -> Path:
    """``path`` itself or its nearest ancestor that exists (``.`` for a relative path with none)."""
    p = path
    while not os.path.lexists(p):
        if p.parent == p:
            break
        p = p.parent
    return p


def _probe_writable(folder: Path, target: Path, what: str) -> None:
    """Make and remove a temporary file in ``folder``; ValueError naming ``what`` and ``target`` if that fails."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".physrelight-probe.", dir=folder)
    except OSError as err:
        reason = err.strerror or type(err).__name__
        raise ValueError(f"cannot write {what} {str(target)!r}: {str(folder)!r} does not take new files "
                         f"({reason})") from None
    os.close(fd)
    os.remove(tmp)


def check_output_folder(path: str | os.PathLike, what: str = "output folder") -> Path:
    """Refuse, before any work, a folder that cannot be made or written (it is made later with its parents).

    The path must be a folder or not exist; its nearest existing ancestor must be a folder that takes new files.
    Returns the path. Raises ``ValueError`` naming ``what`` and the problem.
    """
    p = Path(path)
    if str(path) == "":
        raise ValueError(f"{what} is an empty path")
    base = _nearest_existing(p)
    if base.exists() and not base.is_dir():
        if base == p:
            raise ValueError(f"{what} {str(p)!r} is a file, not a folder")
        raise ValueError(f"cannot make {what} {str(p)!r}: {str(base)!r} is a file, not a folder")
    if not base.exists():  # a dangling link, or nothing at all up to the root
        raise ValueError(f"cannot make {what} {str(p)!r}: {str(base)!r} does not exist")
    _probe_writable(base, p, what)
    return p


def check_output_file(path: str | os.PathLike, what: str = "output") -> Path:
    """Refuse, before any work, a file that cannot be written: a folder already there, or a parent that cannot
    be made or written (parents are made when the file is written). Returns the path; ``ValueError`` otherwise."""
    p = Path(path)
    if str(path) == "":
        raise ValueError(f"{what} is an empty path")
    if p.is_dir():
        raise ValueError(f"{what} {str(p)!r} is a folder, not a file")
    base = _nearest_existing(p.parent if str(p.parent) else Path("."))
    if base.exists() and not base.is_dir():
        raise ValueError(f"cannot write {what} {str(p)!r}: {str(base)!r} is a file, not a folder")
    if not base.exists():
        raise ValueError(f"cannot write {what} {str(p)!r}: {str(base)!r} does not exist")
    _probe_writable(base, p, what)
    return p


def _option(dest: str) -> str:
    return dest if dest in ("output", "photo") else "--" + dest.replace("_", "-")


def check_outputs(args: argparse.Namespace) -> None:
    """Check the output arguments a subcommand declared (``output_files``/``output_folders`` defaults naming
    ``args`` attributes; None values are skipped) with :func:`check_output_file`/:func:`check_output_folder`."""
    for dest in getattr(args, "output_files", ()):
        value = getattr(args, dest, None)
        if value is not None:
            check_output_file(value, _option(dest))
    for dest in getattr(args, "output_folders", ()):
        value = getattr(args, dest, None)
        if value is not None:
            check_output_folder(value, _option(dest))


def check_not_input(output: str | os.PathLike, inputs: dict[str, Any]) -> None:
    """Refuse an output that is one of the inputs (``{what: path}``; None skipped): the same file by
    ``os.path.samefile`` when both exist (links, ``./`` and ``..`` seen through), else by resolved path."""
    out = Path(output)
    for what, path in inputs.items():
        if path is None:
            continue
        same = (os.path.samefile(out, path) if out.exists() and Path(path).exists()
                else out.resolve() == Path(path).resolve())
        if same:
            raise ValueError(f"output {str(out)!r} is the {what} {str(path)!r}: writing it would destroy the "
                             f"original; give another output path")


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation without swapping: Linux's ``MemAvailable``
    (``/proc/meminfo``), else free pages times the page size (``os.sysconf``); None where neither is known."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 / 10 else f"{n / 2**20:.1f} MiB"


def check_fits_in_memory(needed: int, what: str, fraction: float = MEMORY_FRACTION,
                         available: int | None = None) -> None:
    """Refuse a run that plans to hold ``needed`` bytes when that exceeds ``fraction`` of the available memory
    (:func:`available_memory`, or ``available``); ``what`` says what needs it. Unknown memory: no check."""
    avail = available_memory() if available is None else available
    if avail is None:
        return
    if needed > fraction * avail:
        raise ValueError(f"{what} needs about {_gib(needed)} of memory, more than {fraction:.0%} of the "
                         f"{_gib(avail)} available")


def keep_freed_memory() -> bool:
    """Let this process's C allocator keep the memory it frees for its next allocations (glibc's ``mallopt``: no
    ``mmap`` per block, freed memory never trimmed, one arena for every thread); False where the C library
    is not glibc (nothing changes).

    glibc serves a block over its mmap threshold (a few MiB: any full-size plane of a photo) by a fresh ``mmap`` and
    returns it on free, so every full-size temporary of a large relight is page-faulted in anew: half of a
    12-megapixel ``relight``'s CPU time was the kernel zeroing pages (18.5 s system against 15.6 s user, one
    thread; docs/bench.md, "Speed of relight"). Kept, the blocks are reused. The cost is memory the process
    holds after a peak (a 12-megapixel relight's peak resident memory went from 2.6 to 3.1 GB). One arena: a worker
    thread's own arena (:mod:`physrelight.parallel`) cannot hold a full-size plane and would map each one afresh
    (two threads were slower than one without it). Never trimmed (``M_TRIM_THRESHOLD`` -1, glibc's "disables
    trimming"): with a 2 GiB threshold a two-thread 12-megapixel relight still gave 2.5 GB back to the kernel in five
    trims and faulted it in again (4.2 s of system time; 0.44 s without trimming, peak 4.5 -> 5.2 GB). Process-wide,
    so called by the commands that need it (``relight``), not by the library."""
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        mallopt = libc.mallopt if libc is not None else None
        gnu = libc.gnu_get_libc_version if libc is not None else None
    except (OSError, AttributeError):
        return False
    if mallopt is None or gnu is None:
        return False
    m_trim_threshold, m_mmap_max, m_arena_max = -1, -4, -8  # malloc.h
    return all([bool(mallopt(m_mmap_max, 0)), bool(mallopt(m_trim_threshold, -1)),
                bool(mallopt(m_arena_max, 1))])
