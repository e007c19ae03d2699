"""The multimodal NMF learner (Thesis section 6.4, eq. 6.3, Fig. 6.2).

Examples observed in several named modalities are stacked side by side,
``X = [X_1 / s_1, X_2 / s_2, ...]`` with ``s_m`` the average L1 norm of modality ``m``
over the training examples (so "the error in each modality is treated on a fair level"),
and factorized by I-divergence NMF, ``X ~ W H``: the rows of H = ``components_`` are the
multimodal atoms, ``H = [H_1, H_2, ...]`` split by modality. The coefficients ``w`` of an
example are the learner's *internal representation*. Orientation: the thesis writes
``V = (V_mod1; V_mod2; ...) ~ W H`` with examples as columns; its ``W_mod`` is our
``H_m.T`` and its internal representation ``h`` is our ``w``.

From any subset of modalities, :meth:`MultimodalNMF.transform` fits ``w`` with the
dictionary fixed, on the sub-dictionary of the observed modalities (eq. 6.3):

.. math:: w^* = \\arg\\min_{w \\ge 0} D_I\\big([x_m / s_m]_{m \\in S} \\,\\big|\\, w\\,[H_m]_{m \\in S}\\big)

and :meth:`MultimodalNMF.reconstruct` gives the expected perception in any modality,
``x_hat_m = s_m (w H_m)``, in the modality's own units.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import scipy.sparse as sp
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from .._persist import SaveLoadMixin
from .._validation import Interval, Options, check_nonnegative_matrix, validate_params
from ..errors import DataError, DataFormatError, MMConceptsError
from ..nmf import NMF

__all__ = ["MultimodalNMF", "FORMAT_VERSION"]

#: Version of the save format written by :meth:`MultimodalNMF.save` (version 1 files still load).
FORMAT_VERSION = 2


class MultimodalNMF(SaveLoadMixin, TransformerMixin, BaseEstimator):
    """NMF over any number of named modalities (Thesis section 6.4).

    Parameters
    ----------
    n_components : int, default=50
        Number of atoms k (the thesis uses k = 50).
    beta_loss : float or str, default="kullback-leibler"
        The beta-divergence (the thesis: I-divergence, beta = 1).
    max_iter : int, default=50
        Multiplicative-update iterations for fitting (the thesis: 50).
    transform_max_iter : int, optional
        Iterations for :meth:`transform` (default ``max_iter``).
    tol : float, default=0.0
        Stopping tolerance; 0 runs exactly ``max_iter`` iterations, as the thesis does.
    normalize : {"l1", None}, default="l1"
        "l1": each modality is divided by its average L1 norm over the training examples
        (the same factor is applied at transform and undone at reconstruction); None
        keeps the data as given.
    init : {"random", "nndsvd", "nndsvda", "nndsvdar"} or None, default="random"
        Initialization of the factorization (see :func:`mmconcepts.nmf.beta_nmf`). Random
        (seeded) factors scaled to the data, as in the thesis' experiments; "nndsvda"
        costs a truncated SVD of the stacked matrix (about 5 s for 900 x 110 000 HAC
        vectors, a third of the whole fit).
    random_state : int, Generator or None

    Attributes
    ----------
    modalities_ : list of str
        Modality names, in the order of the stacked columns.
    n_features_ : dict of str to int
    scales_ : dict of str to float
        ``s_m``, the average L1 norm of each modality on the training data (1 when
        ``normalize`` is None).
    components_ : ndarray of shape (n_components, sum of n_features)
        The multimodal dictionary H (the same array as ``nmf_.components_``).
    nmf_ : NMF
        The underlying factorization.

    Notes
    -----
    X is a mapping of modality names to matrices, not one 2-D array, so scikit-learn's
    ``check_estimator`` cannot run on this learner; it is still a scikit-learn estimator
    (``clone``, ``get_params``/``set_params``, ``NotFittedError``). :meth:`save` writes
    format version 2 (the inner :class:`~mmconcepts.nmf.NMF` saved as a nested model);
    :meth:`load` also reads the version-1 files of earlier mmconcepts (the dictionary and
    a header with the modalities, their widths and scales).
    """

    _parameter_constraints: ClassVar[dict] = {
        "n_components": [Interval("int", 1)],  # NMF's None (min(n_samples, n_features)) is not offered
        **{name: NMF._parameter_constraints[name]
           for name in ("beta_loss", "max_iter", "transform_max_iter", "tol", "random_state")},
        "normalize": [Options("l1", None)],
        "init": [Options("random", "nndsvd", "nndsvda", "nndsvdar"), None],  # no 'custom': fit takes no factors
    }
    _hints: ClassVar[dict] = {
        "init": "'custom' is not available: MultimodalNMF.fit takes no starting factors.",
    }
    _save_format_version: ClassVar[int] = FORMAT_VERSION

    def __init__(
        self,
        n_components: int = 50,
        *,
        beta_loss: float | str = "kullback-leibler",
        max_iter: int = 50,
        transform_max_iter: int | None = None,
        tol: float = 0.0,
        normalize: str | None = "l1",
        init: str | None = "random",
        random_state: Any = None,
    ) -> None:
        self.n_components = n_components
        self.beta_loss = beta_loss
        self.max_iter = max_iter
        self.transform_max_iter = transform_max_iter
        self.tol = tol
        self.normalize = normalize
        self.init = init
        self.random_state = random_state

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False  # X is a mapping of modality names to matrices
        tags.input_tags.dict = True
        tags.input_tags.sparse = True
        tags.input_tags.positive_only = True
        return tags

    # ------------------------------------------------------------------ helpers
    def _nmf(self) -> NMF:
        return NMF(
            self.n_components,
            beta_loss=self.beta_loss,
            max_iter=self.max_iter,
            transform_max_iter=self.transform_max_iter,
            tol=self.tol,
            init=self.init,
            random_state=self.random_state,
        )

    @staticmethod
    def _check_modalities(X: Any) -> dict[str, Any]:
        if not isinstance(X, Mapping) or not X:
            raise DataError(
                "X must be a non-empty mapping of modality names to (n_samples, n_features) arrays, "
                f"e.g. {{'sound': X_sound, 'motion': X_motion}}; got {type(X).__name__}."
            )
        out: dict[str, Any] = {}
        n = None
        for name, Xm in X.items():
            if not isinstance(name, str):
                raise DataError(f"modality names must be strings; got {name!r}.")
            try:
                Xm = check_nonnegative_matrix(Xm, f"modality {name!r}")
            except MMConceptsError:
                raise
            except (TypeError, ValueError) as exc:  # e.g. an object array holding text
                raise DataError(f"modality {name!r} must be a numeric matrix ({exc}).") from None
            if n is None:
                n = Xm.shape[0]
            elif Xm.shape[0] != n:
                raise DataError(
                    f"modality {name!r} has {Xm.shape[0]} examples but the first modality has {n}; "
                    "every modality needs one row per example."
                )
            out[name] = Xm
        return out

    @staticmethod
    def _columns(modalities: Sequence[str], n_features: Mapping[str, int]) -> dict[str, slice]:
        """The columns of each modality in the stacked matrix, in the order of ``modalities``."""
        out, start = {}, 0
        for name in modalities:
            out[name] = slice(start, start + int(n_features[name]))
            start += int(n_features[name])
        return out

    @staticmethod
    def _stack(X: Mapping[str, Any], modalities: Sequence[str], n_features: Mapping[str, int],
               scales: Mapping[str, float]) -> tuple[Any, np.ndarray]:
        """The weighted stacked matrix of the given modalities and its columns in the full dictionary."""
        columns = MultimodalNMF._columns(modalities, n_features)
        blocks, cols = [], []
        for name in modalities:
            if name not in X:
                continue
            Xm = X[name]
            if Xm.shape[1] != n_features[name]:
                raise DataError(
                    f"modality {name!r} has {Xm.shape[1]} features; the learner was fitted with {n_features[name]}."
                )
            blocks.append(Xm * (1.0 / scales[name]))
            cols.append(np.arange(columns[name].start, columns[name].stop))
        if any(sp.issparse(b) for b in blocks):
            stacked = sp.hstack([sp.csr_matrix(b) for b in blocks], format="csr")
        else:
            stacked = np.hstack(blocks)
        return stacked, np.concatenate(cols)

    def _slice(self, modality: str) -> slice:
        if modality not in self.n_features_:
            raise DataError(f"unknown modality {modality!r}; the learner knows {self.modalities_}.")
        return self._columns(self.modalities_, self.n_features_)[modality]

    # ------------------------------------------------------------------ API
    def fit(self, X: Mapping[str, Any], y: Any = None) -> MultimodalNMF:
        """Learn the multimodal dictionary from examples observed in every modality.

        Parameters
        ----------
        X : mapping of str to {array-like, sparse matrix} of shape (n_samples, n_features_m)
            One nonnegative matrix per modality, rows aligned (row i of every modality is
            example i).
        y : ignored

        Returns
        -------
        self
        """
        self.fit_transform(X)
        return self

    def fit_transform(self, X: Mapping[str, Any], y: Any = None) -> np.ndarray:
        """Fit, and return the internal representations of the training examples.

        Returns
        -------
        ndarray of shape (n_samples, n_components)
        """
        validate_params(self, self._parameter_constraints, hints=self._hints)
        mods = self._check_modalities(X)
        scales = {}
        for name, Xm in mods.items():
            l1 = np.asarray(abs(Xm).sum(axis=1)).ravel().mean() if self.normalize == "l1" else 1.0
            if not l1 > 0:
                raise DataError(f"modality {name!r} is all zeros on the training data; it cannot be normalised.")
            scales[name] = float(l1)
        names = list(mods)
        n_features = {name: int(Xm.shape[1]) for name, Xm in mods.items()}
        stacked, _ = self._stack(mods, names, n_features, scales)
        nmf = self._nmf()
        W = nmf.fit_transform(stacked)
        self.modalities_, self.n_features_, self.scales_ = names, n_features, scales
        self.nmf_ = nmf
        self.components_ = nmf.components_
        return W

    def transform(self, X: Mapping[str, Any]) -> np.ndarray:
        """Internal representations from any subset of the modalities (eq. 6.3).

        Parameters
        ----------
        X : mapping of str to array-like
            The observed modalities (any non-empty subset of ``modalities_``), rows aligned.

        Returns
        -------
        ndarray of shape (n_samples, n_components)
        """
        check_is_fitted(self)
        if isinstance(X, Mapping):
            unknown = [k for k in X if k not in self.modalities_]
            if unknown:
                raise DataError(f"unknown modality {unknown[0]!r}; the learner knows {self.modalities_}.")
        mods = self._check_modalities(X)
        stacked, cols = self._stack(mods, self.modalities_, self.n_features_, self.scales_)
        return self.nmf_.transform(stacked, features=cols)

    def reconstruct(self, W: Any, modality: str | Sequence[str]) -> np.ndarray:
        """Expected perception in ``modality`` from internal representations, in its own units.

        Parameters
        ----------
        W : array-like of shape (n_samples, n_components)
        modality : str or sequence of str
            One modality, or several (their reconstructions side by side).

        Returns
        -------
        ndarray of shape (n_samples, sum of the modalities' n_features)
        """
        check_is_fitted(self)
        if isinstance(modality, str):
            names = [modality]
        elif isinstance(modality, Sequence) and modality and all(isinstance(m, str) for m in modality):
            names = list(modality)
        else:
            raise DataError(f"modality must be a modality name or a non-empty sequence of names among "
                            f"{self.modalities_}; got {modality!r}.")
        try:
            W = np.asarray(W, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise DataError(f"W must be a numeric array of shape (n_samples, {self.components_.shape[0]}) ({exc}).") \
                from None
        if W.ndim != 2 or W.shape[1] != self.components_.shape[0]:
            raise DataError(f"W must be (n_samples, {self.components_.shape[0]}); got shape {W.shape}.")
        if not np.isfinite(W).all() or (W < 0).any():
            raise DataError("W must be finite and nonnegative (internal representations from transform).")
        out = []
        for name in names:
            out.append(W @ self.components_[:, self._slice(name)] * self.scales_[name])
        return np.hstack(out)

    def component_slice(self, modality: str) -> slice:
        """Columns of ``components_`` belonging to ``modality``."""
        check_is_fitted(self)
        return self._slice(modality)

    # ------------------------------------------------------------------ persistence
    def _get_state(self) -> dict[str, Any]:
        state = super()._get_state()
        state.pop("components_", None)  # the same array as nmf_.components_, saved once with nmf_
        return state

    def _set_state(self, state: dict[str, Any]) -> None:
        super()._set_state(state)
        self.components_ = self.nmf_.components_

    def _check_loaded_state(self) -> None:
        """The loaded modalities, widths, scales and dictionary agree (an edited file fails here, naming itself)."""
        names = self.modalities_
        if not (isinstance(names, list) and names and all(isinstance(m, str) for m in names)
                and len(set(names)) == len(names)):
            raise DataError(f"modalities_ must be a non-empty list of distinct names; got {names!r}.")
        for what, table in (("n_features_", self.n_features_), ("scales_", self.scales_)):
            if not isinstance(table, dict) or sorted(table) != sorted(names):
                raise DataError(f"{what} must have one entry per modality {names}; got {table!r}.")
        if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in self.n_features_.values()):
            raise DataError(f"n_features_ must be positive integers; got {self.n_features_!r}.")
        if not all(isinstance(v, float) and np.isfinite(v) and v > 0 for v in self.scales_.values()):
            raise DataError(f"scales_ must be finite positive numbers; got {self.scales_!r}.")
        if not isinstance(self.nmf_, NMF):
            raise DataError(f"nmf_ must be a fitted NMF; got {type(self.nmf_).__name__}.")
        H = self.components_
        want = (int(self.n_components), sum(self.n_features_.values()))
        if not isinstance(H, np.ndarray) or H.dtype.kind != "f" or H.shape != want:
            raise DataError(f"the dictionary must be a float array of shape {want}; got "
                            f"{getattr(H, 'shape', type(H).__name__)}.")
        if not np.isfinite(H).all() or (H < 0).any():
            raise DataError("the dictionary holds negative, NaN or infinite values.")

    @classmethod
    def _load_other_version(cls, path: Path, header: dict, z: Any) -> MultimodalNMF:
        """Read a version-1 file: ``components`` and a header with modalities, n_features, scales."""
        if header.get("format_version") != 1:
            return super()._load_other_version(path, header, z)
        try:
            components = np.asarray(z["components"], dtype=np.float64)
            model = cls(**header["params"])
            names = list(header["modalities"])
            n_features = {m: int(header["n_features"][m]) for m in names}
            scales = {m: float(header["scales"][m]) for m in names}
        except (KeyError, TypeError, ValueError) as e:
            raise DataFormatError(f"{path}: a corrupt saved MultimodalNMF ({type(e).__name__}: {e}).") from None
        if components.shape != (model.n_components, sum(n_features.values())):
            raise DataFormatError(f"{path}: dictionary of shape {components.shape} does not match its header.")
        # A version-1 file holds only the inner NMF's dictionary: the NMF is restored from
        # the part of a saved NMF's state that its transform uses (dictionary and shape).
        nmf = model._nmf()
        nmf._set_state({"components_": components, "n_components_": components.shape[0],
                        "n_features_in_": components.shape[1]})
        model._set_state({"modalities_": names, "n_features_": n_features, "scales_": scales, "nmf_": nmf})
        try:
            model._check_loaded_state()
        except ValueError as e:
            raise DataFormatError(f"{path}: a corrupt saved MultimodalNMF ({e}).") from None
        return model
