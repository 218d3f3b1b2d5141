"""The learned pipeline (Yu et al., ECCV 2020), first stage: inverse rendering network,
lighting solved and projected onto an outdoor subspace, ShadowNet; trained self-supervised.

``from learned import Relighter``: ``Relighter.load()`` uses the weights shipped in
``learned/weights``. Modules, photo to relit photo: ``data``, ``networks``, ``lighting`` (the
prior), ``objectives``, ``neural_renderer``, ``sky_segmentation``, ``sky_gan``, ``relight_options``,
``relighter``, ``relight_cli``; training: ``runs`` (what the loops share), ``train``, ``train_renderer``,
``train_sky``, ``checkpoint``, ``evaluate``, ``relight_eval``, ``cli`` (docs/learned.md).
"""

from __future__ import annotations

from typing import Any

__all__ = ["RelightOptions", "Relighter"]


def __getattr__(name: str) -> Any:
    # Lazy: `physrelight --help` imports learned.cli and must stay light.
    if name == "Relighter":
        from .relighter import Relighter

        return Relighter
    if name == "RelightOptions":
        from .relight_options import RelightOptions

        return RelightOptions
    raise AttributeError(f"module 'learned' has no attribute {name!r}")
