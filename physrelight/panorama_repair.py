"""Repair of lossy (DWA-compressed) lat-long panoramas: negative ringing and damaged bright sources.

OpenEXR's DWA codecs compress R, G, B in 8 x 8 DCT blocks aligned to the data window's origin. Two kinds of damage
follow, both seen in the packaged Poly Haven maps of ``data/hdri_more``:

* small negative lobes round sharp edges (a horizon, a window frame): clamped to zero;
* wrecked blocks at a bright source (a sun, a lamp): strong negative rings (down to -3894 beside 29856), or a
  channel lost altogether. OpenEXR 3.5 itself writes a half-float overflow (a sun brighter than 65504 in R or G)
  as zeros in that channel, so a warm sun keeps only its blue channel.

The repair (:func:`repair_panorama`) clamps the negatives (:func:`clamp_negative`), finds the damaged windows
(:func:`find_damaged_windows`) and replaces each by a smooth fill from the texels round it plus a small disc
that holds the rest of the window's energy (:func:`repair_window`). Energies are solid-angle weighted with
:func:`physrelight.envmap.solid_angles` (the texel solid angle of DESIGN.md's lat-long layout, integrated
exactly for the renderer's bilinear lookup).
:func:`repair_report` states what a repair changed: total energy and the order-2 SH.

Maps are numpy ``(H, W, 3)`` float arrays (``W == 2 H``, row 0 the zenith) at this IO boundary.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from physrelight import envmap, sh

DWA_BLOCK = 8
"""Side of the DCT blocks of OpenEXR's DWAA/DWAB codecs, aligned to the data window's origin."""


def _check_map(env: np.ndarray, name: str, allow_negative: bool) -> np.ndarray:
    if not isinstance(env, np.ndarray):
        raise ValueError(f"{name} must be a numpy array, got {type(env).__name__}")
    if env.ndim != 3 or env.shape[-1] != 3:
        raise ValueError(f"{name} must be an (H, W, 3) lat-long RGB map, got shape {env.shape}")
    h, w = env.shape[:2]
    if h < 2 or w != 2 * h:
        raise ValueError(f"{name} must be a 2:1 lat-long map (W == 2 H), got H={h}, W={w}")
    if not np.issubdtype(env.dtype, np.floating):
        raise ValueError(f"{name} must hold floats, got dtype {env.dtype}")
    if not np.all(np.isfinite(env)):
        raise ValueError(f"{name} holds non-finite values (NaN or inf)")
    if not allow_negative and env.min() < 0:
        raise ValueError(f"{name} must be non-negative radiance, min {float(env.min()):.4g}")
    return env


def clamp_negative(env: np.ndarray) -> np.ndarray:
    """Clamp negative radiance (DCT ringing) to zero.

    Args:
        env: ``(H, W, 3)`` lat-long radiance as decoded, negatives allowed.

    Returns:
        ``(H, W, 3)`` a copy, same dtype, with every value below zero set to zero.
    """
    _check_map(env, "env", allow_negative=True)
    return np.clip(env, 0.0, None).astype(env.dtype, copy=False)


def _luminance(env: np.ndarray) -> np.ndarray:
    return env.astype(np.float64) @ np.asarray(envmap.LUMINANCE)


def _dilate_wrapped(mask: np.ndarray, iterations: int) -> np.ndarray:
    """Square dilation of an ``(H, W)`` mask by ``iterations`` texels, wrapping in u (columns), not in rows."""
    if iterations <= 0:
        return mask.copy()
    size = 2 * iterations + 1
    return ndimage.maximum_filter(mask.view(np.uint8), size=size, mode=("constant", "wrap"), cval=0) > 0


def find_damaged_windows(env: np.ndarray, block: int = DWA_BLOCK, contrast: float = 50.0,
                         ringing: float = 0.1, broken_ratio: float = 0.01) -> np.ndarray:
    """Label the damaged windows round bright sources: groups of DCT blocks to replace.

    The rule, on the ``block x block`` grid aligned to texel (0, 0) (DWA's blocks), with ``Y`` the luminance of
    the map clamped at zero and the *ring* of a block the texels two blocks away (the 5 x 5-block
    neighbourhood less the 3 x 3 one; columns wrap, rows stop at the poles):

    * A *source* is a block whose peak ``Y`` is at least ``contrast`` times ``max(median Y of its ring,
      median Y of the map)`` (the second term keeps a faint glint in a black room from counting).
    * A block next to (or equal to) a source is *damaged* when some channel ``c`` went below
      ``-ringing`` times the source block's peak in ``c`` (strong DCT ringing; weaker ringing is only clamped),
      or when its colour is implausible next to the ring: at its brightest texel (largest channel) some
      channel is at most ``broken_ratio`` times the largest one while the ring's median holds more than that
      share of it (a lost channel: a half-float overflow decodes as exactly 0 there).
    * Sources are visited from the brightest down (ties in raster order). A source whose 3 x 3 neighbourhood
      holds a damaged block gets a window: itself and its damaged neighbours, less the blocks an earlier
      window took. Windows therefore never exceed 3 x 3 blocks and each holds one source.

    Args:
        env: ``(H, W, 3)`` lat-long radiance as decoded, negatives allowed.
        block: side of the codec's blocks in texels.
        contrast: peak-to-surroundings luminance ratio of a source.
        ringing: depth of a negative lobe, as a share of the source's peak, that counts as damage.
        broken_ratio: at or below this share of the largest channel at the brightest texel a channel is lost.

    Returns:
        ``(H, W)`` int32 labels: 0 outside any window, ``1..n`` for the ``n`` windows, brightest source first.
        A clean map gives all zeros.
    """
    _check_map(env, "env", allow_negative=True)
    if not (isinstance(block, int) and block >= 1):
        raise ValueError(f"block must be a positive integer, got {block!r}")
    if not contrast > 1:
        raise ValueError(f"contrast must be > 1, got {contrast}")
    if not 0 < ringing < 1:
        raise ValueError(f"ringing must be in (0, 1), got {ringing}")
    if not 0 < broken_ratio < 1:
        raise ValueError(f"broken_ratio must be in (0, 1), got {broken_ratio}")
    h, w = env.shape[:2]
    raw = env.astype(np.float64)
    lit = np.clip(raw, 0.0, None)
    y = _luminance(lit)
    dw = envmap.solid_angles(h, w)
    floor = float(np.median(y))
    nby, nbx = -(-h // block), -(-w // block)

    def texels(by0: int, by1: int, bx0: int, bx1: int) -> tuple[slice, np.ndarray]:
        rows = slice(max(by0, 0) * block, min(by1 * block, h))
        cols = np.arange(bx0 * block, min(bx1 * block, bx0 * block + w)) % w
        return rows, cols

    peak = np.zeros((nby, nbx))
    for by in range(nby):
        for bx in range(nbx):
            rows, cols = texels(by, by + 1, bx, bx + 1)
            peak[by, bx] = y[rows][:, cols].max()

    def ring_of(by: int, bx: int) -> np.ndarray:
        rows, cols = texels(by - 2, by + 3, bx - 2, bx + 3)
        r_idx = np.arange(rows.start, rows.stop)[:, None]
        c_off = np.arange(len(cols))[None, :]
        inner = (r_idx >= (by - 1) * block) & (r_idx < (by + 2) * block) & (c_off >= block) & (c_off < 4 * block)
        return lit[rows][:, cols][~inner]

    def damaged(by: int, bx: int, source_peak: np.ndarray, ring_rgb: np.ndarray) -> bool:
        rows, cols = texels(by, by + 1, bx, bx + 1)
        if np.any(raw[rows][:, cols] < -ringing * source_peak):
            return True
        return bool(_broken_channels(lit[rows][:, cols], ring_rgb, broken_ratio).any())

    lum = np.asarray(envmap.LUMINANCE)
    candidates = []
    for by in range(nby):
        for bx in range(nbx):
            ring = ring_of(by, bx)
            if len(ring) and peak[by, bx] > 0 and peak[by, bx] >= contrast * max(float(np.median(ring @ lum)), floor):
                candidates.append((-peak[by, bx], by, bx))
    taken = np.zeros((nby, nbx), np.int32)
    n = 0
    for _, by, bx in sorted(candidates):
        if taken[by, bx]:
            continue
        rows, cols = texels(by, by + 1, bx, bx + 1)
        source_peak = lit[rows][:, cols].max(axis=(0, 1))
        ring_rgb = np.median(ring_of(by, bx), axis=0)
        hits = [(j, i % nbx) for j in range(by - 1, by + 2) for i in range(bx - 1, bx + 2)
                if 0 <= j < nby and not taken[j, i % nbx] and damaged(j, i % nbx, source_peak, ring_rgb)]
        if hits:
            n += 1
            taken[by, bx] = n
            for j, i in hits:
                taken[j, i] = n
    out = np.repeat(np.repeat(taken, block, axis=0), block, axis=1)[:h, :w]
    return np.ascontiguousarray(out, dtype=np.int32)


def _broken_channels(texels_rgb: np.ndarray, ring_rgb: np.ndarray, broken_ratio: float) -> np.ndarray:
    """``(3,)`` bool: the channels at most ``broken_ratio`` times the largest one at the brightest texel of
    ``texels_rgb`` ``(..., 3)`` (clamped radiance) although the ring ``(3,)`` has more than that share of them
    (a saturated yellow next to a yellow ring is a colour, not a loss); all False when that texel is black."""
    flat = texels_rgb.reshape(-1, 3)
    top = flat[int(np.argmax(flat.max(axis=1)))]
    if not top.max() > 0:
        return np.zeros(3, bool)
    return (top <= broken_ratio * top.max()) & (ring_rgb > broken_ratio * ring_rgb.max())


@dataclass(frozen=True)
class WindowRepair:
    """What :func:`repair_window` did to one window.

    Attributes:
        direction: ``(3,)`` unit world direction of the disc's centre (the window's energy centroid).
        energy: ``(3,)`` the disc's energy ``sum L dOmega`` per channel (above the fill).
        background: ``(3,)`` the fill's mean radiance over the window (solid-angle weighted).
        broken: ``(3,)`` bool, the channels whose energy came from the ring's colour (lost channels).
        texels: number of texels in the window.
    """

    direction: np.ndarray
    energy: np.ndarray
    background: np.ndarray
    broken: np.ndarray
    texels: int


def _disc_coverage(h: int, w: int, centre: np.ndarray, radius_deg: float, where: np.ndarray,
                   supersample: int = 8) -> np.ndarray:
    """``(H, W)`` share of each texel's footprint (``supersample``^2 points) inside the disc, on ``where`` only."""
    out = np.zeros((h, w))
    rows, cols = np.nonzero(where)
    cos_r = np.cos(np.radians(radius_deg))
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
    for a in offsets:
        theta = np.pi * np.clip(rows + a, 0, h - 1) / (h - 1)
        for b in offsets:
            phi = 2 * np.pi * (cols + 0.5 + b) / w
            d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], axis=-1)
            out[rows, cols] += d @ centre >= cos_r
    return out / supersample**2


