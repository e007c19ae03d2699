"""Beta-divergence nonnegative matrix factorization (thesis section 2.1).

Orientation, used everywhere in mmconcepts
------------------------------------------
X is (n_samples, n_features), one example per row, and is approximated as

    X ~ W @ H,   W: (n_samples, n_components) coefficients,
                 H: (n_components, n_features) the dictionary, one atom per row.

``NMF.components_`` is H; ``NMF.transform`` returns W. This is scikit-learn's
orientation. The thesis writes V ~ W H with examples as *columns*: its V is our ``X.T``,
its W (the dictionary, atoms as columns) is our ``H.T = components_.T``, and its H
(coefficients) is our ``W.T``. Docstrings citing a thesis equation say which is which.

Contents
--------
beta_nmf
    The function doing the work: multiplicative updates with the MM exponent of thesis
    Table 2.2 or the heuristic update (eq. 2.17), projected gradient (eq. 2.9-2.13),
    Hoyer sparseness (eq. 2.20), L1/L2 penalties, masks, dense or sparse X.
NMF
    The scikit-learn estimator over it, with ``transform(X, features=..., mask=...)``,
    ``inverse_transform(W, features=...)`` and ``partial_fit``; ``NMF.from_params(owner)``
    builds one from the NMF parameters of an estimator that takes them under NMF's names.
select_rank, RankSelection
    The number of components chosen by the error on held-out entries (masked fits).
beta_divergence
    D_beta(X | WH) (eq. 2.2-2.3), never densifying a sparse X.
match_components, dictionary_distance
    Comparing dictionaries up to scaling and permutation (Hungarian algorithm).
hoyer_sparseness, project_hoyer
    Hoyer's sparseness measure and projection.
LabelNMF, make_svm_baseline
    Weak supervision by label sets (thesis sections 3.3.2 and 5.4): NMF on stacked
    [features, labels], labels reconstructed from the features alone; the linear SVM baseline.
l_single, l_given_number, l_full, l_full_curve
    The scores of thesis section 3.3.3.
beta_nmf_out_of_core, save_npz_chunks, load_npz_chunks, hstack_row_chunks
    Larger than memory: ``beta_nmf`` and ``NMF`` also take a ``dask.array`` split by rows
    (the same iterates as in memory); a folder of ``.npz`` row chunks is fitted without
    loading it whole (the ``dask`` extra).
"""

from ._beta import elementwise_beta_divergence, mm_exponent
from ._dask import beta_nmf_out_of_core, hstack_row_chunks, load_npz_chunks, save_npz_chunks
from ._estimator import NMF
from ._problem import beta_divergence
from ._solver import beta_nmf
from ._updates import NMFResult
from .compare import ComponentMatching, dictionary_distance, match_components
from .labels import DEFAULT_THRESHOLD_GRID, LabelNMF, make_svm_baseline
from .rank import RankSelection, select_rank
from .scores import l_full, l_full_curve, l_given_number, l_single, threshold_scores
from .sparseness import hoyer_sparseness, project_hoyer

__all__ = [
    "NMF",
    "NMFResult",
    "beta_nmf",
    "beta_divergence",
    "elementwise_beta_divergence",
    "mm_exponent",
    "match_components",
    "dictionary_distance",
    "ComponentMatching",
    "hoyer_sparseness",
    "project_hoyer",
    "LabelNMF",
    "DEFAULT_THRESHOLD_GRID",
    "make_svm_baseline",
    "l_single",
    "l_given_number",
    "l_full",
    "l_full_curve",
    "threshold_scores",
    "select_rank",
    "RankSelection",
    "beta_nmf_out_of_core",
    "save_npz_chunks",
    "load_npz_chunks",
    "hstack_row_chunks",
]
