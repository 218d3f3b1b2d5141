"""The learned pipeline (Yu et al., ECCV 2020), first stage: inverse rendering network,
lighting solved and projected onto an outdoor subspace, ShadowNet; trained self-supervised.

``from learned import Relighter``: ``Relighter.load()`` uses the weights shipped in
``learned/weights``. Modules: ``networks``, ``lighting`` (the prior), ``data``,
``objectives``, ``evaluate``, ``checkpoint``, ``train``, ``relighter``, ``cli``.
"""

from __future__ import annotations

from typing import Any

__all__ = ["Relighter"]


def __getattr__(name: str) -> Any:
    # Lazy: `physrelight --help` imports learned.cli and must stay light.
    if name == "Relighter":
        from .relighter import Relighter

        return Relighter
    raise AttributeError(f"module 'learned' has no attribute {name!r}")
