"""Heights in metres and one datum: units, the EGM96 geoid in between, unit names."""

import numpy as np
import pytest

from core.errors import InputError
from core.geoid import GeoidGrid
from core.heights import Z_UNITS, HeightFrame, height_difference_m, unit_key


def test_height_difference_units_and_datums():
    geoid = GeoidGrid(np.full((3, 3), 48.0), 43.0, 4.0, 1.0, 1.0)  # N = 48 m everywhere
    dem_h = np.array([150.0, 260.0])
    lidar_h_ft = np.array([100.0, 200.0]) / 0.3048  # 100 m, 200 m ellipsoidal, in feet
    same = height_difference_m(dem_h, HeightFrame("ellipsoidal"), lidar_h_ft,
                               HeightFrame("ellipsoidal", 0.3048))
    np.testing.assert_allclose(same, [50.0, 60.0], atol=1e-9)
    lidar_H = np.array([52.0, 152.0])  # EGM96: h = H + 48
    dz = height_difference_m(dem_h, HeightFrame("ellipsoidal"), lidar_H, HeightFrame("egm96"),
                             [5.0, 5.0], [44.0, 44.0], geoid)
    np.testing.assert_allclose(dz, [50.0, 60.0], atol=1e-9)
    dz = height_difference_m(dem_h - 48.0, HeightFrame("egm96"), [100.0, 200.0],
                             HeightFrame("ellipsoidal"), [5.0, 5.0], [44.0, 44.0], geoid)
    np.testing.assert_allclose(dz, [50.0, 60.0], atol=1e-9)
    with pytest.raises(InputError, match="geoid"):
        height_difference_m(dem_h, HeightFrame("egm96"), dem_h, HeightFrame("ellipsoidal"))
    with pytest.raises(InputError, match="datum"):
        HeightFrame("navd88")


def test_unit_names_and_factors():
    assert Z_UNITS["us-ft"] == pytest.approx(0.3048006096012192, rel=1e-15)
    for name, key in (("metre", "m"), ("Meters", "m"), ("foot", "ft"), ("US survey foot", "us-ft"),
                      ("us_survey_foot", "us-ft"), ("ftUS", "us-ft"), ("foot_us", "us-ft")):
        assert unit_key(name, "test") == key
    assert unit_key(None, "test") is None and unit_key("  ", "test") is None
    with pytest.raises(InputError, match="furlong"):
        unit_key("furlong", "DEM band")


def test_the_one_datum_rule_order_and_refusal():
    from core.heights import decide_datum

    kw = {"what": "DEM x.tif", "option": "--dem-vertical"}
    # the option wins over everything the file says
    assert decide_datum(**kw, given="ellipsoidal", tag="EGM96", srtm_name="N44E005.hgt"
                        ).datum == "ellipsoidal"
    # then the tag (gcpfree's own "WGS84 ellipsoid (h = SRTM H + EGM96 N)" is ellipsoidal)
    d = decide_datum(**kw, tag="WGS84 ellipsoid (h = SRTM H + EGM96 N)", crs_datum="egm96",
                     crs_vertical_name="EGM96 height", srtm_name="N44E005.tif")
    assert (d.datum, d.source.startswith("tag")) == ("ellipsoidal", True)
    assert decide_datum(**kw, tag="EGM96 geoid (EPSG:5773), H = h - N").datum == "egm96"
    # then the CRS's vertical part, then an SRTM name
    d = decide_datum(**kw, crs_datum="egm96", crs_vertical_name="EGM96 height",
                     srtm_name=None)
    assert (d.datum, d.source) == ("egm96", "CRS: EGM96 height")
    assert decide_datum(**kw, srtm_name="n44_e005_1arc_v3.tif").datum == "egm96"
    # nothing says it: refused, naming the option, never guessed
    with pytest.raises(InputError, match="--dem-vertical egm96 or --dem-vertical ellipsoidal"):
        decide_datum(**kw)
    with pytest.raises(InputError, match="NAVD88"):
        decide_datum(**kw, crs_datum=None, crs_vertical_name="NAVD88 height")
    with pytest.raises(InputError, match="Normal Null"):
        decide_datum(**kw, tag="Normal Null")
    with pytest.raises(InputError, match="unknown"):
        decide_datum(**kw, given="navd88")
