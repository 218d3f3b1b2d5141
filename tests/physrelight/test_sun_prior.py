"""Specification of the sun prior (physrelight.sun_prior): fitted to the training side's outdoor panoramas only,
a probability on the posterior's grid that follows the suns it saw without ruling any elevation out, uniform in
azimuth, kinds add-one smoothed; the shipped file is what its script writes, byte for byte."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from physrelight import data, envmap
from physrelight import sun_prior as sp
from physrelight.sun_from_sky import ELEVATIONS_DEG, _cell_solid_angles

ROOT = Path(__file__).resolve().parents[2]


def _script():
    spec = importlib.util.spec_from_file_location("fit_sun_prior", ROOT / "scripts" / "fit_sun_prior.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_01_the_shipped_prior_comes_from_the_training_side_only() -> None:
    """Its maps are exactly the outdoor maps of data/hdri and data/hdri_more; no held-out map (sunrise) is one."""
    prior = sp.load_sun_prior()
    training = set(data.hdri_names(collection="shipped", kind="outdoor")) | set(
        data.hdri_names(collection="more", kind="outdoor"))
    assert set(prior.maps) == training and len(prior.maps) == 9
    assert not set(prior.maps) & set(data.hdri_names(heldout=True))
    assert {n for _, n in _script().training_maps()} == training


def test_02_the_shipped_prior_is_a_normalised_grid_constant_in_azimuth() -> None:
    prior = sp.load_sun_prior()
    assert prior.probability.shape == (len(ELEVATIONS_DEG), len(prior.azimuths_deg))
    assert prior.probability.sum() == pytest.approx(1.0, abs=1e-12) and (prior.probability > 0).all()
    assert np.ptp(prior.probability, axis=1).max() < 1e-15
    assert prior.kind_probability.sum() == pytest.approx(1.0) and len(prior.kind_probability) == len(sp.PRIOR_KINDS)
    assert 0.0 < prior.sun_probability < 1.0


def test_03_the_elevations_are_the_suns_split_sun_finds_in_the_training_maps() -> None:
    """Measured again here: each map's sun by envmap.split_sun; the prior holds those elevations (city 47.9, forest
    19.5, pm_sky 48.1 when it was fitted)."""
    prior = sp.load_sun_prior()
    found = []
    for coll, name in _script().training_maps():
        split = envmap.split_sun(envmap.read(data.hdri(name, collection=coll)))
        if split.has_sun:
            found.append(math.degrees(math.asin(float(split.direction[1]))))
    np.testing.assert_allclose(np.sort(prior.sun_elevations_deg), np.sort(found), atol=1e-9)


def test_04_the_fit_follows_its_samples_and_rules_no_elevation_out() -> None:
    """Suns at 20 and 50 deg: the elevation marginal peaks within a grid step of them and is lowest far from both;
    every cell keeps at least UNIFORM_SHARE of the uniform prior's mass. With no sun at all: the uniform prior."""
    prior = sp.fit_sun_prior([20.0, 50.0], ["clear", "clear", "overcast"])
    el = prior.elevations_deg
    marginal = prior.probability.sum(1)
    band = _cell_solid_angles(el, 1)[:, 0]
    density = marginal / (np.diff(np.concatenate([[el[0]], (el[1:] + el[:-1]) / 2, [90.0]])))
    peaks = [el[i] for i in range(1, len(el) - 1) if density[i] >= density[i - 1] and density[i] >= density[i + 1]]
    assert any(abs(p - 20) <= 4 for p in peaks) and any(abs(p - 50) <= 4 for p in peaks), peaks
    uniform = band / band.sum()
    assert np.all(marginal >= sp.UNIFORM_SHARE * uniform - 1e-15)
    assert marginal[el > 80].sum() < uniform[el > 80].sum()
    none = sp.fit_sun_prior([], ["overcast"])
    np.testing.assert_allclose(none.probability, sp.uniform_sun_prior().probability)
    np.testing.assert_allclose(prior.kind_probability, np.array([3, 1, 2, 1]) / 7)  # clear, hazy, overcast, night


def test_05_the_script_rewrites_the_shipped_file_byte_for_byte(tmp_path: Path) -> None:
    out = tmp_path / "prior.safetensors"
    assert _script().main(["-o", str(out)]) == 0
    assert out.read_bytes() == sp.SUN_PRIOR.read_bytes()
    again = sp.load_sun_prior(out)
    np.testing.assert_array_equal(again.probability, sp.load_sun_prior().probability)


def test_06_bad_input_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="sun elevations must lie in"):
        sp.fit_sun_prior([95.0], ["clear"])
    with pytest.raises(ValueError, match="kinds must be"):
        sp.fit_sun_prior([30.0], ["sunny"])
    with pytest.raises(ValueError, match="kinds must be"):
        sp.fit_sun_prior([30.0], [])
    with pytest.raises(ValueError, match="no sun prior at"):
        sp.load_sun_prior(tmp_path / "missing.safetensors")
    from safetensors.numpy import save_file

    other = tmp_path / "other.safetensors"
    save_file({"x": np.zeros(3)}, str(other))
    with pytest.raises(ValueError, match="is not a sun prior"):
        sp.load_sun_prior(other)
    with pytest.raises(ValueError, match="kind must be one of"):
        sp.load_sun_prior().kind("sunny")
