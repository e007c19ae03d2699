"""Property tests (hypothesis) of the NMF core's invariants.

Hoyer's projection (thesis eq. 2.20; Hoyer 2004, Fig. 1) gives a nonnegative vector with
the target L1 and L2 norms, hence the target sparseness, and is idempotent; the
multiplicative updates with the MM exponent never increase the beta-divergence
(Fevotte & Idier 2011), for any beta, with or without a mask. ``NMF.from_params`` gives NMF's
defaults, overridden by the owner's NMF parameters, overridden by the explicit overrides.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from mmconcepts.nmf import NMF, LabelNMF, beta_nmf, hoyer_sparseness, project_hoyer
from mmconcepts.nmf._beta import resolve_beta
from mmconcepts.nmf._coefficients import determined_rows
from mmconcepts.nmf.sparseness import l1_for_sparseness

pytestmark = pytest.mark.property

_SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# entries 0 or of magnitude 1e-6 to 50: squares of ~1e-160 underflow, and the L2 norm with them
_entries = st.one_of(st.just(0.0), st.floats(1e-6, 50.0), st.floats(-50.0, -1e-6))
vectors = st.integers(2, 40).flatmap(lambda n: arrays(np.float64, n, elements=_entries))


@_SETTINGS
@given(x=vectors, sparseness=st.floats(0.01, 0.95), l2=st.floats(0.1, 10.0))
def test_hoyer_projection_has_the_target_norms_and_sparseness(x, sparseness, l2):
    n = x.size
    l1 = l1_for_sparseness(sparseness, n, l2)
    p = project_hoyer(x, l1, l2)
    assert p.shape == (n,)
    assert (p >= 0).all()
    np.testing.assert_allclose(p.sum(), l1, rtol=1e-8)
    np.testing.assert_allclose(np.linalg.norm(p), l2, rtol=1e-8)
    np.testing.assert_allclose(hoyer_sparseness(p), sparseness, atol=1e-7)


@_SETTINGS
@given(x=vectors, sparseness=st.floats(0.01, 0.95), l2=st.floats(0.1, 10.0))
# found by hypothesis: x nearly constant once its negative entry is zeroed, so the last step is long and scaled
# the rounding of the step's sum into the L1 norm
@example(x=np.array([0.0, -11.0] + [1e-6] * 37), sparseness=0.015625, l2=1.0)
def test_hoyer_projection_is_idempotent(x, sparseness, l2):
    l1 = l1_for_sparseness(sparseness, x.size, l2)
    p = project_hoyer(x, l1, l2)
    np.testing.assert_allclose(project_hoyer(p, l1, l2), p, atol=1e-8 * l2)


@_SETTINGS
@given(x=vectors, l2=st.floats(0.1, 10.0))
def test_hoyer_projection_at_sparseness_zero_is_the_constant_vector(x, l2):
    """Sparseness 0: the only feasible vector is constant (returned directly: the general
    step would reach it through the root of a quadratic whose constant term is a rounding
    error, with sqrt(eps) accuracy)."""
    p = project_hoyer(x, l1_for_sparseness(0.0, x.size, l2), l2)
    np.testing.assert_allclose(p, l2 / np.sqrt(x.size), rtol=1e-12)


@_SETTINGS
@given(x=vectors, scale=st.floats(0.01, 100.0), seed=st.integers(0, 2**32 - 1))
def test_hoyer_sparseness_ignores_scale_and_order(x, scale, seed):
    if not np.any(x):
        x = x + 1.0
    s = hoyer_sparseness(x)
    assert -1e-12 <= s <= 1 + 1e-12
    perm = np.random.default_rng(seed).permutation(x.size)
    np.testing.assert_allclose(hoyer_sparseness(scale * x[perm]), s, atol=1e-12)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    # beta within ~1e-6 of 0 or 1 is left out: the divergence's closed form divides by
    # beta (beta - 1) and loses every digit there (the updates are fine, the loss values are not)
    beta=st.one_of(st.sampled_from([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]), st.floats(0.01, 0.99), st.floats(1.01, 3.0)),
    n=st.integers(3, 12),
    m=st.integers(3, 12),
    k=st.integers(1, 4),
    masked=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_multiplicative_updates_never_increase_the_beta_divergence(beta, n, m, k, masked, seed):
    rng = np.random.default_rng(seed)
    X = rng.gamma(1.0, 1.0, (n, m)) + 0.01  # positive: beta <= 1 is defined everywhere
    mask = rng.random((n, m)) < 0.7 if masked else None
    res = beta_nmf(X, k, beta_loss=beta, init="random", random_state=int(rng.integers(2**31)), max_iter=30,
                   tol=0, loss_every=1, mask=mask)
    h = np.asarray(res.loss_history)
    assert np.isfinite(h).all()
    assert np.diff(h).max() <= 1e-9 * h[0]


@pytest.mark.parametrize("value, l2", [(-46.16003937, 0.1), (-50.0, 0.1015625), (3.0, 1.0), (1e-300, 1.0)])
def test_hoyer_projection_of_a_constant_vector(value, l2):
    """Found by hypothesis in CI: a constant vector was projected to the constant (sparseness 0, not the
    target) or to nothing (ZeroDivisionError), depending on the rounding noise of x - mean(x)."""
    x = np.full(21, value)
    l1 = l1_for_sparseness(0.5, 21, l2)
    p = project_hoyer(x, l1, l2)
    assert (p >= 0).all() and np.isclose(p.sum(), l1) and np.isclose(np.linalg.norm(p), l2)
    np.testing.assert_allclose(project_hoyer(p, l1, l2), p, atol=1e-8 * l2)


# ----------------------------------------------------------------------------- NMF.from_params

_NMF_NAMES = sorted(NMF().get_params())
_values = st.one_of(st.none(), st.integers(-5, 500), st.sampled_from(["mu", "kullback-leibler", "nndsvda", "same"]),
                    st.floats(0.0, 3.0))


class _Owner:
    def __init__(self, params):
        self.params = params

    def get_params(self, deep=True):
        return dict(self.params)


@_SETTINGS
@given(shared=st.dictionaries(st.sampled_from(_NMF_NAMES), _values),
       others=st.dictionaries(st.text("abcxyz_", min_size=1, max_size=8).filter(lambda n: n not in _NMF_NAMES),
                              _values),
       overrides=st.dictionaries(st.sampled_from(_NMF_NAMES), _values, max_size=4))
def test_from_params_is_nmfs_defaults_then_the_owners_nmf_parameters_then_the_overrides(shared, others, overrides):
    nmf = NMF.from_params(_Owner({**others, **shared}), **overrides)
    assert nmf.get_params() == {**NMF().get_params(), **shared, **overrides}


@_SETTINGS
@given(data=st.data())
def test_every_label_nmf_parameter_value_reaches_the_nmf_it_builds(data):
    """Valid values of each parameter LabelNMF shares with NMF, set on a LabelNMF, are the built NMF's."""
    choices = {
        "n_components": st.integers(1, 300), "beta_loss": st.one_of(st.floats(0.01, 3.0), st.sampled_from(
            ["frobenius", "kullback-leibler", "itakura-saito"])), "max_iter": st.integers(0, 1000),
        "tol": st.floats(0.0, 1.0), "init": st.sampled_from([None, "random", "nndsvd", "nndsvda", "nndsvdar"]),
        "solver": st.sampled_from(["mu", "pg"]), "update_rule": st.sampled_from(["mm", "heuristic"]),
        "transform_max_iter": st.one_of(st.none(), st.integers(0, 1000)), "random_state": st.integers(0, 2**31 - 1),
    }
    values = {name: data.draw(strategy, label=name) for name, strategy in choices.items()}
    assert set(values) == set(LabelNMF().get_params()) & set(_NMF_NAMES)
    owner = LabelNMF(label_weight=3.0, threshold=0.2, cv=4, n_jobs=2).set_params(**values)
    got = NMF.from_params(owner).get_params()
    assert {name: got[name] for name in values} == values
    assert {k: v for k, v in got.items() if k not in values} == {k: v for k, v in NMF().get_params().items()
                                                                    if k not in values}


