"""MultimodalNMF in scikit-learn's model selection: one 2-D table split by ``modalities``, and ``score``.

With ``modalities`` the learner takes a table (dense or sparse) whose column blocks are the
modalities, gives the same fit as the mapping of those blocks, and is scored by cross-modal
success on held-out pairs, so ``GridSearchCV``, ``cross_val_score`` and ``Pipeline`` work.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from sklearn.base import clone
from sklearn.model_selection import GridSearchCV, cross_val_score
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import MaxAbsScaler
from sklearn.utils import get_tags
from sklearn.utils.estimator_checks import check_estimator

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.multimodal import MultimodalNMF, matching_success_rate, pairwise_divergence

pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")

SOUND, IMAGE = slice(0, 30), slice(30, None)
MODALITIES = {"sound": SOUND, "image": IMAGE}


def paired(seed: int, n_concepts: int = 6, n_per: int = 20, d_sound: int = 30, d_image: int = 20):
    """Paired examples of ``n_concepts`` concepts: each modality a Poisson count histogram around the
    concept's own sparse (gamma-distributed) prototype, plus a flat background; rows in random order."""
    rng = np.random.default_rng(seed)
    y = rng.permutation(np.repeat(np.arange(n_concepts), n_per))
    prototypes = [rng.gamma(0.3, size=(n_concepts, d)) for d in (d_sound, d_image)]
    X = np.hstack([rng.poisson(3 * P[y] + 0.3).astype(float) for P in prototypes])
    return X, y


def _blocks(X):
    return {"sound": X[:, SOUND], "image": X[:, IMAGE]}


# --------------------------------------------------------------------------- a table is its column blocks


@pytest.mark.parametrize("to", [np.asarray, sp.csr_matrix, sp.csc_array], ids=["dense", "csr", "csc"])
def test_a_table_gives_the_fit_of_the_mapping_of_its_column_blocks(to):
    X, _ = paired(0)
    blocks = _blocks(to(X))  # the same format: sparse and dense products round differently
    table = MultimodalNMF(5, modalities=MODALITIES, max_iter=20, random_state=1)
    mapping = MultimodalNMF(5, max_iter=20, random_state=1)
    W_table, W_map = table.fit_transform(to(X)), mapping.fit_transform(blocks)
    np.testing.assert_array_equal(W_table, W_map)
    np.testing.assert_array_equal(table.components_, mapping.components_)
    assert table.scales_ == mapping.scales_ and table.n_features_ == {"sound": 30, "image": 20}
    assert table.modalities_ == ["sound", "image"] and table.n_features_in_ == 50
    assert not hasattr(mapping, "n_features_in_")
    np.testing.assert_array_equal(table.transform(to(X)), mapping.transform(blocks))
    # a table-fitted learner still takes a mapping, and from a subset of the modalities
    image = {"image": blocks["image"]}
    np.testing.assert_array_equal(table.transform(image), mapping.transform(image))


def test_column_index_arrays_and_a_mapping_in_another_order_give_the_same_fit():
    X, _ = paired(1)
    rng = np.random.default_rng(0)
    order = rng.permutation(50)  # the columns shuffled; the modalities given by index arrays
    shuffled = X[:, order]
    where = np.argsort(order)
    by_index = MultimodalNMF(4, modalities={"sound": where[:30], "image": where[30:]}, max_iter=15, random_state=2)
    by_slice = MultimodalNMF(4, modalities=MODALITIES, max_iter=15, random_state=2)
    np.testing.assert_array_equal(by_index.fit_transform(shuffled), by_slice.fit_transform(X))
    # with modalities, a mapping is read in modalities' order, whatever its own
    reordered = by_slice.fit_transform({"image": X[:, IMAGE], "sound": X[:, SOUND]})
    np.testing.assert_array_equal(reordered, by_index.fit_transform(shuffled))
    assert by_slice.modalities_ == ["sound", "image"] and not hasattr(by_slice, "n_features_in_")


def test_partial_fit_on_tables_is_partial_fit_on_their_blocks():
    X, _ = paired(2)
    table = MultimodalNMF(4, modalities=MODALITIES, max_iter=10, partial_max_iter=3, random_state=0)
    mapping = MultimodalNMF(4, max_iter=10, partial_max_iter=3, random_state=0)
    for rows in (slice(0, 40), slice(40, 80), slice(80, 120)):
        table.partial_fit(X[rows])
        mapping.partial_fit(_blocks(X[rows]))
    np.testing.assert_array_equal(table.components_, mapping.components_)
    assert table.scales_ == mapping.scales_ and table.n_features_in_ == 50


