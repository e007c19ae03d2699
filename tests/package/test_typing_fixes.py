"""Bugs that mypy found (type hints that check).

Each test failed before its fix; the fix and the mypy error that led to it are named.
"""

from __future__ import annotations

from fractions import Fraction

import pytest

from mmconcepts._validation import Interval, check_scalar, validate_params
from mmconcepts.errors import ParameterError


# mypy: np.isfinite has no overload for numbers.Real. At run time the ufunc raised TypeError for
# real numbers that are not Python/numpy scalars, so a Fraction or an int beyond float range got
# an untyped TypeError instead of being accepted or refused with a ParameterError.
def test_interval_accepts_any_finite_real_number():
    validate_params({"x": Fraction(1, 2)}, {"x": [Interval("real", 0, 1)]}, owner="f")
    with pytest.raises(ParameterError, match=r"f: x must be a real number in \[0, 1\]; got Fraction\(3, 2\)"):
        validate_params({"x": Fraction(3, 2)}, {"x": [Interval("real", 0, 1)]}, owner="f")


def test_interval_refuses_int_beyond_float_range_with_parameter_error():
    with pytest.raises(ParameterError, match="x must be a real number >= 0"):
        validate_params({"x": 10**400}, {"x": [Interval("real", 0, None)]}, owner="f")


def test_check_scalar_fraction_and_huge_int():
    assert check_scalar(Fraction(1, 4), "x") == 0.25
    with pytest.raises(ParameterError, match="x must be a finite real number"):
        check_scalar(10**400, "x")


def test_stack_descriptors_takes_a_fraction_weight():
    # the same np.isfinite(numbers.Real) call in mmconcepts.vision.features._check_real
    import numpy as np
    import scipy.sparse as sp

    from mmconcepts.vision import stack_descriptors

    out = stack_descriptors({"a": sp.csr_matrix(np.ones((2, 3)))}, weights={"a": Fraction(1, 2)})
    np.testing.assert_array_equal(out.toarray(), np.full((2, 3), 0.5))
    with pytest.raises(ParameterError, match=r"weights\['a'\] must be a real >= 0"):
        stack_descriptors({"a": sp.csr_matrix(np.ones((2, 3)))}, weights={"a": 10**400})


# What a user's type checker sees (the package ships py.typed): calls the documentation shows
# must type-check. Before, a numpy array of labels was not a valid y_test/y_ref (typed Sequence).
_USER_CODE = '''
import numpy as np
from mmconcepts.multimodal import matching_success_rate
from mmconcepts.nmf import LabelNMF, dictionary_distance
from mmconcepts.sound import ClusterTree, EventVoting

def l1(q: np.ndarray, c: np.ndarray) -> list[float]:
    return [float(v) for v in np.abs(c - q).sum(axis=1)]

trees = [ClusterTree(1.0), ClusterTree(1.0, metric="dtw"), ClusterTree(1.0, metric=l1),
         ClusterTree(1.0, metric=lambda q, c: np.linalg.norm(c - q, axis=1))]
rate: float = matching_success_rate(np.zeros((2, 2)), np.array([0, 1]), np.array([0, 1]))
rate = matching_success_rate([[0.0, 1.0]], ["a"], ["a", "b"], n_draws=2, random_state=0)
d: float = dictionary_distance(np.eye(2), np.eye(2), metric="l1")
model = LabelNMF(2, solver="pg", update_rule="heuristic")
voting = EventVoting().fit([np.array([0, 1])], np.array(["yes"]))
'''


@pytest.mark.slow
def test_documented_calls_type_check(tmp_path):
    api = pytest.importorskip("mypy.api")
    script = tmp_path / "user_code.py"
    script.write_text(_USER_CODE)
    out, err, status = api.run([str(script), "--no-incremental", "--follow-imports=silent",
                                "--ignore-missing-imports", "--python-version", "3.10"])
    assert status == 0, out + err
