"""The bracketed root search that replaced SciPy's ``brentq`` (``engine/roots.py``)."""

import math

import numpy as np
import pytest

from featurewarp_cli.engine.roots import bracketed_root


def _counted(function):
    calls = []

    def counted(t):
        calls.append(t)
        return function(t)
    return counted, calls


@pytest.mark.parametrize("function, root", [
    (lambda t: math.cos(t) - t, 0.7390851332151607),          # smooth: superlinear
    (lambda t: (t - 0.7) ** 3, 0.7),                          # a flat root
    (lambda t: -1.0 if t < 0.3718 else 2.0, 0.3718),          # a jump: converges on it
    (lambda t: 1.0 - 4.0 * t, 0.25),                          # decreasing
])
def test_the_root_is_within_xtol_in_no_more_evaluations_than_bisection_and_one(function, root):
    counted, calls = _counted(function)
    found = bracketed_root(counted, 0.0, 1.0, xtol=1e-12)
    assert abs(found - root) <= 1e-12
    assert len(calls) <= 2 + math.ceil(math.log2(1.0 / 2e-12)) + 1
    assert all(0.0 <= t <= 1.0 for t in calls)


def test_a_smooth_root_takes_few_evaluations():
    counted, calls = _counted(lambda t: math.cos(t) - t)
    bracketed_root(counted, 0.0, 1.0, xtol=1e-12)
    assert len(calls) <= 12                                    # bisection: 41


def test_one_ulp_moves_the_root_by_rounding_only():
    base = bracketed_root(lambda t: math.exp(t) - 2.0, 0.0, 1.0)
    nudged = bracketed_root(lambda t: math.exp(np.nextafter(t, 2.0)) - 2.0, 0.0, 1.0)
    assert abs(base - math.log(2.0)) <= 1e-12 and abs(nudged - base) <= 4 * np.spacing(base)


def test_a_zero_at_an_end_is_the_root_and_a_bracket_without_a_sign_change_is_refused():
    assert bracketed_root(lambda t: t, 0.0, 1.0) == 0.0
    assert bracketed_root(lambda t: t - 1.0, 0.0, 1.0) == 1.0
    with pytest.raises(ValueError, match="same sign"):
        bracketed_root(lambda t: t + 1.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="low < high"):
        bracketed_root(lambda t: t - 0.5, 1.0, 0.0)


def test_an_infinite_margin_at_the_far_end_is_bisected_to_the_sign_change():
    """Silently: numpy's "invalid value encountered in scalar divide" (inf - inf in the regula
    falsi) reached the user as a warning line (coins, stretch 0.6 x 1.2, rigid)."""
    import warnings

    import numpy as np

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for infinite in (math.inf, np.float64(np.inf)):
            assert abs(bracketed_root(lambda t: -1.0 if t < 0.6 else infinite, 0.0, 1.0) - 0.6) <= 1e-12
