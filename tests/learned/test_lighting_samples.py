"""``learned.lighting``: which outdoor maps the lighting prior's real-sky samples come from (issue 43)."""

from __future__ import annotations

import numpy as np
import pytest

from learned import lighting


def test_01_the_hdri_sets_name_their_outdoor_maps_and_never_a_room_or_the_held_out_one() -> None:
    from synth import lighting as sl

    shipped = lighting.prior_hdris("shipped")
    assert [p.stem for p in shipped] == ["city", "courtyard", "forest"] and shipped == sl.list_hdris()
    more = lighting.prior_hdris("more")
    assert more[:3] == shipped
    assert [p.stem for p in more[3:]] == ["pm_city", "pm_dawn", "pm_forest", "pm_night", "pm_sky", "pm_venice"]
    assert "sunrise" not in {p.stem for p in more}
    with pytest.raises(ValueError, match="HDRI set must be one of shipped, more, got 'all'"):
        lighting.prior_hdris("all")


def test_02_samples_come_from_the_named_set_and_the_default_is_unchanged() -> None:
    """Sky samples first (the same draws whatever the set), then ``n_hdri_per_map`` per map: the shipped set's
    samples are a prefix of the ``more`` set's, which adds six maps' worth."""
    a = lighting.outdoor_lightings(n_sky=2, n_hdri_per_map=1, seed=5, resolution=8)
    b = lighting.outdoor_lightings(n_sky=2, n_hdri_per_map=1, seed=5, resolution=8, hdris="shipped")
    c = lighting.outdoor_lightings(n_sky=2, n_hdri_per_map=1, seed=5, resolution=8, hdris="more")
    assert a.shape == (5, 9, 3) and c.shape == (11, 9, 3)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(c[:5], a)
    assert np.all(c[5:, 0].sum(-1) > 0)  # every map's DC is positive light
