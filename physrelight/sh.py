"""Real spherical harmonics: basis, projection of environment maps, irradiance, rotation.

Conventions (DESIGN.md, followed everywhere in physrelight):

* Real, orthonormal SH without the Condon-Shortley phase, flat index ``l (l + 1) + m``.
  Order 2 is ``[Y00, Y1-1 (y), Y10 (z), Y11 (x), Y2-2 (xy), Y2-1 (yz), Y20 (3z^2-1),
  Y21 (xz), Y22 (x^2-y^2)]``. The basis is evaluated on the components of a direction
  in whatever frame the coefficients live in (world: Y up; camera: z towards viewer).
* Lighting arrays are ``(..., K, 3)``: ``K = (order + 1)**2`` coefficients, RGB minor.
* *Radiance SH* ``L_lm`` is the projection of an environment map (W m^-2 sr^-1).
  *Irradiance* is ``E(n) = sum_lm A_l L_lm Y_lm(n)`` (W m^-2), with the clamped-cosine
  coefficients ``A_0 = pi, A_1 = 2pi/3, A_2 = pi/4, A_3 = 0, A_4 = -pi/24``.
  *Shading* is ``E / pi``: a Lambertian surface of albedo rho reflects ``rho * E / pi``.
* Rotation: ``c' = rotation(R) @ c`` represents ``f'(w) = f(R^T w)``, equivalently
  ``basis(R x) = rotation(R) @ basis(x)``.

Every function accepts numpy arrays or torch tensors and returns the type it was given.
"""

from __future__ import annotations

import functools
import math
from typing import Sequence

import numpy as np
import torch

from physrelight import envmap as _envmap
from physrelight._checks import (
    Array,
    check_finite,
    check_last_dim,
    check_nonnegative,
    check_rotation,
    to_tensor,
)

MAX_ORDER = 8
"""Largest order the general recurrences here are tested for (DESIGN asks for 4)."""


def num_coeffs(order: int) -> int:
    """Number of coefficients ``(order + 1)**2`` of an SH expansion of ``order``."""
    return (_check_order(order) + 1) ** 2


def order_of(num: int) -> int:
    """Inverse of :func:`num_coeffs`: the order whose expansion has ``num`` coefficients."""
    order = math.isqrt(int(num)) - 1
    if order < 0 or (order + 1) ** 2 != num:
        raise ValueError(f"{num} is not a number of SH coefficients (1, 4, 9, 16, 25, ...)")
    return order


def _check_order(order: int) -> int:
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or not 0 <= order <= MAX_ORDER:
        raise ValueError(f"SH order must be an integer in [0, {MAX_ORDER}], got {order!r}")
    return int(order)


def _band(order: int) -> list[int]:
    """Degree l of every flat index up to ``order``."""
    return [l for l in range(order + 1) for _ in range(2 * l + 1)]


# --------------------------------------------------------------------------- basis


@functools.lru_cache(maxsize=None)
def _normalisation(l: int, m: int) -> float:
    """K_l^m = sqrt((2l+1)/(4pi) (l-m)!/(l+m)!) for m >= 0."""
    return math.sqrt((2 * l + 1) / (4 * math.pi) * math.factorial(l - m) / math.factorial(l + m))


def _basis_xyz(x: torch.Tensor, y: torch.Tensor, z: torch.Tensor, order: int, dim: int = -1) -> torch.Tensor:
    """Real SH of unit directions given by components, ``(...)`` each -> ``(..., K)``
    (the coefficient axis inserted at ``dim``).

    Uses the associated Legendre recurrence on ``P_l^m(z) / sin^m(theta)`` (a polynomial
    in z) times ``Re/Im (x + i y)^m`` (= ``sin^m cos/sin(m phi)``), so it is polynomial in
    the components: no atan2, no singularity at the poles, differentiable everywhere.
    """
    ones = torch.ones_like(z)
    # cm[m], sm[m] = Re, Im of (x + iy)^m
    cm, sm = [ones], [torch.zeros_like(z)]
    for _ in range(order):
        c_prev, s_prev = cm[-1], sm[-1]
        cm.append(x * c_prev - y * s_prev)
        sm.append(x * s_prev + y * c_prev)
    out: list[torch.Tensor | None] = [None] * ((order + 1) ** 2)
    for m in range(order + 1):
        # Pbar_l^m = P_l^m / sin^m, without the Condon-Shortley phase.
        p_mm = ones * float(np.prod(np.arange(1, 2 * m, 2))) if m > 0 else ones
        p_prev2, p_prev = None, p_mm
        for l in range(m, order + 1):
            if l == m:
                p = p_mm
            elif l == m + 1:
                p = z * (2 * m + 1) * p_mm
            else:
                p = ((2 * l - 1) * z * p_prev - (l + m - 1) * p_prev2) / (l - m)
            if l > m:
                p_prev2, p_prev = p_prev, p
            k = _normalisation(l, m)
            if m == 0:
                out[l * (l + 1)] = k * p
            else:
                out[l * (l + 1) + m] = math.sqrt(2.0) * k * p * cm[m]
                out[l * (l + 1) - m] = math.sqrt(2.0) * k * p * sm[m]
    return torch.stack(out, dim=dim)  # type: ignore[arg-type]


