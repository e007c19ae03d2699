"""
Choosing the number of components by held-out entries
=====================================================

How many atoms does a nonnegative matrix need? :func:`mmconcepts.nmf.select_rank` holds
out a random tenth of the entries of ``X``, fits ``X ~ W @ H`` on the others with a mask
(the held-out entries have no influence on the fit), and measures the error on the
held-out entries. The training error keeps falling as the rank grows; the held-out error
falls until the rank explains the data, and then rises as the extra atoms fit the noise.

Orientation: ``X`` is ``(n_samples, n_features)``, ``H`` is ``components_``.
"""

# %%
# Data of rank 4 with a little noise
# ----------------------------------
import matplotlib.pyplot as plt
import numpy as np

from mmconcepts.nmf import select_rank

rng = np.random.default_rng(0)
V = rng.gamma(1.0, 1.0, (60, 4)) @ rng.gamma(1.0, 1.0, (4, 40))
X = np.maximum(V + 0.05 * V.std() * rng.standard_normal(V.shape), 0.0)

# %%
# Held-out error against the rank
# -------------------------------
# Five splits; every rank is scored on the same held-out entries. The chosen rank is the
# smallest whose mean error is within one standard error of the best (``rule``).
result = select_rank(X, range(1, 9), n_splits=5, holdout=0.1, random_state=0)
print(f"chosen rank: {result.rank} (smallest mean error at rank {result.best_rank})")

fig, ax = plt.subplots(figsize=(5, 3.5))
ax.errorbar(result.ranks, result.mean, yerr=result.sem, marker="o", capsize=3, label="held-out entries")
ax.plot(result.ranks, result.train.mean(axis=1), "s--", color="0.5", label="entries the fit saw")
ax.axvline(result.rank, color="C3", lw=1, ls=":", label=f"chosen rank {result.rank}")
ax.set_yscale("log")
ax.set_xlabel("number of components")
ax.set_ylabel("mean divergence per entry")
ax.legend()
fig.tight_layout()
plt.show()
