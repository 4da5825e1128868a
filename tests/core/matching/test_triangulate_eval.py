"""DisparityToGround's compiled evaluation against the polynomials written out over arrays."""

from __future__ import annotations

import numpy as np
import pytest

from core.matching.triangulate import DisparityToGround, _exponents


@pytest.mark.parametrize("degree", [1, 3, 5])
def test_compiled_polynomials_give_the_array_sum_exactly(degree):
    """Same products in the same order as the sum over arrays: the same floats, bit for bit
    (so the DSMs made before the kernel are made again byte for byte)."""
    rng = np.random.default_rng(degree)
    exps = _exponents(degree)
    coef = rng.normal(size=(len(exps), 4)) * 1000.0
    centre, scale = rng.normal(size=3) * 100.0, rng.uniform(50.0, 500.0, 3)
    model = DisparityToGround(centre, scale, exps, coef, 0.0)
    u, v, d = (rng.uniform(-600.0, 600.0, 200_001) for _ in range(3))
    q = [(a - c) / k for a, c, k in zip((u, v, d), centre, scale, strict=True)]
    want = np.zeros((u.size, 4))
    for (i, j, k), c in zip(exps, coef, strict=True):
        pu = np.ones_like(q[0])
        for _ in range(i):
            pu = pu * q[0]
        pv = np.ones_like(q[0])
        for _ in range(j):
            pv = pv * q[1]
        pd = np.ones_like(q[0])
        for _ in range(k):
            pd = pd * q[2]
        want += (pu * pv * pd)[:, None] * c
    got = model(u, v, d)
    for n, name in enumerate(("x_m", "y_m", "h_m", "miss_m")):
        assert np.array_equal(getattr(got, name), want[:, n]), name
    one = model(u[:1], v[:1], d[:1])
    assert one.h_m.shape == (1,) and one.h_m[0] == want[0, 2]
