"""physrelight.parallel: independent pieces on threads, the results of the plain loop."""

from __future__ import annotations

import pytest
import torch

from physrelight import guided_filter, panorama
from physrelight.parallel import thread_map


@pytest.fixture
def two_threads():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


def test_01_thread_map_gives_the_loops_results_in_order_with_torch_single_threaded_inside(two_threads) -> None:
    items = list(range(7))
    assert thread_map(lambda i: (i * i, torch.get_num_threads()), items) == [(i * i, 1) for i in items]
    assert torch.get_num_threads() == 2  # the caller's setting survives its workers'
    assert thread_map(lambda i: i + 1, items, threads=1) == [i + 1 for i in items]
    assert thread_map(lambda i: i, []) == []


def test_02_an_error_in_one_piece_is_raised_to_the_caller(two_threads) -> None:
    def piece(i: int) -> int:
        if i == 3:
            raise ValueError("piece 3")
        return i

    with pytest.raises(ValueError, match="piece 3"):
        thread_map(piece, range(5))
    assert torch.get_num_threads() == 2


def test_03_the_wide_box_filter_is_the_same_to_the_bit_on_one_thread_and_on_two(two_threads) -> None:
    """The summed-area box filter (:func:`physrelight.window_sums.box_mean`) runs its column pass by strips of columns
    and its row pass by strips of rows on torch's threads; every pixel's sums are made as in one piece."""
    g = torch.Generator().manual_seed(11)
    for shape, radius, dtype in [((1, 3, 600, 701), 42, torch.float32), ((2, 1, 513, 800), 300, torch.float64)]:
        x = torch.randn(*shape, generator=g, dtype=dtype)
        two = guided_filter.box_filter(x, radius)
        torch.set_num_threads(1)
        one = guided_filter.box_filter(x, radius)
        torch.set_num_threads(2)
        assert torch.equal(one, two)


def test_04_a_panorama_view_is_the_same_to_the_bit_on_one_thread_and_on_two(two_threads) -> None:
    """:func:`physrelight.panorama.view` looks its chunks of rows up on torch's threads."""
    g = torch.Generator().manual_seed(12)
    env = torch.rand(32, 64, 3, generator=g) * 5
    K = panorama.view_intrinsics(60.0, 300, 200)
    R = panorama.level_camera(20.0, 10.0)
    for interpolation in panorama.INTERPOLATIONS:
        two = panorama.view(env, K, R, 200, 300, 2, chunk_rays=5000, interpolation=interpolation)
        torch.set_num_threads(1)
        one = panorama.view(env, K, R, 200, 300, 2, chunk_rays=5000, interpolation=interpolation)
        torch.set_num_threads(2)
        assert torch.equal(one, two)
    # one ray per pixel by the B-spline: the compiled loop (panorama._bspline_view), by strips of rows
    two = panorama.view(env, K, R, 200, 300, 1, interpolation="bspline")
    torch.set_num_threads(1)
    one = panorama.view(env, K, R, 200, 300, 1, interpolation="bspline")
    torch.set_num_threads(2)
    assert torch.equal(one, two)


def test_05_single_threaded_runs_torch_on_one_thread_and_restores_the_callers_setting(two_threads) -> None:
    from physrelight.parallel import single_threaded

    with single_threaded():
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == 2
    with pytest.raises(RuntimeError, match="inside"):
        with single_threaded():
            raise RuntimeError("inside")
    assert torch.get_num_threads() == 2


def test_06_strips_cover_the_range_in_order_without_gaps_or_overlaps() -> None:
    """even_strips: ``k`` pieces of near-equal length (fewer when there are fewer items); fixed_strips: pieces of one
    size, the last one shorter, whatever the thread count."""
    from physrelight.parallel import even_strips, fixed_strips

    for n, k in [(10, 3), (2669, 8), (3, 8), (1, 1)]:
        s = even_strips(n, k)
        assert s[0][0] == 0 and s[-1][1] == n and all(a[1] == b[0] for a, b in zip(s, s[1:]))
        assert len(s) == min(n, k) and max(b - a for a, b in s) - min(b - a for a, b in s) <= 1
    assert fixed_strips(300, 128) == [(0, 128), (128, 256), (256, 300)]
    assert fixed_strips(128, 128) == [(0, 128)] and fixed_strips(0, 64) == []
