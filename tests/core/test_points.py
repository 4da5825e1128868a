"""Check points as values: the JSON layout the simulator documents, round trips, bad input."""

import json

import pytest

from core.errors import InputError
from core.points import CheckPoint, CheckPointSet, GeoPoint, ImagePoint


def sample_set() -> CheckPointSet:
    pts = tuple(
        CheckPoint(id=i + 1, lon_deg=5.2 + i * 1e-3, lat_deg=44.1, h_m=612.345678901 + i,
                   H_egm96_m=561.5 + i, x_m=664_300.25, y_m=4_911_700.5, land_cover="bare_soil",
                   image_points={"left": ImagePoint(10.25 + i, 20.5),
                                 "right": ImagePoint(30.0, 40.125)})
        for i in range(3))
    return CheckPointSet("EPSG:32631", ("left", "right"), pts)


def test_layout_is_the_documented_one():
    d = sample_set().to_dict()
    assert list(d) == ["crs", "heights", "image_coordinates", "images", "points"]
    p = d["points"][0]
    assert list(p) == ["id", "lon_deg", "lat_deg", "h_m", "H_egm96_m", "x_m", "y_m",
                       "land_cover", "left", "right"]
    assert p["left"] == {"col": 10.25, "row": 20.5}


def test_json_round_trip_is_exact():
    s = sample_set()
    text = json.dumps(s.to_dict())
    back = CheckPointSet.from_dict(json.loads(text))
    assert back == s and json.dumps(back.to_dict()) == text


def test_bad_records_name_the_problem():
    d = sample_set().to_dict()
    del d["points"][1]["right"]
    with pytest.raises(InputError, match="right"):
        CheckPointSet.from_dict(d)
    with pytest.raises(InputError, match="images"):
        CheckPointSet.from_dict({"crs": "EPSG:4326", "points": []})
    with pytest.raises(InputError, match="lon_deg, lat_deg, h_m"):
        GeoPoint.from_list([1.0, 2.0])


def test_control_points_round_trip():
    from core.points import ControlPoint, GcpSet, control_points_to_dict
    from tasks.io.products import GCPS

    pts = tuple(ControlPoint(i, 5.2 + i * 1e-3, 44.1, 812.5 + i,
                             {"left": ImagePoint(10.5, 20.25), "right": ImagePoint(30.0, 41.0)},
                             2.5, 1.25, "srtm_surface_match",
                             {"correlation": 0.97, "relief_m": 120.0, "status": "OK"})
                for i in range(3))
    text = json.dumps(control_points_to_dict(pts))
    back = GCPS.load(json.loads(text)).points
    assert back == pts and json.dumps(GCPS.dump(GcpSet(points=back))) == text
    with pytest.raises(InputError, match="gcps.json"):
        GCPS.load({"points": [{"id": 1}]})
