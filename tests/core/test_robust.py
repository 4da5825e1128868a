"""The project's one robust toolbox: the NMAD is a normal sample's sigma and ignores a minority
of outliers, Huber weights down-weight beyond k, the shared adjustment settings check
themselves, and the robust fit finds the dominant population's level under a canopy."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from core.orientation.absolute import AbsoluteConfig
from core.orientation.relative import RelativeConfig
from core.robust import NMAD_FACTOR, RobustAdjustment, huber_weights, nmad, robust_fit


def test_nmad_is_sigma_and_ignores_outliers():
    rng = np.random.default_rng(0)
    x = rng.normal(3.0, 2.0, 200_000)
    assert nmad(x) == pytest.approx(2.0, rel=0.01)
    x[:40_000] = 1e6  # a fifth of blunders
    assert nmad(x) < 3.0
    assert nmad([1.0, 2.0, 4.0], centre=0.0) == pytest.approx(NMAD_FACTOR * 2.0)
    assert np.isnan(nmad([]))


def test_huber_weights():
    np.testing.assert_allclose(huber_weights([0.0, -1.0, 2.0, -4.0], 2.0), [1, 1, 1, 0.5])


def test_the_adjustments_share_one_checked_set_of_settings():
    assert isinstance(RelativeConfig(), RobustAdjustment)
    assert (AbsoluteConfig().huber_k, RelativeConfig().huber_k) == (2.0, 1.5)
    for bad in ({"huber_k": 0.0}, {"reject_k": 1.0}, {"tol_px": 0.0}, {"max_iterations": 0}):
        with pytest.raises(InputError):
            RelativeConfig(**bad)
        with pytest.raises(InputError):
            AbsoluteConfig(**bad)


def test_robust_fit_takes_the_dominant_mode():
    """Ground under trees on a third of the window: the Huber fit is pulled towards the
    canopy, the mode-seeking fit keeps the ground's level and spread."""
    rng = np.random.default_rng(1)
    d = rng.normal(0.0, 1.0, 3000)
    d[:1000] += 17.5
    basis = np.ones((d.size, 1))
    huber, _ = robust_fit(d, basis)
    mode, spread = robust_fit(d, basis, mode_scale_m=5.0)
    assert huber[0] > 1.0 and abs(mode[0]) < 0.1 and spread == pytest.approx(1.0, rel=0.1)
