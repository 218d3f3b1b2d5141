"""Networks of the paper's first stage: the inverse rendering UNet and ShadowNet.

Both are small UNets with GroupNorm (never BatchNorm: the original ShadowNet ran its
BatchNorm in training mode at test time, so its output depended on the batch). GroupNorm
normalises each image on its own, so a network behaves the same in ``train()`` and
``eval()`` and for any batch size.

Shapes: images ``(B, C, H, W)``; any ``H, W`` works (inputs are padded to a multiple of
``2 ** depth`` by reflection and the outputs cropped back).

* :class:`InverseNet`: linear image ``(B, 3, H, W)`` -> albedo ``(B, 3, H, W)`` in [0, 1]
  (sigmoid), normals ``(B, 3, H, W)`` unit, camera frame, ``n_z > 0`` (facing the
  camera), shadow ``(B, 1, H, W)`` in [0, 1] (sigmoid, 1 = unshadowed).
* :class:`ShadowNet`: normals ``(B, 3, H, W)`` + lighting ``(B, 9, 3)`` tiled per pixel
  (30 channels) -> shadow ``(B, 1, H, W)`` in [0, 1].

:func:`load_network` (``load_inverse``, ``load_shadow``) builds either from a run folder or
an exported weights file; inference (:class:`learned.Relighter`) and training both use it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from physrelight import colour

from . import checkpoint as ckpt

__all__ = ["EXPOSURE_KEY", "UNet", "InverseNet", "ShadowNet", "count_parameters", "load_inverse", "load_network",
           "load_shadow", "log_average_luminance", "metered", "mirror_averaged", "normalise_lighting",
           "repair_top_rows", "tile_lighting"]


def _groups(channels: int) -> int:
    """Largest group count <= 8 dividing ``channels`` (GroupNorm needs a divisor)."""
    for g in (8, 4, 2, 1):
        if channels % g == 0:
            return g
    return 1


class _Block(nn.Sequential):
    """Two 3x3 convolutions, each followed by GroupNorm and ReLU."""

    def __init__(self, cin: int, cout: int) -> None:
        super().__init__(
            nn.Conv2d(cin, cout, 3, padding=1, bias=False), nn.GroupNorm(_groups(cout), cout), nn.ReLU(inplace=True),
            nn.Conv2d(cout, cout, 3, padding=1, bias=False), nn.GroupNorm(_groups(cout), cout), nn.ReLU(inplace=True),
        )


class UNet(nn.Module):
    """A small UNet: ``depth`` stride-2 levels, channels ``width * 2**level``.

    Args:
        in_channels: input channels.
        out_channels: output channels (a 1x1 convolution, no activation).
        width: channels of the first level (the knob the width chart measures).
        depth: number of downsamplings.
    """

    def __init__(self, in_channels: int, out_channels: int, width: int = 16, depth: int = 3) -> None:
        super().__init__()
        if not (isinstance(width, int) and width >= 1):
            raise ValueError(f"width must be a positive integer, got {width!r}")
        if not (isinstance(depth, int) and 1 <= depth <= 6):
            raise ValueError(f"depth must be an integer in [1, 6], got {depth!r}")
        self.depth = depth
        chans = [width * 2**i for i in range(depth + 1)]
        self.inc = _Block(in_channels, chans[0])
        self.down = nn.ModuleList(
            nn.Sequential(nn.Conv2d(chans[i], chans[i], 3, stride=2, padding=1, bias=False),
                          nn.GroupNorm(_groups(chans[i]), chans[i]), nn.ReLU(inplace=True),
                          _Block(chans[i], chans[i + 1]))
            for i in range(depth))
        self.up = nn.ModuleList(_Block(chans[i + 1] + chans[i], chans[i]) for i in reversed(range(depth)))
        self.head = nn.Conv2d(chans[0], out_channels, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, in, H, W)`` -> ``(B, out, H, W)``."""
        h, w = x.shape[-2:]
        m = 2**self.depth
        ph, pw = (-h) % m, (-w) % m
        if ph or pw:
            # Reflection needs pad < size; replicate covers tiny inputs.
            mode = "reflect" if ph < h and pw < w else "replicate"
            x = F.pad(x, (0, pw, 0, ph), mode=mode)
        skips = [self.inc(x)]
        for d in self.down:
            skips.append(d(skips[-1]))
        y = skips.pop()
        for u in self.up:
            s = skips.pop()
            y = u(torch.cat([F.interpolate(y, size=s.shape[-2:], mode="bilinear", align_corners=False), s], 1))
        return self.head(y)[..., :h, :w]


