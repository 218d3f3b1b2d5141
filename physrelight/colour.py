"""Colour: sRGB transfer curves, gamma, exposure, camera-response curves, CIE XYZ and CIELAB.

Everything is differentiable torch code; numpy in gives numpy out (see
:mod:`physrelight._checks`). Radiance inside the library is *linear* sRGB (Rec. 709
primaries, D65 white); encoded (display-referred) values only appear at the boundary:
:func:`to_ldr` is the one tone pipeline used for every PNG written, :func:`from_ldr`
linearises a photo.

Shapes:
    * transfer curves, gamma, exposure and response curves are element-wise: any shape,
      e.g. ``(B, 3, H, W)``;
    * the XYZ / Lab conversions need 3 entries along a channel axis ``dim``: the default
      ``dim=-3`` suits channel-first images ``(B, 3, H, W)`` or ``(3, H, W)``; pass
      ``dim=-1`` for colour lists ``(..., 3)``.

Reference values (agreement measured in ``tests/physrelight/test_colour.py``):
    * sRGB curve: IEC 61966-2-1, as ``colour.cctf_encoding`` / ``colour.cctf_decoding``;
    * RGB -> XYZ: the matrix colour-science uses for its ``'sRGB'`` colourspace (the 4-digit
      IEC matrix); XYZ -> RGB is its exact inverse (colour-science stores the 4-digit IEC
      inverse instead, which differs by up to 4.4e-5);
    * Lab: CIE 1976 with the white of ``colour.XYZ_to_Lab``'s default illuminant, D65 given as
      xy = (0.3127, 0.3290); L* in 0..100. Because that white is not exactly the row sums of
      the 4-digit matrix, RGB white (1, 1, 1) maps to Lab (100, 0.0077, 0.0035), as it does
      in colour-science.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from physrelight._checks import (
    Array,
    check_finite,
    check_last_dim,
    check_nonnegative,
    to_tensor,
)

__all__ = [
    "LUMINANCE",
    "RESPONSE_CURVES",
    "M_RGB_TO_XYZ",
    "M_XYZ_TO_RGB",
    "WHITE_D65_XYZ",
    "srgb_to_linear",
    "linear_to_srgb",
    "gamma_encode",
    "gamma_decode",
    "expose",
    "apply_response",
    "invert_response",
    "to_ldr",
    "from_ldr",
    "rgb_to_xyz",
    "xyz_to_rgb",
    "xyz_to_lab",
    "lab_to_xyz",
    "rgb_to_lab",
    "lab_to_rgb",
]

# ----------------------------------------------------------------------------- constants

#: Luminance weights of linear sRGB / Rec. 709 primaries: the Y row of :data:`M_RGB_TO_XYZ`.
LUMINANCE = (0.2126, 0.7152, 0.0722)
#: Linear sRGB (D65) -> CIE XYZ, exactly ``colour.RGB_COLOURSPACES['sRGB'].matrix_RGB_to_XYZ``.
M_RGB_TO_XYZ = np.array(
    [
        [0.4124, 0.3576, 0.1805],
        [0.2126, 0.7152, 0.0722],
        [0.0193, 0.1192, 0.9505],
    ],
    dtype=np.float64,
)
#: CIE XYZ -> linear sRGB: the exact inverse of :data:`M_RGB_TO_XYZ` (round trips exactly).
M_XYZ_TO_RGB = np.linalg.inv(M_RGB_TO_XYZ)

_D65_XY = (0.3127, 0.3290)
#: Reference white of the Lab conversion: XYZ of D65 xy = (0.3127, 0.3290) with Y = 1,
#: the default of ``colour.XYZ_to_Lab``.
WHITE_D65_XYZ = np.array(
    [_D65_XY[0] / _D65_XY[1], 1.0, (1.0 - _D65_XY[0] - _D65_XY[1]) / _D65_XY[1]], dtype=np.float64
)

# IEC 61966-2-1 sRGB curve. The standard rounds the encoded breakpoint to 0.04045; like
# colour-science we use 12.92 * 0.0031308 = 0.040449936, the image of the linear breakpoint,
# so that decode picks the same branch encode used (the two choices differ by < 2.4e-9, only
# for inputs in that 6e-8 gap).
_SRGB_LIN_BREAK = 0.0031308
_SRGB_ENC_BREAK = 12.92 * _SRGB_LIN_BREAK

# CIE 1976 lightness function f(t): cube root above (6/29)^3, linear segment below.
_LAB_EPS = (6.0 / 29.0) ** 3  # = 216/24389
_LAB_SLOPE = 841.0 / 108.0  # = 1 / (3 (6/29)^2)
_LAB_OFFSET = 16.0 / 116.0

# Filmic curve: Narkowicz's (2015) rational fit to the ACES RRT+ODT tone scale,
#   t(x) = x (a x + b) / (x (c x + d) + e),
# followed by the sRGB encoding. t is strictly increasing on x >= 0 (the numerator of t' is
# 1.408 x^2 + 0.7028 x + 0.0042 > 0), t(0) = 0, and t -> a/c = 1.0329 as x -> inf.
_ACES_A, _ACES_B, _ACES_C, _ACES_D, _ACES_E = 2.51, 0.03, 2.43, 0.59, 0.14

#: Names accepted by :func:`apply_response`, :func:`invert_response`, :func:`to_ldr`, :func:`from_ldr`.
RESPONSE_CURVES = ("linear", "srgb", "gamma2.2", "filmic")

# Derivatives of |x|^p for p < 1 blow up at 0; the backward pass evaluates them at
# max(|x|, _POW_GRAD_FLOOR) instead, so gradients stay finite (values stay exact).
_POW_GRAD_FLOOR = 1e-6


# ----------------------------------------------------------------------------- helpers


def _matrix(m: np.ndarray, like: torch.Tensor) -> torch.Tensor:
    return torch.as_tensor(m, dtype=like.dtype, device=like.device)


def _check_channels(t: torch.Tensor, dim: int, name: str) -> None:
    """Raise unless ``t`` has 3 entries along ``dim`` (the colour channel axis)."""
    if dim == -1:
        check_last_dim(t, 3, name, "(..., 3)")
        return
    if t.ndim == 0 or not -t.ndim <= dim < t.ndim or t.shape[dim] != 3:
        layout = "(B, 3, H, W) or (3, H, W)" if dim == -3 else f"3 entries along dim {dim}"
        raise ValueError(f"{name} must have shape {layout}, got {tuple(t.shape)}")


def _apply_matrix(t: torch.Tensor, m: np.ndarray, dim: int) -> torch.Tensor:
    """Multiply the 3-vectors along ``dim`` of ``t`` by the 3x3 matrix ``m``."""
    v = torch.movedim(t, dim, -1)
    return torch.movedim(v @ _matrix(m, t).T, -1, dim)


def _check_curve(curve: str) -> None:
    if curve not in RESPONSE_CURVES:
        raise ValueError(f"unknown response curve {curve!r}; valid names are {', '.join(RESPONSE_CURVES)}")


def _check_gamma(gamma: float) -> None:
    if not (isinstance(gamma, (int, float)) and np.isfinite(gamma) and gamma > 0):
        raise ValueError(f"gamma must be a finite positive number, got {gamma!r}")


class _SignedPow(torch.autograd.Function):
    """sign(x) |x|^p with exact values and a derivative evaluated at max(|x|, floor)."""

    @staticmethod
    def forward(ctx: Any, x: torch.Tensor, p: float) -> torch.Tensor:
        ctx.save_for_backward(x)
        ctx.p = p
        return torch.sign(x) * x.abs() ** p

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        (x,) = ctx.saved_tensors
        p = ctx.p
        # written with differentiable ops so that double backward works
        return grad * p * x.abs().clamp_min(_POW_GRAD_FLOOR) ** (p - 1.0), None


def _signed_pow(t: torch.Tensor, p: float) -> torch.Tensor:
    if p >= 1.0:  # derivative is finite everywhere: plain autograd
        return torch.sign(t) * t.abs() ** p
    return _SignedPow.apply(t, p)


# ----------------------------------------------------------------------------- sRGB curve (torch core)


def _srgb_to_linear(v: torch.Tensor) -> torch.Tensor:
    # clamp inside the power branch so the unused branch never makes NaN gradients
    power = ((v.clamp_min(_SRGB_ENC_BREAK) + 0.055) / 1.055) ** 2.4
    return torch.where(v <= _SRGB_ENC_BREAK, v / 12.92, power)


def _linear_to_srgb(x: torch.Tensor) -> torch.Tensor:
    power = 1.055 * x.clamp_min(_SRGB_LIN_BREAK) ** (1.0 / 2.4) - 0.055
    return torch.where(x <= _SRGB_LIN_BREAK, 12.92 * x, power)


def srgb_to_linear(x: Array) -> Array:
    """Decode sRGB-encoded values to linear values (IEC 61966-2-1 EOTF, piecewise exact).

    ``v <= 0.040449936 (= 12.92 * 0.0031308) -> v / 12.92``, else ``((v + 0.055) / 1.055) ** 2.4``. Element-wise.
    Values above 1 follow the power branch (no clamping); negative values follow the linear
    segment, as in colour-science. The derivative is finite everywhere (1/12.92 near 0).

    Args:
        x: encoded values, any shape, e.g. ``(B, 3, H, W)``.

    Returns:
        Linear values, same shape and type as ``x``.

    Raises:
        ValueError: ``x`` holds NaN or inf.
    """
    t, restore = to_tensor(x, "x")
    check_finite(t, "x")
    return restore(_srgb_to_linear(t))


def linear_to_srgb(x: Array) -> Array:
    """Encode linear values with the sRGB curve (IEC 61966-2-1 inverse EOTF, piecewise exact).

    ``x <= 0.0031308 -> 12.92 x``, else ``1.055 x ** (1/2.4) - 0.055``. Element-wise.
    No clamping: values above 1 (HDR radiance) encode above 1; use :func:`to_ldr` for a
    display image. Negative values (e.g. a network output during training) follow the
    linear segment, so the function is defined, monotone and differentiable on all reals
    (as colour-science and kornia do) instead of raising; the derivative at 0 is 12.92.

    Args:
        x: linear values, any shape, e.g. ``(B, 3, H, W)``.

    Returns:
        Encoded values, same shape and type as ``x``.

    Raises:
        ValueError: ``x`` holds NaN or inf.
    """
    t, restore = to_tensor(x, "x")
    check_finite(t, "x")
    return restore(_linear_to_srgb(t))


# ----------------------------------------------------------------------------- gamma, exposure


def gamma_encode(x: Array, gamma: float = 2.2) -> Array:
    """Pure power-law encoding ``x ** (1 / gamma)`` (no linear toe). Element-wise.

    Negative values are mapped odd-symmetrically, ``-(|x| ** (1/gamma))``, so that
    :func:`gamma_decode` inverts this on all reals. Values are exact; because the true
    derivative is infinite at 0, the backward pass evaluates it at ``max(|x|, 1e-6)``
    (at most ``1e-6 ** (1/gamma - 1) / gamma`` = 852 for gamma 2.2), so gradients stay finite.

    Args:
        x: linear values, any shape, e.g. ``(B, 3, H, W)``.
        gamma: exponent of the display, > 0.

    Returns:
        Encoded values, same shape and type as ``x``.

    Raises:
        ValueError: ``x`` holds NaN or inf, or ``gamma`` is not a finite positive number.
    """
    _check_gamma(gamma)
    t, restore = to_tensor(x, "x")
    check_finite(t, "x")
    return restore(_signed_pow(t, 1.0 / gamma))


def gamma_decode(x: Array, gamma: float = 2.2) -> Array:
    """Inverse of :func:`gamma_encode`: ``x ** gamma`` (odd-symmetric for negatives). Element-wise.

    Args:
        x: encoded values, any shape, e.g. ``(B, 3, H, W)``.
        gamma: exponent of the display, > 0.

    Returns:
        Linear values, same shape and type as ``x``.

    Raises:
        ValueError: ``x`` holds NaN or inf, or ``gamma`` is not a finite positive number.
    """
    _check_gamma(gamma)
    t, restore = to_tensor(x, "x")
    check_finite(t, "x")
    return restore(_signed_pow(t, float(gamma)))


def _ev_tensor(ev: Any, like: torch.Tensor) -> torch.Tensor:
    e, _ = to_tensor(ev, "ev")
    check_finite(e, "ev")
    return e.to(dtype=like.dtype, device=like.device)


def expose(x: Array, ev: float | Array) -> Array:
    """Scale linear radiance by ``2 ** ev`` (exposure value in stops).

    Args:
        x: linear radiance, any shape, e.g. ``(B, 3, H, W)``.
        ev: stops, a number or an array broadcastable against ``x`` (e.g. ``(B, 1, 1, 1)``
            for one exposure per image).

    Returns:
        ``x * 2 ** ev``, the broadcast shape, type of ``x``.

    Raises:
        ValueError: ``x`` or ``ev`` holds NaN or inf.
    """
    t, restore = to_tensor(x, "x")
    check_finite(t, "x")
    return restore(t * torch.exp2(_ev_tensor(ev, t)))


# ----------------------------------------------------------------------------- response curves


def _aces(x: torch.Tensor) -> torch.Tensor:
    return x * (_ACES_A * x + _ACES_B) / (x * (_ACES_C * x + _ACES_D) + _ACES_E)


def _aces_inverse(y: torch.Tensor) -> torch.Tensor:
    # positive root of (a - c y) x^2 + (b - d y) x - e y = 0, in the form without cancellation
    qa = _ACES_A - _ACES_C * y
    qb = _ACES_B - _ACES_D * y
    disc = torch.sqrt(qb * qb + 4.0 * qa * _ACES_E * y)
    big = torch.where(qb >= 0, qb + disc, torch.ones_like(qb))  # > 0 where used
    small = torch.where(qb < 0, disc - qb, torch.ones_like(qb))
    return torch.where(qb >= 0, 2.0 * _ACES_E * y / big, small / (2.0 * qa))


_FILMIC_MAX_LINEAR = _ACES_A / _ACES_C  # sup of the ACES fit (not reached)
_FILMIC_MAX = 1.055 * _FILMIC_MAX_LINEAR ** (1.0 / 2.4) - 0.055  # sup of the filmic curve, 1.0143


def _apply_response(t: torch.Tensor, curve: str, name: str = "x") -> torch.Tensor:
    if curve == "linear":
        return t.clone()
    if curve == "srgb":
        return _linear_to_srgb(t)
    if curve == "gamma2.2":
        return _signed_pow(t, 1.0 / 2.2)
    check_nonnegative(t, name, "radiance (the filmic curve is defined for x >= 0)")
    return _linear_to_srgb(_aces(t))


def _invert_response(t: torch.Tensor, curve: str) -> torch.Tensor:
    if curve == "linear":
        return t.clone()
    if curve == "srgb":
        return _srgb_to_linear(t)
    if curve == "gamma2.2":
        return _signed_pow(t, 2.2)
    d = t.detach()
    if bool((d < 0).any()) or bool((d >= _FILMIC_MAX).any()):
        raise ValueError(
            f"the filmic curve is invertible on [0, {_FILMIC_MAX:.6f}); y spans "
            f"[{float(d.min()):.6g}, {float(d.max()):.6g}]"
        )
    return _aces_inverse(_srgb_to_linear(t))


def apply_response(x: Array, curve: str = "srgb") -> Array:
    """Map linear radiance to encoded camera/display values with a named response curve.

    Curves (all strictly increasing; element-wise):
        * ``"linear"``: identity.
        * ``"srgb"``: :func:`linear_to_srgb` (IEC 61966-2-1).
        * ``"gamma2.2"``: :func:`gamma_encode` with gamma 2.2.
        * ``"filmic"``: the ACES tone-scale fit of Narkowicz (2015),
          ``t(x) = x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)``, then the sRGB encoding.
          An S-curve in log exposure: a toe (slope 0.21 at 0 before encoding), mid grey
          0.18 -> 0.553, and a shoulder that reaches 1 at x = 7.24 and tends to 1.0143.
          Defined for x >= 0 only.

    No clamping: use :func:`to_ldr` for display images.

    Args:
        x: linear radiance, any shape, e.g. ``(B, 3, H, W)``.
        curve: one of :data:`RESPONSE_CURVES`.

    Returns:
        Encoded values, same shape and type as ``x``.

    Raises:
        ValueError: unknown ``curve`` (the message lists the valid names); ``x`` holds NaN
            or inf; ``x`` is negative with ``curve="filmic"``.
    """
    _check_curve(curve)
    t, restore = to_tensor(x, "x")
    check_finite(t, "x")
    return restore(_apply_response(t, curve))


def invert_response(y: Array, curve: str = "srgb") -> Array:
    """Inverse of :func:`apply_response`: ``invert_response(apply_response(x, c), c) == x``.

    For ``"filmic"`` the inverse is the closed-form positive root of the quadratic behind
    the ACES fit, defined for ``0 <= y < 1.0143`` (the curve's range); the other curves are
    inverted on all reals.

    Args:
        y: encoded values, any shape, e.g. ``(B, 3, H, W)``.
        curve: one of :data:`RESPONSE_CURVES`.

    Returns:
        Linear radiance, same shape and type as ``y``.

    Raises:
        ValueError: unknown ``curve``; ``y`` holds NaN or inf; ``y`` outside the filmic range.
    """
    _check_curve(curve)
    t, restore = to_tensor(y, "y")
    check_finite(t, "y")
    return restore(_invert_response(t, curve))


def to_ldr(radiance: Array, ev: float | Array = 0.0, curve: str = "srgb") -> Array:
    """The display pipeline: expose, apply a response curve, clamp to [0, 1].

    ``clamp(apply_response(radiance * 2 ** ev, curve), 0, 1)``. Every PNG the library
    writes goes through this function (quantise with ``round(255 * v)``).

    Args:
        radiance: linear radiance, any shape, e.g. ``(B, 3, H, W)``.
        ev: exposure in stops, a number or an array broadcastable against ``radiance``.
        curve: one of :data:`RESPONSE_CURVES`.

    Returns:
        Display values in [0, 1], the broadcast shape, type of ``radiance``.

    Raises:
        ValueError: unknown ``curve``; NaN or inf in ``radiance`` or ``ev``; negative
            radiance with ``curve="filmic"``.
    """
    _check_curve(curve)
    t, restore = to_tensor(radiance, "radiance")
    check_finite(t, "radiance")
    exposed = t * torch.exp2(_ev_tensor(ev, t))
    return restore(_apply_response(exposed, curve, "radiance").clamp(0.0, 1.0))


_INT_SCALE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}
_TORCH_INT_SCALE = {torch.uint8: 255.0, torch.uint16: 65535.0}


def from_ldr(image: Array, curve: str = "srgb", ev: float | Array = 0.0) -> Array:
    """Linearise a display-referred image (a photo): inverse of :func:`to_ldr` below saturation.

    ``invert_response(image, curve) / 2 ** ev``. Integer images are scaled first:
    ``uint8`` by 1/255, ``uint16`` by 1/65535; numpy integer input comes back as float64,
    torch integer input as float32.

    Args:
        image: encoded values in [0, 1] (or uint8/uint16), any shape, e.g. ``(B, 3, H, W)``.
        curve: one of :data:`RESPONSE_CURVES`.
        ev: the exposure :func:`to_ldr` applied, undone here.

    Returns:
        Linear radiance, the broadcast shape, float type of ``image``.

    Raises:
        ValueError: unknown ``curve``; NaN or inf; float values outside [0, 1]; an integer
            dtype other than uint8/uint16.
    """
    _check_curve(curve)
    scale = 1.0
    if isinstance(image, np.ndarray) and not np.issubdtype(image.dtype, np.floating):
        if image.dtype not in _INT_SCALE:
            raise ValueError(f"integer images must be uint8 or uint16, got dtype {image.dtype}")
        scale = _INT_SCALE[image.dtype]
    elif isinstance(image, torch.Tensor) and not image.is_floating_point():
        if image.dtype not in _TORCH_INT_SCALE:
            raise ValueError(f"integer images must be uint8 or uint16, got dtype {image.dtype}")
        scale = _TORCH_INT_SCALE[image.dtype]
        image = image.to(torch.float32)
    t, restore = to_tensor(image, "image")
    check_finite(t, "image")
    t = t / scale if scale != 1.0 else t
    d = t.detach()
    if bool((d < 0).any()) or bool((d > 1).any()):
        raise ValueError(
            f"image must hold display values in [0, 1], got range [{float(d.min()):.6g}, {float(d.max()):.6g}]"
        )
    return restore(_invert_response(t, curve) * torch.exp2(-_ev_tensor(ev, t)))


# ----------------------------------------------------------------------------- XYZ and Lab (torch core)


def _lab_f(t: torch.Tensor) -> torch.Tensor:
    # clamp inside the cube root so the unused branch gives no inf/NaN gradient at 0
    return torch.where(t > _LAB_EPS, t.clamp_min(_LAB_EPS) ** (1.0 / 3.0), _LAB_SLOPE * t + _LAB_OFFSET)


def _lab_f_inverse(f: torch.Tensor) -> torch.Tensor:
    return torch.where(f > 6.0 / 29.0, f**3, (f - _LAB_OFFSET) / _LAB_SLOPE)


def _xyz_to_lab(xyz: torch.Tensor, dim: int) -> torch.Tensor:
    white = _matrix(WHITE_D65_XYZ, xyz)
    shape = [1] * xyz.ndim
    shape[dim] = 3
    f = _lab_f(xyz / white.reshape(shape))
    fx, fy, fz = f.unbind(dim)
    return torch.stack([116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)], dim=dim)


def _lab_to_xyz(lab: torch.Tensor, dim: int) -> torch.Tensor:
    L, a, b = lab.unbind(dim)
    fy = (L + 16.0) / 116.0
    f = torch.stack([fy + a / 500.0, fy, fy - b / 200.0], dim=dim)
    white = _matrix(WHITE_D65_XYZ, lab)
    shape = [1] * lab.ndim
    shape[dim] = 3
    return _lab_f_inverse(f) * white.reshape(shape)


def _rgb_to_lab(rgb: torch.Tensor, dim: int) -> torch.Tensor:
    return _xyz_to_lab(_apply_matrix(rgb, M_RGB_TO_XYZ, dim), dim)


def _prepare_colour(x: Array, name: str, dim: int) -> tuple[torch.Tensor, Any]:
    t, restore = to_tensor(x, name)
    _check_channels(t, dim, name)
    check_finite(t, name)
    return t, restore


def rgb_to_xyz(rgb: Array, dim: int = -3) -> Array:
    """Linear sRGB (D65) -> CIE XYZ (Y = 1 for RGB white), as ``colour.RGB_to_XYZ(rgb, 'sRGB')``.

    Args:
        rgb: linear RGB with 3 entries along ``dim``: ``(B, 3, H, W)`` / ``(3, H, W)`` with the
            default ``dim=-3``, or ``(..., 3)`` with ``dim=-1``.
        dim: the channel axis.

    Returns:
        XYZ, same shape and type as ``rgb``.

    Raises:
        ValueError: not 3 entries along ``dim`` (the message names the shape); NaN or inf.
    """
    t, restore = _prepare_colour(rgb, "rgb", dim)
    return restore(_apply_matrix(t, M_RGB_TO_XYZ, dim))


def xyz_to_rgb(xyz: Array, dim: int = -3) -> Array:
    """CIE XYZ -> linear sRGB (D65), the exact inverse of :func:`rgb_to_xyz`.

    Out-of-gamut colours give negative components (no clipping).

    Args:
        xyz: XYZ with 3 entries along ``dim`` (``(B, 3, H, W)`` or, with ``dim=-1``, ``(..., 3)``).
        dim: the channel axis.

    Returns:
        Linear RGB, same shape and type as ``xyz``.

    Raises:
        ValueError: not 3 entries along ``dim``; NaN or inf.
    """
    t, restore = _prepare_colour(xyz, "xyz", dim)
    return restore(_apply_matrix(t, M_XYZ_TO_RGB, dim))


def xyz_to_lab(xyz: Array, dim: int = -3) -> Array:
    """CIE XYZ -> CIELAB (CIE 1976, D65 white, L* in 0..100), as ``colour.XYZ_to_Lab``.

    ``f(t) = t ** (1/3)`` for ``t > (6/29) ** 3``, else the linear segment
    ``t * 841/108 + 16/116``; the linear segment keeps values and gradients finite at and
    below 0 (negative XYZ maps to the continued line).

    Args:
        xyz: XYZ with 3 entries along ``dim`` (``(B, 3, H, W)`` or, with ``dim=-1``, ``(..., 3)``).
        dim: the channel axis.

    Returns:
        Lab (L*, a*, b*) along ``dim``, same shape and type as ``xyz``.

    Raises:
        ValueError: not 3 entries along ``dim``; NaN or inf.
    """
    t, restore = _prepare_colour(xyz, "xyz", dim)
    return restore(_xyz_to_lab(t, dim))


def lab_to_xyz(lab: Array, dim: int = -3) -> Array:
    """CIELAB (D65 white, L* in 0..100) -> CIE XYZ, the exact inverse of :func:`xyz_to_lab`.

    Args:
        lab: Lab with 3 entries along ``dim`` (``(B, 3, H, W)`` or, with ``dim=-1``, ``(..., 3)``).
        dim: the channel axis.

    Returns:
        XYZ, same shape and type as ``lab``.

    Raises:
        ValueError: not 3 entries along ``dim``; NaN or inf.
    """
    t, restore = _prepare_colour(lab, "lab", dim)
    return restore(_lab_to_xyz(t, dim))


def rgb_to_lab(rgb: Array, dim: int = -3) -> Array:
    """Linear sRGB (D65) -> CIELAB (L* in 0..100): :func:`rgb_to_xyz` then :func:`xyz_to_lab`.

    The input is *linear* RGB; for sRGB-encoded images call :func:`srgb_to_linear` first.

    Args:
        rgb: linear RGB with 3 entries along ``dim`` (``(B, 3, H, W)`` or, with ``dim=-1``,
            ``(..., 3)``).
        dim: the channel axis.

    Returns:
        Lab, same shape and type as ``rgb``.

    Raises:
        ValueError: not 3 entries along ``dim``; NaN or inf.
    """
    t, restore = _prepare_colour(rgb, "rgb", dim)
    return restore(_rgb_to_lab(t, dim))


def lab_to_rgb(lab: Array, dim: int = -3) -> Array:
    """CIELAB (L* in 0..100) -> linear sRGB (D65), the inverse of :func:`rgb_to_lab`.

    Args:
        lab: Lab with 3 entries along ``dim`` (``(B, 3, H, W)`` or, with ``dim=-1``, ``(..., 3)``).
        dim: the channel axis.

    Returns:
        Linear RGB (unclipped), same shape and type as ``lab``.

    Raises:
        ValueError: not 3 entries along ``dim``; NaN or inf.
    """
    t, restore = _prepare_colour(lab, "lab", dim)
    return restore(_apply_matrix(_lab_to_xyz(t, dim), M_XYZ_TO_RGB, dim))
