"""Directions, slopes, Rusinkiewicz coordinates and warps (Eq. 1.2, 1.8, 2.4-2.10)."""
import numpy as np

import microfacet as mf
from microfacet import geometry as g

RNG = np.random.default_rng(11)


def _dirs(n, upper=True):
    w = g.normalize(RNG.normal(size=(n, 3)))
    if upper:
        w[:, 2] = np.abs(w[:, 2])
    return w


def test_spherical_round_trip():
    w = _dirs(1000, upper=False)
    theta, phi = g.cartesian_to_spherical(w)
    np.testing.assert_allclose(g.spherical_to_cartesian(theta, phi), w, atol=1e-15)
    np.testing.assert_allclose(g.spherical_to_cartesian(np.pi / 2, np.pi / 2), [0, 1, 0], atol=1e-16)


def test_slopes_and_normals():
    h = _dirs(1000)
    x, y = g.normal_to_slope(h)
    np.testing.assert_allclose(g.slope_to_normal(x, y), h, atol=1e-12)
    theta, phi = g.cartesian_to_spherical(h)
    np.testing.assert_allclose(x, -np.tan(theta) * np.cos(phi), rtol=1e-9, atol=1e-12)   # Eq. 2.9


def test_rusinkiewicz_round_trip():
    wi, wo = _dirs(1000), _dirs(1000)
    h, d = g.io_to_hd(wi, wo)
    np.testing.assert_allclose(h, g.normalize(wi + wo), atol=1e-15)
    np.testing.assert_allclose(g.dot(d, [0, 0, 1]), g.dot(wi, h), atol=1e-14)   # theta_d
    wi2, wo2 = g.hd_to_io(h, d)
    np.testing.assert_allclose(wi2, wi, atol=1e-13)
    np.testing.assert_allclose(wo2, wo, atol=1e-13)
    _, d_back = g.io_to_hd(wo, wo)            # backscattering: d = z
    np.testing.assert_allclose(d_back, np.broadcast_to([0, 0, 1.0], d_back.shape), atol=1e-14)


def test_reflect_and_frames():
    w, n = _dirs(100), _dirs(100)
    r = g.reflect(w, n)
    np.testing.assert_allclose(g.dot(r, n), g.dot(w, n), atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(r, axis=-1), 1, atol=1e-15)
    n = np.concatenate([_dirs(500, upper=False), [[0, 0, 1.0], [0, 0, -1.0]]])
    s, t = g.orthonormal_basis(n)
    for a, b in [(s, t), (s, n), (t, n)]:
        np.testing.assert_allclose(g.dot(a, b), 0, atol=1e-14)
    np.testing.assert_allclose(np.cross(s, t), n, atol=1e-14)
    v = _dirs(len(n), upper=False)
    np.testing.assert_allclose(g.to_world(g.to_local(v, s, t, n), s, t, n), v, atol=1e-14)


def test_concentric_disk_is_area_preserving_and_cosine_warp_density():
    # uniform on [0,1)^2 -> uniform on the disk: the radius CDF is r^2, the angle uniform
    p = g.square_to_concentric_disk(RNG.random((200_000, 2)))
    r2 = np.sum(p * p, axis=-1)
    assert np.all(r2 <= 1 + 1e-15)
    hist = np.histogram(r2, bins=10, range=(0, 1))[0]
    assert np.all(np.abs(hist / 20_000 - 1) < 0.05)
    w = g.square_to_cosine_hemisphere(RNG.random((200_000, 2)))
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), 1, atol=1e-14)
    # E[cos theta] under the cosine density is 2/3
    assert abs(w[:, 2].mean() - 2 / 3) < 5 * w[:, 2].std() / np.sqrt(len(w))
    assert np.isclose(g.cosine_hemisphere_pdf(np.array([0, 0, 1.0])), 1 / np.pi)
