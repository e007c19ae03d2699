"""
Multimodal concepts from three modalities
=========================================

Chapter 6 of the thesis learns concepts from examples in which a word is heard, a gesture
is seen and an object is shown at the same time, without ever being told which concept an
example belongs to. :class:`~mmconcepts.multimodal.MultimodalNMF` stacks the modalities
(each divided by its average L1 norm) and factorises them with the I-divergence
(section 6.4): every atom spans all modalities, so coefficients found from one modality
reconstruct the others.

The cross-modal matching protocol of section 6.6.1 (Fig. 6.3) then asks: given a test
example in one modality (a spoken word), which of several reference examples in another
modality (gestures, one per concept) goes with it? Chance is one over the number of
concepts.

The data here are generated: 10 concepts, each with its own typical histogram in each
modality, observed through Poisson noise and mixed with a concept-independent background.
"""

# %%
# Paired examples in three modalities
# -----------------------------------
import matplotlib.pyplot as plt
import numpy as np

from mmconcepts.multimodal import MultimodalNMF, crossmodal_distances, matching_success_rate

rng = np.random.default_rng(0)
n_concepts = 10
widths = {"sound": 60, "motion": 40, "image": 80}
protos = {m: rng.gamma(0.3, 1.0, (n_concepts, w)) for m, w in widths.items()}


def draw(concepts):
    """One example per concept id in each modality: concept histogram + background, Poisson."""
    out = {}
    for m, P in protos.items():
        P = P / P.sum(1, keepdims=True)
        background = rng.dirichlet(np.ones(widths[m]), len(concepts))
        out[m] = rng.poisson(40 * (0.6 * P[concepts] + 0.4 * background)).astype(float)
    return out


y_train = rng.integers(0, n_concepts, 300)
y_test = rng.integers(0, n_concepts, 100)
y_ref = np.repeat(np.arange(n_concepts), 10)
X_train, X_test, X_ref = draw(y_train), draw(y_test), draw(y_ref)
print({m: X.shape for m, X in X_train.items()})

# %%
# Learning without the concept labels
# -----------------------------------
# The labels ``y_*`` are only used to score the matching; the learner never sees them.
model = MultimodalNMF(20, max_iter=50, random_state=0).fit(X_train)
print("dictionary:", model.components_.shape, "over", model.modalities_)

# Internal representation of spoken words alone, and the gestures it predicts.
h = model.transform({"sound": X_test["sound"]})
motion_hat = model.reconstruct(h, "motion")
print("coefficients from sound only:", h.shape, "-> expected motion:", motion_hat.shape)

# %%
# Cross-modal matching
# --------------------
# Distances are computed in the internal space (both sides transformed), with the
# cosine dissimilarity; the thesis compares three spaces and three measures (Table 6.2).
pairs = [("sound", "motion"), ("motion", "sound"), ("image", "sound"), ("sound", "image")]
rates = {}
for test, ref in pairs:
    D = crossmodal_distances(model, {test: X_test[test]}, {ref: X_ref[ref]}, space="internal", metric="cosine")
    rates[f"{test} -> {ref}"] = matching_success_rate(D, y_test, y_ref, random_state=0)

# Two modalities together (sound and image) to recognise the third (Fig. 6.7).
D = crossmodal_distances(model, {"sound": X_test["sound"], "image": X_test["image"]},
                         {"motion": X_ref["motion"]}, space="internal", metric="cosine")
rates["sound + image -> motion"] = matching_success_rate(D, y_test, y_ref, random_state=0)

# A learner of the same data with the pairing broken: the modalities' rows are shuffled
# independently, so no atom can link them (the thesis' "unrelated pairs").
shuffled = {m: X[rng.permutation(len(X))] for m, X in X_train.items()}
control = MultimodalNMF(20, max_iter=50, random_state=0).fit(shuffled)
D = crossmodal_distances(control, {"sound": X_test["sound"]}, {"motion": X_ref["motion"]},
                         space="internal", metric="cosine")
rates["sound -> motion, unpaired training"] = matching_success_rate(D, y_test, y_ref, random_state=0)
for name, rate in rates.items():
    print(f"{name:36s} {rate:.2f}")

# %%
# Success rates against chance
# ----------------------------
fig, ax = plt.subplots(figsize=(6, 3.5))
names = list(rates)
ax.barh(names, [rates[n] for n in names], color=["C0"] * 5 + ["0.6"])
ax.axvline(1 / n_concepts, color="k", ls="--", label=f"chance (1/{n_concepts})")
ax.set(xlabel="matching success rate", xlim=(0, 1), title="Cross-modal matching (generated data)")
ax.invert_yaxis()
ax.legend(loc="lower right")
fig.tight_layout()
plt.show()
