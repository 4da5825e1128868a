"""The synthetic pushbroom pair the orientation tests share: the delivered models and the truth
(attitude biases and rates added)."""

from __future__ import annotations

import pytest

from tests.core.orientation.test_absolute import models


@pytest.fixture(scope="module")
def pair():
    delivered = models()
    truth = (delivered[0].with_params([1.2e-4, -0.8e-4, 0.5e-4, 1e-6, -2e-6, 0.0]),
             delivered[1].with_params([-0.9e-4, 1.5e-4, -0.7e-4, -2e-6, 1e-6, 0.0]))
    return delivered, truth
