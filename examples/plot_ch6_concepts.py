"""
Seeing the learnt concepts
==========================

A multimodal dictionary learnt without labels (chapter 6 of the thesis) holds atoms made of
histograms of colours, of acoustic co-occurrences and of joint angles: nobody can read them
directly. :mod:`mmconcepts.plot` shows them through what a person can look at and listen
to: for each atom, the examples whose internal representation is most made of it
(:func:`~mmconcepts.multimodal.top_examples`), as images, spectrograms, joint-angle curves
and stick figures; which labels each atom aligns with; the confusion matrix of recognising
a concept across modalities; and the activation of each concept along a stream of speech
cut into sliding windows (section 6.6.2, Fig. 6.9).

The data are generated, so the example runs in seconds with no data folder: six concepts,
each an object (:func:`mmconcepts.vision.make_objects`, one object seen from many
viewpoints), a gesture of the thesis' Table B.2 (:func:`mmconcepts.motion.synthetic.simulate_choreography`,
a simulated Kinect skeleton) and a spoken word. The words are made here from vowels and
consonant bursts (two formants on a harmonic voice, said by three voices at varying speed),
a crude stand-in for speech that has the structure a spectrogram shows. With real
recordings (FSDD, ETH-80, MSR Action3D, see the data sets page), only the loading changes.
"""

# %%
# Six concepts in three modalities
# --------------------------------
# Example ``e`` of concept ``c`` pairs view ``e`` of object ``c``, performance ``e`` of
# gesture ``c`` and utterance ``e`` of word ``c``; examples 0-9 of each concept train, 10-15
# are held out. The learner never sees the concept labels ``y``.
import matplotlib.pyplot as plt
import numpy as np
from scipy import signal

from mmconcepts.motion import JOINT_ANGLE_NAMES, MotionHistograms, joint_angles
from mmconcepts.motion.synthetic import simulate_choreography
from mmconcepts.multimodal import MultimodalNMF, crossmodal_distances, pairwise_divergence
from mmconcepts.sound import HAC, MFCCConfig, mfcc, sliding_windows
from mmconcepts.vision import ColorHistograms, make_objects

rng = np.random.default_rng(0)
WORDS = ["ball", "cup", "dog", "shoe", "book", "car"]
GESTURES = [5, 19, 24, 28, 40, 46]  # raise the right arm, clap, walk, leg flag, bend left elbow, wave left hand
n_concepts, n_each, n_train = 6, 16, 10
SR = 8000
# Eight syllables: a consonant burst (band centre in Hz) and a vowel (two formants in Hz). Words
# share syllables, as "ball" and "book" share a sound, so some can be confused.
SYLLABLE = [(1300, (730, 1090)), (2900, (270, 2290)), (1900, (300, 870)), (2400, (530, 1840)),
            (1600, (570, 840)), (3100, (660, 1720)), (2100, (440, 1020)), (1400, (400, 2000))]
SYLLABLES = {w: [SYLLABLE[a], SYLLABLE[b]] for w, (a, b) in zip(WORDS, [(0, 1), (2, 3), (4, 5), (6, 5), (0, 7),
                                                                       (2, 6)])}


def say(word, f0, rng):
    """One utterance of ``word`` by a voice of pitch ``f0``: speed, formants and noise vary."""
    tempo, shift = rng.uniform(0.85, 1.15), rng.uniform(0.95, 1.05)
    parts = [np.zeros(int(rng.uniform(0.05, 0.15) * SR))]
    for burst, (F1, F2) in SYLLABLES[word]:
        noise = rng.normal(size=int(0.05 * SR * tempo))
        sos = signal.butter(4, [0.8 * burst, 1.2 * burst], btype="bandpass", fs=SR, output="sos")
        parts.append(0.3 * signal.sosfilt(sos, noise) * np.hanning(noise.size))
        n = int(0.16 * SR * tempo)
        pitch = f0 * np.linspace(1.1, 0.9, n)
        phase = 2 * np.pi * np.cumsum(pitch) / SR
        vowel = np.zeros(n)
        for h in range(1, int(SR / 2 / f0)):
            f = h * pitch
            gain = np.exp(-((f - shift * F1) / 120) ** 2) + 0.6 * np.exp(-((f - shift * F2) / 180) ** 2) + 0.02
            vowel += gain * np.sin(h * phase)
        parts.append(0.15 * vowel * np.hanning(n))
    parts.append(np.zeros(int(rng.uniform(0.05, 0.15) * SR)))
    y = np.concatenate(parts)
    return (y + 0.003 * rng.normal(size=y.size)).astype(np.float32)