EDGE_ROWS = 2
"""Rows at the top of the shipped networks' outputs that no loss ever reached (:func:`repair_top_rows`)."""


def repair_top_rows(x: torch.Tensor, rows: int = EDGE_ROWS) -> torch.Tensor:
    """``x (B, C, H, W)`` with its first ``rows`` rows replaced by row ``rows`` (at inference).

    Why: a stride-2 convolution with padding 1 reads zero padding at the top and left borders only,
    and every training photo has sky along its top rows, where no loss looks. So the first rows of
    the shipped networks' layers are wrong whatever the photo (a constant photo's albedo is twice
    as bright in row 0, its normals point down): the band along the top of every layer. Mirror
    averaging hides the left column; nothing hid the top. A mirrored margin round the input instead
    removes the band but moves what the networks learnt near every border (the quick synthetic
    bench's l1 +0.007), so the rows are repaired, not the networks' inputs changed.
    """
    if rows <= 0 or x.shape[-2] <= rows:
        return x
    return torch.cat([x[..., rows: rows + 1, :].expand(*x.shape[:-2], rows, x.shape[-1]), x[..., rows:, :]], dim=-2)


def _check_input(x: torch.Tensor, channels: int, name: str) -> None:
    if not isinstance(x, torch.Tensor) or x.ndim != 4 or x.shape[1] != channels:
        shape = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
        raise ValueError(f"{name} must be a torch tensor of shape (B, {channels}, H, W), got {shape}")


LIGHTING_SOLVES = ("project", "map", "map_relative")


class InverseNet(nn.Module):
    """Image -> albedo, normals, shadow (the paper's InverseRenderNet variant, lighting solved outside).

    Args:
        width: UNet width (first-level channels).
        depth: UNet depth.
        lighting_solve: how the lighting is solved from its outputs
            (:func:`learned.objectives.solve_projected`): ``"project"`` (least squares, then the
            orthogonal projection onto the prior's subspace: the paper) or ``"map"`` (the most
            probable lighting in the subspace). Part of the network's identity: its outputs are
            trained for one of them.
        initial_shadow_logit: the shadow head's initial bias: ``s = sigmoid(.)`` starts there
            (3: s = 0.95, almost no shadow; the default; runs B and D, shipped, used 1). A start
            deep in the sigmoid's flat end scales every gradient reaching ``s`` by ``sigmoid'``
            (0.045 at 3), which the held-out runs found to matter
            (docs/experiments/01-lighting-solve-and-shadow-start.md).
        mirror_average: at inference, decompose the photo and its left-right mirror image and
            average (:func:`mirror_averaged`; :func:`learned.objectives.decompose_and_solve`
            reads it). An inference choice like ``lighting_solve`` (chosen at export); training
            never uses it.
        meter_exposure: at inference, the network sees the photo re-metered to
            :data:`EXPOSURE_KEY` (:func:`metered`), so its layers do not depend on the photo's
            exposure; the lighting is still solved against the photo as given. An inference
            choice (chosen at export); training never uses it.
    """

    def __init__(self, width: int = 16, depth: int = 3, lighting_solve: str = "project",
                 initial_shadow_logit: float = 3.0, mirror_average: bool = False,
                 meter_exposure: bool = False) -> None:
        super().__init__()
        if lighting_solve not in LIGHTING_SOLVES:
            raise ValueError(f"lighting_solve must be one of {LIGHTING_SOLVES}, got {lighting_solve!r}")
        if not math.isfinite(initial_shadow_logit):
            raise ValueError(f"initial_shadow_logit must be finite, got {initial_shadow_logit!r}")
        if not isinstance(mirror_average, bool):
            raise ValueError(f"mirror_average must be True or False, got {mirror_average!r}")
        self.width, self.depth, self.lighting_solve = width, depth, lighting_solve
        if not isinstance(meter_exposure, bool):
            raise ValueError(f"meter_exposure must be True or False, got {meter_exposure!r}")
        self.mirror_average, self.meter_exposure = mirror_average, meter_exposure
        self.unet = UNet(3, 7, width, depth)
        with torch.no_grad():
            # Start from a plausible decomposition: mid-grey albedo, camera-facing
            # normals, little shadow.
            self.unet.head.bias.copy_(torch.tensor([0.0, 0.0, 0.0, 0.0, 0.0, 1.0, float(initial_shadow_logit)]))

    def forward(self, image: torch.Tensor) -> dict[str, torch.Tensor]:
        """``image (B, 3, H, W)`` linear RGB -> ``{"albedo", "normals", "shadow"}``."""
        _check_input(image, 3, "image")
        # log compresses the photo's dynamic range (shadows vs sunlit) for the network.
        x = torch.log(image.clamp_min(0) + 1e-2) - math.log(0.2)
        out = self.unet(x)
        albedo = torch.sigmoid(out[:, 0:3])
        # n_z = softplus > 0: normals face the camera; normalised to unit length.
        raw = torch.cat([out[:, 3:5], F.softplus(out[:, 5:6]) + 1e-4], 1)
        normals = raw / raw.norm(dim=1, keepdim=True)
        shadow = torch.sigmoid(out[:, 6:7])
        return {"albedo": albedo, "normals": normals, "shadow": shadow}


