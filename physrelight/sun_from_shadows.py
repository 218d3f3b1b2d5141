"""The sun's azimuth read from cast shadows and from shading, as log-likelihoods on :class:`SunPosterior`'s grid.

Two cues, each at full resolution, each a log-likelihood over the sun's (elevation x azimuth) grid of
:func:`physrelight.sun_from_sky.estimate_sun_from_sky` (:data:`~physrelight.sun_from_sky.ELEVATIONS_DEG` x
:data:`~physrelight.sun_from_sky.AZIMUTH_STEP_DEG`), so that :func:`physrelight.sun_estimate.estimate_sun` can add
them to the sky's log posterior:

* :func:`shadow_likelihood`: **cast-shadow edges on the ground.** The shadow that a vertical edge casts on level
  ground lies along the sun's azimuth, pointing away from the sun, and starts at the caster's foot. Through the
  camera (pitch and field of view known, as for the sky) every pixel below the horizon is a point of the ground
  plane ``y = -1`` (the camera's height sets only the scale, so none is needed); edges of the log luminance on the
  ground (Canny, :func:`skimage.feature.canny`) are cut into straight segments (the probabilistic Hough transform,
  :func:`skimage.transform.probabilistic_hough_line`) and each segment, mapped to the ground, gives an axis (the
  azimuth mod 180 degrees). Which way along the axis the sun lies is not in the edge itself (a box's shadow has
  one edge dark on its left and one dark on its right under the same sun); it is in the caster: a segment whose
  line runs, past one of its ends, into a caster's *foot* (a non-ground surface, the normals say which, met at its
  bottom outline: :data:`FOOT_PX`) points from its free end to that foot, towards the sun, wrong with probability
  ``sign_error`` (:data:`SIGN_ERROR`: coarse normals misplace the feet). A segment that reaches no foot keeps both
  directions. The edges of a shadow cast by *horizontal* edges (a box's far end) lie along the caster's own edges,
  not the sun's: they reach no foot, so they weigh less (:data:`FREE_SEGMENT_WEIGHT`), and each segment's
  likelihood is a mixture with a uniform outlier (:data:`SEGMENT_OUTLIER`). Ground near the horizon
  (:data:`MIN_DEPRESSION_DEG`) and edges whose dark side is as bright as sunlit ground (:data:`LIT_PERCENTILE`)
  are not read.
* :func:`shading_likelihood`: **surfaces facing left against surfaces facing right.** Given the normals
  (``(3, H, W)`` in the camera frame, as the decomposition gives), near-vertical surfaces facing the camera's left
  and right are compared by their median log luminance: the side the sun lights is brighter. The outcome is one
  binary observation whose error rate shrinks with the contrast (:data:`SHADING_CONTRAST_SCALE`) down to a floor
  (:data:`SHADING_MIN_ERROR`: two sides of a building may be painted differently), a mild cue that halves the
  azimuth circle and nothing more.

Neither cue says anything about the sun's elevation (the shadows' lengths would need the casters' heights): both
log-likelihoods are constant along the elevation axis. Both are exactly flat (all zeros) when there is nothing to
read (no ground, no edges strong enough, no surfaces facing either side): no shadows never means a confident sun.

Azimuths are world azimuths as :func:`physrelight.envmap.direction_from_angles` counts them (0 = world -Z, 90 = +X),
the grid's; with ``pitch_deg``/``fov_deg`` the camera looks along world -Z, so they are also ``relight --sun``'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from physrelight._checks import Array
from physrelight.colour import LUMINANCE, srgb_to_linear
from physrelight.panorama import camera_rays
from physrelight.sun_from_sky import AZIMUTH_STEP_DEG, ELEVATIONS_DEG, _camera

__all__ = ["AGREE_DEG", "CueLikelihood", "EDGE_SIGMA_PX", "FOOT_PX", "FREE_SEGMENT_WEIGHT",
           "ground_and_casters", "GROUND_MAX_TILT_DEG", "LIT_PERCENTILE", "MAX_SEGMENT_OBSERVATIONS",
           "MERGE_GAP_FRACTION", "MIN_DEPRESSION_DEG", "MIN_EDGE_STEP", "MIN_SIDE_PIXELS",
           "SEGMENT_OUTLIER", "SEGMENT_SIGMA_DEG", "SHADING_CONTRAST_SCALE", "shading_likelihood",
           "SHADING_MIN_ERROR", "shadow_likelihood", "shadow_segments", "ShadowSegment", "SIGN_ERROR",
           "TOUCH_FRACTION"]

EDGE_SIGMA_PX = 1.5
"""Gaussian smoothing (pixels) of the log luminance before Canny: a path tracer's or a sensor's noise apart."""
MIN_EDGE_STEP = 0.35
"""Smallest step of log luminance a shadow edge is read at (Canny's high threshold; the low one is half): sunlit
over shaded ground is ``log(1 + E_sun cos / E_sky)``, 0.35 is a sun 40 % brighter than the sky's light there. Paving
joints and texture are mostly weaker; those that are not are outliers of the mixture."""
MIN_DEPRESSION_DEG = 5.0
"""Ground seen less than this below the horizon is not read: there the ground's foreshortening is steep, and a
degree of error in the camera's pitch turns a direction on the ground by tens of degrees (and a far kerb is as
straight and as dark as a shadow)."""
AGREE_DEG = 15.0
"""Segments that touch a caster's foot agree when their sun azimuths lie within this of each other
(:attr:`CueLikelihood.agreeing`)."""
GROUND_MAX_TILT_DEG = 20.0
"""A pixel is ground when its world normal is within this of straight up."""
MIN_SEGMENT_FRACTION = 0.04
"""Shortest segment read, as a share of the image's longer side (at least 8 pixels)."""
TOUCH_FRACTION = 0.03
"""A segment's end touches a caster when the segment's line, continued past that end, meets a caster pixel within
this share of the image's longer side (at least 6 pixels) beyond the contact band kept out of the edge map
(:data:`CONTACT_BAND_PX`): Canny and Hough lose an edge's last pixels at the caster's corner."""
MERGE_GAP_FRACTION = 0.08
"""Hough pieces of one straight edge (directions within 3 degrees in the image, ends within 2 pixels of each
other's line) are merged when the gap between them is under this share of the image's longer side."""
FOOT_PX = 6
"""A caster is met at its foot (where it stands on the ground) when no caster pixel lies this many rows below the
point met, within 2 columns of it: its bottom outline. A shadow's edge that runs into a caster's side is hidden by it
there, and the caster goes on down below that point."""
CONTACT_BAND_PX = 2
"""Ground pixels this close to a non-ground, non-sky pixel are left out of the edge map: the contact line itself
is an edge of the caster, not of its shadow."""
LIT_PERCENTILE = 75.0
"""The sunlit ground's log luminance is this percentile of the ground's. A segment whose dark side is not at least
half of :data:`MIN_EDGE_STEP` below it is no shadow's edge (a box's lit top seen against the ground behind it is
level too, and joins the ground's region in the image: their common edge is one of albedo). Where shadows cover
more than three quarters of the ground, its edges are missed: a flat likelihood, not a wrong one."""
SEGMENT_SIGMA_DEG = 4.0
"""Angular spread of one segment's direction about the sun's azimuth (von Mises, ``kappa = 1 / sigma^2``)."""
SEGMENT_OUTLIER = 0.5
"""Share of a segment's likelihood that is uniform over the azimuth: a segment may be a texture edge, or the edge
of a shadow cast by a horizontal edge (the far end of a box's shadow), which lies along the caster's edges."""
SIGN_ERROR = 0.2
"""Share of a foot-anchored segment's von Mises put on the opposite direction: the foot may be another caster's
(a fence's next post), or the caster a wrong one where the normals are coarse (study 60: on 32 real crops with the
decomposition's 64-px normals the sign was right for 3 of the 8 whose axis was right; on path-traced boxes with
exact normals, for all 22). Exact normals (a renderer's, a depth sensor's) justify ``sign_error=0``."""
FREE_SEGMENT_WEIGHT = 0.25
"""Weight of a segment that touches no caster (it only gives an axis), against 1 for one that does."""
MAX_SEGMENT_OBSERVATIONS = 8.0
"""The segments together count as at most this many independent observations (the pieces of one shadow's edge are
not independent: a tempered likelihood, as the sky's)."""
MIN_SIDE_PIXELS = 50
"""The shading cue reads a side (left- or right-facing surfaces) only with at least this many pixels of it."""
SHADING_CONTRAST_SCALE = 0.25
"""The shading cue's error rate is ``0.5 exp(-|d| / scale)`` for a difference ``d`` of median log luminance between
the sides: a side 10 % brighter is a weak vote (error 0.34), one twice as bright as strong as the floor allows."""
SHADING_MIN_ERROR = 0.4
"""Floor of the shading cue's error rate: the two sides' materials may differ, whatever the contrast, and the
decomposition's normals are coarse (study 60: on 32 real crops of the training side the cue picked the wrong side
11 times of 27). On path-traced boxes it picks the right side every time: a weak vote by design."""
_VERTICAL_MAX_TILT_DEG = 30.0  # a left/right-facing surface is within this of vertical
_SIDE_MIN_X = 0.5  # and its camera-frame normal's x is beyond +-this
_MIN_GROUND_SHARE = 0.2  # a level region is ground when at least this share of the largest one