objects = make_objects(n_concepts, n_each, size=64, random_state=0)
y = np.repeat(np.arange(n_concepts), n_each)
names = np.array(WORDS)[y]
images = objects.images  # object by object: example i is view i % 16 of object i // 16
motions = [simulate_choreography((GESTURES[c],), random_state=i, duration=2.5) for i, c in enumerate(y)]
angles = [joint_angles(r) for r in motions]
voices = [110.0, 160.0, 220.0]
waves = [say(WORDS[c], voices[i % 3], rng) for i, c in enumerate(y)]
train = np.arange(y.size) % n_each < n_train
test = ~train
print(f"{train.sum()} training and {test.sum()} held-out examples of {n_concepts} concepts")

# %%
# Features and the learner
# ------------------------
# Colour histograms of superpixels for the images, joint angle-velocity histograms for the
# motions, histograms of acoustic co-occurrences (HAC) of MFCC for the words; each fitted on
# the training examples only. The multimodal NMF learns 8 atoms over the three modalities.
mfcc_config = MFCCConfig(sr=SR, n_mfcc=13)
frames = [mfcc(w, mfcc_config) for w in waves]
colour = ColorHistograms(n_colors=32, random_state=0).fit([images[i] for i in np.flatnonzero(train)])
motion = MotionHistograms(n_bins=16).fit([angles[i] for i in np.flatnonzero(train)])
hac = HAC(n_clusters=(16, 16, 8), lags=(2, 5), random_state=0).fit([frames[i] for i in np.flatnonzero(train)])
X = {"image": colour.transform(images), "motion": motion.transform(angles), "sound": hac.transform(frames)}
X_train = {m: v[train] for m, v in X.items()}
X_test = {m: v[test] for m, v in X.items()}
model = MultimodalNMF(8, max_iter=200, random_state=0).fit(X_train)
W = model.transform(X_train)  # the internal representation of each training example
print("coefficients:", W.shape)

# %%
# Which labels each atom aligns with
# ----------------------------------
# The share of each atom's activation that falls on the examples of each concept. An atom
# that carries one concept has one bright cell; rows are grouped by their concept.
#
# Every function of :mod:`mmconcepts.plot` returns a figure it made itself (not through
# pyplot: save it with ``fig.savefig``); here each draws in a figure made by pyplot instead
# (``ax=`` or ``fig=``), so that the gallery shows it.
from mmconcepts.multimodal import atom_label_association
from mmconcepts.plot import (
    plot_activation_timeline,
    plot_atom_labels,
    plot_confusion,
    plot_dictionary_images,
    plot_dictionary_motion,
    plot_dictionary_skeletons,
    plot_dictionary_sounds,
)

fig, ax = plt.subplots(figsize=(5, 4), layout="constrained")
plot_atom_labels(W, names[train], annotate=True, ax=ax)

# The atoms in the same order below: grouped by the concept they align with.
A, _ = atom_label_association(W, names[train])
atoms = np.lexsort((-A.max(axis=1), A.argmax(axis=1)))
train_ids = np.flatnonzero(train)

# %%
# The dictionary, seen through images
# -----------------------------------
# Each row is an atom and its four training images that are most made of it; the title of
# each image gives its index, its concept and the share of its representation the atom
# holds. Rows are labelled with the concept the atom aligns with most.
plot_dictionary_images(W, [images[i] for i in train_ids], n=4, y=names[train], atoms=atoms,
                       fig=plt.figure(figsize=(6, 12), layout="constrained"))