# ----------------------------------------------------------------------------- transform and fit_transform


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    n=st.integers(2, 100),
    m=st.integers(2, 50),
    k=st.one_of(st.none(), st.integers(1, 8)),
    beta=st.sampled_from(["frobenius", 1.0, 1.5, 2.0]),
    zeros=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
# found by hypothesis: products near 0 at an x > 0, left by the fit or by a projected step (the refusal of a
# collapsing step), a flat minimum met to the tolerance far from its optimum (the last Newton steps)
@example(n=2, m=31, k=None, beta=1.5, zeros=False, seed=22677)
@example(n=33, m=31, k=6, beta=1.0, zeros=True, seed=420)
@example(n=100, m=19, k=8, beta=1.0, zeros=True, seed=2007873)  # a coefficient 22 orders below its optimum
@example(n=70, m=50, k=None, beta="frobenius", zeros=True, seed=481575569)  # held coefficients at beta = 2
@example(n=2, m=2, k=None, beta=1.5, zeros=False, seed=599418)
# found by hypothesis: a row of a square dictionary (41 atoms, 41 features) that stopped at max_iter, 1.4e-5 from
# fit_transform's coefficient. From its fourth Newton step it alternated: one coefficient near zero, held, was lifted
# by its own gradient step while the free ones were solved for it where it was; at the next step they pushed it back
# down, and were solved for it where it had been lifted to
@example(n=100, m=41, k=None, beta=1.5, zeros=False, seed=100000)
def test_fit_transform_is_fit_then_transform(n, m, k, beta, zeros, seed):
    """The scikit-learn contract, for random data of any shape: fit_transform(X) equals
    fit(X).transform(X) to 1e-6 of W's scale wherever the problem in W has one minimiser
    (1 <= beta <= 2: it is convex, and both reach it), which is every row of data without zeros
    and with no more atoms than features. Under the I-divergence, a row with fewer nonzero values
    than atoms has directions without curvature, along which the objective is linear: its minimum
    is flat, and is left out. For 1 < beta < 2, without zeros in X: where x = 0 the curvature is
    infinite at w H = 0, and the steps can stop about 1e-3 short of the minimum."""
    rng = np.random.default_rng(seed)
    X = rng.gamma(0.5, 1.0, (n, m))
    if zeros and beta != 1.5:
        X[rng.random((n, m)) < 0.5] = 0.0
    model = NMF(k, beta_loss=beta, random_state=int(rng.integers(2**31)), max_iter=100)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's own ConvergenceWarning at max_iter
        W = model.fit_transform(X)
        again = model.fit(X).transform(X)
    H = model.components_
    live = H.sum(axis=0) > 0
    one = determined_rows(X[:, live], H[:, live], resolve_beta(beta))
    assert one.all() or zeros or (k or 0) > min(n, m)  # more atoms than samples or features: a set of minimisers
    if resolve_beta(beta) == 1.0:  # fewer nonzero values than atoms: flat directions (the objective is linear)
        one &= np.count_nonzero(X[:, live], axis=1) >= H.shape[0]
    assert np.abs(W - again)[one].max(initial=0.0) <= 1e-6 * max(np.abs(W).max(), 1e-12)


