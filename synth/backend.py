"""Select Mitsuba's variant before anything imports it.

``llvm_ad_rgb`` (vectorised, differentiable) needs a shared LLVM >= 16 library, found
here and handed to Dr.Jit through ``DRJIT_LIBLLVM_PATH`` *before* ``import mitsuba``.
The system LLVM 15 of Debian 12 crashes Dr.Jit ("Cannot select fminimum"), so it is
never picked. Without a suitable LLVM, forward renders fall back to ``scalar_rgb``
(about 4.5x slower, not differentiable) with a one-line warning, and anything that
needs gradients fails with a message that says what to install.

Usage::

    from synth.backend import load_mitsuba
    mi = load_mitsuba()                      # llvm_ad_rgb, or scalar_rgb with a warning
    mi = load_mitsuba(differentiable=True)   # llvm_ad_rgb or RuntimeError
"""

from __future__ import annotations

import glob
import os
import re
import sys
import warnings
from pathlib import Path
from types import ModuleType

from physrelight.cli_common import MissingSetup  # a RuntimeError: one line from the command line

MIN_LLVM = 16
DIFFERENTIABLE_VARIANT = "llvm_ad_rgb"
FALLBACK_VARIANT = "scalar_rgb"

_SEARCH_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/opt/homebrew/opt/llvm/lib",
    "/usr/local/opt/llvm/lib",
)


def _llvm_version(path: str) -> int | None:
    """Major version from a library name: libLLVM-19.so, libLLVM.so.19.1, libLLVM-19.so.1."""
    name = os.path.basename(path)
    m = re.match(r"libLLVM[-.](?:so\.)?(\d+)", name)
    return int(m.group(1)) if m else None


def find_llvm() -> Path | None:
    """Newest shared LLVM library with major version >= 16, or None.

    An existing ``DRJIT_LIBLLVM_PATH`` wins if it points to a file. Otherwise the usual
    library folders and ``/usr/lib/llvm-*/lib`` are searched.
    """
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env and os.path.isfile(env):
        return Path(env)
    candidates: list[tuple[int, str]] = []
    dirs = list(_SEARCH_DIRS) + sorted(glob.glob("/usr/lib/llvm-*/lib"))
    for d in dirs:
        for path in glob.glob(os.path.join(d, "libLLVM*.so*")) + glob.glob(os.path.join(d, "libLLVM*.dylib")):
            version = _llvm_version(path)
            if version is None and "/llvm-" in path:
                m = re.search(r"/llvm-(\d+)/", path)
                version = int(m.group(1)) if m else None
            if version is not None and version >= MIN_LLVM and os.path.isfile(path):
                candidates.append((version, path))
    if not candidates:
        return None
    return Path(max(candidates)[1])


_INSTALL_HINT = ("install Debian's libllvm19 (apt-get install libllvm19; `bash scripts/setup.sh` does it) "
                 "or set DRJIT_LIBLLVM_PATH to a libLLVM >= 16")


def load_mitsuba(differentiable: bool = False) -> ModuleType:
    """Import mitsuba with the best variant this machine supports and return the module.

    Args:
        differentiable: require ``llvm_ad_rgb``; raise :class:`physrelight.cli_common.MissingSetup` (a
            ``RuntimeError``) if it cannot be had.

    The variant is chosen once per process: a later call that needs gradients after a
    scalar fallback raises rather than silently switching.
    """
    if "mitsuba" in sys.modules:
        mi = sys.modules["mitsuba"]
        current = mi.variant()
        if current is not None:
            if differentiable and current != DIFFERENTIABLE_VARIANT:
                raise MissingSetup(
                    f"differentiable rendering needs Mitsuba's {DIFFERENTIABLE_VARIANT}, but this process "
                    f"runs {current} (no LLVM >= {MIN_LLVM} was found): {_INSTALL_HINT}"
                )
            return mi
    llvm = find_llvm()
    if llvm is not None:
        os.environ["DRJIT_LIBLLVM_PATH"] = str(llvm)
    import mitsuba as mi

    if llvm is not None:
        try:
            mi.set_variant(DIFFERENTIABLE_VARIANT)
            return mi
        except Exception as err:  # noqa: BLE001 - Dr.Jit reports LLVM problems as plain exceptions
            reason = f"{DIFFERENTIABLE_VARIANT} failed to start with {llvm}: {err}"
    else:
        reason = f"no LLVM >= {MIN_LLVM} shared library found"
    if differentiable:
        raise MissingSetup(f"differentiable rendering needs Mitsuba's {DIFFERENTIABLE_VARIANT}: {reason}; "
                           f"{_INSTALL_HINT}")
    warnings.warn(f"{reason}; falling back to {FALLBACK_VARIANT} (slower, not differentiable)", stacklevel=2)
    mi.set_variant(FALLBACK_VARIANT)
    return mi


def variant() -> str | None:
    """The variant in use, or None if Mitsuba has not been loaded yet."""
    mi = sys.modules.get("mitsuba")
    return None if mi is None else mi.variant()