# %%
# ... heard as spectrograms
# -------------------------
# The log mel spectrograms (the MFCC front end before its DCT) of the atoms' top
# utterances: an atom of a word shows the same two syllables, whoever says them.
plot_dictionary_sounds(W, [waves[i] for i in train_ids], sr=SR, n=3, y=names[train], atoms=atoms,
                       fig=plt.figure(figsize=(7, 11), layout="constrained"))

# %%
# ... and seen as motions
# -----------------------
# The arm and leg angles of the atoms' top gestures, and the same gestures as stick figures
# (a front view, four poses from light to dark).
dofs = [JOINT_ANGLE_NAMES.index(n) for n in ("right_shoulder_elev", "right_elbow_flex", "left_shoulder_elev",
                                               "left_elbow_flex", "right_hip_front", "right_knee_flex")]
plot_dictionary_motion(W, [angles[i] for i in train_ids], dofs=dofs, names=JOINT_ANGLE_NAMES, frame_rate=30.0,
                       n=2, y=names[train], atoms=atoms, fig=plt.figure(figsize=(7, 11), layout="constrained"))

# %%
plot_dictionary_skeletons(W, [motions[i] for i in train_ids], n=3, y=names[train], atoms=atoms,
                          fig=plt.figure(figsize=(5, 13), layout="constrained"))

# %%
# Recognising a concept across modalities
# ---------------------------------------
# Section 6.6.1's question, asked of held-out examples: which image goes with a spoken word,
# and which word with an image? Each test example is compared, in the internal space, with
# the held-out examples of the other modality and takes the concept of the nearest one; the
# rows of each matrix are the true concepts (the share of each predicted concept). The two
# directions need not be equally easy (the thesis' Table 6.2 reports both).
fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained")
for ax, (test_m, ref_m) in zip(axes, [("sound", "image"), ("image", "sound")]):
    D = crossmodal_distances(model, {test_m: X_test[test_m]}, {ref_m: X_test[ref_m]}, space="internal",
                             metric="cosine")
    predicted = names[test][D.argmin(axis=1)]
    accuracy = np.mean(predicted == names[test])
    plot_confusion(names[test], predicted, labels=WORDS, normalize="true", colorbar=ax is axes[1],
                   title=f"{test_m} -> {ref_m}: accuracy {accuracy:.2f}", ax=ax)

# %%
# Concepts along a stream of speech
# ---------------------------------
# Four held-out words said in a row by one voice, cut into 0.3 s windows every 50 ms: each
# window's internal representation is compared with each concept's mean representation
# of its held-out images (the thesis' Fig. 6.9 draws the same similarity), plotted at the
# window's centre. The bands show where each word is actually said. Words that share a
# syllable share a rise: "shoe" begins with the syllable that ends "car".
order = [0, 3, 1, 5]
said = [np.flatnonzero(test & (y == c) & (np.arange(y.size) % 3 == 0))[0] for c in order]
stream = np.concatenate([waves[i] for i in said])
bounds = np.cumsum([0] + [waves[i].size for i in said]) / SR
hop = mfcc_config.hop_length / SR
windows = sliding_windows(mfcc(stream, mfcc_config), 30, 5)
H = model.transform({"sound": hac.transform(list(windows))})
I_test = model.transform({"image": X_test["image"]})
prototypes = np.stack([I_test[y[test] == c].mean(axis=0) for c in range(n_concepts)])

similarity = 1 - pairwise_divergence(H, prototypes, metric="cosine")

fig, ax = plt.subplots(figsize=(9, 3.4), layout="constrained")
plot_activation_timeline(similarity, times=(np.arange(len(windows)) * 5 + 15) * hop, labels=WORDS,
                         segments=[(bounds[k], bounds[k + 1], WORDS[c]) for k, c in enumerate(order)],
                         ylabel="cosine similarity to the concept's images", ax=ax)
plt.show()