def _harmonic_fill(env: np.ndarray, window: np.ndarray, cap: np.ndarray, iterations: int = 2000) -> np.ndarray:
    """``(H, W, 3)``: the harmonic (Laplace) interpolation into ``window`` of the texels round it, each capped
    at ``cap`` ``(3,)`` (so a neighbouring lamp on the boundary does not flood the fill), by Jacobi sweeps on
    the window's bounding box (columns wrap; the pole rows have no neighbour beyond them). Outside the window
    the result is ``env`` capped. A smooth, non-negative fill that follows the glow round a source."""
    h, w = window.shape
    # Roll the map so that the window's columns start at column 1: the largest circular gap between them is
    # outside the window, so after the roll its bounding box never straddles the seam.
    cols = np.nonzero(window.any(axis=0))[0]
    gaps = np.diff(np.concatenate([cols, [cols[0] + w]]))
    start = int(cols[(int(np.argmax(gaps)) + 1) % len(cols)])
    shift = (1 - start) % w
    win = np.roll(window, shift, axis=1)
    val = np.roll(env, shift, axis=1).astype(np.float64)
    rows = np.nonzero(win.any(axis=1))[0]
    cols = np.nonzero(win.any(axis=0))[0]
    r0, r1 = max(rows[0] - 1, 0), min(rows[-1] + 2, h)
    c0, c1 = max(cols[0] - 1, 0), min(cols[-1] + 2, w)
    box, inside = np.minimum(val[r0:r1, c0:c1], cap), win[r0:r1, c0:c1]
    outside = box[~inside]
    box[inside] = np.median(outside, axis=0) if len(outside) else 0.0
    ones = np.ones(box.shape[:2])
    count = np.zeros(box.shape[:2])
    count[1:] += ones[:-1]
    count[:-1] += ones[1:]
    count[:, 1:] += ones[:, :-1]
    count[:, :-1] += ones[:, 1:]
    for _ in range(iterations):
        total = np.zeros_like(box)
        total[1:] += box[:-1]
        total[:-1] += box[1:]
        total[:, 1:] += box[:, :-1]
        total[:, :-1] += box[:, 1:]
        box[inside] = (total / count[..., None])[inside]
    val[r0:r1, c0:c1] = box
    return np.roll(val, -shift, axis=1)