def basis(dirs: Array, order: int = 2) -> Array:
    """Real SH basis evaluated at directions.

    Args:
        dirs: ``(..., 3)`` directions. They are normalised here (network normals are
            rarely exactly unit); a zero-length direction is an error.
        order: SH order, ``0 <= order <= MAX_ORDER``.

    Returns:
        ``(..., (order + 1)**2)`` basis values, flat index ``l (l + 1) + m``.
    """
    order = _check_order(order)
    d, restore = to_tensor(dirs, "dirs")
    check_last_dim(d, 3, "dirs", "(..., 3)")
    check_finite(d, "dirs")
    norm = torch.linalg.vector_norm(d, dim=-1, keepdim=True)
    if d.numel() and bool((norm.detach() < 1e-8).any()):
        first = tuple(int(i) for i in torch.nonzero(norm.detach()[..., 0] < 1e-8)[0])
        raise ValueError(f"dirs holds a zero-length direction at index {first}; SH needs unit directions")
    d = d / norm
    return restore(_basis_xyz(d[..., 0], d[..., 1], d[..., 2], order))


# ------------------------------------------------------------------- irradiance


def clamped_cosine_coeffs(order: int) -> np.ndarray:
    """``A_l`` for ``l = 0..order``: SH coefficients of the clamped cosine (Ramamoorthi & Hanrahan).

    ``A_0 = pi, A_1 = 2pi/3``, ``A_l = 0`` for odd ``l > 1`` and, for even ``l``,
    ``A_l = 2pi (-1)^(l/2 - 1) / ((l + 2)(l - 1)) * l! / (2^l ((l/2)!)^2)``.
    """
    order = _check_order(order)
    a = np.zeros(order + 1)
    for l in range(order + 1):
        if l == 0:
            a[l] = math.pi
        elif l == 1:
            a[l] = 2 * math.pi / 3
        elif l % 2 == 0:
            h = l // 2
            a[l] = (2 * math.pi * (-1) ** (h - 1) / ((l + 2) * (l - 1))
                    * math.factorial(l) / (2**l * math.factorial(h) ** 2))
    return a


def _coeff_order(c: torch.Tensor, name: str) -> int:
    if c.ndim < 2 or c.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., K, 3) with K = (order+1)^2, got {tuple(c.shape)}")
    try:
        order = order_of(c.shape[-2])
    except ValueError:
        raise ValueError(
            f"{name} must have shape (..., K, 3) with K = (order+1)^2 in (1, 4, 9, 16, 25, ...), "
            f"got {tuple(c.shape)}"
        ) from None
    if order > MAX_ORDER:
        raise ValueError(f"{name} has order {order}, more than MAX_ORDER={MAX_ORDER}")
    return order


