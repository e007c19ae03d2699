"""The multimodal NMF learner and cross-modal matching (thesis sections 6.4 and 6.6.1)."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError
import scipy.sparse as sp

from mmconcepts.errors import DataError, DataFormatError, ParameterError, VersionMismatchError
from mmconcepts.multimodal import (
    METRICS,
    SPACES,
    MultimodalNMF,
    crossmodal_distances,
    matching_success_rate,
    pairwise_divergence,
)


def concept_data(rng, n=240, k=6, dims=(30, 20, 12), scales=(1.0, 50.0, 0.01)):
    """Each concept has one pattern per modality; examples are noisy, rescaled copies."""
    y = rng.integers(0, k, n)
    mods = {}
    for name, d, s in zip(("sound", "motion", "image"), dims, scales):
        P = rng.random((k, d)) ** 4
        mods[name] = s * (P[y] * rng.uniform(0.5, 2.0, (n, 1)) + 0.05 * rng.random((n, d)))
    return mods, y


def split(mods, idx):
    return {m: X[idx] for m, X in mods.items()}


def test_scales_are_average_l1_norms_and_applied_consistently(rng):
    mods, _ = concept_data(rng)
    model = MultimodalNMF(8, random_state=0).fit(mods)
    for m, X in mods.items():
        assert model.scales_[m] == pytest.approx(X.sum(1).mean())
    # an unnormalised modality 5000x larger than another still gets a fair share of the fit
    W = model.transform({"image": mods["image"]})
    rel = np.linalg.norm(model.reconstruct(W, "image") - mods["image"]) / np.linalg.norm(mods["image"])
    assert rel < 0.3


def test_transform_subset_equals_nmf_on_sub_dictionary(rng):
    mods, _ = concept_data(rng)
    model = MultimodalNMF(6, random_state=0, max_iter=80).fit(mods)
    sl = model.component_slice("motion")
    W = model.transform({"motion": mods["motion"]})
    direct = model.nmf_.transform(mods["motion"] / model.scales_["motion"], features=sl)
    np.testing.assert_allclose(W, direct)
    # order of the mapping does not matter
    a = model.transform({"image": mods["image"], "sound": mods["sound"]})
    b = model.transform({"sound": mods["sound"], "image": mods["image"]})
    np.testing.assert_allclose(a, b)


def test_sparse_equals_dense(rng):
    mods, _ = concept_data(rng, n=80)
    dense = MultimodalNMF(5, random_state=1).fit(mods)
    sparse = MultimodalNMF(5, random_state=1).fit({m: sp.csr_matrix(X) for m, X in mods.items()})
    np.testing.assert_allclose(dense.components_, sparse.components_, rtol=1e-6, atol=1e-9)


def test_fixed_number_of_iterations_by_default(rng):
    mods, _ = concept_data(rng, n=60)
    model = MultimodalNMF(4, random_state=0).fit(mods)
    assert model.nmf_.n_iter_ == 50


def test_crossmodal_matching_beats_chance_and_shuffled_control(rng):
    mods, y = concept_data(rng, n=300)
    tr, te = np.arange(200), np.arange(200, 300)
    model = MultimodalNMF(12, random_state=0, max_iter=100).fit(split(mods, tr))
    rates = {}
    for space in SPACES:
        for metric in METRICS:
            D = crossmodal_distances(model, {"sound": mods["sound"][te]}, {"motion": mods["motion"][te]},
                                     space=space, metric=metric)
            rates[space, metric] = matching_success_rate(D, y[te], y[te], random_state=0)
    assert min(rates.values()) > 0.6  # chance is 1/6
    # control: training pairs whose association is broken
    shuffled = {"sound": mods["sound"][tr], "motion": mods["motion"][rng.permutation(tr)]}
    control = MultimodalNMF(12, random_state=0, max_iter=100).fit(shuffled)
    D = crossmodal_distances(control, {"sound": mods["sound"][te]}, {"motion": mods["motion"][te]})
    assert matching_success_rate(D, y[te], y[te], random_state=0) < 0.4


def test_two_to_one_matching(rng):
    mods, y = concept_data(rng, n=300)
    model = MultimodalNMF(12, random_state=0, max_iter=100).fit(split(mods, np.arange(200)))
    te = np.arange(200, 300)
    D = crossmodal_distances(model, {"sound": mods["sound"][te], "image": mods["image"][te]},
                             {"motion": mods["motion"][te]}, space="reference")
    assert D.shape == (100, 100)
    assert matching_success_rate(D, y[te], y[te], random_state=0) > 0.6


def test_pairwise_divergence_definitions(rng):
    A, B = rng.random((3, 5)), rng.random((4, 5))
    P = A / A.sum(1, keepdims=True)
    Q = B / B.sum(1, keepdims=True)
    kl = np.array([[np.sum(p * np.log(p / q)) for q in Q] for p in P])
    np.testing.assert_allclose(pairwise_divergence(A, B, "kl"), kl, rtol=1e-6)
    np.testing.assert_allclose(pairwise_divergence(A, B, "kl_reversed"), pairwise_divergence(B, A, "kl").T)
    np.testing.assert_allclose(pairwise_divergence(A, B, "kl_symmetric"),
                               pairwise_divergence(A, B, "kl") + pairwise_divergence(A, B, "kl_reversed"))
    np.testing.assert_allclose(pairwise_divergence(A, B, "euclidean"),
                               np.linalg.norm(A[:, None] - B[None], axis=2), atol=1e-12)
    np.testing.assert_allclose(np.diag(pairwise_divergence(A, A, "cosine")), 0.0, atol=1e-12)
    assert (pairwise_divergence(A, B, "kl") >= -1e-12).all()
    with pytest.raises(ParameterError):
        pairwise_divergence(A, B, "manhattan")


def test_dissimilarities_agree_with_scipy(rng):
    """Cosine and Euclidean against scipy.spatial.distance, KL against scipy.stats.entropy."""
    from scipy.spatial.distance import cdist
    from scipy.stats import entropy

    A, B = rng.random((4, 6)) + 0.01, rng.random((5, 6)) + 0.01
    np.testing.assert_allclose(pairwise_divergence(A, B, "cosine"), cdist(A, B, "cosine"), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(pairwise_divergence(A, B, "euclidean"), cdist(A, B, "euclidean"), rtol=1e-10)
    kl = np.array([[entropy(a, b) for b in B] for a in A])  # entropy normalises both to distributions
    np.testing.assert_allclose(pairwise_divergence(A, B, "kl"), kl, rtol=1e-8)


def test_matching_success_rate_by_hand():
    D = np.array([[0.0, 1.0, 2.0], [5.0, 1.0, 0.0]])
    assert matching_success_rate(D, ["a", "b"], ["a", "b", "c"]) == 0.5
    assert matching_success_rate(D, ["a", "c"], ["a", "b", "c"]) == 1.0
    with pytest.raises(DataError, match="no reference"):
        matching_success_rate(D, ["a", "z"], ["a", "b", "c"])


def test_save_load_round_trip_without_pickle(rng, tmp_path):
    mods, _ = concept_data(rng, n=60)
    model = MultimodalNMF(4, random_state=0).fit(mods)
    path = model.save(tmp_path / "learner")
    assert path.suffix == ".npz"
    with np.load(path, allow_pickle=False) as z:  # numbers and strings only, nothing to unpickle
        assert "header" in z.files and all(z[k].dtype != object for k in z.files)
    loaded = MultimodalNMF.load(path)
    assert loaded.modalities_ == model.modalities_ and loaded.scales_ == model.scales_
    np.testing.assert_array_equal(loaded.transform({"sound": mods["sound"]}), model.transform({"sound": mods["sound"]}))
    np.testing.assert_array_equal(loaded.reconstruct(np.ones((1, 4)), "motion"), model.reconstruct(np.ones((1, 4)), "motion"))


def test_load_refuses_corrupt_and_other_versions(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    with pytest.raises(DataFormatError, match="bad.npz"):
        MultimodalNMF.load(bad)
    import json

    header = {"format": "mmconcepts.MultimodalNMF", "format_version": 999, "mmconcepts_version": "9"}
    np.savez(tmp_path / "future.npz", components=np.ones((2, 2)), header=np.array(json.dumps(header)))
    with pytest.raises(VersionMismatchError, match="999"):
        MultimodalNMF.load(tmp_path / "future.npz")


def test_bad_input(rng):
    mods, _ = concept_data(rng, n=30)
    with pytest.raises(DataError, match="mapping"):
        MultimodalNMF(3).fit(np.ones((3, 3)))
    with pytest.raises(DataError, match="'motion' has 29 examples"):
        MultimodalNMF(3).fit({"sound": mods["sound"], "motion": mods["motion"][:29]})
    neg = dict(mods, image=-mods["image"])
    with pytest.raises(DataError, match="image"):
        MultimodalNMF(3).fit(neg)
    with pytest.raises(DataError, match="all zeros"):
        MultimodalNMF(3).fit({"sound": mods["sound"], "motion": np.zeros_like(mods["motion"])})
    model = MultimodalNMF(3, random_state=0).fit(mods)
    with pytest.raises(DataError, match="unknown modality 'smell'"):
        model.transform({"smell": mods["sound"]})
    with pytest.raises(DataError, match="fitted with 30"):
        model.transform({"sound": mods["sound"][:, :5]})
    with pytest.raises(NotFittedError, match="not fitted"):
        MultimodalNMF(3).transform({"sound": mods["sound"]})
    with pytest.raises(DataError, match="must differ"):
        crossmodal_distances(model, {"sound": mods["sound"]}, {"sound": mods["sound"]})
    with pytest.raises(ParameterError):
        MultimodalNMF(3, normalize="l2").fit(mods)


def test_i_divergence_on_unnormalised_data(rng):
    """"idiv" is the generalised KL of eq. 2.8 on the data as they are; "kl" normalises first."""
    A = rng.random((4, 6)) + 0.05
    B = rng.random((5, 6)) + 0.05
    by_hand = np.array([[np.sum(a * np.log(a / b) - a + b) for b in B] for a in A])
    np.testing.assert_allclose(pairwise_divergence(A, B, "idiv"), by_hand, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.diag(pairwise_divergence(A, A, "idiv")), 0.0, atol=1e-9)
    # scale matters to the I-divergence, not to the normalised KL
    assert np.all(pairwise_divergence(A, 3 * A, "idiv")[np.arange(4), np.arange(4)] > 0.1)
    np.testing.assert_allclose(np.diag(pairwise_divergence(A, 3 * A, "kl")), 0.0, atol=1e-9)
    with pytest.raises(DataError, match="nonnegative"):
        pairwise_divergence(-A, B, "idiv")