@dataclass(frozen=True)
class CueLikelihood:
    """One cue's reading of the sun (:func:`shadow_likelihood`, :func:`shading_likelihood`).

    Attributes:
        name: ``"shadows"`` or ``"shading"``.
        azimuths_deg: ``(A,)`` the grid's world azimuths.
        elevations_deg: ``(E,)`` the grid's sun elevations.
        log_likelihood: ``(E, A)`` log-likelihood of each cell up to a constant (max 0; all 0 when the cue is flat).
        spoke: whether the cue read anything (False: ``log_likelihood`` is all 0).
        azimuth_deg: the cue's own most likely world azimuth (refined to 0.5 degree), None when it did not speak.
        observations: segments read (shadows) or sides compared (shading: 0 or 1).
        detail: what was read, or why nothing was.
        anchored: shadow segments that touch a caster's foot (the evidence that a sun casts them); 0 for shading.
        agreeing: the largest number of those whose sun azimuths agree within :data:`AGREE_DEG` (two feet that
            agree are the evidence :func:`physrelight.sun_estimate.estimate_sun` takes for a sun).
    """

    name: str
    azimuths_deg: np.ndarray
    elevations_deg: np.ndarray
    log_likelihood: np.ndarray
    spoke: bool
    azimuth_deg: float | None
    observations: int
    detail: str
    anchored: int = 0
    agreeing: int = 0

    def azimuth_log_likelihood(self, azimuth_deg: Array) -> np.ndarray:
        """The cue's log-likelihood at any world azimuths ``(N,)`` (degrees), on the same scale as
        :attr:`log_likelihood` (it does not depend on the elevation)."""
        return self._fn(np.asarray(azimuth_deg, dtype=np.float64))

    # set by the constructors: the cue as a function of the azimuth (degrees) -> log-likelihood, same offset
    _fn: object = field(default=None, repr=False, compare=False)  # type: ignore[assignment]


