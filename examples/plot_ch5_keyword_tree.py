"""
Keyword recognition with the incremental cluster tree
=====================================================

Section 5.2 of the thesis learns keywords from whole utterances without segmenting them:
every utterance is cut into short overlapping windows of MFCC frames, each window is
inserted into an incremental hierarchical clustering tree whose leaves (balls of radius
``r_max`` under the DTW distance) are the *acoustic events*, and each event counts the
keywords of the utterances it occurred in. A new utterance's windows are looked up in the
tree and its events vote, weighted by TF-IDF (eq. 5.1).

The sequences here are generated, MFCC-like frame sequences (13 coefficients per 10 ms
frame): each word is a smooth random trajectory, said by four speakers with their own
offset, at varying speed and with noise; an utterance is the keyword between one or two
carrier words. With real recordings, the windows come from
:func:`mmconcepts.sound.mfcc_windows` of the audio instead (see the chapter 5 guide).
"""

# %%
# Generated utterances
# --------------------
import matplotlib.pyplot as plt
import numpy as np

from mmconcepts.sound import ClusterTree, TreeVotingClassifier, sliding_windows

rng = np.random.default_rng(0)
n_mfcc = 13
KEYWORDS = ["ball", "car", "dog", "shoe", "book"]
FILLERS = ["look", "the", "at", "nice", "is", "where", "now", "here"]


def smooth_word(n_frames):
    """A word: a smooth random trajectory in MFCC space."""
    knots = rng.normal(0, 3, (4, n_mfcc))
    t = np.linspace(0, 3, n_frames)
    return np.stack([np.interp(t, np.arange(4), knots[:, j]) for j in range(n_mfcc)], 1)


WORDS = {w: smooth_word(int(rng.integers(18, 28))) for w in KEYWORDS + FILLERS}
SPEAKERS = rng.normal(0, 1.0, (4, n_mfcc))  # each speaker's offset


def say(word, speaker):
    """One pronunciation: resampled in time (speed 0.8-1.25), speaker offset, noise."""
    proto = WORDS[word]
    n = max(8, int(len(proto) / rng.uniform(0.8, 1.25)))
    t = np.linspace(0, len(proto) - 1, n)
    frames = np.stack([np.interp(t, np.arange(len(proto)), proto[:, j]) for j in range(n_mfcc)], 1)
    return frames + SPEAKERS[speaker] + rng.normal(0, 1.0, frames.shape)


def utterance(keyword, speaker):
    words = list(rng.choice(FILLERS, int(rng.integers(1, 3)), replace=False))
    words.insert(int(rng.integers(0, len(words) + 1)), keyword)
    return np.concatenate([say(w, speaker) for w in words])


n_train, n_test = 150, 60
tags = list(rng.choice(KEYWORDS, n_train + n_test))
speakers = rng.integers(0, 4, n_train + n_test)
# 8-frame windows (80 ms) sliding by a third of their length, as in the thesis.
windows = [sliding_windows(utterance(k, s), 8) for k, s in zip(tags, speakers)]
print(len(windows), "utterances;", windows[0].shape, "(windows, frames, coefficients) for the first")

# %%
# Choosing ``r_max``
# ------------------
# The leaf radius sets the size of the vocabulary of acoustic events and depends on the
# scale of the features: a quantile of the DTW distances between windows is a usable
# start (the thesis tuned it on its data).
from mmconcepts.sound import dtw_one_to_many

sample = np.concatenate(windows[:20])
d = np.concatenate([dtw_one_to_many(w, sample) for w in sample[:30]])
r_max = float(np.quantile(d[d > 0], 0.05))
print(f"r_max = {r_max:.1f} (5 % quantile of {d.size} DTW distances)")

# %%
# Learning incrementally
# ----------------------
# Utterances arrive in batches (:meth:`~mmconcepts.sound.TreeVotingClassifier.partial_fit`);
# after each batch the recogniser is scored on the held-out utterances, as in the
# protocol of thesis Fig. 5.3.
model = TreeVotingClassifier(ClusterTree(r_max, metric="dtw", random_state=0))
test_w, test_tags = windows[n_train:], tags[n_train:]
seen, scores, n_events = [], [], []
for start in range(0, n_train, 30):
    batch = slice(start, start + 30)
    model.partial_fit(windows[batch], tags[batch])
    seen.append(start + 30)
    scores.append(model.score(test_w, test_tags))
    n_events.append(model.tree_.n_leaves_)
    print(f"{seen[-1]:4d} utterances: {model.tree_.n_leaves_:5d} acoustic events, "
          f"held-out accuracy {scores[-1]:.2f}")

# %%
# Recognition rate against the number of utterances heard
# -------------------------------------------------------
fig, ax = plt.subplots(figsize=(5.5, 3.5))
ax.plot(seen, scores, "o-", label="cluster tree + TF-IDF voting")
ax.axhline(1 / len(KEYWORDS), color="0.5", ls="--", label=f"chance (1/{len(KEYWORDS)})")
ax.set(xlabel="training utterances", ylabel="held-out accuracy", ylim=(0, 1.05),
       title="Incremental keyword learning (generated sequences)")
ax.legend(loc="center right")
fig.tight_layout()
plt.show()
