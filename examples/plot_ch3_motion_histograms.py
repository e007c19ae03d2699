"""
Motion histograms from Kinect skeleton files
============================================

Chapter 3 of the thesis represents a dance gesture by histograms of its joint angles and
of their delayed velocities (section 3.2), one histogram per degree of freedom, smoothed by
a Gaussian kernel (KDE) on a regular grid. Gestures then become nonnegative vectors that
NMF can factorise.

This example writes a few tiny skeleton files in the text layout of MSR Action3D
(``aAA_sSS_eEE_skeleton3D.txt``: 20 lines ``x y z confidence`` per frame, one per Kinect
joint), loads them with :func:`mmconcepts.motion.load_msr_action3d`, computes the 16 joint
angles of the thesis' limb model and turns each recording into one histogram vector. With
the real data set, only the folder changes (see the data sets page).
"""

# %%
# Write a tiny data set: three actions, three subjects, two repetitions
# ---------------------------------------------------------------------
# A stick figure stands 2.5 m in front of the camera (y is up). Each action moves some
# limbs periodically; each subject has its own size, tempo and tracking noise.
import shutil
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from mmconcepts.motion import MSR_JOINTS, MotionHistograms, joint_angles, load_msr_action3d

REST = {  # metres, the joints of MSR_JOINTS in a neutral pose
    "head": (0, 1.65, 0), "neck": (0, 1.45, 0), "spine": (0, 1.15, 0), "hip_center": (0, 0.95, 0),
    "left_shoulder": (0.18, 1.42, 0), "right_shoulder": (-0.18, 1.42, 0),
    "left_elbow": (0.22, 1.15, 0), "right_elbow": (-0.22, 1.15, 0),
    "left_wrist": (0.24, 0.92, 0), "right_wrist": (-0.24, 0.92, 0),
    "left_hand": (0.25, 0.85, 0), "right_hand": (-0.25, 0.85, 0),
    "left_hip": (0.1, 0.92, 0), "right_hip": (-0.1, 0.92, 0),
    "left_knee": (0.11, 0.5, 0), "right_knee": (-0.11, 0.5, 0),
    "left_ankle": (0.12, 0.08, 0), "right_ankle": (-0.12, 0.08, 0),
    "left_foot": (0.12, 0.02, 0.1), "right_foot": (-0.12, 0.02, 0.1),
}
ACTIONS = {1: "high arm wave", 11: "two hand wave", 14: "forward kick"}


def wave(P, side, phase):
    """Raise one arm above the head and swing the forearm sideways."""
    s = 1.0 if side == "left" else -1.0
    sh = P[f"{side}_shoulder"]
    elbow = sh + np.array([s * 0.12, 0.22, 0.0])
    swing = 0.5 * np.sin(phase)
    fore = np.array([s * 0.25 * np.sin(swing + 0.3 * s), 0.25 * np.cos(swing), 0.0])
    P[f"{side}_elbow"] = elbow
    P[f"{side}_wrist"] = elbow + fore
    P[f"{side}_hand"] = elbow + 1.2 * fore


def kick(P, phase):
    """Swing the right leg forward and back."""
    a = 0.6 * max(np.sin(phase), 0.0)
    hip = P["right_hip"]
    knee = hip + 0.42 * np.array([0.0, -np.cos(a), np.sin(a)])
    ankle = knee + 0.42 * np.array([0.0, -np.cos(0.5 * a), np.sin(0.5 * a)])
    P["right_knee"], P["right_ankle"], P["right_foot"] = knee, ankle, ankle + [0, -0.06, 0.1]


def skeleton_file(path, action, subject, rng, n_frames=45):
    size, tempo = 0.9 + 0.05 * subject, 2 * np.pi / (12 + 2 * subject)
    lines = []
    for t in range(n_frames):
        P = {j: np.array(REST[j], float) for j in MSR_JOINTS}
        phase = tempo * t + rng.uniform(0, 0.2)
        if action == 1:
            wave(P, "right", phase)
        elif action == 11:
            wave(P, "right", phase)
            wave(P, "left", phase + np.pi)
        else:
            kick(P, phase)
        for j in MSR_JOINTS:
            x, y, z = size * P[j] + [0.0, 0.0, 2.5] + rng.normal(0, 0.01, 3)
            lines.append(f"{x:.5f} {y:.5f} {z:.5f} 1\n")
    Path(path).write_text("".join(lines))


rng = np.random.default_rng(0)
folder = Path(tempfile.mkdtemp(prefix="mmconcepts-msr-"))
for a in ACTIONS:
    for s in (1, 2, 3):
        for e in (1, 2):
            skeleton_file(folder / f"a{a:02d}_s{s:02d}_e{e:02d}_skeleton3D.txt", a, s, rng)
print(sorted(p.name for p in folder.iterdir())[:3], "...")

# %%
# Load, compute joint angles and histograms
# -----------------------------------------
# The loader checks the layout and names the file it cannot read. ``joint_angles`` gives
# the 16 angles of the limb model (radians). ``MotionHistograms`` learns its grids from the
# training recordings only; ``data="joint"`` makes a 2-D angle x velocity histogram per
# angle (``n_bins=16``: a 4 x 4 grid), the representation of thesis Fig. 3.6.
dataset = load_msr_action3d(folder)
shutil.rmtree(folder)  # the loader has read everything
angles = [joint_angles(rec) for rec in dataset]
labels = np.array([rec.labels[0] for rec in dataset])
print(len(dataset), "recordings;", angles[0].shape, "(frames, angles) for the first")

hist = MotionHistograms(data="joint", n_bins=16, delay=3, smoothing=1.0)
X = hist.fit_transform(angles)
print("histogram vectors:", X.shape, "each angle's histogram sums to one:",
      np.allclose(X.reshape(len(X), 16, -1).sum(-1), 1))

# %%
# Recordings of one action look alike
# -----------------------------------
# Cosine similarity of the histogram vectors, recordings sorted by action: the blocks on
# the diagonal are the three actions. Chapter 3 factorises such vectors with NMF, stacked
# with label vectors, to learn gestures from recordings that mix several of them.
Xn = X / np.linalg.norm(X, axis=1, keepdims=True)
order = np.argsort(labels, kind="stable")
fig, ax = plt.subplots(figsize=(5, 4.2))
im = ax.imshow(Xn[order] @ Xn[order].T, vmin=0, vmax=1, cmap="viridis")
ticks = [np.flatnonzero(labels[order] == a).mean() for a in ACTIONS]
ax.set_xticks(ticks, list(ACTIONS.values()), fontsize="small")
ax.set_yticks(ticks, list(ACTIONS.values()), fontsize="small", rotation=90, va="center")
fig.colorbar(im, ax=ax, label="cosine similarity")
ax.set_title("Similarity of motion histograms (18 recordings)")
fig.tight_layout()
plt.show()