def test_table_errors_say_what_was_expected():
    X, y = paired(0)
    with pytest.raises(DataError, match=r"mapping of modality names.*got ndarray.*MultimodalNMF\(modalities="):
        MultimodalNMF(3).fit(X)
    model = MultimodalNMF(3, modalities=MODALITIES, max_iter=5, random_state=0).fit(X)
    with pytest.raises(DataError, match="X has 49 features, but MultimodalNMF is expecting 50 features as input"):
        model.transform(X[:, :49])
    with pytest.raises(DataError, match=r"unknown: \['motion'\]"):
        model.transform({"motion": X[:, SOUND]})
    with pytest.raises(DataError, match=r"missing: \['image'\]"):
        clone(model).fit({"sound": X[:, SOUND]})
    cases = [
        ({"a": slice(0, 10), "b": slice(5, 20)}, ParameterError, "modalities 'a' and 'b' share columns"),
        ({"a": slice(0, 10), "b": slice(60, 70)}, DataError, r"modality 'b' has no column in X's 50 feature\(s\)"),
        ({"a": [0, 1], "b": [2, 50]}, DataError, "X has 50 features, but modality 'b' takes columns 2 to 50"),
        ({"a": np.ones(50, bool)}, ParameterError, r"np.flatnonzero\(mask\)"),
        ({}, ParameterError, "modalities must name at least one modality"),
        ([("a", slice(0, 3))], ParameterError, "modalities must be a mapping of modality names to column slices"),
    ]
    for modalities, error, message in cases:
        with pytest.raises(error, match=message):
            MultimodalNMF(3, modalities=modalities).fit(X)


def test_the_parameter_is_declared_cloned_and_saved(tmp_path):
    model = MultimodalNMF(3, modalities=MODALITIES, max_iter=5, random_state=0)
    assert model.get_params()["modalities"] is MODALITIES
    assert clone(model).get_params()["modalities"] == MODALITIES
    assert get_tags(model).input_tags.two_d_array and not get_tags(MultimodalNMF()).input_tags.two_d_array
    X, _ = paired(3)
    model.fit(X)
    path = model.save(tmp_path / "m")
    with np.load(path, allow_pickle=False) as z:
        assert json.loads(str(z["header"]))["params"]["modalities"]["sound"]["items"] == [0, 30, None]
    loaded = MultimodalNMF.load(path)
    assert loaded.get_params() == model.get_params() and loaded.n_features_in_ == 50
    np.testing.assert_array_equal(loaded.transform(X), model.transform(X))


# --------------------------------------------------------------------------- score


def test_score_is_the_matching_of_each_example_against_the_other_examples():
    """Pinned to matching_success_rate called by hand: internal space, cosine, both directions,
    the example's own view never among its references, the documented seeding."""
    X, y = paired(4, n_per=5)
    model = MultimodalNMF(6, modalities=MODALITIES, max_iter=30, random_state=7).fit(X)
    W = {m: model.transform({m: X[:, cols]}) for m, cols in MODALITIES.items()}
    streams = np.random.SeedSequence([7, 0x5C0E]).spawn(2)
    rates = []
    for (a, b), stream in zip((("sound", "image"), ("image", "sound")), streams):
        D, rng = pairwise_divergence(W[a], W[b], "cosine"), np.random.default_rng(stream)
        rates.append(np.mean([matching_success_rate(np.delete(D[i:i + 1], i, axis=1), y[i:i + 1], np.delete(y, i),
                                                    n_draws=10, random_state=rng) for i in range(len(y))]))
    assert model.score(X, y) == pytest.approx(np.mean(rates), abs=1e-12)
    assert model.score(X, y) == model.score(X, y)  # deterministic
    assert model.score(sp.csr_matrix(X), y) == model.score(X, y) == model.score(_blocks(X), y)


