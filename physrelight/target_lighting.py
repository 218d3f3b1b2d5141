"""The target lighting of a relighting: SH coefficients, an environment map or a sun, as order-2 SH in the camera
frame, and the sun alone within it.

Targets are given in the *world* frame (Y up): SH coefficients ``(9, 3)``, an environment map (array
``(H, 2H, 3)`` or an EXR path) or a sun, as a direction ``(3,)`` towards it or as its angles :class:`Sun` (a sun of
its elevation's colour plus a clear or overcast sky, :data:`SKY_TYPES`); they are rotated into the camera with
``world_to_camera`` (``(4, 4)`` or its ``(3, 3)`` rotation; None: camera frame = world frame).

Angles about the vertical follow one convention (docs/conventions.md): an azimuth is clockwise seen from above, from
world -Z (straight ahead of a level camera) towards +X (its right), as ``relight --sun ELEV AZIM`` counts it, and
turning a target by ``t`` degrees (:func:`rotate_azimuth`, ``Relighter.relight(..., azimuth_deg=t)``,
``relight --azimuth t``) adds ``t`` to every direction's azimuth.
"""

from __future__ import annotations

import functools
import math
import numbers
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from physrelight import rotations, sh
from physrelight.image_input import as_rotation

__all__ = ["SKY_TYPES", "Sun", "as_lighting_batch", "azimuth_turn", "camera_target", "clear_sky_sun", "overcast_level",
           "read_target", "rotate_azimuth", "sky_map_kind", "sun_lighting", "sun_rgb", "sun_sky_map",
           "target_lighting", "target_sun", "turned_camera"]

SKY_TYPES = ("clear", "overcast")


