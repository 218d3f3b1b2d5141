"""Specification of physrelight.stats: the paired cluster bootstrap used to say "method A beats B"."""

from __future__ import annotations

import numpy as np
import pytest

from physrelight.stats import paired_bootstrap


def test_01_the_difference_is_the_paired_mean_and_the_same_seed_gives_the_same_interval() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=50), rng.normal(size=50)
    r = paired_bootstrap(a, b, seed=3)
    assert r.diff == pytest.approx(float(np.mean(a - b)), abs=1e-12)
    assert r.lo < r.diff < r.hi and r.groups == 50
    assert paired_bootstrap(a, b, seed=3) == r
    assert paired_bootstrap(a, b, seed=4) != r


def test_02_coverage_of_the_95_percent_interval_is_near_95_percent() -> None:
    # 300 datasets of 40 i.i.d. differences with mean 0.3: the interval holds 0.3 in ~95 %.
    # Percentile intervals under-cover slightly at n = 40 (~93-94 %); the band is +-3.5 binomial s.d.
    rng = np.random.default_rng(1)
    hits = 0
    for k in range(300):
        d = 0.3 + rng.standard_normal(40)
        r = paired_bootstrap(d, np.zeros(40), samples=1000, seed=k)
        hits += r.lo <= 0.3 <= r.hi
    sd = np.sqrt(300 * 0.95 * 0.05)
    assert 300 * 0.95 - 3.5 * sd - 6 <= hits <= 300, hits


def test_03_resampling_whole_groups_widens_the_interval_when_cases_share_a_group_effect() -> None:
    # 10 scenes x 20 cases with a strong per-scene effect: cases are not independent, so the
    # case bootstrap is overconfident; the scene bootstrap's width is that of 10 scene means.
    rng = np.random.default_rng(2)
    scene_effect = np.repeat(rng.normal(scale=1.0, size=10), 20)
    d = scene_effect + 0.1 * rng.standard_normal(200)
    groups = np.repeat(np.arange(10), 20)
    by_case = paired_bootstrap(d, np.zeros(200))
    by_scene = paired_bootstrap(d, np.zeros(200), groups=groups)
    assert by_scene.groups == 10
    assert (by_scene.hi - by_scene.lo) > 3.0 * (by_case.hi - by_case.lo)
    # ~ 2 * 1.96 * sd(scene means) / sqrt(10), within the bootstrap's own small-sample spread
    expected = 2 * 1.96 * np.std(d.reshape(10, 20).mean(1)) / np.sqrt(10)
    assert 0.6 * expected < by_scene.hi - by_scene.lo < 1.3 * expected


@pytest.mark.parametrize("kwargs, match", [
    (dict(a=[1.0, 2.0], b=[1.0]), "same length"),
    (dict(a=[], b=[]), "at least one"),
    (dict(a=[1.0, np.nan], b=[1.0, 2.0]), "finite"),
    (dict(a=[1.0, 2.0], b=[1.0, 2.0], groups=[0]), "groups"),
    (dict(a=[1.0], b=[1.0], level=1.5), "level"),
    (dict(a=[1.0], b=[1.0], samples=0), "samples"),
])
def test_04_bad_input_names_the_problem(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        paired_bootstrap(**kwargs)


def test_05_quantile_is_torchs_below_its_limit_and_the_order_statistics_above() -> None:
    """``stats.quantile``: bit for bit ``torch.quantile`` up to ``TORCH_QUANTILE_MAX`` elements (which torch itself
    refuses beyond), and above it numpy's linear quantile of the same values (a 24-megapixel sky has more)."""
    import torch

    from physrelight.stats import TORCH_QUANTILE_MAX, quantile

    g = torch.Generator().manual_seed(0)
    for n in (1, 2, 7, 1000):
        x = torch.rand(n, generator=g)
        for q in (0.0, 0.1, 0.5, 0.99, 1.0):
            assert torch.equal(quantile(x, q), torch.quantile(x, q))
    big = torch.rand(TORCH_QUANTILE_MAX + 5, generator=g, dtype=torch.float64)
    with pytest.raises(RuntimeError, match="too large"):
        torch.quantile(big, 0.5)
    for q in (0.0, 0.37, 0.99, 1.0):
        assert float(quantile(big, q)) == pytest.approx(float(np.quantile(big.numpy(), q)), abs=1e-12)
    assert float(quantile(big.reshape(3, -1), 0.5)) == float(quantile(big, 0.5))  # all the elements, any shape
    with pytest.raises(ValueError, match="empty"):
        quantile(torch.zeros(0), 0.5)
    with pytest.raises(ValueError, match="q must"):
        quantile(big, 1.5)


def test_05b_the_selected_quantile_is_torchs_to_the_bit_with_ties_nan_and_either_precision() -> None:
    """Below the limit ``stats.quantile`` selects its two order statistics (``torch.kthvalue``) instead of sorting
    as ``torch.quantile`` does; with torch's own rank arithmetic (``q`` in the input's dtype) it gives the same
    number: random sizes and ``q``, rounded values (ties), float32 and float64, and NaN propagated."""
    import torch

    from physrelight.stats import quantile

    g = torch.Generator().manual_seed(1)
    for t in range(400):
        n = int(torch.randint(1, 3000, (1,), generator=g))
        x = torch.randn(n, generator=g, dtype=torch.float32 if t % 2 else torch.float64) * 10
        x = x.round() if t % 3 == 0 else x
        q = float(torch.rand(1, generator=g))
        assert torch.equal(quantile(x, q), torch.quantile(x, q)), (t, n, q)
    x = torch.tensor([1.0, float("nan"), 3.0])
    assert torch.isnan(quantile(x, 0.5)) and torch.isnan(torch.quantile(x, 0.5))