@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="not solved: a coefficient held by Bertsekas' eps, wide where the row's coefficients span 1e7, "
                          "creeps to its optimum by its scaled gradient")
def test_a_row_whose_coefficients_span_seven_orders_reaches_its_minimum():
    """Found by a fuzz of the solve (a review): beta = 1.75, a mask, 14 nearly collinear atoms whose rows are scaled
    by 1e-8 to 2. The row's coefficients span 0.06 to 1.1e7, so the eps that holds coefficients near zero (a tenth
    of the largest, or the largest scaled-gradient move) holds coefficient 2 at 0.35, far above its optimum 0.058:
    it creeps down by its scaled gradient, about 2 % per step, and the row stops at max_iter 1.4e-4 above its
    minimum. The solve before the free ones were solved where the held ones land converged in 15 steps: its held
    set alternated, which released the coefficient."""
    from pathlib import Path

    from mmconcepts.nmf._beta import elementwise_beta_divergence
    from mmconcepts.nmf._coefficients import solve_coefficients

    case = np.load(Path(__file__).resolve().parents[1] / "data" / "solver_cases" / "held_by_a_wide_row.npz")
    x, mask, w0, H = case["x"], case["mask"], case["w0"], case["H"]

    def objective(w):
        return float((elementwise_beta_divergence(x, w @ H, 1.75) * mask).sum())

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reference, _ = solve_coefficients(x, H, w0, 1.75, mask=mask, max_iter=1000, tol=1e-12)
        w, converged = solve_coefficients(x, H, w0, 1.75, mask=mask)
    assert converged
    assert objective(w) <= objective(reference) * (1 + 1e-9)