def repair_window(env: np.ndarray, window: np.ndarray, ring_width: int = 4, disc_radius_deg: float = 1.0,
                  broken_ratio: float = 0.01) -> tuple[np.ndarray, WindowRepair]:
    """Replace one damaged window by a smooth fill from its ring plus a disc holding the window's energy.

    * Ring: the texels within ``ring_width`` texels of the window (columns wrap), outside it. Its per-channel
      median is the *ring colour*.
    * Fill ``F``: the harmonic (Laplace) interpolation into the window of the texels round it, each capped at
      the ring's 75th percentile per channel (a neighbouring lamp must not flood it); scaled down in a
      channel where its energy would exceed the window's.
    * Channels: ``E_c = sum_window L_c dOmega``. A channel is *broken* when, at the window's brightest texel
      (largest channel), it is at most ``broken_ratio`` times the largest channel while the ring holds more
      than that share of it; the others are *intact*.
    * Disc energy: intact channels carry exactly ``D_c = E_c - sum_window F_c dOmega`` (so the window keeps
      its energy in every intact channel, to float rounding); a broken channel takes the ring's colour,
      ``D_c = ring_c * sum_intact D / sum_intact ring``.
    * Centre: the energy centroid (solid-angle weighted mean direction) of the intact channels' excess over
      ``F``. Shape: a disc of angular radius ``disc_radius_deg`` rasterised with 8 x 8 points per texel and
      restricted to the window, scaled so that ``sum D_c(texel) dOmega = D_c``.

    Args:
        env: ``(H, W, 3)`` non-negative lat-long radiance (already clamped).
        window: ``(H, W)`` bool, the texels to replace.
        ring_width: width of the ring in texels.
        disc_radius_deg: angular radius of the disc (about 1.4 texels at 256 rows: a sun is below the
            resolution, and the renderer's bilinear lookup blurs it over a texel anyway).
        broken_ratio: as in :func:`find_damaged_windows`.

    Returns:
        ``((H, W, 3)`` repaired copy in ``env``'s dtype, :class:`WindowRepair`).
    """
    _check_map(env, "env", allow_negative=False)
    if not (isinstance(window, np.ndarray) and window.shape == env.shape[:2] and window.dtype == bool):
        raise ValueError(f"window must be a bool array of shape {env.shape[:2]}, got "
                         f"{getattr(window, 'shape', None)} {getattr(window, 'dtype', type(window).__name__)}")
    if not window.any():
        raise ValueError("window is empty")
    if not (isinstance(ring_width, int) and ring_width >= 1):
        raise ValueError(f"ring_width must be a positive integer, got {ring_width!r}")
    if not 0 < disc_radius_deg < 45:
        raise ValueError(f"disc_radius_deg must be in (0, 45), got {disc_radius_deg}")
    if not 0 < broken_ratio < 1:
        raise ValueError(f"broken_ratio must be in (0, 1), got {broken_ratio}")
    h, w = env.shape[:2]
    src = env.astype(np.float64)
    dw = envmap.solid_angles(h, w)
    ring = _dilate_wrapped(window, ring_width) & ~window
    if not ring.any():
        raise ValueError("window has no ring round it (it covers the whole map)")
    ring_rgb = np.median(src[ring], axis=0)
    omega = float(dw[window].sum())
    energy = (src[window] * dw[window][:, None]).sum(axis=0)
    broken = _broken_channels(src[window], ring_rgb, broken_ratio)
    if broken.any() and not ring_rgb[~broken].sum() > 0:
        raise ValueError("a channel is lost in the window but its ring is black in the others: no colour to use")
    intact = ~broken
    fill = _harmonic_fill(src, window, np.percentile(src[ring], 75, axis=0))
    fill_energy = (fill[window] * dw[window][:, None]).sum(axis=0)
    # A window darker than its fill in an intact channel: scale the fill down so the disc never goes negative.
    scale_fill = np.where(intact & (fill_energy > energy), energy / np.maximum(fill_energy, 1e-300), 1.0)
    fill = fill * scale_fill
    fill_energy = fill_energy * scale_fill
    disc = energy - fill_energy
    if broken.any():
        scale = disc[intact].sum() / max(ring_rgb[intact].sum(), 1e-30)
        disc = np.where(broken, ring_rgb * scale, disc)
    background = fill_energy / omega
    excess = (np.clip(src - fill, 0.0, None)[..., intact].sum(axis=-1)) * dw * window
    dirs = envmap.directions(h, w)
    centroid = (dirs * excess[..., None]).sum(axis=(0, 1))
    norm = np.linalg.norm(centroid)
    if norm > 0:
        centre = centroid / norm
    else:  # nothing above the ring: centre on the window's own centroid
        centre = (dirs * (dw * window)[..., None]).sum(axis=(0, 1))
        centre /= np.linalg.norm(centre)
    cover = _disc_coverage(h, w, centre, disc_radius_deg, window)
    if cover.sum() == 0:  # disc thinner than the sampling: put it on the texel nearest the centre
        k = np.argmax(np.where(window, dirs @ centre, -2.0))
        cover.flat[k] = 1.0
    shape = cover / float((cover * dw).sum())
    out = src.copy()
    out[window] = fill[window] + shape[window][:, None] * disc
    info = WindowRepair(direction=centre, energy=disc, background=background, broken=broken,
                        texels=int(window.sum()))
    return out.astype(env.dtype), info


