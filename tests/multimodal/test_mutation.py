"""Tests written from the mutation run on ``mmconcepts.multimodal``.

Each test kills mutants that the rest of the suite let survive (see /work/notes/mutation13.md):
argument checks whose ``or`` could become ``and``, error messages that must name what is wrong,
and the Fig. 6.3 success rate, whose random draws must follow ``random_state`` and whose value
is checked against the probability worked out by hand.
"""

from __future__ import annotations

import numpy as np
import pytest

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.multimodal import MultimodalNMF, crossmodal_distances, matching_success_rate

pytestmark = pytest.mark.mutation


@pytest.fixture(scope="module")
def fitted():
    rng = np.random.default_rng(7)
    mods = {"sound": rng.random((20, 6)) + 0.1, "motion": rng.random((20, 4)) + 0.1}
    return MultimodalNMF(3, random_state=0, max_iter=20).fit(mods), mods


def test_reconstruct_refuses_a_2d_w_with_the_wrong_number_of_components(fitted):
    model, _ = fitted
    np.testing.assert_allclose(model.reconstruct(np.zeros((2, 3)), "sound"), 0.0)
    with pytest.raises(DataError, match=r"W must be \(n_samples, 3\); got shape \(2, 4\)"):
        model.reconstruct(np.ones((2, 4)), "sound")
    with pytest.raises(DataError, match="W must be"):
        model.reconstruct(np.ones(3), "sound")


def test_crossmodal_distances_names_the_argument_that_is_not_a_mapping(fitted):
    model, mods = fitted
    with pytest.raises(DataError, match="X_test must be a non-empty mapping"):
        crossmodal_distances(model, {}, {"motion": mods["motion"]})
    with pytest.raises(DataError, match="X_ref must be a non-empty mapping"):
        crossmodal_distances(model, {"sound": mods["sound"]}, {})


def test_matching_success_rate_refuses_nan_distances_with_a_message():
    D = np.array([[0.0, np.nan], [1.0, 0.0]])
    with pytest.raises(DataError, match=r"^D contains NaN distances\.$"):
        matching_success_rate(D, ["a", "b"], ["a", "b"])


def test_matching_success_rate_follows_random_state_and_the_probability_by_hand():
    """Two classes; class 'a' has a near and a far reference, class 'b' two at distance 1.

    A test example of class 'a' wins exactly when its drawn 'a' reference is the near one:
    probability 1/2 per draw (by hand), so the rate over 200 x 50 draws is 0.5 +- 0.015 (3 sd).
    The same integer seed must give the same rate; different seeds (almost surely) differ.
    """
    n = 200
    D = np.tile([0.1, 10.0, 1.0, 1.0], (n, 1))
    y_test, y_ref = ["a"] * n, ["a", "a", "b", "b"]
    rates = [matching_success_rate(D, y_test, y_ref, n_draws=50, random_state=s) for s in (0, 1, 2)]
    again = [matching_success_rate(D, y_test, y_ref, n_draws=50, random_state=s) for s in (0, 1, 2)]
    assert rates == again
    assert len(set(rates)) > 1
    for r in rates:
        assert abs(r - 0.5) < 0.015


def test_normalize_none_leaves_every_modality_in_its_own_units():
    rng = np.random.default_rng(3)
    mods = {"sound": 100 * (rng.random((15, 5)) + 0.1), "motion": rng.random((15, 4)) + 0.1}
    model = MultimodalNMF(2, normalize=None, random_state=0, max_iter=10).fit(mods)
    assert model.scales_ == {"sound": 1.0, "motion": 1.0}
    l1 = MultimodalNMF(2, random_state=0, max_iter=10).fit(mods)
    assert l1.scales_["sound"] == pytest.approx(mods["sound"].sum(1).mean())


def test_init_reaches_the_factorization():
    """'random' starts depend on random_state, and 'nndsvd' is another start: after five
    iterations they differ by far more than the ~1e-5 by which the randomized SVD's seed moves
    an SVD-based start."""
    rng = np.random.default_rng(4)
    mods = {"sound": rng.random((30, 8)) + 0.05, "motion": rng.random((30, 6)) + 0.05}

    def comps(**kw):
        return MultimodalNMF(3, max_iter=5, **kw).fit(mods).components_

    def rel(a, b):
        return np.abs(a - b).max() / np.abs(b).max()

    assert rel(comps(init="random", random_state=0), comps(init="random", random_state=1)) > 0.05
    assert rel(comps(init="nndsvd", random_state=0), comps(init="random", random_state=0)) > 0.05


def test_a_custom_init_is_refused_with_the_reason(fitted):
    _, mods = fitted
    with pytest.raises(ParameterError, match="'custom' is not available: MultimodalNMF.fit takes no starting"):
        MultimodalNMF(3, init="custom").fit(mods)
