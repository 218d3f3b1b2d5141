"""The checks of ``physrelight validate``, in run order, and how a user names them.

Kept apart from :mod:`validation.report` (which imports numpy and the checks' shared code)
so that the command line can list them without loading anything: ``validate --help`` and
``--checks`` read :data:`CHECKS` from here.
"""

from __future__ import annotations

from typing import Sequence

CHECKS: tuple[tuple[str, str, str], ...] = (
    ("renderer_irradiance", "validation.renderer_irradiance", "renderer vs exact irradiance"),
    ("sh_model", "validation.sh_model", "SH irradiance model"),
    ("shadow_loss", "validation.shadow_loss", "shadow-free loss with ground truth"),
    ("lighting_solve", "validation.lighting_solve", "lighting solve"),
    ("relight_ceiling", "validation.relight_ceiling", "relighting ceiling"),
    ("speed", "validation.speed", "speed vs accuracy"),
    ("gradients", "validation.gradients", "gradients of the differentiable renderer"),
)
"""``(key, module, what it checks)`` in run order; each module has ``run(ctx) -> CheckResult``."""


def check_keys(selection: Sequence[str] | None) -> list[str]:
    """Check keys to run: all, or a selection by key or number (``"1"``, ``"sh_model"``)."""
    keys = [k for k, _, _ in CHECKS]
    if not selection:
        return keys
    out = []
    for s in selection:
        if s.isdigit() and 1 <= int(s) <= len(keys):
            out.append(keys[int(s) - 1])
        elif s in keys:
            out.append(s)
        else:
            raise ValueError(f"unknown check {s!r}; expected 1-{len(keys)} or one of {', '.join(keys)}")
    return [k for k in keys if k in out]
