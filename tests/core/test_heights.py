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


def test_egm2008_and_other_geoids_through_the_one_rule():
    """EGM2008 is learnt from a tag, a CRS's vertical part and a Copernicus name; its heights
    go through the grid given, else PROJ's, else are refused in one line naming --geoid; never
    read as EGM96. A grid given replaces EGM96's, names the geoid of heights nothing else
    describes (or a datum gcpfree does not know), and is refused for ellipsoidal heights."""
    from core.heights import decide_datum

    kw = {"what": "DEM x.tif", "option": "--reference-vertical", "geoid_option": "--geoid"}
    named = ("egm2008", "Copernicus GLO-30 file c.tif: EGM2008")
    for says in ({"tag": "EGM2008 geoid"}, {"crs_vertical_name": "EGM2008 height"},
                 {"named": named}):
        with pytest.raises(InputError, match="give it with --geoid GRID.*never read as EGM96"):
            decide_datum(**kw, **says)
        d = decide_datum(**kw, **says, geoid="/g/egm08.gtx")
        assert (d.datum, d.geoid, d.geoid_source) == ("egm2008", "/g/egm08.gtx", "given: --geoid")
        assert "EGM2008 orthometric heights, converted with h = H + N, N from egm08.gtx" in \
            d.describe()
        d = decide_datum(**kw, **says, proj_grid="/proj/us_nga_egm08_25.tif")
        assert (d.geoid, d.geoid_source) == ("/proj/us_nga_egm08_25.tif", "PROJ's grid")
        assert d.to_dict()["geoid"] == "/proj/us_nga_egm08_25.tif"
        # a command that converts EGM96 only refuses it, saying how to convert it first
        with pytest.raises(InputError, match="prepare-reference --dem-dir DIR --geoid GRID"):
            decide_datum("DEM x.tif", "--dem-vertical", **says, proj_grid="/p.tif")
    # EGM96 keeps the bundled grid unless one is given (today's prepare-reference --geoid)
    d = decide_datum(**kw, srtm_name="N44E005.hgt")
    assert (d.datum, d.geoid) == ("egm96", None) and d.to_dict() == {
        "vertical": "egm96", "vertical_source": "SRTM file N44E005.hgt: EGM96"}
    assert decide_datum(**kw, srtm_name="N44E005.hgt", geoid="/g/e96.tif").geoid == "/g/e96.tif"
    # the grid names the geoid of heights nothing else describes, or of a datum not known
    d = decide_datum(**kw, geoid="/g/national.tif")
    assert (d.datum, d.source) == ("orthometric", "given: --geoid national.tif")
    assert decide_datum(**kw, crs_vertical_name="NAVD88 height", geoid="/g/g18.tif").datum == \
        "orthometric"
    with pytest.raises(InputError, match="NAVD88.*give the geoid grid they refer to with --geoid"):
        decide_datum(**kw, crs_vertical_name="NAVD88 height")
    with pytest.raises(InputError, match="ellipsoidal.*drop --geoid"):
        decide_datum(**kw, tag="WGS84 ellipsoid", geoid="/g/egm08.gtx")
    with pytest.raises(InputError, match="need the geoid grid"):
        from core.heights import DatumDecision

        DatumDecision("egm2008", "tag")