@dataclass(frozen=True)
class PanoramaRepair:
    """The result of :func:`repair_panorama`.

    Attributes:
        env: ``(H, W, 3)`` the cleaned map, non-negative.
        windows: ``(H, W)`` int32 labels of the repaired windows (0 = untouched by step 3).
        repairs: one :class:`WindowRepair` per window, in label order.
    """

    env: np.ndarray
    windows: np.ndarray
    repairs: tuple[WindowRepair, ...]


def repair_panorama(env: np.ndarray, block: int = DWA_BLOCK, contrast: float = 50.0, ringing: float = 0.1,
                    broken_ratio: float = 0.01, ring_width: int = 4, disc_radius_deg: float = 1.0) -> PanoramaRepair:
    """Clean a DWA-decoded panorama: clamp the negatives, find the damaged windows, repair each.

    Args:
        env: ``(H, W, 3)`` lat-long radiance as decoded (negatives allowed), ``W == 2 H``.
        block, contrast, ringing, broken_ratio: as in :func:`find_damaged_windows`.
        ring_width, disc_radius_deg: as in :func:`repair_window`.

    Returns:
        :class:`PanoramaRepair`; ``env`` keeps the input's float dtype. A map with no negatives and no damaged
        window comes back equal to the input.
    """
    _check_map(env, "env", allow_negative=True)
    windows = find_damaged_windows(env, block=block, contrast=contrast, ringing=ringing,
                                   broken_ratio=broken_ratio)
    out = clamp_negative(env)
    repairs = []
    for k in range(1, int(windows.max()) + 1):
        out, info = repair_window(out, windows == k, ring_width=ring_width, disc_radius_deg=disc_radius_deg,
                                  broken_ratio=broken_ratio)
        repairs.append(info)
    return PanoramaRepair(env=out, windows=windows, repairs=tuple(repairs))


