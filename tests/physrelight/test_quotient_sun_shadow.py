"""Specification of the sun-only shadows of :mod:`physrelight.quotient` (``source_sun`` / ``target_sun``).

A sun visibility dims the sun's light only (the sky still lights an umbra), as ``oracle_sh_shadow``
does: ``shading(n; L - L_sun) + v * shading(n; L_sun)``. Photos are made here with exactly that
image model, so the quotient must undo the source's sun shadows and cast the target's.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physrelight import image_model, quotient, sh


def _lighting(sun_dir, sun_rgb, sky_level: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``(L (1, 9, 3), L_sun (1, 9, 3))``: a delta sun plus a sky with some gradient."""
    d = np.asarray(sun_dir, dtype=np.float64) / np.linalg.norm(sun_dir)
    sun = torch.from_numpy(np.asarray(sh.project_sun(d, np.asarray(sun_rgb, dtype=np.float64)))).float()[None]
    sky = torch.zeros(1, 9, 3)
    sky[:, 0] = sky_level
    sky[:, 1] = 0.3 * sky_level  # brighter above
    return sky + sun, sun


def _scene(seed: int, h: int = 20, w: int = 24):
    g = torch.Generator().manual_seed(seed)
    n = torch.randn(1, 3, h, w, generator=g)
    n[:, 2] = n[:, 2].abs() + 0.3
    n = n / n.norm(dim=1, keepdim=True)
    albedo = torch.rand(1, 3, h, w, generator=g) * 0.8 + 0.1
    v_s = (torch.rand(1, 1, h, w, generator=g) > 0.4).float()
    v_t = (torch.rand(1, 1, h, w, generator=g) > 0.5).float()
    return n, albedo, v_s, v_t


def _model(albedo, n, L, L_sun, v):
    return albedo * (image_model.shading(n, L - L_sun) + v * image_model.shading(n, L_sun))


def test_01_relit_to_its_own_lighting_with_its_own_sun_shadows_is_the_photo_bit_for_bit() -> None:
    n, albedo, v_s, _ = _scene(0)
    L, L_sun = _lighting((0.3, 0.7, 0.6), (2.0, 1.8, 1.5), 0.5)
    photo = _model(albedo, n, L, L_sun, v_s).clamp_min(0)
    got = quotient.quotient_relight(photo, n, L, L, source_shadow=v_s, target_shadow=v_s, source_sun=L_sun,
                                    target_sun=L_sun)
    assert torch.equal(got, photo)


def test_02_removes_the_source_sun_shadows_and_casts_the_target_ones() -> None:
    """With the guard at 1e-9 the quotient is the image model's ratio: the relit photo equals the
    photo rendered under the target (relative error < 1e-4 where the target shading is not tiny)."""
    n, albedo, v_s, v_t = _scene(1)
    L_s, sun_s = _lighting((0.3, 0.7, 0.6), (2.0, 1.8, 1.5), 0.5)
    L_t, sun_t = _lighting((-0.5, 0.4, 0.75), (1.2, 1.3, 1.6), 0.8)
    photo = _model(albedo, n, L_s, sun_s, v_s)
    assert bool((photo > 1e-3).all())  # the test scene keeps every shading positive
    want = _model(albedo, n, L_t, sun_t, v_t)
    got = quotient.quotient_relight(photo, n, L_s, L_t, source_shadow=v_s, target_shadow=v_t, source_sun=sun_s,
                                    target_sun=sun_t, guard=1e-9)
    torch.testing.assert_close(got, want, rtol=1e-4, atol=1e-6)
    # The whole-shading shadow (no sun parts) is the inconsistent model: it darkens sky-lit umbrae.
    whole = quotient.quotient_relight(photo, n, L_s, L_t, source_shadow=v_s.clamp_min(1e-3), target_shadow=v_t,
                                      guard=1e-9)
    assert (whole - want).abs().mean() > 10 * (got - want).abs().mean()


