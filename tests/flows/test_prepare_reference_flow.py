"""The prepare-reference flow end to end under a Prefect test harness."""

from pathlib import Path

import pytest
import rasterio

from flows.prepare_reference import ReferenceParams, prepare_reference


def test_flow_writes_cog_png_and_summary(prefect_harness, tmp_path):
    out = tmp_path / "products" / "ref.tif"
    png = tmp_path / "products" / "ref.png"
    s = prepare_reference(ReferenceParams(bbox=(5.2, 44.1, 5.5, 44.3), out=out,
                                          margin_deg=0.01, hillshade_png=png))
    assert Path(s.path) == out and out.exists() and png.stat().st_size > 10_000
    assert s.bbox == pytest.approx((5.19, 44.09, 5.51, 44.31))
    with rasterio.open(out) as src:
        assert (src.width, src.height) == (385, 265)
    # Mont Ventoux (1909 m) is in the box; N is about +50.9 m there
    assert 1880 < s.H_max_m < 1912
    assert 49.5 < s.h_max_m - s.H_max_m < 52.5 and 49.5 < s.h_min_m - s.H_min_m < 52.5
