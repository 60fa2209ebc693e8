"""The cache of freed output arrays (:mod:`microfacet._buffers`)."""
import gc

import numpy as np
import pytest

import microfacet as mf
from microfacet import _buffers, kernels, protocol

BIG = (1 << 18, 3)                       # 6 MiB of float64: from the cache


def _address(a):
    return a.__array_interface__["data"][0]


@pytest.fixture(autouse=True)
def _empty_cache():
    gc.collect()            # else earlier tests' garbage, collected mid-test, returns its outputs to the cache
    kernels.release_outputs()
    yield
    kernels.release_outputs()


def test_a_freed_output_is_reused_and_a_live_view_keeps_its_memory():
    a = protocol.output(None, BIG, np.float64)
    assert a.shape == BIG and a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable
    where = _address(a)
    view = a[10:]
    del a
    gc.collect()
    b = protocol.output(None, BIG, np.float64)             # the view still holds the first buffer
    where_b, size = _address(b), BIG[0] * BIG[1] * 8
    assert where_b != where and _buffers._cache.kept == 0
    view[:] = 1.0
    b[:] = 2.0
    assert np.all(view == 1.0)
    del view, b
    gc.collect()
    assert _buffers._cache.kept == 2 * size
    c = protocol.output(None, BIG, np.float64)             # one of the two, the other waits
    assert _address(c) in (where, where_b) and _buffers._cache.kept == size
    assert kernels.release_outputs() == size and _buffers._cache.kept == 0


def test_small_outputs_and_a_cache_turned_off_are_plain_arrays(monkeypatch):
    assert protocol.output(None, (100, 3), np.float64).flags.owndata
    monkeypatch.setattr(_buffers._cache, "limit", 0)
    assert protocol.output(None, BIG, np.float32).flags.owndata


def test_the_cache_keeps_at_most_its_limit():
    cache = _buffers._Cache(limit=3 << 20)
    for size in (1 << 20, 1 << 20, 2 << 20, 8 << 20):     # the last one alone exceeds the limit
        cache.give(np.empty(size, np.uint8))
    assert cache.kept <= 3 << 20 and cache.take(8 << 20) is None
    assert cache.take(2 << 20) is not None or cache.take(1 << 20) is not None


def test_results_into_reused_outputs_equal_those_into_passed_ones():
    rng = np.random.default_rng(3)
    n = 1 << 17
    u = rng.random((n, 2))
    wo = mf.geometry.spherical_to_cartesian(np.arccos(rng.random(n)), 2 * np.pi * rng.random(n))
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.4), fresnel=mf.fresnel.Conductor.metal("Au"))
    out = tuple(np.empty(s) for s in ((n, 3), (n, 3), (n,)))
    ref = brdf.sample(u, wo, out=out)
    for _ in range(3):                                      # fresh, then reused buffers
        got = brdf.sample(u, wo)
        for a, b in zip(got, ref):
            np.testing.assert_array_equal(a, b)
        del got
        gc.collect()


def test_a_bad_cache_size_is_named(monkeypatch):
    monkeypatch.setenv("MICROFACET_OUTPUT_CACHE_MB", "lots")
    with pytest.raises(ValueError, match="MICROFACET_OUTPUT_CACHE_MB"):
        _buffers._limit()
    for bad in ("-1", "nan", "inf"):
        monkeypatch.setenv("MICROFACET_OUTPUT_CACHE_MB", bad)
        with pytest.raises(ValueError, match="MICROFACET_OUTPUT_CACHE_MB"):
            _buffers._limit()
    monkeypatch.setenv("MICROFACET_OUTPUT_CACHE_MB", "0.5")
    assert _buffers._limit() == 1 << 19
