"""A tiny rendered dataset (shared by the learned tests) and a tiny lighting prior."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

TINY = dict(scenes=3, views=2, lights=2, res=24, spp=4, gbuffer_spp=2, shadow_spp=2, env_resolution=16,
            kinds=("sunsky", "overcast", "hdri"))
TINY_NET = dict(width=4, depth=2, res=24)


def tiny_train_config(data: Path, out: Path, prior: Path, **kw):
    """A :class:`learned.train.TrainConfig` of the inverse stage for a few steps of the tiny network on ``data``
    (every split, one thread, seed 5, no progress bar); ``kw`` overrides any field."""
    from learned.train import TrainConfig

    base = dict(stage="inverse", data=str(data), out=str(out), prior=str(prior), train_split="all",
                val_split="all", batch=2, steps=6, val_every=1000, val_images=4, ckpt_every=3, log_every=1,
                threads=1, seed=5, progress=False, lr=3e-3, **TINY_NET)
    base.update(kw)
    return TrainConfig(**base)


def save_weights(net: torch.nn.Module, path: Path, kind: str, **extra: str) -> Path:
    """Export a module the way ``train export`` does (weights + kind/width/depth/res metadata, and
    ``extra`` metadata such as ``lighting_solve`` or ``meter_exposure``)."""
    from learned.checkpoint import _atomic_save_tensors

    path.parent.mkdir(parents=True, exist_ok=True)
    _atomic_save_tensors(dict(net.state_dict()), path, {"kind": kind, "width": str(net.width),
                                                        "depth": str(net.depth), "res": "24", **extra})
    return path


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    """3 scenes x 2 views x 2 lightings at 24 px (a few seconds with Mitsuba)."""
    from synth import writer

    root = tmp_path_factory.mktemp("learned_ds")
    writer.write_dataset(root, writer.SynthConfig(**TINY), progress=False)
    return root


@pytest.fixture(scope="session")
def tiny_prior(tmp_path_factory) -> Path:
    """A prior fitted on a few outdoor lightings (seconds), saved as .npz."""
    from learned.lighting import fit_outdoor_prior

    path = tmp_path_factory.mktemp("prior") / "prior.npz"
    fit_outdoor_prior(k=12, n_sky=24, n_hdri_per_map=4, seed=3, path=path)
    return path

