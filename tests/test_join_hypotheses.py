"""Joining a further hypothesis's components to a model-averaged mixture."""

import warnings

import numpy as np
import pytest

from calibration.choice.averaging import join_hypotheses, mixture_of
from calibration.regression.conjugate import LinearPosterior


def _posterior(orders, rng, log_evidence=0.0):
    n = sum(orders)
    root = rng.normal(size=(n, n)) / n
    return LinearPosterior(
        orders=orders, mean=rng.normal(size=n), scale=root @ root.T + np.eye(n),
        dof=np.inf, log_evidence=log_evidence, noise_variance=1.0, chi2=float(n), n_rows=50,
    )


def _mixture(rng):
    parts = [_posterior((2, 1, 1, 2, 1), rng), _posterior((1, 2, 1, 2, 1), rng)]
    return mixture_of(parts, np.array([0.7, 0.3]), 0.0, 50)


@pytest.mark.parametrize("behind", [5.0, 800.0, 5000.0])
def test_a_hypothesis_far_behind_adds_no_weightless_component(behind):
    """A further hypothesis ``behind`` nats below the mixture weighs exp(-behind) in all.

    Beyond about 745 nats its weight underflows: it then joins with none at all, and
    without a 0/0 (the selection of its components is taken from its own largest).
    """
    rng = np.random.default_rng(3)
    mixture = _mixture(rng)
    others = [_posterior((4, 4, 4, 4, 4), rng) for _ in range(3)]
    log_weights = -behind + np.log(np.array([0.5, 0.3, 0.2]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        joined = join_hypotheses(mixture, 0.0, others, log_weights)
    share = np.exp(-behind) / (1.0 + np.exp(-behind))
    np.testing.assert_allclose(joined.weights[2:].sum(), share, rtol=1e-9, atol=0)
    np.testing.assert_allclose(
        joined.weights[:2], mixture.weights * (1.0 - share), rtol=1e-12, atol=0
    )
    assert np.all(joined.weights > 0)
    assert len(joined.components) == (5 if share > 0 else 2)


def test_the_further_components_keep_their_own_proportions():
    rng = np.random.default_rng(4)
    mixture = _mixture(rng)
    others = [_posterior((3, 3, 3, 3, 3), rng) for _ in range(4)]
    own = np.array([0.4, 0.3, 0.2, 0.1])
    joined = join_hypotheses(mixture, np.log(3.0), others, np.log(own))
    # The mixture's total evidence 3 against the others' 1: shares 3/4 and 1/4.
    np.testing.assert_allclose(joined.weights[:2], 0.75 * mixture.weights, rtol=1e-12)
    np.testing.assert_allclose(joined.weights[2:], 0.25 * own, rtol=1e-12)
