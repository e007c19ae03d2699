"""The shared pieces of the estimator contract: parameter constraints and pickle-free save/load."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from mmconcepts._codec import decode, encode
from mmconcepts._persist import SaveLoadMixin
from mmconcepts._validation import InstanceOf, Interval, Options, describe_constraints, validate_params
from mmconcepts.errors import DataFormatError, ParameterError, VersionMismatchError

# ---------------------------------------------------------------- constraints


@settings(max_examples=200, deadline=None)
@given(value=st.one_of(st.integers(-5, 5), st.floats(-5, 5), st.sampled_from([math.nan, math.inf]), st.booleans()),
       low=st.one_of(st.none(), st.integers(-3, 3)), high=st.one_of(st.none(), st.integers(-3, 3)),
       closed=st.sampled_from(["both", "left", "right", "neither"]), kind=st.sampled_from(["int", "real"]))
def test_interval_agrees_with_a_direct_reading(value, low, high, closed, kind):
    expected = not isinstance(value, bool) and (isinstance(value, int) or kind == "real") and math.isfinite(value)
    if expected and low is not None:
        expected = value > low or (value == low and closed in ("both", "left"))
    if expected and high is not None:
        expected = value < high or (value == high and closed in ("both", "right"))
    assert Interval(kind, low, high, closed=closed).is_satisfied_by(value) == expected


def test_interval_accepts_numpy_scalars_and_describes_itself():
    assert Interval("int", 1).is_satisfied_by(np.int64(3))
    assert not Interval("int", 1).is_satisfied_by(np.float64(3.0))
    assert Interval("real", 0, 1).is_satisfied_by(np.float32(0.5))
    assert str(Interval("int", 1)) == "an int >= 1"
    assert str(Interval("real", 0, 1, closed="left")) == "a real number in [0, 1)"
    assert str(Interval("real", 0, None, closed="neither")) == "a real number > 0"


def test_options_do_not_confuse_bools_with_numbers():
    o = Options("l1", None, 1)
    assert [o.is_satisfied_by(v) for v in ["l1", None, 1, True, "x", [1, 2], np.zeros(3)]] == [
        True, True, True, False, False, False, False]
    assert Options(True).is_satisfied_by(np.bool_(True))
    assert not Options(True).is_satisfied_by(1)


def test_validate_params_message_says_expected_got_and_fix():
    constraints = {"n_components": [Interval("int", 1), None], "normalize": [Options("l1", None)],
                   "random_state": ["random_state"], "flag": ["boolean"], "data": [InstanceOf(dict, description="a dict")]}
    ok = dict(n_components=None, normalize="l1", random_state=np.random.default_rng(0), flag=False, data={})
    validate_params(ok, constraints, owner="Thing")
    with pytest.raises(ParameterError, match=r"^Thing: n_components must be an int >= 1 or None; got 0\. Use k > 0\.$"):
        validate_params({**ok, "n_components": 0}, constraints, owner="Thing", hints={"n_components": "Use k > 0."})
    with pytest.raises(ParameterError, match="normalize must be one of 'l1', None; got 'l2'"):
        validate_params({**ok, "normalize": "l2"}, constraints)
    with pytest.raises(ParameterError, match="random_state must be an int >= 0"):
        validate_params({**ok, "random_state": -1}, constraints)
    with pytest.raises(ParameterError, match="flag must be a bool; got 1"):
        validate_params({**ok, "flag": 1}, constraints)
    with pytest.raises(ParameterError, match="data must be a dict; got"):
        validate_params({**ok, "data": []}, constraints)
    # unnamed parameters and "no_validation" are not checked
    validate_params({**ok, "other": object()}, {**constraints, "data": "no_validation"})
    assert describe_constraints([Interval("int", 0), None, "callable"]) == "an int >= 0, None or a callable"


def test_validate_params_reads_an_estimators_parameters():
    from sklearn.base import BaseEstimator

    class Est(BaseEstimator):
        _parameter_constraints = {"k": [Interval("int", 1)]}

        def __init__(self, k=1):
            self.k = k

    validate_params(Est(2), Est._parameter_constraints)
    with pytest.raises(ParameterError, match="^Est: k must be an int >= 1; got 0"):
        validate_params(Est(0), Est._parameter_constraints)


# ---------------------------------------------------------------- save / load

_scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=False),
                     st.sampled_from([math.inf, -math.inf]), st.text(max_size=5))
_arrays = st.one_of(hnp.arrays(st.sampled_from([np.float64, np.float32, np.int64, np.bool_]),
                               hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4)),
                    st.lists(st.text(max_size=3), max_size=4).map(lambda xs: np.array(xs, dtype=object)))
_values = st.recursive(
    st.one_of(_scalars, _arrays),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.tuples(inner, inner),
                            st.dictionaries(st.text(max_size=4), inner, max_size=3),
                            st.dictionaries(st.integers(-3, 3), inner, max_size=3)),
    max_leaves=8)


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return (isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape
                and bool(np.all((a == b) | ((a != a) & (b != b)))))
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return type(a) is type(b) and a == b


@settings(max_examples=150, deadline=None)
@given(_values)
def test_encode_then_decode_gives_back_the_value_through_json(value):
    arrays: dict = {}
    header = json.loads(json.dumps(encode(value, arrays, where="v"), allow_nan=False))
    assert _same(value, decode(header, arrays))


def test_encode_refuses_what_needs_pickle():
    with pytest.raises(ParameterError, match="cannot be saved without pickle"):
        encode(np.array([object(), 1], dtype=object), {}, where="x")
    with pytest.raises(ParameterError, match="a set cannot be saved without pickle"):
        encode({1, 2}, {}, where="x")


class _Toy(SaveLoadMixin):
    """A minimal estimator to exercise the mixin (module-level so that its class path resolves)."""

    _persisted_private = ("_cache",)

    def __init__(self, k=2, random_state=None):
        self.k = k
        self.random_state = random_state

    def get_params(self, deep=False):
        return {"k": self.k, "random_state": self.random_state}

    def fit(self):
        self.coef_ = np.arange(self.k, dtype=float)
        self.classes_ = np.array(["a", "b"], dtype=object)
        self._cache = (np.ones(2), {1: "x"})
        self.not_state = 5
        return self


def test_mixin_round_trip_and_refusals(tmp_path, monkeypatch):
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        _Toy().save(tmp_path / "t")
    toy = _Toy(3, random_state=np.random.default_rng(0)).fit()
    path = toy.save(tmp_path / "t")
    assert path.name == "t.npz"
    back = _Toy.load(path)
    assert back.k == 3 and back.random_state is None
    assert np.array_equal(back.coef_, toy.coef_) and back.classes_.dtype == object
    assert back._cache[1] == {1: "x"} and not hasattr(back, "not_state")
    # another class refuses the file, naming what it holds
    class Other(_Toy):
        pass
    with pytest.raises(DataFormatError, match="its format is 'mmconcepts._Toy'"):
        Other.load(path)
    # a newer save format is refused with a fix
    monkeypatch.setattr(_Toy, "_save_format_version", 2)
    with pytest.raises(VersionMismatchError, match="reads version 2 of _Toy"):
        _Toy.load(path)
    # not an npz
    (tmp_path / "x.npz").write_text("nope")
    with pytest.raises(DataFormatError, match="not a saved"):
        _Toy.load(tmp_path / "x.npz")


def test_decode_only_builds_mmconcepts_classes():
    with pytest.raises(DataFormatError, match="only mmconcepts classes"):
        decode({"__mmconcepts__": "estimator", "class": "os.system", "params": {}, "state": {}}, {})
    with pytest.raises(DataFormatError, match="not a model that can be loaded"):
        decode({"__mmconcepts__": "estimator", "class": "mmconcepts.errors.DataError", "params": {}, "state": {}}, {})