def irradiance_transfer(order: int, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """``(K,)`` per-coefficient factors ``A_l``: multiply radiance SH by them to get irradiance SH."""
    a = clamped_cosine_coeffs(order)
    return torch.tensor([a[l] for l in _band(order)], dtype=dtype)


def irradiance(coeffs: Array, normals: Array) -> Array:
    """Irradiance ``E(n) = sum_lm A_l L_lm Y_lm(n)`` from radiance SH.

    Args:
        coeffs: ``(..., K, 3)`` radiance SH in the frame of ``normals``.
        normals: ``(..., 3)`` unit normals. Batch dimensions of ``normals[..., :]`` and
            ``coeffs[..., :, :]`` broadcast, e.g. ``(9, 3)`` with ``(N, 3)`` -> ``(N, 3)``;
            for per-image lighting ``(B, 9, 3)`` and normals ``(B, H, W, 3)`` pass
            ``coeffs[:, None, None]``.

    Returns:
        ``(..., 3)`` irradiance (W m^-2 for radiance in W m^-2 sr^-1).
    """
    c, restore = to_tensor(coeffs, "coeffs")
    n, _ = to_tensor(normals, "normals")
    order = _coeff_order(c, "coeffs")
    check_finite(c, "coeffs")
    y = to_tensor(basis(n, order), "basis")[0].to(c.dtype)  # (..., K)
    a = irradiance_transfer(order, c.dtype).to(c.device)
    try:
        e = torch.einsum("...k,...kc->...c", y, c * a[:, None])
    except RuntimeError as err:
        raise ValueError(
            f"coeffs {tuple(c.shape)} and normals {tuple(n.shape)} have batch shapes that do not broadcast"
        ) from err
    return restore(e)


def shading(coeffs: Array, normals: Array) -> Array:
    """Lambertian shading ``E(n) / pi``: the outgoing radiance of a white (albedo 1) surface.

    Same shapes as :func:`irradiance`.
    """
    e = irradiance(coeffs, normals)
    return e / math.pi


# ------------------------------------------------------------------- projection


# World -> "pole frame" rotation: p = (d.z, d.x, d.y). In the pole frame the lat-long
# polar axis (+Y) is +z, so every SH polynomial separates into a function of the row
# times cos/sin(m phi') of the column, phi' = atan2(p.y, p.x) = pi - phi.
_POLE = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@functools.lru_cache(maxsize=16)
def _projection_factors(height: int, width: int, order: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Separable lat-long projection weights, cached per resolution and order.

    The renderer sees the map as the bilinear interpolant of its texels (hat functions
    in theta between rows, in phi between columns). In the pole frame
    ``Y_lm = row_lm(theta) * trig_m(phi')``, so the projection of that interpolant is
    exactly ``sum_ij L_ij [int hat_i(theta) row_lm(theta) sin(theta) dtheta]
    [int hat_j(phi') trig_m(phi') dphi']``. The theta integral is done with 8-point
    Gauss-Legendre per row interval (the integrand is a smooth trigonometric polynomial:
    exact to rounding); the phi integral is closed form,
    ``trig_m(phi'_j) dphi sinc^2(m dphi / 2)``.

    Returns:
        ``row (H, K)``, ``col (K, W)`` and ``D^T (K, K)`` taking pole-frame coefficients
        back to the world frame.
    """
    dt = math.pi / (height - 1)
    dphi = 2 * math.pi / width
    nodes, weights = np.polynomial.legendre.leggauss(8)
    t = torch.from_numpy((nodes + 1) / 2)  # position within an interval, in [0, 1]
    g = torch.from_numpy(weights / 2 * dt)
    theta = (torch.arange(height - 1, dtype=torch.float64)[:, None] + t[None, :]) * dt  # (H-1, 8)
    y0 = _basis_xyz(torch.sin(theta), torch.zeros_like(theta), torch.cos(theta), order)  # (H-1, 8, K)
    f = y0 * (torch.sin(theta) * g)[..., None]
    k = (order + 1) ** 2
    row_abs = torch.zeros(height, k, dtype=torch.float64)
    row_abs[:-1] += ((1 - t)[None, :, None] * f).sum(dim=1)  # falling hat of row i
    row_abs[1:] += (t[None, :, None] * f).sum(dim=1)  # rising hat of row i + 1
    phi_pole = math.pi - (torch.arange(width, dtype=torch.float64) + 0.5) * dphi
    row = torch.empty(height, k, dtype=torch.float64)
    col = torch.empty(k, width, dtype=torch.float64)
    for l in range(order + 1):
        for m in range(-l, l + 1):
            # At phi' = 0, (x + iy)^m = sin^m(theta): Y_l|m| holds row_lm for both signs of m.
            row[:, l * (l + 1) + m] = row_abs[:, l * (l + 1) + abs(m)]
            half = abs(m) * dphi / 2
            hat = dphi * (math.sin(half) / half) ** 2 if m else dphi
            col[l * (l + 1) + m] = hat * (torch.sin(-m * phi_pole) if m < 0 else torch.cos(m * phi_pole))
    d_t = torch.from_numpy(np.ascontiguousarray(rotation(_POLE, order).T))
    return row, col, d_t


def project_envmap(env: Array, order: int = 2) -> Array:
    """Radiance SH of a lat-long environment map (world frame, Y up).

    Args:
        env: ``(H, W, 3)`` linear radiance, Mitsuba lat-long layout (``W == 2 H``; row 0
            is the zenith, rows align-corners, columns texel-centred; see
            :mod:`physrelight.envmap`). Non-negative and finite.
        order: SH order.

    Returns:
        ``(K, 3)`` radiance SH ``L_lm = int L(w) Y_lm(w) dw`` of the map as the renderer
        sees it (the bilinear interpolant of the texels, as Mitsuba's ``envmap`` looks it
        up), integrated exactly. A uniform map gives exactly ``L00 = sqrt(4 pi) L`` and
        zeros elsewhere. Separable, float64, ~O(H W K).
    """
    order = _check_order(order)
    e, restore = to_tensor(env, "env")
    _envmap.check_envmap(e, "env")
    row, col, d_t = (t.to(e.device) for t in _projection_factors(e.shape[0], e.shape[1], order))
    e64 = e.to(torch.float64)
    fourier = torch.einsum("kw,hwc->hkc", col, e64)  # (H, K, 3): per-row Fourier sums
    pole = torch.einsum("hk,hkc->kc", row, fourier)
    return restore((d_t @ pole).to(e.dtype))


def project_sun(direction: Array, irradiance_rgb: Array, order: int = 2) -> Array:
    """Radiance SH of a sun modelled as a delta: ``L(w) = E_sun delta(w - s)``.

    Args:
        direction: ``(3,)`` unit direction *towards* the sun, in the frame of the result.
        irradiance_rgb: ``(3,)`` sun irradiance on a surface facing it (W m^-2).
        order: SH order.

    Returns:
        ``(K, 3)`` radiance SH ``E_sun Y_lm(s)``. A finite solar disk of angular radius
        alpha differs by a factor ``1 - O(l^2 alpha^2)``: 1e-4 for the real sun at l = 4.
    """
    s, restore = to_tensor(direction, "direction")
    e, _ = to_tensor(irradiance_rgb, "irradiance_rgb")
    if s.shape != (3,):
        raise ValueError(f"direction must have shape (3,), got {tuple(s.shape)}")
    if e.shape != (3,):
        raise ValueError(f"irradiance_rgb must have shape (3,), got {tuple(e.shape)}")
    check_finite(e, "irradiance_rgb")
    check_nonnegative(e, "irradiance_rgb", "irradiance")
    y = to_tensor(basis(s, order), "basis")[0]
    return restore(y[:, None] * e.to(y.dtype)[None, :])


def sun_of(coeffs: Array) -> tuple[Array, Array]:
    """The delta sun whose radiance SH (order >= 1) is ``coeffs``: the inverse of :func:`project_sun`.

    For ``L(w) = E delta(w - s)`` the coefficients are ``E Y_lm(s)``: the DC term gives
    ``E = c_00 / Y_00`` per colour, and band 1 (ordered y, z, x) points at ``s``; the direction is
    read from the luminance-weighted band 1, so a coloured sun keeps one direction.

    Args:
        coeffs: ``(K, 3)`` or ``(B, K, 3)`` radiance SH of a sun alone, ``K >= 4``.

    Returns:
        ``direction`` ``(3,)`` / ``(B, 3)`` unit vector towards the sun (``(0, 0, 0)`` for an
        all-zero input) and ``irradiance`` ``(3,)`` / ``(B, 3)`` on a surface facing it.
    """
    c, restore = to_tensor(coeffs, "coeffs")
    check_finite(c, "coeffs")
    batched = c.ndim == 3
    if c.ndim not in (2, 3) or c.shape[-1] != 3 or c.shape[-2] < 4:
        raise ValueError(f"coeffs must have shape (K, 3) or (B, K, 3) with K >= 4, got {tuple(c.shape)}")
    c = c if batched else c[None]
    lum = torch.tensor(_envmap.LUMINANCE, dtype=c.dtype, device=c.device)
    y1 = c[:, 1:4] @ lum  # (B, 3): y, z, x
    d = torch.stack([y1[:, 2], y1[:, 0], y1[:, 1]], -1)
    d = d / d.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(c.dtype).tiny)
    e = c[:, 0] / (0.5 / math.sqrt(math.pi))
    if not batched:
        d, e = d[0], e[0]
    return restore(d), restore(e)


# ------------------------------------------------------------------- rotation


def _rotation_blocks(R: torch.Tensor, order: int) -> list[torch.Tensor]:
    """Per-band rotation matrices ``(..., 2l+1, 2l+1)`` by the Ivanic-Ruedenberg recurrence.

    J. Ivanic, K. Ruedenberg, "Rotation matrices for real spherical harmonics. Direct
    determination by recursion", J. Phys. Chem. 100 (1996), with the 1998 erratum.
    Band 1 is the rotation itself in the basis order (y, z, x); band l is built from
    band l-1 and band 1, so every order comes from one general formula.
    """
    perm = [1, 2, 0]  # Y1-1 ~ y, Y10 ~ z, Y11 ~ x
    r1 = R[..., perm, :][..., :, perm]
    batch = R.shape[:-2]
    blocks = [torch.ones(*batch, 1, 1, dtype=R.dtype, device=R.device)]
    if order >= 1:
        blocks.append(r1)

    def r(i: int, j: int) -> torch.Tensor:  # band-1 entry with indices in -1..1
        return r1[..., i + 1, j + 1]

    for l in range(2, order + 1):
        prev = blocks[l - 1]

        def m_prev(a: int, b: int) -> torch.Tensor:  # band l-1 entry, indices in -(l-1)..(l-1)
            return prev[..., a + l - 1, b + l - 1]

        def p(i: int, a: int, b: int) -> torch.Tensor:
            if b == l:
                return r(i, 1) * m_prev(a, l - 1) - r(i, -1) * m_prev(a, -l + 1)
            if b == -l:
                return r(i, 1) * m_prev(a, -l + 1) + r(i, -1) * m_prev(a, l - 1)
            return r(i, 0) * m_prev(a, b)

        rows = []
        for m in range(-l, l + 1):
            row = []
            for n in range(-l, l + 1):
                d0 = 1.0 if m == 0 else 0.0
                denom = (l + n) * (l - n) if abs(n) < l else 2 * l * (2 * l - 1)
                u = math.sqrt((l + m) * (l - m) / denom)
                v = 0.5 * math.sqrt((1 + d0) * (l + abs(m) - 1) * (l + abs(m)) / denom) * (1 - 2 * d0)
                w = -0.5 * math.sqrt((l - abs(m) - 1) * (l - abs(m)) / denom) * (1 - d0)
                term = u * p(0, m, n) if u != 0.0 else 0.0
                if v != 0.0:
                    if m == 0:
                        vv = p(1, 1, n) + p(-1, -1, n)
                    elif m > 0:
                        d1 = 1.0 if m == 1 else 0.0
                        vv = p(1, m - 1, n) * math.sqrt(1 + d1) - (p(-1, -m + 1, n) * (1 - d1) if m != 1 else 0.0)
                    else:
                        d1 = 1.0 if m == -1 else 0.0
                        vv = (p(1, m + 1, n) * (1 - d1) if m != -1 else 0.0) + p(-1, -m - 1, n) * math.sqrt(1 + d1)
                    term = term + v * vv
                if w != 0.0:
                    if m > 0:
                        ww = p(1, m + 1, n) + p(-1, -m - 1, n)
                    else:
                        ww = p(1, m - 1, n) - p(-1, -m + 1, n)
                    term = term + w * ww
                if not isinstance(term, torch.Tensor):
                    term = torch.zeros(batch, dtype=R.dtype, device=R.device)
                row.append(term)
            rows.append(torch.stack(row, dim=-1))
        blocks.append(torch.stack(rows, dim=-2))
    return blocks


def rotation(R: Array, order: int = 2) -> Array:
    """SH rotation matrix ``D(R)`` with ``basis(R x) = D(R) basis(x)``.

    Rotating coefficients ``c' = D(R) c`` gives the function ``f'(w) = f(R^T w)``, i.e.
    the lighting turned by R. To move lighting from world to a camera frame whose
    world-to-camera rotation is ``R_wc``, use ``D(R_wc)``.

    Args:
        R: ``(..., 3, 3)`` rotation matrices (orthonormal, det +1).
        order: SH order.

    Returns:
        ``(..., K, K)`` block-diagonal, orthogonal.
    """
    order = _check_order(order)
    r, restore = to_tensor(R, "R")
    check_rotation(r, "R")
    blocks = _rotation_blocks(r, order)
    k = (order + 1) ** 2
    out = torch.zeros(*r.shape[:-2], k, k, dtype=r.dtype, device=r.device)
    start = 0
    for l, b in enumerate(blocks):
        size = 2 * l + 1
        out[..., start:start + size, start:start + size] = b
        start += size
    return restore(out)


def rotate(coeffs: Array, R: Array) -> Array:
    """Rotate SH lighting ``(..., K, 3)`` by ``R (3, 3)`` (or batched ``(..., 3, 3)``): ``D(R) c``."""
    c, restore = to_tensor(coeffs, "coeffs")
    order = _coeff_order(c, "coeffs")
    r, _ = to_tensor(R, "R")
    d = to_tensor(rotation(r.to(c.dtype), order), "D")[0]
    return restore(d @ c)


# ------------------------------------------------------------------- order selection


def fibonacci_sphere(n: int) -> np.ndarray:
    """``(n, 3)`` nearly uniform unit directions (spherical Fibonacci lattice), deterministic."""
    if n < 1:
        raise ValueError(f"n must be positive, got {n}")
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = math.pi * (3.0 - math.sqrt(5.0)) * i
    s = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    return np.stack([s * np.cos(phi), z, s * np.sin(phi)], axis=-1)


def order_errors(env: Array, orders: Sequence[int] = (0, 1, 2, 3, 4), normals: Array | None = None,
                 reference: Array | None = None) -> dict[int, dict[str, float]]:
    """Irradiance error of each SH order against the brute-force reference.

    Args:
        env: ``(H, W, 3)`` environment map.
        orders: SH orders to evaluate.
        normals: ``(N, 3)`` normals to test; default 512 directions over the sphere.
        reference: ``(N, 3)`` precomputed :func:`physrelight.envmap.irradiance_reference`.

    Returns:
        ``{order: {"nmae", "mean_relative", "max_relative", "max_fraction"}}``, each from
        the luminance of E: ``nmae = mean|dE| / mean E``; ``mean_relative`` and
        ``max_relative`` of ``|dE| / E`` per normal (E floored at 1e-3 of its mean so a
        back-facing normal in total darkness does not divide by zero); ``max_fraction =
        max|dE| / int L dw`` (the quantity of the 0.094 bound for order 2).
    """
    e, _ = to_tensor(env, "env")
    e = e.to(torch.float64)
    _envmap.check_envmap(e, "env")
    n = torch.from_numpy(fibonacci_sphere(512)) if normals is None else to_tensor(normals, "normals")[0].to(torch.float64)
    check_last_dim(n, 3, "normals", "(N, 3)")
    ref = _envmap.irradiance_reference(e, n) if reference is None else to_tensor(reference, "reference")[0].to(torch.float64)
    lum = torch.tensor(_envmap.LUMINANCE, dtype=torch.float64)
    ref_y = ref @ lum
    total = float((_envmap.luminance_integral(e)))
    floor = 1e-3 * float(ref_y.mean().clamp_min(1e-30))
    coeffs = project_envmap(e, max(orders))
    out: dict[int, dict[str, float]] = {}
    for order in orders:
        k = (order + 1) ** 2
        est_y = irradiance(coeffs[:k], n) @ lum
        err = (est_y - ref_y).abs()
        rel = err / ref_y.clamp_min(floor)
        out[int(order)] = {
            "nmae": float(err.mean() / ref_y.mean().clamp_min(1e-30)),
            "mean_relative": float(rel.mean()),
            "max_relative": float(rel.max()),
            "max_fraction": float(err.max() / max(total, 1e-30)),
        }
    return out


def select_order(env: Array, tolerance: float = 0.05, metric: str = "nmae",
                 orders: Sequence[int] = (0, 1, 2, 4), normals: Array | None = None) -> int:
    """Smallest SH order whose irradiance error is within ``tolerance``.

    Model no more than a scene needs: an overcast sky is met by order 1 or 2, a sharp
    sun may need order 4, and if no candidate meets the tolerance the largest is
    returned (with the errors available from :func:`order_errors`).

    Args:
        env: ``(H, W, 3)`` environment map.
        tolerance: allowed error, in the units of ``metric`` (a fraction, e.g. 0.05).
        metric: one of the keys of :func:`order_errors` (``"nmae"`` by default).
        orders: candidate orders, tried in increasing order (3 adds nothing to
            irradiance: ``A_3 = 0``, so it is not a default candidate).
        normals: ``(N, 3)`` normals the scene actually has (e.g. only upward-facing
            ones); default 512 directions over the sphere.
    """
    if not tolerance > 0:
        raise ValueError(f"tolerance must be positive, got {tolerance}")
    if not orders:
        raise ValueError("orders must not be empty")
    errors = order_errors(env, sorted(orders), normals)
    if metric not in next(iter(errors.values())):
        raise ValueError(f"metric must be one of {sorted(next(iter(errors.values())))}, got {metric!r}")
    for order in sorted(orders):
        if errors[order][metric] <= tolerance:
            return order
    return max(orders)