#: The log-average luminance :func:`metered` maps a photo to: the key synth's camera meters to
#: (``synth.photo.metered_ev``; the linearised training photos' median is 0.174).
EXPOSURE_KEY = 0.18


def log_average_luminance(image: torch.Tensor) -> torch.Tensor:
    """``(B,)`` log-average Rec. 709 luminance of ``image (B, 3, H, W)`` linear RGB, over the
    whole frame (sky included, as a camera meters; luminance floored at 1e-6)."""
    _check_input(image, 3, "image")
    y = (image * image.new_tensor(colour.LUMINANCE)[None, :, None, None]).sum(1)
    return torch.exp(torch.log(y.clamp_min(1e-6)).mean((1, 2)))


def metered(image: torch.Tensor, key: float = EXPOSURE_KEY) -> torch.Tensor:
    """``image (B, 3, H, W)`` linear RGB scaled per photo so its log-average luminance is ``key``.

    A photo 3 stops under-exposed is brought back to the exposures the network was trained on
    (synth meters every photo to 0.18 +- 0.7 EV); the gain is limited to 2**+-8 so a black frame
    stays finite. Scaling a photo by ``k`` (no clipping) leaves the result unchanged.
    """
    if not (math.isfinite(key) and key > 0):
        raise ValueError(f"key must be a positive number, got {key!r}")
    gain = (key / log_average_luminance(image)).clamp(2.0**-8, 2.0**8)
    return image * gain[:, None, None, None]


def mirror_averaged(net: nn.Module, image: torch.Tensor) -> dict[str, torch.Tensor]:
    """The mean of ``net``'s layers for ``image (B, 3, H, W)`` and for its left-right mirror image.

    The mirrored photo shows the mirrored scene (:func:`learned.data.mirror_view`): its layers
    are flipped back and its normals get ``n_x -> -n_x`` before averaging; the mean normal is
    renormalised (its ``n_z`` stays > 0). Two network passes; a prediction that is not
    mirror-symmetric has its asymmetric part cancelled. Returns ``{"albedo", "normals",
    "shadow"}`` like :class:`InverseNet`.
    """
    a, m = net(image), net(image.flip(-1))
    flip_x = torch.tensor([-1.0, 1.0, 1.0], dtype=image.dtype, device=image.device)[None, :, None, None]
    normals = a["normals"] + m["normals"].flip(-1) * flip_x
    return {"albedo": 0.5 * (a["albedo"] + m["albedo"].flip(-1)),
            "normals": normals / normals.norm(dim=1, keepdim=True).clamp_min(1e-12),
            "shadow": 0.5 * (a["shadow"] + m["shadow"].flip(-1))}


def normalise_lighting(lighting: torch.Tensor) -> torch.Tensor:
    """``(B, 9, 3)`` -> ``(B, 9, 3)`` divided by the DC term's RGB norm.

    Shadows do not depend on the lighting's overall brightness, so ShadowNet sees the
    lighting's shape only; the same deterministic normalisation at training and
    inference time (no batch statistics).
    """
    if lighting.ndim != 3 or lighting.shape[-1] != 3:
        raise ValueError(f"lighting must have shape (B, K, 3), got {tuple(lighting.shape)}")
    dc = lighting[:, :1, :].norm(dim=-1, keepdim=True).clamp_min(1e-6)
    return lighting / dc


