"""
NMF with missing values and a subset of features
================================================

Beta-NMF (thesis chapter 2) learns a dictionary ``H`` of nonnegative atoms such that
``X ~ W @ H``. Two things the rest of the thesis relies on are shown here:

* a **mask** of observed cells: unobserved cells have no influence at all on the fit
  (their values may be anything, even NaN);
* **a subset of features**: with the dictionary fixed, the coefficients ``W`` of new
  examples are found from some columns only, and the other columns are reconstructed.
  Chapter 3 predicts labels from motion this way, chapter 6 a modality from another.

Orientation: ``X`` is ``(n_samples, n_features)``, ``components_`` is ``H``, one atom per
row (the thesis writes ``V ~ W H`` with examples as columns, so its ``W`` is our ``H.T``).
"""

# %%
# Data drawn from a known dictionary
# ----------------------------------
# Five nonnegative atoms over 40 features, sparse-ish coefficients, Poisson counts.
import matplotlib.pyplot as plt
import numpy as np

from mmconcepts.nmf import NMF, match_components

rng = np.random.default_rng(0)
k, n_features, n_samples = 5, 40, 300
H_true = rng.gamma(0.5, 1.0, (k, n_features))
W_true = rng.gamma(0.5, 4.0, (n_samples, k))
X = rng.poisson(W_true @ H_true).astype(float)
print(X.shape, f"{(X == 0).mean():.0%} zeros")

# %%
# A fit that never sees 30 % of the cells
# ---------------------------------------
# The hidden cells are overwritten with garbage (1e6) to show that they play no role.
mask = rng.random(X.shape) > 0.3
X_garbage = np.where(mask, X, 1e6)

full = NMF(k, beta_loss="kullback-leibler", max_iter=300, random_state=0).fit(X)
masked = NMF(k, beta_loss="kullback-leibler", max_iter=300, random_state=0).fit(X_garbage, mask=mask)

# Dictionaries are compared up to scaling and permutation (Hungarian algorithm):
# the mean cosine distance between matched atoms, 0 for a rescaled, permuted copy.
d_full = match_components(H_true, full.components_).distance
d_masked = match_components(H_true, masked.components_).distance
print(f"distance to the true dictionary: all cells {d_full:.3f}, 70 % of the cells {d_masked:.3f}")

# %%
# Reconstructing unseen features
# ------------------------------
# New examples show only their first 30 features; their coefficients are fit on that part
# of the dictionary, and the last 10 features are predicted from them.
W_new = rng.gamma(0.5, 4.0, (50, k))
X_new = W_new @ H_true  # the noise-free truth, to measure the prediction
seen, hidden = slice(0, 30), slice(30, 40)
W_hat = full.transform(rng.poisson(X_new[:, seen]).astype(float), features=seen)
X_hidden_hat = full.inverse_transform(W_hat, features=hidden)
err = np.linalg.norm(X_hidden_hat - X_new[:, hidden]) / np.linalg.norm(X_new[:, hidden])
baseline = np.linalg.norm(X[:, hidden].mean(0) - X_new[:, hidden]) / np.linalg.norm(X_new[:, hidden])
print(f"relative error on the 10 hidden features: {err:.2f} (predicting the mean: {baseline:.2f})")

# %%
# The atoms, matched to the true ones
# -----------------------------------
m = match_components(H_true, masked.components_)
fig, axes = plt.subplots(k, 1, figsize=(6, 6), sharex=True)
for ax, i, j in zip(axes, m.rows, m.cols):
    ax.bar(np.arange(n_features), H_true[i] / H_true[i].sum(), color="0.7", label="true atom")
    ax.plot(masked.components_[j] / masked.components_[j].sum(), "C3.-", label="learnt with 30 % hidden")
    ax.set_ylabel(f"atom {i}")
axes[0].legend(loc="upper right", fontsize="small")
axes[-1].set_xlabel("feature")
fig.suptitle("Atoms (normalised to sum 1) learnt from a masked matrix")
fig.tight_layout()
plt.show()