@dataclass(frozen=True)
class Sun:
    """A sun target by its angles, as ``relight --sun ELEV AZIM`` takes them: ``Sun(10, 60)`` is a sun 10 degrees
    above the horizon and 60 degrees clockwise seen from above from straight ahead of a level camera (world -Z;
    90 = +X, its right; docs/conventions.md). Accepted wherever a target is (``Relighter.relight(photo, Sun(10,
    60))``, ``source=``, :func:`target_lighting`, :func:`rotate_azimuth`, ...) as its :attr:`direction`, so with the
    sky type of a direction (``sky="clear"`` or ``"overcast"``).

    Attributes:
        elevation_deg: degrees above the horizon, in [-90, 90] (a clear sky's sun needs > 0).
        azimuth_deg: degrees clockwise seen from above from world -Z, any finite number.

    Raises:
        ValueError: an angle that is not a finite number, or an elevation outside [-90, 90], named.
    """

    elevation_deg: float
    azimuth_deg: float

    def __post_init__(self) -> None:
        for name in ("elevation_deg", "azimuth_deg"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise ValueError(f"Sun's {name} must be a finite number of degrees, got {value!r}")
            object.__setattr__(self, name, float(value))
        if not -90.0 <= self.elevation_deg <= 90.0:
            raise ValueError(f"Sun's elevation_deg must lie in [-90, 90] degrees, got {self.elevation_deg:g}")

    @property
    def direction(self) -> np.ndarray:
        """``(3,)`` float64 unit world direction towards the sun (:func:`physrelight.envmap.direction_from_angles`:
        ``(cos e sin a, sin e, -cos e cos a)``)."""
        from physrelight.envmap import direction_from_angles

        return direction_from_angles(self.elevation_deg, self.azimuth_deg)


def as_lighting_batch(x: Any, batch: int, name: str = "lighting") -> torch.Tensor:
    """Radiance SH ``(9, 3)`` or ``(batch, 9, 3)`` -> ``(batch, 9, 3)`` float32 (one lighting shared by the batch is
    expanded), checked finite; ``name`` names it in the error."""
    x = torch.as_tensor(x, dtype=torch.float32)
    if x.shape == (9, 3):
        x = x[None].expand(batch, -1, -1)
    if x.shape != (batch, 9, 3):
        raise ValueError(f"{name} must have shape (9, 3) or ({batch}, 9, 3), got {tuple(x.shape)}")
    if not torch.isfinite(x).all():
        raise ValueError(f"{name} holds NaN or inf")
    return x


def read_target(target: Any) -> Any:
    """A target as an array: an env map's path (``str`` or ``os.PathLike``) read (:func:`physrelight.envmap.read`,
    ``(H, 2H, 3)``), a :class:`Sun` as its direction ``(3,)``, anything else as it is.

    Raises:
        ValueError: two numbers, which could be a sun's angles or a direction missing a component: ambiguous, so
            refused with the two spellings that are not (``Sun(elevation_deg, azimuth_deg)``, a ``(3,)`` vector).
    """
    if isinstance(target, Sun):
        return target.direction
    if isinstance(target, (str, os.PathLike)):
        from physrelight import envmap

        return envmap.read(target)
    if isinstance(target, (tuple, list, np.ndarray, torch.Tensor)) and tuple(np.shape(target)) == (2,):
        raise ValueError(f"a target of two numbers {tuple(float(x) for x in target)} is ambiguous: give a sun's "
                         f"angles as physrelight.target_lighting.Sun(elevation_deg, azimuth_deg) (relight --sun's "
                         f"convention) or its direction as a (3,) vector")
    return target


def _sun_direction(direction: Any) -> np.ndarray:
    d = np.asarray(direction, dtype=np.float64)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
        raise ValueError(f"a sun direction must be a finite non-zero (3,) vector, got {d.tolist()}")
    return d / np.linalg.norm(d)


def clear_sky_sun(direction: Any) -> np.ndarray:
    """``(3,)`` unit ``direction`` (``(3,)``, any length) towards a clear sky's sun, checked above the horizon: a
    clear day's sun below it lights nothing directly and its twilight sky is not modelled (Hosek-Wilkie's sky
    starts at 2 degrees up), so it is refused."""
    d = _sun_direction(direction)
    if not d[1] > 0:
        raise ValueError(f"a clear sky's sun must be above the horizon (elevation > 0), got "
                         f"{math.degrees(math.asin(float(np.clip(d[1], -1, 1)))):.3g} deg; use sky 'overcast' for a sunless sky")
    return d


def sun_rgb(direction: np.ndarray) -> np.ndarray:
    """``(3,)`` the colour of a sun towards unit ``direction (3,)`` (luminance 1, white at the zenith):
    :func:`physrelight.sky_model.sun_colour` at its elevation."""
    from physrelight.sky_model import sun_colour

    return sun_colour(math.degrees(math.asin(float(np.clip(direction[1], -1.0, 1.0)))))


def sun_sky_map(sky: str = "clear", direction: Any = (0.0, 1.0, 0.0), height: int = 64) -> np.ndarray:
    """``(height, 2 height, 3)`` the sky of :func:`sun_lighting` without its sun, world frame.

    ``"clear"``: a clear day's sky for the sun towards ``direction``,
    :func:`physrelight.sky_model.sunsky_radiance` (Mitsuba 3's Hosek-Wilkie sky, turbidity 3, tabulated),
    in units where the sun's irradiance on a surface facing it has luminance 1: its level against the sun
    is the model's (order-2 irradiance on a horizontal surface 0.29 of the sun's at 5 degrees up,
    0.19-0.22 from 15 degrees up, in luminance), its colour and gradient too (a deep blue zenith, a pale horizon, warm
    under a low sun, the aureole round the sun). ``"overcast"``: the grey CIE overcast sky
    ``L(theta) = L_z (1 + 2 cos theta) / 3``, scaled to order-2 irradiance 1 on a horizontal
    surface; ``direction`` is ignored. Both are dark below the horizon.
    """
    if sky not in SKY_TYPES:
        raise ValueError(f"sky must be one of {SKY_TYPES}, got {sky!r}")
    from physrelight import envmap

    from physrelight.sky_model import overcast_sky, sunsky_radiance

    d = envmap.directions(height, 2 * height)
    if sky == "overcast":
        return np.repeat(overcast_sky(d)[..., None], 3, axis=-1) * overcast_level()
    return sunsky_radiance(d, clear_sky_sun(direction))


@functools.lru_cache(maxsize=1)
def overcast_level() -> float:
    """The factor that gives the CIE overcast sky (:func:`physrelight.sky_model.overcast_sky`) order-2 irradiance 1
    on a horizontal surface, as projected from its 64-row lat-long map."""
    from physrelight import envmap
    from physrelight.sky_model import overcast_sky

    env = np.repeat(overcast_sky(envmap.directions(64, 128))[..., None], 3, axis=-1)
    return 1.0 / float(sh.irradiance(sh.project_envmap(env, order=2), np.array([[0.0, 1.0, 0.0]]))[0, 1])


def sun_lighting(direction: Any, sky: str = "clear") -> np.ndarray:
    """Order-2 radiance SH ``(9, 3)`` (world frame) of a simple outdoor lighting.

    ``"clear"``: a delta sun towards ``direction`` of luminance 1 on a surface facing it, white at the
    zenith and warmer as it sinks (its light crosses more air: :func:`physrelight.sky_model.sun_colour`,
    a clear atmosphere's Rayleigh and aerosol extinction), plus the clear sky of :func:`sun_sky_map`
    (Hosek-Wilkie's, at its level against the sun: the fill light).
    ``"overcast"``: the CIE overcast sky of :func:`sun_sky_map`, no sun; the direction is
    ignored. Skies are projected from a 64 x 128 map.
    """
    d = _sun_direction(direction) if sky == "overcast" else clear_sky_sun(direction)
    coeffs = np.asarray(sh.project_envmap(sun_sky_map(sky, d), order=2))
    if sky == "overcast":
        return coeffs
    return sh.project_sun(d, sun_rgb(d), order=2) + coeffs


def sky_map_kind(target: Any) -> str:
    """``"env"`` (a lat-long map ``(H, 2H, 3)`` or its path), ``"sun"`` (a direction ``(3,)`` or a :class:`Sun`)
    or ``"sh"``: whether a target says what its sky looks like (the first two do; SH coefficients do not)."""
    if isinstance(target, (str, os.PathLike)):
        return "env"
    if isinstance(target, Sun):
        return "sun"
    shape = tuple(np.shape(target))
    if shape == (3,):
        return "sun"
    if len(shape) == 3 and shape[-1] == 3 and shape[1] == 2 * shape[0]:
        return "env"
    return "sh"


def target_lighting(target: Any, world_to_camera: Any = None, sky: str = "clear") -> torch.Tensor:
    """``(9, 3)`` float64 camera-frame radiance SH of a target (SH ``(9, 3)``, env map ``(H, 2H, 3)`` or EXR path,
    or a sun direction ``(3,)`` towards the sun with ``sky`` in :data:`SKY_TYPES`, see :func:`sun_lighting`; all
    in the world frame), rotated by ``world_to_camera`` (``(4, 4)``, ``(3, 3)`` or None)."""
    target = read_target(target)
    t = torch.as_tensor(np.asarray(target, dtype=np.float64) if not isinstance(target, torch.Tensor)
                        else target.double())
    if t.shape == (3,):
        coeffs = torch.as_tensor(sun_lighting(t.numpy(), sky))
    elif t.ndim == 2 and t.shape == (9, 3):
        coeffs = t
    elif t.ndim == 3 and t.shape[-1] == 3 and t.shape[1] == 2 * t.shape[0]:
        coeffs = torch.as_tensor(sh.project_envmap(t.numpy(), order=2))
    else:
        raise ValueError(f"target must be SH coefficients (9, 3), an env map (H, 2H, 3) or a sun direction (3,), "
                         f"got {tuple(t.shape)}")
    if not torch.isfinite(coeffs).all():
        raise ValueError("target holds NaN or inf")
    return torch.as_tensor(sh.rotate(coeffs, as_rotation(world_to_camera)))


def target_sun(target: Any, world_to_camera: Any = None, sky: str = "clear") -> torch.Tensor | None:
    """``(9, 3)`` float64 camera-frame radiance SH of the sun alone within a target (see :func:`target_lighting`),
    or None when it has none: a sun direction's delta sun (clear sky), an environment map's delta sun as
    :func:`physrelight.envmap.split_sun` splits it off (the rule synth renders a map's sun by; a map without a
    compact source carrying 1 % of its light has none), an SH target's the delta sun of the sky model fitted to it
    (:func:`physrelight.sky_model.fit_sky`; study 33); overcast skies: None."""
    target = read_target(target)
    t = np.asarray(target.detach().cpu().double() if isinstance(target, torch.Tensor) else target, np.float64)
    if t.shape == (3,):
        d = _sun_direction(t)
        coeffs = None if sky == "overcast" else sh.project_sun(d, sun_rgb(d), order=2)
    elif t.ndim == 3 and t.shape[-1] == 3 and t.shape[1] == 2 * t.shape[0]:
        from physrelight.envmap import split_sun

        # One sun finder for the package (issue 41): split_sun's delta sun, the one the renders and the
        # synthetic bench use; its exact cosine plus the rest in SH is also the truer shading on the shipped
        # outdoor maps (mean error against brute force: city 2.05 -> 1.74 %, forest 3.97 -> 3.62 %).
        split = split_sun(t)
        coeffs = np.asarray(sh.project_sun(split.direction, split.irradiance, order=2)) if split.has_sun else None
    elif t.shape == (9, 3) and np.all(np.isfinite(t)) and np.all(t[0] > 0):
        from physrelight.sky_model import fit_sky

        # An SH target says nothing of its sun; the fitted sky model's sun lets the quotient shade it by
        # its exact cosine, as an env map's is (study 33: data/val5 -0.0009 l1; data/heldout +0.0003, n.s.).
        fit = fit_sky(t)
        coeffs = np.asarray(sh.project_sun(fit.sun_direction, fit.weights[0], order=2)) \
            if bool((fit.weights[0] > 0).any()) else None
    else:
        coeffs = None
    return None if coeffs is None else torch.as_tensor(sh.rotate(coeffs, as_rotation(world_to_camera)))


def azimuth_turn(degrees: float) -> np.ndarray:
    """``(3, 3)`` float64 the world rotation that turns a target by ``degrees`` about the vertical, clockwise seen
    from above: every direction's azimuth (0 = world -Z, 90 = +X; :func:`physrelight.envmap.direction_from_angles`)
    grows by ``degrees``. The one place the convention is built (:func:`rotate_azimuth`, :func:`turned_camera`):
    :func:`physrelight.rotations.about_y` turns by the right-hand rule about +Y, counter-clockwise from above, so
    this is ``about_y(-degrees)``."""
    if not math.isfinite(float(degrees)):
        raise ValueError(f"azimuth must be a finite number of degrees, got {degrees!r}")
    return rotations.about_y(-float(degrees))


def rotate_azimuth(target: Any, degrees: float) -> Any:
    """Turn a world-frame target (SH ``(9, 3)``, env map ``(H, 2H, 3)``, EXR path or sun direction ``(3,)``) by
    ``degrees`` about the vertical, clockwise seen from above (:func:`azimuth_turn`: a sun at azimuth ``a`` goes to
    ``a + degrees``; the SH rotation is exact; env maps are projected first): a sun direction ``(3,)`` or SH
    ``(9, 3)`` comes back."""
    target = read_target(target)
    R = azimuth_turn(degrees)  # the same turn as turned_camera's, from one formula
    t = np.asarray(target, dtype=np.float64) if not isinstance(target, torch.Tensor) else target.double().numpy()
    if t.shape == (3,):
        return R @ t
    if t.ndim == 3 and t.shape[-1] == 3 and t.shape[1] == 2 * t.shape[0]:
        t = sh.project_envmap(t, order=2)
    if t.shape != (9, 3):
        raise ValueError(f"target must be SH coefficients (9, 3), an env map (H, 2H, 3) or a sun direction (3,), "
                         f"got {t.shape}")
    return sh.rotate(t, R)


def turned_camera(world_to_camera: Any, azimuth_deg: float) -> np.ndarray:
    """``(3, 3)`` the camera rotation (of ``world_to_camera``, ``(4, 4)`` or ``(3, 3)``) that sees a target turned
    by ``azimuth_deg`` as :func:`rotate_azimuth` turns it (clockwise seen from above):
    ``target'(w) = target(R_t^T w)`` with ``R_t = azimuth_turn(azimuth_deg)``, so ``R = T R_t`` (the camera turned
    the other way)."""
    return np.asarray(world_to_camera, dtype=np.float64)[:3, :3] @ azimuth_turn(azimuth_deg)


def camera_target(target: Any, world_to_camera: Any, azimuth_deg: float = 0.0,
                  sky: str = "clear") -> tuple[torch.Tensor, torch.Tensor | None]:
    """``(lighting (9, 3), sun (9, 3) or None)`` float32, camera frame: :func:`target_lighting` and
    :func:`target_sun` of a world-frame target (as :func:`target_lighting` takes it) turned first by
    ``azimuth_deg`` clockwise seen from above (:func:`rotate_azimuth`), seen by ``world_to_camera`` (``(4, 4)`` or
    ``(3, 3)``)."""
    target = read_target(target)
    turned = rotate_azimuth(target, azimuth_deg) if azimuth_deg else target
    lighting = target_lighting(turned, world_to_camera, sky).float()
    if azimuth_deg and sky_map_kind(target) == "env":
        # rotate_azimuth projects a map to SH: take the map's own sun, turned with the camera as the
        # map's sky is (physrelight.sky_view.target_sky), not the sun of a sky model fitted to its SH
        sun = target_sun(target, turned_camera(world_to_camera, azimuth_deg), sky)
    else:
        sun = target_sun(turned, world_to_camera, sky)
    return lighting, None if sun is None else sun.float()
