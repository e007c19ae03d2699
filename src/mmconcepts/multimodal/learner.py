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

import json
import numbers
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
from sklearn.exceptions import NotFittedError

from .. import __version__
from .._validation import check_nonnegative_matrix
from ..errors import DataError, DataFormatError, ParameterError, VersionMismatchError
from ..nmf import NMF

__all__ = ["MultimodalNMF", "FORMAT_VERSION"]

#: Version of the save format written by :meth:`MultimodalNMF.save`.
FORMAT_VERSION = 1


class MultimodalNMF:
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
    init : str, default="random"
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
        The multimodal dictionary H.
    nmf_ : NMF
        The underlying factorization.
    """

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
            Xm = check_nonnegative_matrix(Xm, f"modality {name!r}")
            if n is None:
                n = Xm.shape[0]
            elif Xm.shape[0] != n:
                raise DataError(
                    f"modality {name!r} has {Xm.shape[0]} examples but the first modality has {n}; "
                    "every modality needs one row per example."
                )
            out[name] = Xm
        return out

    def _check_fitted(self) -> None:
        if not hasattr(self, "components_"):
            raise NotFittedError("MultimodalNMF is not fitted yet; call fit first.")

    def _stack(self, X: dict[str, Any]) -> tuple[Any, np.ndarray]:
        """The weighted stacked matrix of the given modalities and its column indices."""
        blocks, cols = [], []
        for name in self.modalities_:
            if name not in X:
                continue
            Xm = X[name]
            if Xm.shape[1] != self.n_features_[name]:
                raise DataError(
                    f"modality {name!r} has {Xm.shape[1]} features; the learner was fitted with {self.n_features_[name]}."
                )
            blocks.append(Xm * (1.0 / self.scales_[name]))
            cols.append(np.arange(*self._slices[name].indices(self.components_.shape[1])))
        if any(sp.issparse(b) for b in blocks):
            stacked = sp.hstack([sp.csr_matrix(b) for b in blocks], format="csr")
        else:
            stacked = np.hstack(blocks)
        return stacked, np.concatenate(cols)

    def _set_layout(self, names: Sequence[str], widths: Sequence[int]) -> None:
        self.modalities_ = list(names)
        self.n_features_ = {n: int(w) for n, w in zip(names, widths)}
        self._slices = {}
        start = 0
        for n, w in zip(names, widths):
            self._slices[n] = slice(start, start + int(w))
            start += int(w)

    # ------------------------------------------------------------------ API
    def fit(self, X: Mapping[str, Any], y: Any = None) -> MultimodalNMF:
        """Learn the multimodal dictionary from examples observed in every modality.

        Parameters
        ----------
        X : mapping of str to {array-like, sparse matrix} of shape (n_samples, n_features_m)
            One nonnegative matrix per modality, rows aligned (row i of every modality is
            example i).
        """
        self.fit_transform(X)
        return self

    def fit_transform(self, X: Mapping[str, Any], y: Any = None) -> np.ndarray:
        """Fit, and return the internal representations of the training examples."""
        if self.normalize not in ("l1", None):
            raise ParameterError(f"normalize must be 'l1' or None; got {self.normalize!r}.")
        if not isinstance(self.n_components, numbers.Integral) or self.n_components < 1:
            raise ParameterError(f"n_components must be a positive int; got {self.n_components!r}.")
        mods = self._check_modalities(X)
        scales = {}
        for name, Xm in mods.items():
            l1 = np.asarray(abs(Xm).sum(axis=1)).ravel().mean() if self.normalize == "l1" else 1.0
            if not l1 > 0:
                raise DataError(f"modality {name!r} is all zeros on the training data; it cannot be normalised.")
            scales[name] = float(l1)
        self.scales_ = scales
        self._set_layout(list(mods), [Xm.shape[1] for Xm in mods.values()])
        self.components_ = np.zeros((self.n_components, sum(self.n_features_.values())))  # for _stack's widths
        stacked, _ = self._stack(mods)
        self.nmf_ = self._nmf()
        W = self.nmf_.fit_transform(stacked)
        self.components_ = self.nmf_.components_
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
        self._check_fitted()
        if isinstance(X, Mapping):
            unknown = [k for k in X if k not in self.modalities_]
            if unknown:
                raise DataError(f"unknown modality {unknown[0]!r}; the learner knows {self.modalities_}.")
        mods = self._check_modalities(X)
        stacked, cols = self._stack(mods)
        return self.nmf_.transform(stacked, features=cols)

    def reconstruct(self, W: Any, modality: str | Sequence[str]) -> np.ndarray:
        """Expected perception in ``modality`` from internal representations, in its own units.

        Parameters
        ----------
        W : array-like of shape (n_samples, n_components)
        modality : str or sequence of str
            One modality, or several (their reconstructions side by side).
        """
        self._check_fitted()
        names = [modality] if isinstance(modality, str) else list(modality)
        W = np.asarray(W, dtype=np.float64)
        if W.ndim != 2 or W.shape[1] != self.components_.shape[0]:
            raise DataError(f"W must be (n_samples, {self.components_.shape[0]}); got shape {W.shape}.")
        out = []
        for name in names:
            if name not in self._slices:
                raise DataError(f"unknown modality {name!r}; the learner knows {self.modalities_}.")
            out.append(W @ self.components_[:, self._slices[name]] * self.scales_[name])
        return np.hstack(out)

    def component_slice(self, modality: str) -> slice:
        """Columns of ``components_`` belonging to ``modality``."""
        self._check_fitted()
        if modality not in self._slices:
            raise DataError(f"unknown modality {modality!r}; the learner knows {self.modalities_}.")
        return self._slices[modality]

    def get_params(self, deep: bool = True) -> dict:
        return {k: getattr(self, k) for k in (
            "n_components", "beta_loss", "max_iter", "transform_max_iter", "tol", "normalize", "init", "random_state")}

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | Path) -> Path:
        """Save to ``path`` (a ``.npz`` holding the dictionary and a JSON header); no pickle.

        The write is atomic (a temporary file renamed into place).
        """
        self._check_fitted()
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(".npz")
        params = self.get_params()
        if not isinstance(params["random_state"], (int, type(None))):
            params["random_state"] = None
        header = {
            "format": "mmconcepts.MultimodalNMF",
            "format_version": FORMAT_VERSION,
            "mmconcepts_version": __version__,
            "params": params,
            "modalities": self.modalities_,
            "n_features": self.n_features_,
            "scales": self.scales_,
        }
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez(tmp, components=self.components_, header=np.array(json.dumps(header)))
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> MultimodalNMF:
        """Load a learner written by :meth:`save`.

        Raises
        ------
        DataFormatError
            If the file is not a saved MultimodalNMF or is corrupt.
        VersionMismatchError
            If it was written in another save-format version.
        """
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                header = json.loads(str(z["header"]))
                components = np.asarray(z["components"], dtype=np.float64)
        except (OSError, ValueError, KeyError) as e:
            raise DataFormatError(f"{path}: not a saved MultimodalNMF ({e}).") from None
        if header.get("format") != "mmconcepts.MultimodalNMF":
            raise DataFormatError(f"{path}: not a saved MultimodalNMF (format {header.get('format')!r}).")
        if header.get("format_version") != FORMAT_VERSION:
            raise VersionMismatchError(
                f"{path}: saved with format version {header.get('format_version')} "
                f"(mmconcepts {header.get('mmconcepts_version')}); this mmconcepts reads version {FORMAT_VERSION}."
            )
        model = cls(**header["params"])
        model._set_layout(header["modalities"], [header["n_features"][m] for m in header["modalities"]])
        model.scales_ = {k: float(v) for k, v in header["scales"].items()}
        if components.shape != (model.n_components, sum(model.n_features_.values())):
            raise DataFormatError(f"{path}: dictionary of shape {components.shape} does not match its header.")
        model.nmf_ = model._nmf()
        model.nmf_._set_fitted(components, None)
        model.components_ = components
        return model