def test_score_is_one_on_separable_concepts_and_chance_on_shuffled_labels():
    rng = np.random.default_rng(0)
    y = np.repeat(np.arange(4), 10)
    X = np.zeros((40, 16))
    for c in range(4):  # concept c owns columns 2c, 2c+1 of the sound and 8 + 2c, 8 + 2c + 1 of the image
        rows = y == c
        X[np.ix_(rows, [2 * c, 2 * c + 1, 8 + 2 * c, 9 + 2 * c])] = 1 + rng.random((10, 4))
    model = MultimodalNMF(4, modalities={"sound": slice(0, 8), "image": slice(8, 16)}, max_iter=200,
                          init="nndsvda", random_state=0).fit(X)
    assert model.score(X, y) == 1.0
    # labels that say nothing of the examples: chance, 1 / 4 (mean of 10 label shufflings)
    chance = np.mean([model.score(X, rng.permutation(y)) for _ in range(10)])
    assert abs(chance - 0.25) < 0.05


def test_score_errors():
    X, y = paired(0, n_per=4)
    model = MultimodalNMF(3, modalities=MODALITIES, max_iter=5, random_state=0).fit(X)
    with pytest.raises(DataError, match=r"score needs y"):
        model.score(X, None)
    with pytest.raises(DataError, match=r"one concept per example of X, shape \(24,\); got shape \(23,\)"):
        model.score(X, y[:-1])
    with pytest.raises(DataError, match="at least two of"):
        model.score({"sound": X[:, SOUND]}, y)
    with pytest.raises(DataError, match="concepts with at least two examples"):
        model.score(X[:3], [0, 1, 2])


# --------------------------------------------------------------------------- model selection


def test_grid_search_picks_enough_atoms_for_the_concepts():
    """6 concepts, two modalities. Over data seeds 0-5, k=2 (fewer atoms than concepts) scores
    0.26-0.35 and k=6 and k=12 0.75-0.94, either of them best; chance is 1/6."""
    X, y = paired(0)
    search = GridSearchCV(MultimodalNMF(modalities=MODALITIES, max_iter=50, random_state=0),
                          {"n_components": [2, 6, 12]}, cv=3).fit(X, y)
    scores = dict(zip([p["n_components"] for p in search.cv_results_["params"]],
                      search.cv_results_["mean_test_score"]))
    assert search.best_params_["n_components"] in (6, 12)
    assert search.best_score_ > 3 / 6  # three times chance
    assert scores[6] - scores[2] > 0.25
    assert search.best_estimator_.n_components == search.best_params_["n_components"]
    again = GridSearchCV(MultimodalNMF(modalities=MODALITIES, max_iter=50, random_state=0),
                         {"n_components": [2, 6, 12]}, cv=3).fit(X, y)
    np.testing.assert_array_equal(again.cv_results_["mean_test_score"], search.cv_results_["mean_test_score"])


def test_cross_val_score_and_a_pipeline():
    X, y = paired(1)
    model = MultimodalNMF(6, modalities=MODALITIES, max_iter=50, random_state=0)
    scores = cross_val_score(model, X, y, cv=3)
    assert scores.shape == (3,) and (scores > 3 / 6).all()
    # each column scaled to a maximum of 1 (nonnegative data stays nonnegative), then the learner
    pipe = Pipeline([("scale", MaxAbsScaler()), ("mm", model)])
    search = GridSearchCV(pipe, {"mm__n_components": [2, 6]}, cv=3).fit(X, y)
    assert search.best_params_ == {"mm__n_components": 6} and search.best_score_ > 3 / 6
    assert search.score(X, y) == search.best_estimator_.named_steps["mm"].score(MaxAbsScaler().fit_transform(X), y)


# --------------------------------------------------------------------------- scikit-learn's checks

@pytest.mark.slow
def test_check_estimator_passes_with_modalities():
    """Every check runs on tables (one column for "a", the rest for "b") and passes, those comparing
    fit_transform's W with transform's included (the coefficients are solved to convergence)."""
    model = MultimodalNMF(2, modalities={"a": slice(0, 1), "b": slice(1, None)}, max_iter=20, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = check_estimator(model, on_fail=None)
    status = {}
    for r in results:
        status.setdefault(r["check_name"], set()).add(r["status"])
    assert {name for name, s in status.items() if "failed" in s} == set()
    assert {"check_transformer_general", "check_transformer_data_not_an_array"} <= {
        name for name, s in status.items() if s == {"passed"}}
    assert len([n for n, s in status.items() if s == {"passed"}]) >= 40
