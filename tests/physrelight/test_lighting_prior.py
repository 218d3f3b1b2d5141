"""Specification of physrelight.lighting_prior: whitened PCA of outdoor SH lighting."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physrelight import rotations, sh
from physrelight.lighting_prior import LightingPrior, fit_lighting_prior


def outdoor_lightings(hdris, n: int = 60, seed: int = 0) -> np.ndarray:
    """The three outdoor maps seen from random camera frames (any yaw, pitch +-30 deg): (3n, 9, 3)."""
    rng = np.random.default_rng(seed)
    out = []
    for name in ("city", "courtyard", "forest"):
        c = sh.project_envmap(hdris[name], 2)
        c = c / c[0].mean()  # exposure-normalised, as a photo would be
        for _ in range(n):
            r = rotations.axis_angle([1, 0, 0], rng.uniform(-30, 30)) @ rotations.about_y(rng.uniform(0, 360))
            out.append(sh.rotate(c, r))
    return np.stack(out)


def test_01_data_in_a_k_dim_subspace_is_reproduced_exactly() -> None:
    rng = np.random.default_rng(0)
    basis = np.linalg.qr(rng.normal(size=(27, 5)))[0].T  # 5 orthonormal directions
    x = rng.normal(size=(200, 5)) * [5, 4, 3, 2, 1] @ basis + rng.normal(size=27)
    prior = fit_lighting_prior(x.reshape(200, 9, 3), k=5)
    np.testing.assert_allclose(prior.project(x.reshape(200, 9, 3)), x.reshape(200, 9, 3), atol=1e-10)
    assert prior.explained == pytest.approx(1.0)


def test_02_whitened_coordinates_have_unit_covariance_on_the_training_set() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(size=(500, 27)) * np.linspace(3, 0.1, 27)
    prior = fit_lighting_prior(x.reshape(500, 9, 3), k=10)
    z = prior.encode(x.reshape(500, 9, 3))
    np.testing.assert_allclose(np.cov(z.T), np.eye(10), atol=1e-10)
    # The prior loss is the mean squared whitened coordinate: (N-1)/N on training data.
    assert float(prior.loss(x.reshape(500, 9, 3))) == pytest.approx(499 / 500, rel=1e-10)


def test_03_projection_is_idempotent_and_orthogonal() -> None:
    rng = np.random.default_rng(2)
    x = rng.normal(size=(100, 9, 3))
    prior = fit_lighting_prior(x, k=6)
    p = prior.project(x)
    np.testing.assert_allclose(prior.project(p), p, atol=1e-12)
    residual = (x - p).reshape(100, 27)
    np.testing.assert_allclose(residual @ prior.components.numpy().T, 0.0, atol=1e-10)


def test_04_real_outdoor_lighting_is_low_dimensional(hdris) -> None:
    lights = outdoor_lightings(hdris)
    prior = fit_lighting_prior(lights, k=18)
    # 18 of 27 dimensions (the paper's choice) hold 99.99 % of the variance of outdoor
    # lighting seen from tourist cameras; 8 already hold 97 %.
    assert prior.explained > 0.999
    assert fit_lighting_prior(lights, k=8).explained > 0.95
    # A lighting no outdoor map produces (the sky below the horizon) costs far more.
    flipped = sh.rotate(lights[0], rotations.axis_angle([1, 0, 0], 180))
    assert float(prior.loss(flipped[None])) > 10 * float(prior.loss(lights))


def test_05_save_load_round_trip(tmp_path) -> None:
    rng = np.random.default_rng(3)
    prior = fit_lighting_prior(rng.normal(size=(50, 9, 3)), k=4)
    prior.save(tmp_path / "prior.npz")
    back = LightingPrior.load(tmp_path / "prior.npz")
    torch.testing.assert_close(back.components, prior.components)
    assert back.order == 2 and back.dim == 4
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="cannot read"):
        LightingPrior.load(tmp_path / "bad.npz")


def test_06_gradcheck_prior_loss_and_projection() -> None:
    rng = np.random.default_rng(4)
    prior = fit_lighting_prior(rng.normal(size=(40, 9, 3)), k=5)
    light = torch.tensor(rng.normal(size=(2, 9, 3)), requires_grad=True)
    assert torch.autograd.gradcheck(prior.loss, (light,))
    assert torch.autograd.gradcheck(prior.project, (light,))


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: fit_lighting_prior(np.ones((10, 9, 3)) + np.arange(10)[:, None, None], k=20), "k must be"),
        (lambda: fit_lighting_prior(np.ones((10, 8, 3)), k=2), "SH coefficients"),
        (lambda: fit_lighting_prior(np.ones((10, 27)), k=2), r"\(N, K, 3\)"),
        (lambda: fit_lighting_prior(np.tile(np.arange(27.0), (10, 1)).reshape(10, 9, 3), k=2), "span"),
    ],
)
def test_07_bad_input_raises_a_clear_value_error(call, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()