@dataclass(frozen=True)
class ShadowSegment:
    """A straight edge on the ground (:func:`shadow_segments`).

    Attributes:
        endpoints_px: ``(2, 2)`` its ends ``(column, row)`` as pixel indices (as
            :func:`skimage.transform.probabilistic_hough_line` gives; a pixel's centre is its index + 0.5).
        axis_deg: world azimuth of its direction on the ground, in [0, 180) (the axis; the sun is at it or at it +
            180).
        sun_azimuth_deg: world azimuth from its free end to the end that touches a caster (towards the sun), or
            None when neither or both ends touch one.
        length_px: its length in the image.
        step: median step of log luminance across it (its contrast).
    """

    endpoints_px: np.ndarray
    axis_deg: float
    sun_azimuth_deg: float | None
    length_px: float
    step: float


def _grid() -> tuple[np.ndarray, np.ndarray]:
    return np.array(ELEVATIONS_DEG), np.arange(0.0, 360.0, AZIMUTH_STEP_DEG)


def _as_numpy(x: Array, name: str) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    if not isinstance(x, np.ndarray):
        raise ValueError(f"{name} must be a numpy array or a torch tensor, got {type(x).__name__}")
    return x


def _check_image(image: Array, linear: bool) -> np.ndarray:
    img = np.asarray(_as_numpy(image, "image"), dtype=np.float64)
    if img.ndim != 3 or img.shape[-1] != 3:
        raise ValueError(f"image must have shape (H, W, 3), got {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError("image must be finite")
    if img.min(initial=0.0) < 0:
        raise ValueError(f"image must be non-negative, got a minimum of {img.min():g}")
    if not linear and img.max(initial=0.0) > 1.0 + 1e-6:
        raise ValueError(f"a display image holds values in [0, 1], got a maximum of {img.max():g} "
                         "(pass linear=True for radiance)")
    return img


def _check_mask(mask: Array | None, shape: tuple[int, int], name: str) -> np.ndarray | None:
    if mask is None:
        return None
    m = _as_numpy(mask, name)
    if m.shape != shape:
        raise ValueError(f"{name} must have the image's shape (H, W) = {shape}, got {m.shape}")
    if m.dtype != bool:
        raise ValueError(f"{name} must be boolean, got dtype {m.dtype}")
    return m


def _check_normals(normals: Array, shape: tuple[int, int]) -> np.ndarray:
    n = np.asarray(_as_numpy(normals, "normals"), dtype=np.float64)
    if n.shape != (3, *shape):
        raise ValueError(f"normals must have shape (3, H, W) = (3, {shape[0]}, {shape[1]}) (camera frame), got {n.shape}")
    if not np.all(np.isfinite(n)):
        raise ValueError("normals must be finite")
    return np.moveaxis(n, 0, -1)


def _log_luminance(img: np.ndarray, linear: bool) -> np.ndarray:
    lin = img if linear else np.asarray(srgb_to_linear(img))
    y = lin @ np.asarray(LUMINANCE)
    floor = 1e-3 * max(float(np.median(y)), 1e-30)  # black pixels a thousandth of the median, not -inf
    return np.log(np.maximum(y, floor))


def ground_and_casters(normals: Array, world_to_camera_rotation: np.ndarray, sky_mask: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Ground and caster pixels from a normal map.

    Args:
        normals: ``(3, H, W)`` camera-frame normals (zero, or anything shorter than 0.5, where unknown).
        world_to_camera_rotation: ``(3, 3)``.
        sky_mask: ``(H, W)`` bool.

    Returns:
        ``(ground, casters)``, two ``(H, W)`` bool maps: ground has a world normal within
        :data:`GROUND_MAX_TILT_DEG` of up and belongs to the largest such region (or one at least a fifth of its
        size); casters are the other known, non-sky pixels. A level top seen apart from the ground (a table, a box
        seen from below its top's height) is a caster; one whose outline touches the ground behind it in the image
        joins the ground's region (normals alone cannot part them: :data:`LIT_PERCENTILE`).
    """
    n = _check_normals(normals, sky_mask.shape)
    length = np.linalg.norm(n, axis=-1)
    known = (length > 0.5) & ~sky_mask
    up = (n @ np.asarray(world_to_camera_rotation, dtype=np.float64))[..., 1] / np.maximum(length, 1e-12)
    level = known & (up > math.cos(math.radians(GROUND_MAX_TILT_DEG)))
    # a box's top faces up too but is no ground: the ground is the largest level region (and any other at least a
    # fifth of its size: the ground may be cut in two by a caster)
    from scipy import ndimage

    labels, count = ndimage.label(level)
    if count == 0:
        return level, known
    sizes = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    keep = np.concatenate([[False], sizes >= _MIN_GROUND_SHARE * sizes.max()])
    ground = keep[labels]
    return ground, known & ~ground


def _ground_points(rays: np.ndarray) -> np.ndarray:
    """``(..., 2)`` (x, z) of the ground plane ``y = -1`` along world rays ``(..., 3)`` that point down."""
    t = 1.0 / np.maximum(-rays[..., 1], 1e-9)
    return np.stack([rays[..., 0] * t, rays[..., 2] * t], -1)


def _pixel_rays(Kc: np.ndarray, R: np.ndarray, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """World rays ``(N, 3)`` through pixel positions (continuous, pixel centres at index + 0.5)."""
    uv1 = np.stack([cols, rows, np.ones_like(cols)], -1)
    vision = uv1 @ np.linalg.inv(Kc).T
    cam = vision * np.array([1.0, -1.0, -1.0])  # x right, y up, z towards the viewer
    world = cam @ R
    return world / np.linalg.norm(world, axis=-1, keepdims=True)


def _azimuth(dx: float, dz: float) -> float:
    return math.degrees(math.atan2(dx, -dz)) % 360.0


def shadow_segments(image: Array, sky_mask: Array, K: Array | None = None, world_to_camera: Array | None = None, *,
                    normals: Array | None = None, ground_mask: Array | None = None, pitch_deg: float | None = None,
                    fov_deg: float | None = None, linear: bool = False, seed: int = 0) -> list[ShadowSegment]:
    """Straight edges of the log luminance on the ground, mapped to the ground plane (see the module doc).

    Args:
        image: ``(H, W, 3)`` display values in [0, 1] (sRGB), or linear radiance with ``linear=True``.
        sky_mask: ``(H, W)`` bool.
        K, world_to_camera, pitch_deg, fov_deg: the camera, as :func:`physrelight.sun_from_sky.estimate_sun_from_sky`.
        normals: ``(3, H, W)`` camera-frame normals: they say which pixels are ground and which are casters
            (:func:`ground_and_casters`). Without them and without ``ground_mask`` nothing is read (an empty
            list): a facade's windows are straight edges too.
        ground_mask: ``(H, W)`` bool, overrides the ground of the normals (casters: the non-sky, non-ground pixels
            with known normals; without normals, every non-sky, non-ground pixel).
        seed: the Hough transform's random generator (the same seed gives the same segments).

    Returns:
        The segments, longest first.
    """
    img = _check_image(image, linear)
    shape = img.shape[:2]
    sky = _check_mask(sky_mask, shape, "sky_mask")
    if sky is None:
        raise ValueError("sky_mask is required (an all-False mask where no sky shows)")
    Kc, R = _camera(K, world_to_camera, pitch_deg, fov_deg, *shape)
    rays = camera_rays(Kc, R, *shape).numpy()[:, :, 0]
    below = rays[..., 1] < -math.sin(math.radians(MIN_DEPRESSION_DEG))
    casters = np.zeros(shape, bool)
    given = _check_mask(ground_mask, shape, "ground_mask")
    if normals is not None:
        ground, casters = ground_and_casters(normals, R, sky)
    elif given is None:
        return []  # a facade's windows are straight edges too: without knowing the ground, nothing is read
    if given is not None:
        ground = given & ~sky
        casters = casters & ~ground if normals is not None else ~ground & ~sky
    ground = ground & below
    if not ground.any():
        return []
    from scipy import ndimage
    from skimage.feature import canny
    from skimage.transform import probabilistic_hough_line

    loglum = _log_luminance(img, linear)
    # Canny's Sobel magnitude of a step s smoothed by sigma peaks at 8 s / (sigma sqrt(2 pi)) (Sobel's weights sum
    # to 8 per unit slope): thresholds in steps of log luminance
    per_step = 8.0 / (EDGE_SIGMA_PX * math.sqrt(2.0 * math.pi))
    # the edge map is read on the ground only, its contact band with the casters and the sky left out; what lies
    # outside the ground is filled with the nearest ground value so that the ground's border makes no edge
    inner = ndimage.binary_erosion(ground, iterations=CONTACT_BAND_PX, border_value=1)
    nearest = ndimage.distance_transform_edt(~ground, return_distances=False, return_indices=True)
    filled = loglum[nearest[0], nearest[1]]
    edges = canny(filled, sigma=EDGE_SIGMA_PX, low_threshold=0.5 * MIN_EDGE_STEP * per_step,
                  high_threshold=MIN_EDGE_STEP * per_step) & inner
    if edges.sum() < 3:
        return []
    min_len = max(8, int(round(MIN_SEGMENT_FRACTION * max(shape))))
    theta = np.linspace(-math.pi / 2, math.pi / 2, 720, endpoint=False)
    lines = probabilistic_hough_line(edges, threshold=10, line_length=min_len, line_gap=3, theta=theta,
                                     rng=np.random.default_rng(seed))
    smooth = ndimage.gaussian_filter(filled, EDGE_SIGMA_PX)
    # the sunlit ground's level: the upper quartile of the ground (a shadow darkens less than three quarters of it)
    lit = float(np.percentile(smooth[inner], LIT_PERCENTILE)) if inner.any() else float("inf")
    ey, ex = np.nonzero(edges)
    big = max(shape)
    reach = max(6.0, TOUCH_FRACTION * big) + CONTACT_BAND_PX
    out = []
    for p0, p1 in _merge_collinear([(np.array(a, float), np.array(b, float)) for a, b in lines],
                                   MERGE_GAP_FRACTION * big):
        length = float(np.linalg.norm(p1 - p0))
        if length < min_len:
            continue
        # refine the direction by the edge pixels along the segment, fitted on the ground plane (straight lines
        # stay straight under the ground's homography)
        t_dir = (p1 - p0) / length
        normal = np.array([-t_dir[1], t_dir[0]])
        rel = np.stack([ex - p0[0], ey - p0[1]], -1)
        along, across = rel @ t_dir, rel @ normal
        near = (np.abs(across) <= 1.5) & (along >= -1) & (along <= length + 1)
        if near.sum() < min_len // 2:
            continue
        g = _ground_points(_pixel_rays(Kc, R, ex[near] + 0.5, ey[near] + 0.5))
        _, _, vt = np.linalg.svd(g - g.mean(0), full_matrices=False)
        direction = vt[0]
        ends = _ground_points(_pixel_rays(Kc, R, np.array([p0[0], p1[0]]) + 0.5, np.array([p0[1], p1[1]]) + 0.5))
        if (ends[1] - ends[0]) @ direction < 0:
            direction = -direction  # from end 0 to end 1
        axis = _azimuth(direction[0], direction[1]) % 180.0
        # contrast: the smoothed log luminance 3 pixels either side of the segment's middle half
        ts = np.linspace(0.25, 0.75, 9)[:, None] * (p1 - p0) + p0
        va = ndimage.map_coordinates(smooth, [ts[:, 1] + 3 * normal[1], ts[:, 0] + 3 * normal[0]], order=1,
                                     mode="nearest")
        vb = ndimage.map_coordinates(smooth, [ts[:, 1] - 3 * normal[1], ts[:, 0] - 3 * normal[0]], order=1,
                                     mode="nearest")
        step = float(np.median(np.abs(va - vb)))
        if step < 0.75 * MIN_EDGE_STEP:  # Canny's hysteresis followed a weak edge, or the ground's fill made one
            continue
        if min(float(np.median(va)), float(np.median(vb))) > lit - 0.5 * MIN_EDGE_STEP:
            continue  # its dark side is as bright as sunlit ground: an edge of paint, or of a caster's lit top
        sun = None
        if casters.any():
            t0 = _meets_foot(casters, p0, -t_dir, reach)
            t1 = _meets_foot(casters, p1, t_dir, reach)
            if t0 != t1:
                towards = direction if t1 else -direction  # from the free end to the caster
                sun = _azimuth(towards[0], towards[1])
        out.append(ShadowSegment(endpoints_px=np.stack([p0, p1]), axis_deg=axis, sun_azimuth_deg=sun,
                                 length_px=length, step=step))
    out.sort(key=lambda s: -s.length_px)
    return out


def _meets_foot(casters: np.ndarray, start: np.ndarray, direction: np.ndarray, reach: float) -> bool:
    """Whether the ray from pixel position ``start (2,)`` (column, row) along image ``direction (2,)`` meets the
    foot of a caster within ``reach`` pixels: the caster met ends within :data:`FOOT_PX` rows below that point in
    every column within 2 pixels of it (its bottom outline, where it stands on the ground). Where a shadow's edge runs
    into the caster's side instead, the caster hides the rest of the shadow: that is no contact."""
    t = np.arange(0.0, reach + 1e-9, 0.5)
    side = np.array([-direction[1], direction[0]])
    h, w = casters.shape
    first = None
    # a narrow cone about the line (1.5 pixels wide at the end, widening by 0.15 per pixel): Canny places an edge
    # a pixel or two off near a corner, and a caster's foot is a corner
    for frac in (0.0, -0.5, 0.5, -1.0, 1.0):
        pts = np.round(start[None] + t[:, None] * direction[None]
                       + (frac * (1.5 + 0.15 * t))[:, None] * side[None]).astype(int)
        inside = (pts[:, 0] >= 0) & (pts[:, 0] < w) & (pts[:, 1] >= 0) & (pts[:, 1] < h)
        hit = np.nonzero(inside & casters[np.clip(pts[:, 1], 0, h - 1), np.clip(pts[:, 0], 0, w - 1)])[0]
        if len(hit) and (first is None or t[hit[0]] < first[0]):
            first = (t[hit[0]], pts[hit[0]])
    if first is None:
        return False
    c, r = first[1]
    below = r + FOOT_PX
    if below >= h:
        return False  # the caster runs out of the frame: its foot is not seen
    return not bool(casters[below, max(0, c - 2):c + 3].any())


def _merge_collinear(segments: list[tuple[np.ndarray, np.ndarray]], max_gap: float
                     ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Merge Hough pieces of one straight edge: directions within 3 degrees, each end within 2 pixels of the other's
    line, a gap under ``max_gap`` pixels. Longest first; a merged segment spans its pieces' extreme ends."""
    segs = sorted(segments, key=lambda ab: -float(np.linalg.norm(ab[1] - ab[0])))
    merged: list[tuple[np.ndarray, np.ndarray]] = []
    for a, b in segs:
        u = (b - a) / max(float(np.linalg.norm(b - a)), 1e-9)
        for k, (c, d) in enumerate(merged):
            v = (d - c) / max(float(np.linalg.norm(d - c)), 1e-9)
            if abs(u @ v) < math.cos(math.radians(3.0)):
                continue
            n = np.array([-v[1], v[0]])
            if abs((a - c) @ n) > 2.0 or abs((b - c) @ n) > 2.0:
                continue
            ta, tb, td = (a - c) @ v, (b - c) @ v, (d - c) @ v
            lo, hi = min(ta, tb), max(ta, tb)
            gap = max(lo - td, -hi, 0.0)
            if gap > max_gap:
                continue
            t_min, t_max = min(0.0, lo), max(td, hi)
            merged[k] = (c + t_min * v, c + t_max * v)
            break
        else:
            merged.append((a, b))
    return merged


def _von_mises(delta_rad: np.ndarray, kappa: float) -> np.ndarray:
    """Density of a von Mises over the circle (radians), numerically safe for large ``kappa``."""
    from scipy.special import i0e

    return np.exp(kappa * (np.cos(delta_rad) - 1.0)) / (2.0 * math.pi * float(i0e(kappa)))


def _segments_fn(segments: list[ShadowSegment], sign_error: float):
    kappa = 1.0 / math.radians(SEGMENT_SIGMA_DEG) ** 2
    w = np.array([s.length_px * s.step * (1.0 if s.sun_azimuth_deg is not None else FREE_SEGMENT_WEIGHT)
                  for s in segments])
    omega = min(len(segments), MAX_SEGMENT_OBSERVATIONS) * w / w.sum()

    def fn(az_deg: np.ndarray) -> np.ndarray:
        phi = np.radians(np.asarray(az_deg, dtype=np.float64))
        ll = np.zeros(phi.shape)
        for s, o in zip(segments, omega):
            if s.sun_azimuth_deg is not None:
                a = math.radians(s.sun_azimuth_deg)
                f = (1 - sign_error) * _von_mises(phi - a, kappa) + sign_error * _von_mises(phi - a - math.pi, kappa)
            else:
                a = math.radians(s.axis_deg)
                f = 0.5 * (_von_mises(phi - a, kappa) + _von_mises(phi - a - math.pi, kappa))
            ll += o * np.log(SEGMENT_OUTLIER / (2 * math.pi) + (1 - SEGMENT_OUTLIER) * f)
        return ll

    return fn


def _flat(name: str, detail: str) -> CueLikelihood:
    el, az = _grid()
    return CueLikelihood(name=name, azimuths_deg=az, elevations_deg=el, log_likelihood=np.zeros((len(el), len(az))),
                         spoke=False, azimuth_deg=None, observations=0, detail=detail,
                         _fn=lambda a: np.zeros(np.shape(a)))


def _from_fn(name: str, fn, observations: int, detail: str, anchored: int = 0, agreeing: int = 0) -> CueLikelihood:
    el, az = _grid()
    fine = np.arange(0.0, 360.0, 0.5)
    ll_fine = fn(fine)
    top = float(ll_fine.max())
    best = float(fine[int(np.argmax(ll_fine))])
    row = fn(az) - top
    return CueLikelihood(name=name, azimuths_deg=az, elevations_deg=el,
                         log_likelihood=np.repeat(np.minimum(row, 0.0)[None], len(el), 0), spoke=True,
                         azimuth_deg=best, observations=observations, detail=detail, anchored=anchored,
                         agreeing=agreeing,
                         _fn=lambda a: fn(np.asarray(a, dtype=np.float64)) - top)


def shadow_likelihood(image: Array, sky_mask: Array, K: Array | None = None, world_to_camera: Array | None = None, *,
                      normals: Array | None = None, ground_mask: Array | None = None, pitch_deg: float | None = None,
                      fov_deg: float | None = None, linear: bool = False, seed: int = 0,
                      sign_error: float = SIGN_ERROR) -> CueLikelihood:
    """The sun's azimuth from cast-shadow edges on the ground, as a log-likelihood on the posterior's grid.

    Args: as :func:`shadow_segments`, and
        sign_error: share of a foot-anchored segment's weight on the opposite direction, in [0, 0.5]:
            :data:`SIGN_ERROR` for the decomposition's normals; 0 where the normals outline the casters exactly
            (a renderer's G-buffer, a depth sensor's).

    Returns:
        :class:`CueLikelihood` named ``"shadows"``: each segment is a mixture of a von Mises about the sun's
        azimuth (:data:`SEGMENT_SIGMA_DEG`; about both ends of its axis when it touches no caster) and a uniform
        (:data:`SEGMENT_OUTLIER`), weighted by its length times its contrast, the whole tempered to at most
        :data:`MAX_SEGMENT_OBSERVATIONS` observations. Flat (all zeros, ``spoke`` False) when no segment is read.

    Raises:
        ValueError: shapes, non-finite or negative values, masks that are not boolean, a bad camera.
    """
    segments = shadow_segments(image, sky_mask, K, world_to_camera, normals=normals, ground_mask=ground_mask,
                               pitch_deg=pitch_deg, fov_deg=fov_deg, linear=linear, seed=seed)
    if not (isinstance(sign_error, (int, float)) and 0.0 <= sign_error <= 0.5):
        raise ValueError(f"sign_error must be a number in [0, 0.5], got {sign_error!r}")
    if normals is None and ground_mask is None:
        return _flat("shadows", "the ground is not known (give normals or ground_mask)")
    if not segments:
        return _flat("shadows", "no straight edge strong enough on the ground")
    suns = np.array([s.sun_azimuth_deg for s in segments if s.sun_azimuth_deg is not None])
    anchored = len(suns)
    agreeing = int(max((np.abs((suns - a + 180.0) % 360.0 - 180.0) <= AGREE_DEG).sum() for a in suns)) if anchored else 0
    return _from_fn("shadows", _segments_fn(segments, float(sign_error)), len(segments),
                    f"{len(segments)} edge segments on the ground, {anchored} touching a caster's foot "
                    f"({agreeing} agreeing)", anchored, agreeing)


def shading_likelihood(image: Array, normals: Array, sky_mask: Array | None = None, K: Array | None = None,
                       world_to_camera: Array | None = None, *, pitch_deg: float | None = None,
                       fov_deg: float | None = None, linear: bool = False) -> CueLikelihood:
    """The side the sun is on, from the brightness of surfaces facing left against those facing right.

    Near-vertical surfaces (world normal within 30 degrees of horizontal) whose camera-frame normal points left
    (``x < -0.5``) or right (``x > 0.5``) are compared by their median log luminance ``d = right - left``. A sun
    towards camera-frame ``s`` lights the right side when ``s_x > 0``: the observation "right brighter" has
    probability ``1 - e`` there and ``e`` on the other half (a logistic step of width 0.05 in ``s_x``), with the
    error rate ``e = max(SHADING_MIN_ERROR, 0.5 exp(-|d| / SHADING_CONTRAST_SCALE))``.

    Args:
        image: ``(H, W, 3)`` display values in [0, 1] (sRGB), or linear radiance with ``linear=True``.
        normals: ``(3, H, W)`` camera-frame normals (zero where unknown).
        sky_mask: ``(H, W)`` bool or None (sky pixels are left out).
        K, world_to_camera, pitch_deg, fov_deg: the camera, as :func:`physrelight.sun_from_sky.estimate_sun_from_sky`.

    Returns:
        :class:`CueLikelihood` named ``"shading"``; flat when a side has fewer than :data:`MIN_SIDE_PIXELS` pixels.

    Raises:
        ValueError: shapes, non-finite values, a bad camera.
    """
    img = _check_image(image, linear)
    shape = img.shape[:2]
    n = _check_normals(normals, shape)
    sky = _check_mask(sky_mask, shape, "sky_mask")
    Kc, R = _camera(K, world_to_camera, pitch_deg, fov_deg, *shape)
    length = np.linalg.norm(n, axis=-1)
    known = length > 0.5 if sky is None else (length > 0.5) & ~sky
    unit = n / np.maximum(length, 1e-12)[..., None]
    vertical = np.abs((unit @ R)[..., 1]) < math.sin(math.radians(_VERTICAL_MAX_TILT_DEG))
    left = known & vertical & (unit[..., 0] < -_SIDE_MIN_X)
    right = known & vertical & (unit[..., 0] > _SIDE_MIN_X)
    if left.sum() < MIN_SIDE_PIXELS or right.sum() < MIN_SIDE_PIXELS:
        return _flat("shading", f"too few surfaces facing left ({int(left.sum())}) or right ({int(right.sum())}); "
                                f"{MIN_SIDE_PIXELS} of each are needed")
    loglum = _log_luminance(img, linear)
    d = float(np.median(loglum[right]) - np.median(loglum[left]))
    err = max(SHADING_MIN_ERROR, 0.5 * math.exp(-abs(d) / SHADING_CONTRAST_SCALE))
    x_cam = R[0]  # the camera's right, in the world frame

    def fn(az_deg: np.ndarray) -> np.ndarray:
        # the grid's cells carry no elevation dependence: the sun's horizontal direction decides the side
        a = np.radians(az_deg)
        s_x = np.sin(a) * x_cam[0] - np.cos(a) * x_cam[2]
        p_right = err + (1 - 2 * err) / (1 + np.exp(-s_x / 0.05))
        return np.log(p_right if d > 0 else 1 - p_right)

    return _from_fn("shading", fn, 1, f"right-facing surfaces {d:+.2f} log luminance against left-facing "
                                      f"({int(right.sum())} and {int(left.sum())} pixels); error rate {err:.2f}")