def repair_report(before: np.ndarray, after: np.ndarray) -> dict[str, float | list[float]]:
    """What a cleaning changed: total energy and order-2 SH, before vs after.

    ``before`` may hold negatives (the map as decoded): its energy is the signed sum and its SH those of the
    signed map, projected as ``project(max(L, 0)) - project(max(-L, 0))`` (the projection is linear and
    :func:`physrelight.sh.project_envmap` takes non-negative radiance), so the change covers clamp and repair.

    Args:
        before: ``(H, W, 3)`` the map as decoded.
        after: ``(H, W, 3)`` the cleaned map, same shape, non-negative.

    Returns:
        A dict: ``energy_before``, ``energy_clamped``, ``energy_after`` (``(3,)`` lists, ``sum L dOmega`` per
        channel), ``luminance_before``, ``luminance_after``, ``luminance_change`` (relative);
        ``l1_over_l00_before/after`` and ``l2_over_l00_before/after`` (luminance SH, band norms over the DC);
        ``sh_change``: ``||c_after - c_before|| / ||c_before||`` over the 27 coefficients. The step after the
        clamp alone: ``luminance_clamped``, ``luminance_change_repair`` and ``sh_change_repair`` (after vs the
        map clamped at zero).
    """
    _check_map(before, "before", allow_negative=True)
    _check_map(after, "after", allow_negative=False)
    if before.shape != after.shape:
        raise ValueError(f"before and after must have the same shape, got {before.shape} and {after.shape}")
    h, w = before.shape[:2]
    dw = envmap.solid_angles(h, w)[..., None]
    b64, a64 = before.astype(np.float64), after.astype(np.float64)
    e_before = (b64 * dw).sum(axis=(0, 1))
    e_clamped = (np.clip(b64, 0.0, None) * dw).sum(axis=(0, 1))
    e_after = (a64 * dw).sum(axis=(0, 1))
    lum = np.asarray(envmap.LUMINANCE)
    c_clamped = np.asarray(sh.project_envmap(np.clip(b64, 0.0, None)))
    c_before = c_clamped - np.asarray(sh.project_envmap(np.clip(-b64, 0.0, None)))
    c_after = np.asarray(sh.project_envmap(a64))

    def bands(c: np.ndarray) -> tuple[float, float]:
        y = c @ lum
        return float(np.linalg.norm(y[1:4]) / y[0]), float(np.linalg.norm(y[4:9]) / y[0])

    l1b, l2b = bands(c_before)
    l1a, l2a = bands(c_after)
    return {
        "energy_before": e_before.tolist(),
        "energy_clamped": e_clamped.tolist(),
        "energy_after": e_after.tolist(),
        "luminance_before": float(e_before @ lum),
        "luminance_after": float(e_after @ lum),
        "luminance_clamped": float(e_clamped @ lum),
        "luminance_change": float(e_after @ lum / (e_before @ lum) - 1),
        "luminance_change_repair": float(e_after @ lum / (e_clamped @ lum) - 1),
        "l1_over_l00_before": l1b,
        "l1_over_l00_after": l1a,
        "l2_over_l00_before": l2b,
        "l2_over_l00_after": l2a,
        "sh_change": float(np.linalg.norm(c_after - c_before) / np.linalg.norm(c_before)),
        "sh_change_repair": float(np.linalg.norm(c_after - c_clamped) / np.linalg.norm(c_clamped)),
    }
