"""MultimodalNMF on dask arrays: the same fit as in memory, modality by modality chunk by chunk."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

da = pytest.importorskip("dask.array", reason="the dask extra is not installed")
import dask  # noqa: E402

from mmconcepts.errors import DataError  # noqa: E402
from mmconcepts.multimodal import MultimodalNMF  # noqa: E402


def _modalities(sparse_sound: bool, seed: int = 0):
    rng = np.random.default_rng(seed)
    concepts = rng.integers(0, 4, 90)
    sound = rng.poisson(0.3, (90, 60)).astype(float) + 3.0 * (np.arange(60)[None, :] // 15 == concepts[:, None])
    motion = rng.gamma(1.0, 1.0, (90, 24)) + 5.0 * (np.arange(24)[None, :] // 6 == concepts[:, None])
    return {"sound": sp.csr_matrix(sound) if sparse_sound else sound, "motion": motion}


def _chunked(X, chunks=(25, 25, 25, 15)):
    return {m: da.from_array(x, chunks=(chunks, -1), asarray=False) for m, x in X.items()}


@pytest.mark.parametrize("sparse_sound", [False, True], ids=["dense", "sparse"])
def test_dask_fit_and_transform_equal_the_in_memory_learner(sparse_sound):
    X = _modalities(sparse_sound)
    params = dict(n_components=6, max_iter=30, random_state=0)
    ref = MultimodalNMF(**params).fit(X)
    with dask.config.set(scheduler="synchronous"):
        model = MultimodalNMF(**params)
        W = model.fit_transform(_chunked(X))
        assert isinstance(W, da.Array) and W.chunks[0] == (25, 25, 25, 15)
        for m in X:
            assert model.scales_[m] == pytest.approx(ref.scales_[m], rel=1e-13)
        np.testing.assert_allclose(model.components_, ref.components_, rtol=1e-10, atol=1e-300)
        # from one modality (eq. 6.3), chunk by chunk
        w_sound = model.transform({"sound": _chunked(X)["sound"]})
        assert isinstance(w_sound, da.Array)
        np.testing.assert_allclose(w_sound.compute(), ref.transform({"sound": X["sound"]}), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(model.reconstruct(w_sound.compute(), "motion"),
                                   ref.reconstruct(ref.transform({"sound": X["sound"]}), "motion"), rtol=1e-9,
                                   atol=1e-12)


def test_dask_fit_transform_equals_the_in_memory_fit_transform():
    X = _modalities(False)
    params = dict(n_components=5, max_iter=20, random_state=3)
    W_ref = MultimodalNMF(**params).fit_transform(X)
    with dask.config.set(scheduler="synchronous"):
        W = MultimodalNMF(**params).fit_transform(_chunked(X)).compute()
    np.testing.assert_allclose(W, W_ref, rtol=1e-10, atol=1e-300)


def test_dask_bad_input():
    X = _modalities(False)
    chunked = _chunked(X)
    with dask.config.set(scheduler="synchronous"):
        with pytest.raises(DataError, match="row chunks"):  # modalities chunked differently
            MultimodalNMF(n_components=3, max_iter=2).fit({"sound": chunked["sound"],
                                                           "motion": da.from_array(X["motion"], chunks=(45, -1))})
        with pytest.raises(DataError, match="dask array like the others"):
            MultimodalNMF(n_components=3, max_iter=2).fit({"sound": chunked["sound"], "motion": X["motion"]})
        with pytest.raises(DataError, match="column chunks"):
            MultimodalNMF(n_components=3, max_iter=2).fit({"sound": da.from_array(X["sound"], chunks=(25, 30)),
                                                           "motion": chunked["motion"]})
        with pytest.raises(DataError, match="examples but the first modality"):
            MultimodalNMF(n_components=3, max_iter=2).fit({"sound": chunked["sound"],
                                                           "motion": da.from_array(X["motion"][:80], chunks=(40, -1))})
        bad = X["motion"].copy()
        bad[70, 3] = -1.0
        with pytest.raises(DataError, match="chunk 2"):  # found by the solver's first pass, named by its chunk
            MultimodalNMF(n_components=3, max_iter=2).fit({"sound": chunked["sound"],
                                                           "motion": da.from_array(bad, chunks=((25, 25, 25, 15), -1))})
        model = MultimodalNMF(n_components=3, max_iter=2, random_state=0).fit(X)
        with pytest.raises(DataError, match="partial_fit takes in-memory batches"):
            model.partial_fit(chunked)
