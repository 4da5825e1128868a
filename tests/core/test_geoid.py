import numpy as np
import pyproj
import pytest

from core.errors import InputError
from core.geoid import GeoidGrid
from tasks.io.geoid import EGM96_GTX, load_geoid, read_gtx


@pytest.fixture(scope="module")
def egm96():
    return load_geoid()


@pytest.fixture(scope="module")
def proj_geoid():
    # PROJ interpolating the very same grid file; +multiplier=1 makes z_out = z_in + N
    t = pyproj.Transformer.from_pipeline(
        f"+proj=pipeline +step +proj=vgridshift +grids={EGM96_GTX} +multiplier=1"
    )
    assert "ballpark" not in t.description.lower()
    return t


def test_agrees_with_proj_on_same_grid(egm96, proj_geoid):
    rng = np.random.default_rng(7)
    lon = rng.uniform(-180, 180, 10_000)
    lat = rng.uniform(-89.7, 89.7, 10_000)
    lon[:4] = [-180.0, 179.99, 179.8, -179.9]  # across the antimeridian seam
    ours = egm96.undulation_m(lon, lat)
    _, _, n_proj = proj_geoid.transform(lon, lat, np.zeros_like(lon))
    assert np.isfinite(n_proj).all()
    assert np.abs(ours - n_proj).max() < 0.01


@pytest.mark.parametrize(
    "lon, lat, expected, tol",
    [
        (5.27, 44.17, 50.855667, 1e-4),  # value measured for this grid (STACK.md)
        (0.0, 0.0, 17.16, 0.01),  # EGM96 at the origin
        (78.0, 5.0, -102.0, 3.0),  # Indian Ocean geoid low, about -105 m around 78E 5N
        (147.0, -5.0, 75.0, 6.0),  # New Guinea high, about +80 m
    ],
)
def test_known_egm96_values(egm96, lon, lat, expected, tol):
    assert float(egm96.undulation_m(lon, lat)) == pytest.approx(expected, abs=tol)


def test_longitudes_wrap(egm96):
    assert egm96.undulation_m(365.27, 44.17) == pytest.approx(egm96.undulation_m(5.27, 44.17))
    assert egm96.undulation_m(-180.0, 10.0) == pytest.approx(egm96.undulation_m(180.0, 10.0))


def test_bilinear_is_exact_on_a_plane():
    lat, lon = np.mgrid[0:5, 0:6].astype(float)
    grid = GeoidGrid(2.0 * lon - 3.0 * lat + 1.0, 10.0, 20.0, 1.0, 1.0)
    q_lon, q_lat = np.array([20.3, 24.9, 25.0]), np.array([10.2, 13.7, 14.0])
    exp = 2.0 * (q_lon - 20) - 3.0 * (q_lat - 10) + 1.0
    np.testing.assert_allclose(grid.undulation_m(q_lon, q_lat), exp, atol=1e-12)
    with pytest.raises(InputError, match="outside geoid grid"):
        grid.undulation_m(30.0, 11.0)


def test_truncated_gtx_is_rejected(tmp_path):
    bad = tmp_path / "bad.gtx"
    bad.write_bytes(EGM96_GTX.read_bytes()[:1000])
    with pytest.raises(InputError, match="malformed"):
        read_gtx(bad)
    with pytest.raises(InputError, match="cannot read"):
        read_gtx(tmp_path / "missing.gtx")