def test_03_backward_compatible() -> None:
    n, albedo, v_s, v_t = _scene(2)
    L_s, sun_s = _lighting((0.3, 0.7, 0.6), (2.0, 1.8, 1.5), 0.5)
    L_t, sun_t = _lighting((-0.5, 0.4, 0.75), (1.2, 1.3, 1.6), 0.8)
    photo = _model(albedo, n, L_s, sun_s, v_s)
    # Sun parts without shadows: exactly the unsplit shading.
    assert torch.equal(quotient.quotient_relight(photo, n, L_s, L_t, source_sun=sun_s, target_sun=sun_t),
                       quotient.quotient_relight(photo, n, L_s, L_t))
    # A shadow without a sun part multiplies the whole shading, as before the option existed.
    old = quotient.quotient_relight(photo, n, L_s, L_t, source_shadow=v_s, target_shadow=v_t)
    s_src = image_model.shading(n, L_s).clamp_min(0) * v_s
    s_tgt = image_model.shading(n, L_t).clamp_min(0) * v_t
    g = quotient.DEFAULT_GUARD * s_src.mean((2, 3), keepdim=True)
    torch.testing.assert_close(old, photo * (s_tgt + g) / (s_src + g))
    # One side split, the other not.
    mixed = quotient.quotient_relight(photo, n, L_s, L_t, source_shadow=v_s, target_shadow=v_t, target_sun=sun_t)
    s_tgt_sun = (image_model.shading(n, L_t - sun_t) + v_t * image_model.shading(n, sun_t)).clamp_min(0)
    torch.testing.assert_close(mixed, photo * (s_tgt_sun + g) / (s_src + g))


def test_04_invariant_to_the_albedo_lighting_scale() -> None:
    n, albedo, v_s, v_t = _scene(3)
    L_s, sun_s = _lighting((0.3, 0.7, 0.6), (2.0, 1.8, 1.5), 0.5)
    L_t, sun_t = _lighting((-0.5, 0.4, 0.75), (1.2, 1.3, 1.6), 0.8)
    photo = _model(albedo, n, L_s, sun_s, v_s)
    ref = quotient.quotient_relight(photo, n, L_s, L_t, source_shadow=v_s, target_shadow=v_t, source_sun=sun_s,
                                    target_sun=sun_t)
    for k in (0.01, 3.0, 250.0):
        got = quotient.quotient_relight(photo, n, k * L_s, k * L_t, source_shadow=v_s, target_shadow=v_t,
                                        source_sun=k * sun_s, target_sun=k * sun_t)
        torch.testing.assert_close(got, ref, rtol=1e-5, atol=1e-7)


def test_05_bad_shapes_raise_value_errors_naming_them() -> None:
    n, albedo, v_s, v_t = _scene(4)
    L, sun = _lighting((0.3, 0.7, 0.6), (2.0, 1.8, 1.5), 0.5)
    with pytest.raises(ValueError, match=r"source_sun must have shape \(1, 9, 3\), got \(9, 3\)"):
        quotient.quotient_ratio(n, L, L, source_shadow=v_s, source_sun=sun[0])
    with pytest.raises(ValueError, match=r"target_shadow must have shape \(1, 1, 20, 24\), got \(1, 20, 24\)"):
        quotient.quotient_ratio(n, L, L, target_shadow=v_t[0], target_sun=sun)


def test_06_with_the_exact_sun_cosine_the_shadow_dims_the_exact_sun_term_only() -> None:
    """``sun_cosine``: photos made with ``shading(n; L - L_sun) + v * sun_shading(n; L_sun)`` are relit exactly
    (guard 1e-9, relative error < 1e-4) to the target's; dropping either side's shadow on the sun term is off by
    the shadowed sun share (more than 10 % of the target in the target's shadows)."""
    n, albedo, v_s, v_t = _scene(5)
    L_s, sun_s = _lighting((0.3, 0.7, 0.6), (2.0, 1.8, 1.5), 0.5)
    L_t, sun_t = _lighting((-0.5, 0.4, 0.75), (1.2, 1.3, 1.6), 0.8)

    def exact(L, L_sun, v):
        return albedo * (image_model.shading(n, L - L_sun) + v * image_model.sun_shading(n, L_sun))

    photo = exact(L_s, sun_s, v_s)
    assert bool((photo > 1e-3).all())
    want = exact(L_t, sun_t, v_t)
    got = quotient.quotient_relight(photo, n, L_s, L_t, source_shadow=v_s, target_shadow=v_t, source_sun=sun_s,
                                    target_sun=sun_t, guard=1e-9, sun_cosine=True)
    torch.testing.assert_close(got, want, rtol=1e-4, atol=1e-6)
    # What the shadow takes away in the target's shadows: the lit sun share, a measurable part of the light.
    lit_t = exact(L_t, sun_t, torch.ones_like(v_t))
    shade = (v_t < 0.5) & (image_model.sun_shading(n, sun_t).sum(1, keepdim=True) > 0.1)
    assert bool(shade.any())
    assert float(((lit_t - want) / want)[shade.expand_as(want)].mean()) > 0.1
