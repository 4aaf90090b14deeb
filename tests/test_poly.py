"""The one stability test (hystid.poly) against the roots numpy computes."""

from __future__ import annotations

import numpy as np
import pytest

from hystid.poly import KMAX_STABLE, STABILITY_MARGIN, is_stable, roots_inside, schur_stable


def test_schur_cohn_agrees_with_the_roots_of_random_polynomials():
    rng = np.random.default_rng(0)
    for order in range(1, 7):
        for _ in range(200):
            roots = rng.uniform(0.2, 1.3, order) * np.exp(1j * rng.uniform(0, np.pi, order))
            # real polynomial: pair complex roots, keep a real one for odd orders
            pairs = np.r_[roots[: order // 2], roots[: order // 2].conj()]
            real = np.real(roots[order // 2 * 2:]) * rng.choice([-1, 1])
            p = np.real(np.poly(np.r_[pairs, real]))
            radius = np.max(np.abs(np.roots(p)))
            if abs(radius - 1) < 1e-6:
                continue
            assert is_stable(p[1:]) == (radius < 1), (p, radius)
            assert roots_inside(3.0 * p) == (radius < 1)


def test_one_margin_separates_the_circle_from_just_inside():
    assert STABILITY_MARGIN > 0 and KMAX_STABLE == 1 - STABILITY_MARGIN
    inside = np.array([-(1 - 1e-6)])  # a pole at the identifiers' search bound
    on = np.array([-1.0])
    assert schur_stable(inside) and not schur_stable(on)
    assert not is_stable(np.array([np.nan, 0.1])) and is_stable([])
    assert roots_inside([0.0, 2.0, 1.0])  # a leading zero is dropped: 2 + z^-1
    with pytest.raises(ValueError, match="poly"):
        roots_inside([0.0, 0.0])
