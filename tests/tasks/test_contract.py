"""The estimator contract of the task learners: GradIRL, MaxEntIRL, FactorialIRL,
FactorialInverseControl, the RBFFeatures parameter object, and the parameter tables of the public
functions of ``mmconcepts.tasks``.

scikit-learn's ``check_estimator`` cannot run on these learners: GradIRL, MaxEntIRL and FactorialIRL
fit ``(mdp, demonstrations)`` -- an MDP object and a list (tasks) of lists of variable-length
(state, action) arrays -- and FactorialInverseControl fits a list of trajectories of different
lengths (with optional mixing coefficients); none of them takes the 2-D ``X`` that every check
builds, so every check would fail at its first ``fit``. The parts of the contract are therefore
tested directly: clone, get_params/set_params, one parameter table checked at the start of fit,
NotFittedError, save/load.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.utils.validation import check_is_fitted

from mmconcepts.errors import DataFormatError, ParameterError, VersionMismatchError
from mmconcepts.tasks import (
    MDP,
    FactorialInverseControl,
    FactorialIRL,
    GradIRL,
    MaxEntIRL,
    RBFFeatures,
    adjoint_gradient,
    armijo_descent,
    boltzmann_policy,
    brillinger_regression,
    control_trajectories,
    gradirl_objective,
    greedy_policy,
    grid_world,
    maxent_objective,
    policy_iteration,
    q_gradient,
    q_values,
    sample_trajectories,
    soft_value_iteration,
    value_iteration,
)
from mmconcepts.tasks.factorial import factorial_objective

# ---------------------------------------------------------------- small data, fitted fast


def _irl_data():
    rng = np.random.default_rng(0)
    world = grid_world(3)
    R = rng.standard_normal((3, world.n_states, world.n_actions))
    _, Q = value_iteration(world, R)
    demos = [sample_trajectories(world, greedy_policy(Q[i]), 3, 5, random_state=rng) for i in range(3)]
    features = rng.standard_normal((world.n_states, world.n_actions, 4))
    return world, demos, features


def _control_data():
    rng = np.random.default_rng(1)
    f = RBFFeatures(3, sigma=0.5)
    D = rng.standard_normal((2, f.n_features))
    A = rng.uniform(0.2, 1.0, (5, 2))
    trajs = control_trajectories(f, A @ D, rng.random((5, 2)), n_steps=12)
    return list(trajs), A


WORLD, DEMOS, FEATURES = _irl_data()
TRAJS, COEFS = _control_data()

# name -> (unfitted learner, fit, outputs of the fitted learner to compare after save/load)
CASES = {
    "GradIRL": (lambda: GradIRL(FEATURES, beta=2.0, max_iter=3),
                lambda est: est.fit(WORLD, DEMOS), lambda est: [est.rewards_]),
    "MaxEntIRL": (lambda: MaxEntIRL(l2=0.1, max_iter=3),
                  lambda est: est.fit(WORLD, DEMOS), lambda est: [est.rewards_]),
    "FactorialIRL": (lambda: FactorialIRL(2, max_iter=2, inner_steps=2, flat_max_iter=3),
                     lambda est: est.fit(WORLD, DEMOS),
                     lambda est: [est.reward_features(WORLD), est.transform(WORLD, DEMOS[:1], max_iter=2)]),
    "FactorialIRL-random": (lambda: FactorialIRL(2, init="random", max_iter=1, inner_steps=1,
                                                 random_state=np.random.default_rng(3)),
                            lambda est: est.fit(WORLD, DEMOS), lambda est: [est.reward_features(WORLD)]),
    "FactorialInverseControl": (lambda: FactorialInverseControl(2, features=RBFFeatures(3, sigma=0.5), max_iter=3,
                                                                random_state=0),
                                lambda est: est.fit(TRAJS), lambda est: [est.transform(TRAJS[:2])]),
    "FactorialInverseControl-supervised": (lambda: FactorialInverseControl(2, max_iter=3, d_solver="cg",
                                                                           random_state=4),
                                           lambda est: est.fit(TRAJS, COEFS), lambda est: [est.transform(TRAJS)]),
}


def _fit(name):
    make, fit, _ = CASES[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a few steps do not converge, on purpose
        return fit(make())


def _fitted_state(est) -> dict:
    return {k: v for k, v in vars(est).items()
            if (k.endswith("_") and not k.startswith("__")) or k in type(est)._persisted_private}


def _assert_same(a, b, what=""):
    if isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype, what
        np.testing.assert_array_equal(a, b, err_msg=what)
    elif isinstance(a, RBFFeatures):
        assert type(b) is RBFFeatures and a.get_params() == b.get_params(), what
        np.testing.assert_array_equal(a.centres, b.centres)
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), what
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{what}[{i}]")
    else:
        assert a == b and type(a) is type(b), (what, a, b)


def _assert_same_params(a, b):
    pa, pb = a.get_params(deep=False), b.get_params(deep=False)
    assert pa.keys() == pb.keys()
    for k in pa:
        if isinstance(pa[k], np.random.Generator):
            assert pb[k] is None  # a generator is saved as None (documented)
        else:
            _assert_same(pa[k], pb[k], k)


# ---------------------------------------------------------------- clone, get_params, set_params


@pytest.mark.parametrize("name", CASES)
def test_every_constructor_parameter_is_declared_once(name):
    est = CASES[name][0]()
    assert set(est.get_params(deep=False)) == set(type(est)._parameter_constraints)


@pytest.mark.parametrize("name", CASES)
def test_clone_is_an_unfitted_copy_that_fits_the_same(name):
    make, fit, outputs = CASES[name]
    est = make()
    twin = clone(est)
    assert twin is not est and type(twin) is type(est)
    params, twin_params = est.get_params(deep=False), twin.get_params(deep=False)
    for k, v in params.items():
        if isinstance(v, np.random.Generator):  # clone copies a generator: same state, another object
            assert twin_params[k] is not v and twin_params[k].bit_generator.state == v.bit_generator.state
        else:
            _assert_same(v, twin_params[k], k)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit(est)
        fit(twin)
    for x, y in zip(outputs(est), outputs(twin)):
        np.testing.assert_array_equal(x, y)
    fresh = clone(est)  # a fitted learner clones to an unfitted one
    with pytest.raises(NotFittedError):
        check_is_fitted(fresh)


@pytest.mark.parametrize("name", CASES)
def test_set_params_changes_what_get_params_gives(name):
    est = CASES[name][0]()
    assert est.set_params(max_iter=7, tol=0.5) is est
    assert est.get_params()["max_iter"] == 7 and est.tol == 0.5
    with pytest.raises(ValueError, match="Invalid parameter"):
        est.set_params(no_such_parameter=1)


def test_nested_feature_parameters_are_reachable():
    est = FactorialInverseControl(2, features=RBFFeatures(3))
    params = est.get_params(deep=True)
    assert params["features__grid_size"] == 3 and params["features__sigma"] is None
    est.set_params(features__sigma=0.3)
    assert est.features.sigma == 0.3 and est.get_params()["features__sigma"] == 0.3
    twin = clone(est)
    assert twin.features is not est.features and twin.features.get_params() == {"grid_size": 3, "sigma": 0.3}


def test_rbf_features_is_a_parameter_object_whose_set_params_recomputes_the_grid():
    f = RBFFeatures(5)
    assert f.get_params() == {"grid_size": 5, "sigma": None} and f.sigma == 0.25  # the width in use
    assert repr(f) == "RBFFeatures(grid_size=5, sigma=None)"
    f.set_params(grid_size=3)
    assert f.n_features == 9 and f.sigma == 0.5  # the default width follows the grid
    np.testing.assert_array_equal(f.centres, RBFFeatures(3).centres)
    f.set_params(sigma=0.1)
    assert f.sigma == 0.1 and f.get_params() == {"grid_size": 3, "sigma": 0.1}
    with pytest.raises(ParameterError, match="RBFFeatures: grid_size must be an int >= 2; got 1"):
        f.set_params(grid_size=1)
    with pytest.raises(ParameterError, match="no parameter 'width'"):
        f.set_params(width=0.1)
    c = clone(RBFFeatures(4, sigma=0.2))
    assert c.get_params() == {"grid_size": 4, "sigma": 0.2}


# ---------------------------------------------------------------- parameter constraints

BAD_PARAMETERS = [
    # GradIRL.tol was never checked: a negative or NaN tol was accepted silently
    (GradIRL, {"tol": -1.0}, "GradIRL: tol must be a real number >= 0; got -1.0"),
    (GradIRL, {"tol": np.nan}, "GradIRL: tol must be a real number >= 0; got nan"),
    (GradIRL, {"beta": 0.0}, "GradIRL: beta must be a real number > 0; got 0.0. beta is the Boltzmann"),
    (GradIRL, {"max_iter": 0}, "GradIRL: max_iter must be an int >= 1; got 0"),
    (GradIRL, {"step0": 0.0}, "GradIRL: step0 must be a real number > 0"),
    (GradIRL, {"features": "tabular"}, "GradIRL: features must be an array-like or None"),
    (MaxEntIRL, {"l2": -0.1}, "MaxEntIRL: l2 must be a real number >= 0"),
    (MaxEntIRL, {"tol": -1e-3}, "MaxEntIRL: tol must be a real number >= 0"),
    (MaxEntIRL, {"max_iter": 2.5}, "MaxEntIRL: max_iter must be an int >= 1"),
    (MaxEntIRL, {"step0": -1.0}, "MaxEntIRL: step0 must be a real number > 0"),
    (FactorialIRL, {"n_components": 0}, "FactorialIRL: n_components must be an int >= 1"),
    (FactorialIRL, {"beta": -1.0}, "FactorialIRL: beta must be a real number > 0"),
    (FactorialIRL, {"max_iter": -1}, "FactorialIRL: max_iter must be an int >= 0"),
    (FactorialIRL, {"inner_steps": 0}, "FactorialIRL: inner_steps must be an int >= 1"),
    (FactorialIRL, {"tol": -1.0}, "FactorialIRL: tol must be a real number >= 0"),
    (FactorialIRL, {"init": "svd"}, "FactorialIRL: init must be one of 'pca', 'random' or an array-like; got 'svd'"),
    (FactorialIRL, {"flat_max_iter": 0}, "FactorialIRL: flat_max_iter must be an int >= 1"),
    (FactorialIRL, {"random_state": -1}, "FactorialIRL: random_state must be an int >= 0"),
    (FactorialInverseControl, {"n_components": 0}, "FactorialInverseControl: n_components must be an int >= 1"),
    (FactorialInverseControl, {"features": "grid"}, "FactorialInverseControl: features must be None or an instance "
                                                    "of RBFFeatures"),
    (FactorialInverseControl, {"lam": 0.0}, "FactorialInverseControl: lam must be a real number > 0"),
    (FactorialInverseControl, {"dt": -0.01}, "FactorialInverseControl: dt must be a real number > 0"),
    (FactorialInverseControl, {"regression": "lasso"}, "FactorialInverseControl: regression must be one of"),
    (FactorialInverseControl, {"alpha": -1.0}, "FactorialInverseControl: alpha must be a real number >= 0"),
    (FactorialInverseControl, {"max_iter": 0}, "FactorialInverseControl: max_iter must be an int >= 1"),
    (FactorialInverseControl, {"d_steps": 0}, "FactorialInverseControl: d_steps must be an int >= 1"),
    (FactorialInverseControl, {"d_solver": "newton"}, "FactorialInverseControl: d_solver must be one of 'steepest'"),
    (FactorialInverseControl, {"tol": -1.0}, "FactorialInverseControl: tol must be a real number >= 0"),
    (FactorialInverseControl, {"random_state": "seed"}, "FactorialInverseControl: random_state must be an int >= 0"),
]


@pytest.mark.parametrize("cls, params, message", BAD_PARAMETERS,
                         ids=[f"{c.__name__}-{next(iter(p))}" for c, p, _ in BAD_PARAMETERS])
def test_a_bad_parameter_is_refused_at_the_start_of_fit(cls, params, message):
    est = cls(**params)  # __init__ only stores
    assert all(getattr(est, k) is v for k, v in params.items())
    with pytest.raises(ParameterError) as info:
        if cls is FactorialInverseControl:
            est.fit(["not a trajectory"])  # the parameters are checked before the data
        else:
            est.fit("not an MDP", "not demonstrations")
    assert str(info.value).startswith(message)


@pytest.mark.parametrize("tol", [-1.0, np.nan])
def test_gradirl_checks_its_tolerance_on_good_data(tol):
    # once, GradIRL.tol was never checked: this fit ran and returned
    with pytest.raises(ParameterError, match="GradIRL: tol must be a real number >= 0"):
        GradIRL(tol=tol, max_iter=2).fit(WORLD, DEMOS)


def test_the_learners_run_at_the_edges_of_their_ranges():
    GradIRL(tol=0.0, max_iter=2).fit(WORLD, DEMOS)  # tol = 0 runs max_iter steps
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fa = FactorialIRL(1, max_iter=0, flat_max_iter=1).fit(WORLD, DEMOS)  # 0 alternations: the initialisation
    np.testing.assert_array_equal(fa.components_, fa.init_components_)
    FactorialInverseControl(2, tol=0.0, max_iter=1, alpha=0.0, regression="ridge", random_state=0).fit(TRAJS)


@pytest.mark.parametrize("function", [value_iteration, soft_value_iteration, policy_iteration])
def test_zero_iterations_are_a_parameter_error(function):
    # value_iteration(max_iter=0) and soft_value_iteration(max_iter=0) raised UnboundLocalError once
    R = np.zeros((WORLD.n_states, WORLD.n_actions))
    with pytest.raises(ParameterError, match=rf"^{function.__name__}: max_iter must be an int >= 1; got 0\. .*q_values"):
        function(WORLD, R, max_iter=0)


@pytest.mark.parametrize("function", [value_iteration, soft_value_iteration])
def test_one_sweep_is_one_bellman_backup_from_the_start_then_the_returned_q(function):
    rng = np.random.default_rng(5)
    R = rng.standard_normal((WORLD.n_states, WORLD.n_actions))
    with pytest.warns(Warning, match="max_iter=1"):
        V, Q = function(WORLD, R, max_iter=1)
    # one sweep from V = 0 gives V1 = backup(0); the returned Q is the backup of V1
    Q0 = q_values(WORLD, np.zeros(WORLD.n_states), R)
    V1 = Q0.max(axis=1) if function is value_iteration else np.log(np.exp(Q0).sum(axis=1))
    np.testing.assert_allclose(Q, q_values(WORLD, V1, R), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("function", [value_iteration, soft_value_iteration])
@pytest.mark.parametrize("tol", [0.0, -1e-3, np.inf])
def test_a_tolerance_that_can_never_be_met_is_refused(function, tol):
    R = np.zeros((WORLD.n_states, WORLD.n_actions))
    with pytest.raises(ParameterError, match=rf"^{function.__name__}: tol must be a real number > 0"):
        function(WORLD, R, tol=tol)


def _objective_args():
    S, A = WORLD.n_states, WORLD.n_actions
    theta = np.zeros((1, S * A))
    mu = np.full((1, S), 1.0 / S)
    pi = np.full((1, S, A), 1.0 / A)
    return theta, mu, pi


BAD_CALLS = [
    ("MDP: discount must be a real number in [0, 1); got 1.0", lambda: MDP(np.full((1, 2, 2), 0.5), discount=1.0)),
    ("grid_world: size must be an int >= 2; got 1", lambda: grid_world(1)),
    ("grid_world: success_prob must be a real number in [0, 1]; got 1.5", lambda: grid_world(3, success_prob=1.5)),
    ("grid_world: random_includes_intended must be a bool", lambda: grid_world(3, random_includes_intended="yes")),
    ("value_iteration: mdp must be an MDP", lambda: value_iteration(np.eye(3), np.zeros((3, 1)))),
    ("value_iteration: max_iter must be an int >= 1; got 2.0", lambda: value_iteration(WORLD, max_iter=2.0)),
    ("policy_iteration: init must be an array-like or None", lambda: policy_iteration(WORLD, init="zeros")),
    ("greedy_policy: tie_tol must be a real number >= 0", lambda: greedy_policy(np.zeros((2, 2)), tie_tol=-1.0)),
    ("boltzmann_policy: beta must be a real number >= 0", lambda: boltzmann_policy(np.zeros((2, 2)), -1.0)),
    ("sample_trajectories: n_trajectories must be an int >= 1; got 0",
     lambda: sample_trajectories(WORLD, np.full((9, 4), 0.25), 0, 3)),
    ("sample_trajectories: length must be an int >= 1; got 0",
     lambda: sample_trajectories(WORLD, np.full((9, 4), 0.25), 2, 0)),
    ("sample_trajectories: random_state must be", lambda: sample_trajectories(WORLD, np.full((9, 4), 0.25), 2, 3,
                                                                              random_state=-2)),
    ("adjoint_gradient: method must be one of 'auto', 'solve', 'iterate'; got 'lu'",
     lambda: adjoint_gradient(WORLD, np.zeros((1, 9, 4)), np.full((1, 9, 4), 0.25), method="lu")),
    ("adjoint_gradient: tol must be a real number > 0",
     lambda: adjoint_gradient(WORLD, np.zeros((1, 9, 4)), np.full((1, 9, 4), 0.25), tol=0.0)),
    ("q_gradient: method must be one of 'solve', 'iterate'; got 'auto'",
     lambda: q_gradient(WORLD, None, np.full((9, 4), 0.25), method="auto")),
    ("q_gradient: max_iter must be an int >= 1", lambda: q_gradient(WORLD, None, np.full((9, 4), 0.25), max_iter=0)),
    ("gradirl_objective: method must be one of", lambda: gradirl_objective(WORLD, *_objective_args(), method="x")),
    ("gradirl_objective: beta must be a real number >= 0",
     lambda: gradirl_objective(WORLD, *_objective_args(), beta=-1.0)),
    ("maxent_objective: l2 must be a real number >= 0",
     lambda: maxent_objective(WORLD, _objective_args()[0], np.ones((1, 9, 4)), l2=-1.0)),
    ("maxent_objective: return_values must be a bool",
     lambda: maxent_objective(WORLD, _objective_args()[0], np.ones((1, 9, 4)), return_values=1)),
    ("factorial_objective: beta must be a real number >= 0",
     lambda: factorial_objective(WORLD, np.zeros((1, 36)), np.zeros((1, 1)), *_objective_args()[1:], beta=-1.0)),
    ("armijo_descent: c must be a real number in (0, 1); got 1.5",
     lambda: armijo_descent(lambda X, rows: (X.sum(1), X), np.ones((1, 2)), c=1.5)),
    ("armijo_descent: shrink must be a real number in (0, 1); got 1.0",
     lambda: armijo_descent(lambda X, rows: (X.sum(1), X), np.ones((1, 2)), shrink=1.0)),
    ("armijo_descent: grow must be a real number >= 1", lambda: armijo_descent(lambda X, rows: (X.sum(1), X),
                                                                               np.ones((1, 2)), grow=0.5)),
    ("armijo_descent: fun must be a callable", lambda: armijo_descent("f", np.ones((1, 2)))),
    ("RBFFeatures: sigma must be a real number > 0 or None; got 0.0", lambda: RBFFeatures(3, sigma=0.0)),
    ("control_trajectories: dt must be a real number > 0; got 0.0",
     lambda: control_trajectories(RBFFeatures(3), np.zeros(9), [0.5, 0.5], dt=0.0)),
    ("control_trajectories: n_steps must be an int >= 1; got 0",
     lambda: control_trajectories(RBFFeatures(3), np.zeros(9), [0.5, 0.5], n_steps=0)),
    ("control_trajectories: method must be one of 'euler', 'ode'; got 'rk4'",
     lambda: control_trajectories(RBFFeatures(3), np.zeros(9), [0.5, 0.5], method="rk4")),
    ("brillinger_regression: alpha must be a real number >= 0",
     lambda: brillinger_regression(RBFFeatures(3), TRAJS[0], regression="ridge", alpha=-1.0)),
    ("brillinger_regression: lam must be a real number > 0", lambda: brillinger_regression(RBFFeatures(3), TRAJS[0],
                                                                                           lam=0.0)),
]


@pytest.mark.parametrize("message, call", BAD_CALLS, ids=[m.split(" must")[0] for m, _ in BAD_CALLS])
def test_public_functions_check_their_parameters_from_one_table(message, call):
    with pytest.raises(ParameterError) as info:
        call()
    assert str(info.value).startswith(message)


def test_armijo_descent_with_zero_steps_returns_the_start():
    X, f, n_iter, _ = armijo_descent(lambda X, rows: ((X**2).sum(1), 2 * X), np.ones((2, 3)), max_iter=0)
    np.testing.assert_array_equal(X, np.ones((2, 3)))
    assert n_iter == 0 and f.tolist() == [3.0, 3.0]


# ---------------------------------------------------------------- not fitted

NOT_FITTED_CALLS = {
    "FactorialIRL.reward_features": lambda: FactorialIRL(2).reward_features(WORLD),
    "FactorialIRL.transform": lambda: FactorialIRL(2).transform(WORLD, DEMOS),
    "FactorialInverseControl.transform": lambda: FactorialInverseControl(2).transform(TRAJS),
}


@pytest.mark.parametrize("name", NOT_FITTED_CALLS)
def test_methods_of_an_unfitted_learner_raise_not_fitted_error(name):
    with pytest.raises(NotFittedError, match="not fitted yet"):
        NOT_FITTED_CALLS[name]()


@pytest.mark.parametrize("name", CASES)
def test_check_is_fitted_tells_fitted_from_unfitted(name, tmp_path):
    est = CASES[name][0]()
    with pytest.raises(NotFittedError):
        check_is_fitted(est)
    with pytest.raises(NotFittedError):
        est.save(tmp_path / "m")
    check_is_fitted(_fit(name))


# ---------------------------------------------------------------- save and load


@pytest.mark.parametrize("name", CASES)
def test_save_load_keeps_parameters_learnt_arrays_and_outputs(name, tmp_path):
    est = _fit(name)
    path = est.save(tmp_path / "model")
    assert path.suffix == ".npz"
    loaded = type(est).load(path)
    assert type(loaded) is type(est)
    _assert_same_params(est, loaded)
    state, state_loaded = _fitted_state(est), _fitted_state(loaded)
    assert state.keys() == state_loaded.keys() and "n_iter_" in state
    for k in state:
        _assert_same(state[k], state_loaded[k], k)
    outputs = CASES[name][2]
    for x, y in zip(outputs(est), outputs(loaded)):
        np.testing.assert_array_equal(x, y)


def test_a_loaded_factorial_irl_refuses_an_mdp_of_another_size(tmp_path):
    loaded = FactorialIRL.load(_fit("FactorialIRL").save(tmp_path / "f"))
    with pytest.raises(ParameterError, match="9 states and 4 actions of the training MDP; got 16 states"):
        loaded.reward_features(grid_world(4))


def test_rbf_features_save_by_their_parameters(tmp_path):
    f = RBFFeatures(4)
    g = RBFFeatures.load(f.save(tmp_path / "rbf"))
    assert g.get_params() == {"grid_size": 4, "sigma": None} and g.sigma == f.sigma
    np.testing.assert_array_equal(g.centres, f.centres)


def test_loading_the_wrong_class_or_a_newer_version_raises(tmp_path):
    path = _fit("GradIRL").save(tmp_path / "g")
    with pytest.raises(DataFormatError, match="not a saved MaxEntIRL"):
        MaxEntIRL.load(path)
    with np.load(path, allow_pickle=False) as z:
        entries = {k: z[k] for k in z.files}
    header = json.loads(str(entries["header"]))
    header["format_version"] = GradIRL._save_format_version + 1
    entries["header"] = np.array(json.dumps(header))
    newer = tmp_path / "newer.npz"
    np.savez(newer, **entries)
    with pytest.raises(VersionMismatchError, match="format version 2"):
        GradIRL.load(newer)
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a model")
    with pytest.raises(DataFormatError):
        GradIRL.load(garbage)