def tile_lighting(normals: torch.Tensor, lighting: torch.Tensor) -> torch.Tensor:
    """Normals ``(B, 3, H, W)`` + lighting ``(B, 9, 3)`` -> ``(B, 30, H, W)`` (27-D lighting tiled)."""
    _check_input(normals, 3, "normals")
    if lighting.shape != (normals.shape[0], 9, 3):
        raise ValueError(f"lighting must have shape ({normals.shape[0]}, 9, 3), got {tuple(lighting.shape)}")
    b, _, h, w = normals.shape
    flat = normalise_lighting(lighting).reshape(b, 27, 1, 1).expand(b, 27, h, w)
    return torch.cat([normals, flat.to(normals.dtype)], 1)


class ShadowNet(nn.Module):
    """Normals + target lighting -> shadow map (30 input channels, GroupNorm, sigmoid output)."""

    def __init__(self, width: int = 16, depth: int = 3) -> None:
        super().__init__()
        self.width, self.depth = width, depth
        self.unet = UNet(30, 1, width, depth)
        with torch.no_grad():
            self.unet.head.bias.fill_(3.0)

    def forward(self, normals: torch.Tensor, lighting: torch.Tensor) -> torch.Tensor:
        """``normals (B, 3, H, W)``, ``lighting (B, 9, 3)`` camera-frame SH -> ``(B, 1, H, W)``."""
        return torch.sigmoid(self.unet(tile_lighting(normals, lighting)))


def count_parameters(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


# ------------------------------------------------------------------------- loading


_NETWORKS = ("inverse", "shadow")


def load_network(path: str | Path, kind: str) -> torch.nn.Module:
    """An ``"inverse"`` or ``"shadow"`` network from a run folder (latest checkpoint) or an
    exported weights file (its metadata must say ``kind``), in eval mode."""
    if kind not in _NETWORKS:
        raise ValueError(f"kind must be one of {list(_NETWORKS)}, got {kind!r}")
    p = Path(path)
    if p.is_dir():
        side = ckpt.latest_checkpoint(p)
        if side is None:
            raise FileNotFoundError(f"no checkpoint in {str(p)!r}")
        net = _build(kind, json.loads(side.read_text())["config"])
        ckpt.load_checkpoint(side, net, restore_rng=False)
    else:
        if not p.is_file():
            raise FileNotFoundError(f"no {kind} run folder or weights file at {str(p)!r}")
        tensors, meta = ckpt.load_weights(p)
        if meta.get("kind") != kind:
            raise ValueError(f"{str(p)!r} holds {meta.get('kind')!r} weights, not {kind!r} ones")
        cfg = {"width": int(meta["width"]), "depth": int(meta["depth"]), **json.loads(meta.get("config", "{}"))}
        if "lighting_solve" in meta:  # chosen at export (train export --lighting-solve)
            cfg["lighting_solve"] = meta["lighting_solve"]
        if "mirror_average" in meta:  # chosen at export (train export --mirror-average)
            cfg["mirror_average"] = meta["mirror_average"] == "1"
        if "meter_exposure" in meta:  # chosen at export (train export --meter-exposure)
            cfg["meter_exposure"] = meta["meter_exposure"] == "1"
        net = _build(kind, cfg)
        net.load_state_dict(tensors)
    return net.eval()


def _build(kind: str, cfg: dict[str, Any]) -> torch.nn.Module:
    """An untrained network of a run's configuration (runs before ``lighting_solve`` existed: project)."""
    if kind == "inverse":
        return InverseNet(int(cfg["width"]), int(cfg["depth"]), cfg.get("lighting_solve", "project"),
                          mirror_average=bool(cfg.get("mirror_average", False)),
                          meter_exposure=bool(cfg.get("meter_exposure", False)))
    return ShadowNet(int(cfg["width"]), int(cfg["depth"]))


def load_inverse(path: str | Path) -> InverseNet:
    """The inverse network of a run folder or an exported weights file (:func:`load_network`)."""
    return load_network(path, "inverse")


def load_shadow(path: str | Path) -> ShadowNet:
    """ShadowNet of a run folder or an exported weights file (:func:`load_network`)."""
    return load_network(path, "shadow")
