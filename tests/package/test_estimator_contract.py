"""One contract for every learner of the package, checked across all subpackages.

Each public estimator class: subclasses scikit-learn's BaseEstimator, declares every constructor
parameter once in ``_parameter_constraints``, survives ``clone`` with its parameters, and, when a
user would keep it fitted, saves and loads without pickle (SaveLoadMixin). The per-package test
files (test_contract_*.py) check the behaviour; this file checks that no learner was left out.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest
from sklearn.base import BaseEstimator, clone

import mmconcepts
from mmconcepts._persist import SaveLoadMixin

_SKIP_MODULES = ("mmconcepts.experiments", "mmconcepts.report", "mmconcepts.cli", "mmconcepts.__main__")


def _public_estimators() -> list[type]:
    found: dict[str, type] = {}
    for info in pkgutil.walk_packages(mmconcepts.__path__, "mmconcepts."):
        if info.name.startswith(_SKIP_MODULES):
            continue
        try:
            module = importlib.import_module(info.name)
        except ImportError:  # an optional extra that is not installed
            continue
        for name, obj in vars(module).items():
            if (inspect.isclass(obj) and issubclass(obj, BaseEstimator) and obj.__module__ == info.name
                    and not name.startswith("_") and not inspect.isabstract(obj)):
                found[f"{obj.__module__}.{name}"] = obj
    return [found[k] for k in sorted(found)]


ESTIMATORS = _public_estimators()

#: The learners the issue names; each must be found by the walk above.
NAMED = {"NMF", "LabelNMF", "GradIRL", "MaxEntIRL", "FactorialIRL", "FactorialInverseControl", "MultimodalNMF",
         "EventVoting", "TreeVotingClassifier", "ImageFeatures", "HAC", "ClusterTree"}

#: Fitted models a user would keep: they must save and load without pickle.
KEPT = {"NMF", "LabelNMF", "ClusterTree", "HAC", "TreeVotingClassifier", "GradIRL", "MaxEntIRL", "FactorialIRL",
        "FactorialInverseControl", "MultimodalNMF"}


#: Values for the parameters that have no default (a data-dependent radius).
REQUIRED = {"r_max": 1.0}


def test_every_named_learner_is_an_estimator():
    assert NAMED <= {cls.__name__ for cls in ESTIMATORS}


@pytest.mark.parametrize("cls", ESTIMATORS, ids=lambda c: c.__name__)
def test_constraints_declare_every_parameter_once(cls):
    params = set(inspect.signature(cls.__init__).parameters) - {"self", "args", "kwargs"}
    table = getattr(cls, "_parameter_constraints", None)
    assert isinstance(table, dict), f"{cls.__name__} has no _parameter_constraints table"
    assert set(table) == params, f"{cls.__name__}: table {sorted(table)} vs parameters {sorted(params)}"


@pytest.mark.parametrize("cls", ESTIMATORS, ids=lambda c: c.__name__)
def test_clone_keeps_the_parameters(cls):
    required = {name: REQUIRED[name] for name, p in inspect.signature(cls.__init__).parameters.items()
                if p.default is inspect.Parameter.empty and name not in ("self", "args", "kwargs")}
    est = cls(**required)
    again = clone(est)
    assert type(again) is cls and again.get_params(deep=False).keys() == est.get_params(deep=False).keys()


@pytest.mark.parametrize("name", sorted(KEPT))
def test_kept_models_save_without_pickle(name):
    cls = next(c for c in ESTIMATORS if c.__name__ == name)
    assert issubclass(cls, SaveLoadMixin)
