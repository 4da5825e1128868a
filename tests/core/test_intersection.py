import numpy as np
import pytest

from core.errors import InputError
from core.geodesy import ecef_to_geodetic, geodetic_to_ecef
from core.intersection import intersect_rays, intersect_two_rays, triangulate


def test_two_rays_known_skew_lines():
    # ray 1 along x through the origin; ray 2 along y through (0, 0, 2)
    r = intersect_two_rays([[5, 0, 0]], [[1, 0, 0]], [[0, 3, 2]], [[0, -2, 0]])
    np.testing.assert_allclose(r.point_ecef, [[0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(r.miss_m, [2.0], atol=1e-12)
    np.testing.assert_allclose(r.s_m, [-5.0])
    np.testing.assert_allclose(r.t_m, [3.0])


def test_two_rays_random_against_brute_force():
    rng = np.random.default_rng(3)
    o1, o2 = rng.normal(size=(200, 3)) * 1e3, rng.normal(size=(200, 3)) * 1e3
    d1, d2 = rng.normal(size=(200, 3)), rng.normal(size=(200, 3))
    r = intersect_two_rays(o1, d1, o2, d2)
    u1 = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    u2 = d2 / np.linalg.norm(d2, axis=1, keepdims=True)
    p1 = o1 + r.s_m[:, None] * u1
    p2 = o2 + r.t_m[:, None] * u2
    # the connecting segment is perpendicular to both rays
    seg = p2 - p1
    assert np.abs(np.einsum("ij,ij->i", seg, u1)).max() < 1e-8
    assert np.abs(np.einsum("ij,ij->i", seg, u2)).max() < 1e-8
    np.testing.assert_allclose(r.miss_m, np.linalg.norm(seg, axis=1), rtol=1e-10)


def test_parallel_rays_flagged():
    r = intersect_two_rays([[0, 0, 0]], [[1, 0, 0]], [[0, 4, 3]], [[2, 0, 0]])
    assert np.isnan(r.point_ecef).all()
    assert r.miss_m[0] == pytest.approx(5.0)


def test_multi_ray_recovers_point_and_matches_two_ray():
    rng = np.random.default_rng(5)
    x = rng.normal(size=(50, 3)) * 100
    d = rng.normal(size=(50, 4, 3))
    o = x[:, None, :] - 1e3 * d
    res = intersect_rays(o, d)
    np.testing.assert_allclose(res.point_ecef, x, atol=1e-8)
    assert res.rms_m.max() < 1e-8
    o2 = o.copy()
    o2[:, 2:, :] = np.nan  # only two valid rays: equals the midpoint rule
    o2[:, 1, :] += rng.normal(size=(50, 3))
    two = intersect_two_rays(o2[:, 0], d[:, 0], o2[:, 1], d[:, 1])
    res2 = intersect_rays(o2, d)
    np.testing.assert_allclose(res2.point_ecef, two.point_ecef, atol=1e-8)
    np.testing.assert_allclose(res2.rms_m, two.miss_m / 2, rtol=1e-8)
    assert (res2.n_rays == 2).all()


def test_multi_ray_bad_shape():
    with pytest.raises(InputError):
        intersect_rays(np.zeros((3, 3)), np.zeros((3, 3)))


class PinholeOnEllipsoid:
    """A tiny frame camera (straight rays) to test triangulate independently of real sensors."""

    def __init__(self, centre_ecef, look_at_ecef, f_px=1e4):
        self.c = np.asarray(centre_ecef, float)
        z = np.asarray(look_at_ecef, float) - self.c
        z /= np.linalg.norm(z)
        x = np.cross(z, [0, 0, 1.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        self.r = np.stack([x, y, z])
        self.f = f_px

    def project(self, lon, lat, h):
        p = np.stack(geodetic_to_ecef(lon, lat, h), axis=-1) - self.c
        q = p @ self.r.T
        return self.f * q[..., 0] / q[..., 2], self.f * q[..., 1] / q[..., 2]

    def localize(self, col, row, h):
        d = np.stack([col / self.f, row / self.f, np.ones_like(col)], axis=-1) @ self.r
        lon = np.empty(np.shape(col))
        lat = np.empty(np.shape(col))
        flat_d = d.reshape(-1, 3)
        hh = np.broadcast_to(h, np.shape(col)).ravel()
        # march along the ray to the height h with Newton on the geodetic height
        t = np.full(flat_d.shape[0], 8e5)
        for _ in range(50):
            p = self.c + t[:, None] * flat_d
            _, _, hp = ecef_to_geodetic(*p.T)
            p2 = self.c + (t[:, None] + 1.0) * flat_d
            _, _, hp2 = ecef_to_geodetic(*p2.T)
            t = t - (hp - hh) / (hp2 - hp)
        lo, la, _ = ecef_to_geodetic(*(self.c + t[:, None] * flat_d).T)
        lon.flat[:], lat.flat[:] = lo, la
        return lon, lat

    params = np.zeros(0)

    def with_params(self, p):
        return self


def test_triangulate_through_two_models_recovers_ground_truth():
    target = np.array(geodetic_to_ecef(5.3, 44.2, 800.0))
    up = target / np.linalg.norm(target)
    east = np.cross([0, 0, 1.0], up)
    east /= np.linalg.norm(east)
    m1 = PinholeOnEllipsoid(target + 8e5 * up + 3e5 * east, target)
    m2 = PinholeOnEllipsoid(target + 8e5 * up - 3e5 * east, target)
    rng = np.random.default_rng(9)
    lon = 5.3 + rng.uniform(-0.05, 0.05, 30)
    lat = 44.2 + rng.uniform(-0.05, 0.05, 30)
    h = rng.uniform(100, 2000, 30)
    c1, r1 = m1.project(lon, lat, h)
    c2, r2 = m2.project(lon, lat, h)
    tri = triangulate([m1, m2], [c1, c2], [r1, r2], (0.0, 3000.0))
    np.testing.assert_allclose(tri.lon_deg, lon, atol=1e-9)
    np.testing.assert_allclose(tri.lat_deg, lat, atol=1e-9)
    np.testing.assert_allclose(tri.h_m, h, atol=1e-3)
    assert tri.miss_m.max() < 1e-3
    # an image error breaks the intersection: the miss distance is linear in its size
    m_a = triangulate([m1, m2], [c1 + 0.5, c2], [r1 + 0.5, r2], (0.0, 3000.0)).miss_m
    m_b = triangulate([m1, m2], [c1 + 1.0, c2], [r1 + 1.0, r2], (0.0, 3000.0)).miss_m
    assert m_a.min() > 1.0
    np.testing.assert_allclose(m_b / m_a, 2.0, rtol=1e-3)
