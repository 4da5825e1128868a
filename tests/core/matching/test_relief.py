"""The relief verdict: the noise a window's correlation reveals takes part in it, and a refusal
names its true reason with its figures, never NaN."""

from __future__ import annotations

from dataclasses import replace

import pytest

from core.matching.relief import realistic_precision_m, relief_sufficiency
from core.matching.surface import SurfaceMatchConfig, WindowMatch, WindowStatus


def test_measured_noise_takes_part_in_the_relief_verdict():
    """A window promising 4 m with SRTM's nominal 5 m of noise whose surfaces correlate at
    only 0.5 over 25 m of relief carries 25 m of noise (rho = r^2 / (r^2 + n^2)): it
    promises 20 m, and on terrain this flat the noise decides."""
    cfg = SurfaceMatchConfig(max_precision_m=10.0, height_noise_m=5.0)
    noisy = WindowMatch(WindowStatus.LOW_CORRELATION, relief_m=25.0, predicted_precision_m=4.0,
                        correlation=0.5, n_cells=900, masked_share=0.0)
    assert realistic_precision_m(noisy, cfg) == pytest.approx(20.0)
    verdict = relief_sufficiency([noisy] * 9, cfg, 3)
    assert not verdict.enough and verdict.n_qualified == 0
    assert verdict.relief_needed_m == pytest.approx(25.0 * 20.0 / 10.0)
    # rho 0.99 over 25 m: 2.5 m of noise, under the nominal 5 m: the nominal stays
    clean = replace(noisy, correlation=0.99)
    assert realistic_precision_m(clean, cfg) == pytest.approx(4.0)
    assert relief_sufficiency([clean] * 9, cfg, 3).enough
    unmatched = replace(noisy, correlation=float("nan"))  # refused before matching: nominal
    assert realistic_precision_m(unmatched, cfg) == pytest.approx(4.0)


def test_a_refusal_names_its_true_reason_never_nan():
    """Too small, reference voids, too few windows and too flat are told apart, each with its
    figures (issue 17 item 5: a 250 m crop was refused as 'too flat ... needed about nan m')."""
    cfg = SurfaceMatchConfig(max_precision_m=10.0)
    # a 250 m crop: each 4 km window holds a dozen 90 m cells of the relative DEM
    tiny = [WindowMatch(WindowStatus.TOO_FEW_CELLS, relief_m=0.0, n_cells=12, n_dem_cells=12,
                        masked_share=0.998) for _ in range(4)]
    v = relief_sufficiency(tiny, cfg, 8, cell_m=90.0)
    assert v.reason == "too_small" and v.best_dem_cells == 12
    msg = v.message()
    assert "too small" in msg and "12 cells" in msg and "100 are needed" in msg
    assert "flat" not in msg and "nan" not in msg.lower()
    # the relative DEM fills the windows, the reference has voids there
    holes = [replace(w, n_dem_cells=3000, n_cells=40) for w in tiny]
    holes += [replace(w, status=WindowStatus.MASKED, n_dem_cells=3000, n_cells=900)
              for w in tiny]
    v = relief_sufficiency(holes, cfg, 8, cell_m=90.0)
    assert v.reason == "voids" and v.n_voids == 8 and "voids" in v.message()
    # every window judged has the relief, but only 4 fit in the scene
    good = [WindowMatch(WindowStatus.OK, relief_m=80.0, predicted_precision_m=3.0,
                        correlation=0.97, n_cells=2000, n_dem_cells=2000, masked_share=0.0)
            for _ in range(4)]
    v = relief_sufficiency(good, cfg, 8, cell_m=90.0)
    assert v.reason == "few_windows" and "4 placed" in v.message()
    assert "--min-windows" in v.message()
    # one marginal window among them does not make the scene flat: 4 could never give 8
    marginal = replace(good[0], correlation=0.5, relief_m=25.0)
    v = relief_sufficiency([*good[:3], marginal], cfg, 8, cell_m=90.0)
    assert v.n_qualified == 3 and v.reason == "few_windows" and "flat" not in v.message()
    # flat windows with no slope at all: found and needed said without NaN
    flat = [WindowMatch(WindowStatus.LOW_RELIEF, relief_m=0.5, predicted_precision_m=float("inf"),
                        n_cells=2000, n_dem_cells=2000, masked_share=0.0) for _ in range(9)]
    v = relief_sufficiency(flat, cfg, 8, cell_m=90.0)
    assert v.reason == "too_flat" and "relief found 0.5 m" in v.message()
    assert "nan" not in v.message().lower() and "no window has a slope" in v.message()
    assert v.to_dict()["relief_needed_m"] is None and v.to_dict()["reason"] == "too_flat"
    # enough: no reason
    assert relief_sufficiency(good * 2, cfg, 8).reason is None