def test_a_row_started_far_from_its_minimum_is_not_declared_optimal_outside_tol():
    """The case hypothesis found for the property below (m = k = 4, beta = 1, a start 10^3.3 times the minimum, seed
    4): row 2's last full Newton step is short (1.1e-7 of its largest coefficient) but also zeroes its held
    coefficients, which moves the free one's minimum; taken as done there, it stopped with its factor num / den at
    1 + 1.16e-7 and ``converged`` True. A short step must be confirmed optimal where it lands."""
    from mmconcepts.nmf._coefficients import solve_coefficients

    rng = np.random.default_rng(4)
    H = rng.gamma(0.5, 1.0, (4, 4)) + 0.01
    X = rng.gamma(0.5, 1.0, (4, 4)) + 0.01
    want, _ = solve_coefficients(X, H, np.ones((4, 4)), 1.0)
    W, converged = solve_coefficients(X, H, want * 10.0**3.3355768150940284 + rng.random(want.shape), 1.0)
    factor = ((X / (W @ H)) @ H.T) / H.sum(axis=1)
    free = W > 1e-7 * W.max(axis=1, keepdims=True)
    assert not converged or np.abs(factor - 1.0)[free].max() <= 1e-7


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    m=st.integers(2, 6),
    k=st.integers(1, 6),
    beta=st.sampled_from([1.0, 1.5, 2.0]),
    log_scale=st.floats(-3.0, 4.0),
    seed=st.integers(0, 2**32 - 1),
)
@example(m=2, k=2, beta=1.5, log_scale=0.0, seed=0)  # a step that collapses a product at an x > 0 (found by hypothesis)
def test_newton_steps_reach_each_rows_minimum_from_any_start(m, k, beta, log_scale, seed):
    """Small problems (k <= m atoms, positive data, atoms far from collinear), starts from 1e-3 to 1e4
    times the minimum: the
    projected Newton steps with their Armijo search converge to the same coefficients as from a flat
    start, and for beta = 2 to scipy's NNLS."""
    from scipy.optimize import nnls

    from mmconcepts.nmf._coefficients import solve_coefficients

    assume(k <= m)
    rng = np.random.default_rng(seed)
    H = rng.gamma(0.5, 1.0, (k, m)) + 0.01
    assume(np.linalg.cond(H / np.linalg.norm(H, axis=1, keepdims=True)) < 1e3)  # accuracy is the conditioning's
    X = rng.gamma(0.5, 1.0, (4, m)) + 0.01
    want, converged = solve_coefficients(X, H, np.ones((4, k)), beta)
    assert converged
    if beta == 2.0:
        np.testing.assert_allclose(want, [nnls(H.T, x)[0] for x in X], rtol=0, atol=1e-7 * want.max())
    start = want * 10.0**log_scale + rng.random(want.shape)
    W, converged = solve_coefficients(X, H, start, beta)
    assert converged
    np.testing.assert_allclose(W, want, rtol=0, atol=1e-7 * want.max())
