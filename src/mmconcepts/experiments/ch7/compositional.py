"""ch7-compositional: words combined in utterances <-> gestures combined in motions (beyond the thesis).

The thesis ends its perspectives with "relating gestures that are observed combined in
complex motions to words that are observed combined in complex sentences". Here each
training example pairs an utterance of 2-3 keywords with a motion of as many simultaneous
gestures, the keyword set and the gesture set standing for the same concepts through a
random keyword -> gesture bijection (thesis Table 6.1, drawn from the data stream). The
learner sees only the paired perceptions: the multimodal NMF of chapter 6
(:class:`~mmconcepts.multimodal.MultimodalNMF`, I-divergence, k = 50, 50 iterations,
modalities normalised by their average L1 norm) on HAC sound features stacked with motion
histograms, as ``ch6-motion-sound``. Data, folds and scorers: :mod:`.protocol`.

What is tested, on each test fold (its sources never used in training):

(a) retrieval: from an utterance, the motion whose gesture set matches, among
    ``n_candidates`` motions of distinct combinations (one matching), compared in the
    internal space with the cosine (Table 6.2's best comparison in the thesis); and back
    (motion -> utterance). Chance 1 / n_candidates; control: the same learner trained on
    shuffled pairs;
(b) naming: the other modality reconstructed from one (expected motion histogram from the
    utterance, expected HAC from the motion), decomposed on the single-concept references
    (the test fold's single-concept examples, averaged per concept), scored as chapter 3:
    l_given_number (the n largest shares are the n concepts) and l_full (the shares above
    a threshold are exactly the concepts; the threshold maximises l_full on a calibration
    set of training-fold examples, the same set for every learner). Chance: a random
    ranking for l_given_number; for l_full the better of the most frequent calibration label
    set and a random label set of the true size; control: shuffled pairs;
(c) combinations never seen together in training (as thesis Table 3.3): each fold holds out
    a share of the pairs and triples from its training set;
(d) by number of concepts per example: 1 (single-concept test examples), 2 and 3;
(e) the same learner trained on as many single-concept pairs.

Every claim is ours (the thesis does not run this experiment). A claim "above chance" asks
for a chance-corrected score ``(p - p0) / (1 - p0)`` above
:data:`~mmconcepts.experiments.ch7.protocol.FAIR_AGREEMENT` (0.2, "fair" agreement on the
kappa scale), ``p0`` the score of a useless learner, computed fold by fold. The per-fold
values are declared as the folds of one cross-validation (corrected resampled t), and the
split is recorded under ``split_groups`` (:func:`split_sources`: no recording behind a test
example is behind a training-side one).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..._fingerprint import code_fingerprint
from ...errors import ConvergenceWarning, DataError, ParameterError
from ..protocols import speech
from . import protocol as common
from ..protocols.explorer import CLIP_RATE, CLIP_SECONDS, angle_curves, concept_cards, cut_clip, explorer_note
from ..._jit import single_threaded
from ...engine import (
    AudioClip,
    Claim,
    Experiment,
    Explorer,
    MotionClip,
    PresetConfig,
    Result,
    RunContext,
    SampleUnit,
    Streams,
    Table,
    array_digest,
    cached_call,
    concept_parts,
    describe_split,
    register,
    streams,
)

__all__ = ["Config", "build_data", "fold_tasks", "split_sources", "compute", "present", "run"]

SUBSETS = ("", "seen.", "unseen.", "n1.", "n2.", "n3.")
LEARNERS = ("", "shuffled.", "single_trained.")
DIRECTIONS = ("s2m", "m2s")
MEASURES = ("retrieval", "l_given_number", "l_full")
SUBSET_TITLES = {"": "2-3 concepts (all)", "seen.": "2-3 concepts, combination seen in training",
                 "unseen.": "2-3 concepts, combination unseen in training", "n1.": "1 concept", "n2.": "2 concepts",
                 "n3.": "3 concepts"}
SHORT_TITLES = {"": "2-3 concepts", "seen.": "2-3, seen\ncombination", "unseen.": "2-3, unseen\ncombination",
                "n1.": "1 concept", "n2.": "2 concepts", "n3.": "3 concepts"}
LEARNER_TITLES = {"": "compositional", "shuffled.": "shuffled pairs (control)",
                  "single_trained.": "single-concept trained"}
_PAUSES_S = (0.1, 0.3)


@dataclass(frozen=True)
class Config(PresetConfig):
    """Sizes and settings; the learner's are the thesis' chapter 6 settings (k = 50, 50 iterations).

    ``n_compositional`` examples of ``min_concepts``..``max_concepts`` concepts (counts used in
    turn) and ``n_single`` single-concept examples; ``n_per_speaker`` sizes the generated
    corpus (ignored for real speech).
    """

    n_compositional: int = 1000
    n_single: int = 1000
    min_concepts: int = 2
    max_concepts: int = 3
    n_folds: int = 10
    k: int = 50
    n_iter: int = 50
    motion_bins: int = 25
    n_candidates: int = 10
    n_draws: int = 10
    n_calibration: int = 200
    n_per_speaker: int = 1000
    seed: int = 0

    hac_fit_frames: int = 100_000  # training frames (at most) for each HAC codebook: HAC's max_fit_frames
    # 5 folds (the fewest that decide a claim); 220 + 220 examples and 60 calibration examples keep the CPU time of
    # the quick run under that of the former 4 folds of 300 + 300 (80): the sizes are ours, nothing in the thesis
    # fixes them
    QUICK = dict(n_compositional=220, n_single=220, n_folds=5, n_calibration=60, n_per_speaker=250,
                 hac_fit_frames=20_000)
    # the smoke preset (seconds, its numbers mean nothing): what it changes from the quick one; 96 compositional
    # examples give the test side of each of the two folds a combination seen in training, on generated data too
    SMOKE = dict(n_compositional=96, n_single=40, n_folds=2, k=10, n_iter=20, n_candidates=5, n_draws=3,
                 n_calibration=20, n_per_speaker=50)


# ---------------------------------------------------------------------------- data
def _check_config(config: Config) -> None:
    for name in ("n_compositional", "n_single", "n_folds", "k", "n_iter", "motion_bins", "n_candidates", "n_draws",
                 "n_calibration", "n_per_speaker"):
        v = getattr(config, name)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ParameterError(f"{name} must be a positive int; got {v!r}.")
    if config.n_folds < 2:
        raise ParameterError(f"n_folds must be >= 2 (train and test); got {config.n_folds}.")
    if not 1 <= config.min_concepts <= config.max_concepts:
        raise ParameterError(f"need 1 <= min_concepts <= max_concepts; got {config.min_concepts}, "
                             f"{config.max_concepts}.")
    if config.n_candidates < 2:
        raise ParameterError(f"n_candidates must be >= 2; got {config.n_candidates}.")


def _speech(ctx: RunContext, config: Config) -> dict:
    sub, speaker, keywords, y = speech.first_speaker(ctx, n_per_speaker=config.n_per_speaker)
    return {"corpus": sub, "speaker": speaker, "keywords": list(keywords), "y": np.asarray(y),
            "source": speech.data_source(ctx)}


def _msr_sources(folder) -> dict:
    from ...motion import msr_joint_angles

    angles, actions, subjects, skipped = msr_joint_angles(folder)
    want = set(common.MSR_VOCABULARY.gestures) | set(common.MSR_IDLE_DONORS)
    keep = [i for i in range(len(angles)) if int(actions[i]) in want]
    have = {int(actions[i]) for i in keep}
    missing = sorted(want - have)
    if missing:
        raise DataError(f"MSR Action3D in {folder} has no usable recording of action(s) {missing}; the compositional "
                        f"experiment needs actions {sorted(want)} (see mmconcepts.experiments.ch7.protocol.MSR_VOCABULARY).")
    return {"angles": [angles[i] for i in keep], "action": np.array([int(actions[i]) for i in keep]),
            "subjects": sorted({int(subjects[i]) for i in keep}), "skipped": list(skipped)}


def build_data(ctx: RunContext, config: Config, st: Streams | None = None) -> dict:
    """The paired examples of every fold (no features yet): plans of the utterances, motions, concept sets.

    Uses only the data stream (bijection, combinations, sources, pauses, synthetic motions)
    and the splits stream (folds of the sources and examples, held-out combinations).

    Returns
    -------
    dict with ``keywords`` (concept c is ``keywords[c]``), ``gestures`` (concept c's gesture
    id), ``slots``, ``mapping`` (keyword -> gesture), ``combos`` (concept set of each
    example), ``Y`` (n, L), ``kind`` ("compositional" or "single"), ``fold``, ``held_out``
    (per fold), ``sound_plan`` (source utterance indices and pauses of each example),
    ``files`` (the source utterances' paths), ``angles`` (joint angles of each motion),
    ``gesture_sets`` (the gestures each motion shows), ``keyword_sets``, and notes.
    """
    _check_config(config)
    st = st if st is not None else streams(config.seed)
    rng = st.rng("data")
    frng = st.rng("splits")
    speech = _speech(ctx, config)
    keywords, y_rec = speech["keywords"], speech["y"]
    L = len(keywords)
    real_motion = ctx.has_dataset("msr-action3d")
    vocab = common.MSR_VOCABULARY if real_motion else common.SYNTHETIC_VOCABULARY
    perm = common.concept_bijection(L, len(vocab.gestures), rng)
    gestures = [int(vocab.gestures[perm[c]]) for c in range(L)]
    slots = [vocab.slots[perm[c]] for c in range(L)]
    counts = list(range(config.min_concepts, config.max_concepts + 1))
    if config.max_concepts > L:
        raise ParameterError(f"max_concepts = {config.max_concepts} is above the vocabulary of {L} concepts.")
    F = config.n_folds
    if config.n_single < L * F:
        raise ParameterError(f"n_single = {config.n_single} is below n_concepts x n_folds = {L} x {F}: every test "
                             "fold needs a single-concept example of every concept (its references); give more "
                             "single-concept examples or fewer folds.")
    # single concepts: every concept equally often (whole random permutations of the concepts)
    cycle = np.concatenate([rng.permutation(L) for _ in range(-(-config.n_single // L))])[: config.n_single]
    combos = common.draw_combinations(config.n_compositional, counts, slots, rng) + [(int(c),) for c in cycle]
    kind = np.array(["compositional"] * config.n_compositional + ["single"] * config.n_single)
    n = len(combos)
    # folds: sources split within each keyword / action; compositional examples dealt round robin, single-concept
    # ones within each concept (so every fold has each concept's references)
    rec_fold = concept_parts(y_rec, F, frng)
    single = kind == "single"
    fold = common.example_folds(combos, single, F, frng)
    possible = [c for m in counts if m > 1 for c in common.possible_combinations(slots, m)]
    held_out = common.held_out_combinations(possible, F, frng)
    motion = _msr_sources(ctx.dataset("msr-action3d")) if real_motion else None
    if motion is not None:
        mot_fold = concept_parts(np.searchsorted(np.unique(motion["action"]), motion["action"]), F, frng)
    # compose: each example from its own fold's recordings
    orders = [tuple(combo[j] for j in rng.permutation(len(combo))) for combo in combos]  # the spoken order
    sound_src = common.draw_sources(orders, fold, y_rec, rec_fold, rng,
                                    what=f"recording of speaker {speech['speaker']}")
    sound_plan = [(srcs, tuple(float(rng.uniform(*_PAUSES_S)) for _ in range(len(srcs) - 1))) for srcs in sound_src]
    files = [str(Path(p).resolve()) for p in speech["corpus"].paths]
    angles: list[np.ndarray] = []
    gesture_sets: list[tuple[int, ...]] = []
    if motion is None:
        motion_src: list[tuple[str, ...]] = [(f"generated motion {i}",) for i in range(n)]  # one per example
        for combo, motion_seed in zip(combos, rng.integers(2**31 - 1, size=n)):
            gs = tuple(sorted(gestures[c] for c in combo))
            angles.append(common.simulate_motion(gs, int(motion_seed)))
            gesture_sets.append(gs)
    else:
        # the idle donors (one-arm actions outside the vocabulary) pooled under the label -1
        label = np.where(np.isin(motion["action"], common.MSR_IDLE_DONORS), -1, motion["action"])
        wanted = [tuple(gestures[c] for c in combo) + (-1,) for combo in combos]
        picks = common.draw_sources(wanted, fold, label, mot_fold, rng, what="MSR Action3D recording")
        motion_src = [tuple(f"msr-action3d recording {j}" for j in p) for p in picks]
        for combo, p in zip(combos, picks):
            parts = {slots[c]: motion["angles"][j] for c, j in zip(combo, p[:-1])}
            angles.append(common.compose_msr_motion(parts, motion["angles"][p[-1]]))
            gesture_sets.append(tuple(sorted(int(motion["action"][j]) for j in p[:-1])))
    sources = [frozenset([f"sound:{files[j]}" for j in srcs] + [f"motion:{m}" for m in msrc])
               for (srcs, _), msrc in zip(sound_plan, motion_src)]
    mapping = {keywords[c]: gestures[c] for c in range(L)}
    corpus = speech["corpus"]
    keyword_sets = [[str(corpus.labels[s][0]) for s in srcs] for srcs, _ in sound_plan]
    common.check_pairing(keyword_sets, gesture_sets, mapping)
    return {"keywords": keywords, "gestures": gestures, "slots": slots, "mapping": mapping, "combos": combos,
            "Y": common.label_matrix(combos, L), "kind": kind, "fold": fold, "held_out": held_out,
            "sound_plan": sound_plan, "files": files, "angles": angles, "sources": sources,
            "gesture_sets": gesture_sets, "keyword_sets": keyword_sets, "speaker": speech["speaker"],
            "speech_source": speech["source"], "n_recordings": len(y_rec), "real_motion": real_motion,
            "motion_info": ({} if motion is None else {"n_recordings": len(motion["angles"]),
                                                        "subjects": motion["subjects"],
                                                        "skipped": motion["skipped"]}),
            "n_possible": len(possible)}


def _mfcc_chunk(task: tuple) -> list[np.ndarray]:
    from ...sound.audio import load_audio
    from ...sound.features import MFCCConfig, mfcc

    files, plans = task
    cfg = MFCCConfig(n_mfcc=22)
    cache: dict[int, np.ndarray] = {}
    out = []
    for srcs, pauses in plans:
        pieces = []
        for s in srcs:
            if s not in cache:
                cache[s] = load_audio(files[s], sr=cfg.sr)
            pieces.append(cache[s])
        out.append(mfcc(common.compose_utterance(pieces, pauses, cfg.sr), cfg))
    return out


def _cached_mfcc(ctx: RunContext, files: list[str], stamps: list, plans: list, code: str) -> list[np.ndarray]:
    """MFCC (22) of every composed utterance; cached by :func:`utterance_mfcc` (``ctx`` not hashed)."""
    chunk = 50
    parts = ctx.parallel(_mfcc_chunk, [(files, plans[i:i + chunk]) for i in range(0, len(plans), chunk)],
                         desc="MFCC of composed utterances")
    return [m for p in parts for m in p]


def utterance_mfcc(ctx: RunContext, data: dict) -> list[np.ndarray]:
    """MFCC sequences of the examples' utterances (composed from the plans), cached on disk."""
    import os

    files = data["files"]
    stamps = [(st.st_size, int(st.st_mtime)) for st in map(os.stat, files)]
    plans = [[list(s), list(p)] for s, p in data["sound_plan"]]
    memo = ctx.memory("ch7-mfcc").cache(_cached_mfcc, ignore=["ctx"])
    return cached_call(memo, ctx, files, stamps, plans, code_fingerprint())


# ---------------------------------------------------------------------------- one fold
def _refs(X, idx: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Mean of the rows ``idx`` of X per concept (single-concept examples): (L, n_features) dense."""
    out = []
    for c in range(Y.shape[1]):
        rows = idx[Y[idx, c] > 0]
        if rows.size == 0:
            raise DataError(f"no single-concept example of concept {c} to serve as its reference; use more "
                            "single-concept examples or fewer folds.")
        block = X[rows]
        out.append(np.asarray(block.mean(axis=0)).ravel())
    return np.vstack(out)


def _best_threshold(Y: np.ndarray, A: np.ndarray) -> float:
    """The threshold maximising l_full on (Y, A) (the middle of the best run of a fine grid)."""
    from ...nmf import l_full_curve

    grid = np.linspace(0.005, 0.995, 199)
    curve = l_full_curve(Y, A, grid)
    best = np.flatnonzero(curve == curve.max())
    return float(grid[best[len(best) // 2]])


def _naming(model, W: np.ndarray, target: str, R: np.ndarray) -> np.ndarray:
    """Shares of each concept in the reconstruction of ``target`` from ``W`` (decomposed on references R)."""
    keep = R.max(axis=0) > 0
    H = model.components_[:, model.component_slice(target)][:, keep] * model.scales_[target]
    return common.decompose_on_references(W @ H, R[:, keep])


def _observed_shares(X, idx: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Shares of each concept in the observed rows ``idx`` of X (decomposed on references R)."""
    keep = R.max(axis=0) > 0
    block = X[idx][:, keep]
    return common.decompose_on_references(block.toarray() if hasattr(block, "toarray") else block, R[:, keep])


def _fold(task: dict) -> dict:
    """Features, the three learners and every score of one fold, per test example."""
    from ...motion import MotionHistograms
    from ...multimodal import MultimodalNMF, pairwise_divergence
    from ...sound.hac import HAC

    Y, combos = task["Y"], task["combos"]
    tr_c, tr_s, te, cal = task["train_comp"], task["train_single"], task["test"], task["calibration"]
    seed = task["learner_seed"]
    single_te = te[Y[te].sum(axis=1) == 1]
    single_tr = np.concatenate([tr_s, task["train_single_extra"]])  # training-fold single examples (references)
    used = np.unique(np.concatenate([tr_c, tr_s, te, cal, single_tr]))
    out: dict = {"test": te}
    with single_threaded(), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        fit_idx = np.unique(np.concatenate([tr_c, tr_s]))
        hac = HAC(random_state=seed, max_fit_frames=task["hac_fit_frames"]).fit([task["mfcc"][i] for i in fit_idx])
        S = hac.transform([task["mfcc"][i] for i in used]).tocsr()
        hist = MotionHistograms(data="joint", method="vq", n_bins=task["motion_bins"], delay=3,
                                random_state=seed).fit([task["angles"][i] for i in fit_idx])
        M = np.asarray(hist.transform([task["angles"][i] for i in used]))
        pos = {int(g): j for j, g in enumerate(used)}

        def rows(idx):
            return np.array([pos[int(i)] for i in idx], dtype=np.int64)

        kw = dict(n_components=task["k"], max_iter=task["n_iter"], random_state=seed)
        perm = np.random.default_rng(task["control_seed"]).permutation(len(tr_c))
        compositional = MultimodalNMF(**kw)
        W = compositional.fit_transform({"sound": S[rows(tr_c)], "motion": M[rows(tr_c)]})
        if task["explorer"]:  # the concept explorer: the compositional learner's coefficients of its training pairs
            out["coefficients"] = W
        # each learner is fitted when its metrics are computed and released after them (every learner has the
        # fold's seed, so the order changes nothing): one sound dictionary in memory at a time
        fitted = [compositional]
        del compositional
        learners = {
            "": fitted.pop,
            "shuffled.": lambda: MultimodalNMF(**kw).fit({"sound": S[rows(tr_c)], "motion": M[rows(tr_c)][perm]}),
            "single_trained.": lambda: MultimodalNMF(**kw).fit({"sound": S[rows(tr_s)], "motion": M[rows(tr_s)]}),
        }
        refs = {"test": {"motion": _refs(M, rows(single_te), Y[used]), "sound": _refs(S, rows(single_te), Y[used])},
                "cal": {"motion": _refs(M, rows(single_tr), Y[used]), "sound": _refs(S, rows(single_tr), Y[used])}}
        combos_te = [combos[i] for i in te]
        for name, learner in learners.items():
            model = learner()
            Ws = model.transform({"sound": S[rows(te)]})
            Wm = model.transform({"motion": M[rows(te)]})
            D = pairwise_divergence(Ws, Wm, "cosine")
            rrng = np.random.default_rng(task["reference_seed"])
            out[f"{name}s2m.retrieval"] = common.combination_retrieval(
                D, combos_te, combos_te, n_candidates=task["n_candidates"], n_draws=task["n_draws"], rng=rrng)
            out[f"{name}m2s.retrieval"] = common.combination_retrieval(
                D.T, combos_te, combos_te, n_candidates=task["n_candidates"], n_draws=task["n_draws"], rng=rrng)
            Ws_cal = model.transform({"sound": S[rows(cal)]})
            Wm_cal = model.transform({"motion": M[rows(cal)]})
            for d, (W, W_cal, target) in {"s2m": (Ws, Ws_cal, "motion"), "m2s": (Wm, Wm_cal, "sound")}.items():
                A = _naming(model, W, target, refs["test"][target])
                A_cal = _naming(model, W_cal, target, refs["cal"][target])
                eta = _best_threshold(Y[cal], A_cal)
                out[f"{name}{d}.l_given_number"], out[f"{name}{d}.l_full"] = common.example_scores(Y[te], A, eta)
                out[f"{name}{d}.threshold"] = eta
            del model
        # ceiling of the naming protocol: the target modality *observed* (not reconstructed) decomposed on the
        # training folds' references (the test fold's would contain the observed recordings themselves), threshold
        # from the same calibration examples
        for d, (X, target) in {"s2m": (M, "motion"), "m2s": (S, "sound")}.items():
            A = _observed_shares(X, rows(te), refs["cal"][target])
            eta = _best_threshold(Y[cal], _observed_shares(X, rows(cal), refs["cal"][target]))
            out[f"observed.{d}.l_given_number"], out[f"observed.{d}.l_full"] = common.example_scores(Y[te], A, eta)
    return out


#: The reference stream's draws per fold (``st.seed_for("reference", draw, fold)``): the calibration set,
#: the reference draws of the tests, the shuffled pairs of the control.
CALIBRATION, REFERENCE, CONTROL = 0, 1, 2


def fold_tasks(data: dict, mfccs: list, config: Config, st: Streams) -> list[dict]:
    """One task per fold, each with its own draws of the learner, composition and reference streams.

    Fold f trains the compositional learner on the other folds' compositional examples
    whose combination is not held out by fold f, the single-concept learner on as many of
    the other folds' single-concept examples (a random subset, composition stream), and
    tests on fold f's examples; the calibration set of the l_full threshold is drawn among
    the other folds' examples (both kinds; reference stream, :data:`CALIBRATION`).
    """
    F = config.n_folds
    kind, fold, combos = data["kind"], data["fold"], data["combos"]
    tasks = []
    for f in range(F):
        crng = st.rng("composition", f)
        held = data["held_out"][f]
        comp = np.flatnonzero((kind == "compositional") & (fold != f))
        tr_c = np.array([i for i in comp if tuple(combos[i]) not in held], dtype=np.int64)
        singles = crng.permutation(np.flatnonzero((kind == "single") & (fold != f)))
        tr_s = np.sort(singles[: len(tr_c)])
        others = np.flatnonzero(fold != f)
        cal = np.sort(st.rng("reference", CALIBRATION, f).permutation(others)[: config.n_calibration])
        tasks.append({"Y": data["Y"], "combos": data["combos"], "mfcc": mfccs, "angles": data["angles"],
                      "train_comp": tr_c, "train_single": tr_s, "train_single_extra": np.sort(singles[len(tr_c):]),
                      "test": np.flatnonzero(fold == f), "calibration": cal, "k": config.k, "n_iter": config.n_iter,
                      "motion_bins": config.motion_bins, "n_candidates": config.n_candidates,
                      "n_draws": config.n_draws, "learner_seed": st.seed_for("learner", f),
                      "reference_seed": st.seed_for("reference", REFERENCE, f),
                      "control_seed": st.seed_for("reference", CONTROL, f), "hac_fit_frames": config.hac_fit_frames,
                      "explorer": f == 0})
    return tasks


def split_sources(data: dict, tasks: list[dict]) -> list[tuple[list, list]]:
    """Per fold, the recordings behind each training-side example and each test example.

    The training side is everything fold f's learners and thresholds see: both learners'
    training sets, the calibration set and the training folds' single-concept examples
    (the calibration references); the test side is fold f's examples (queries,
    candidates and the test references). For
    :func:`~mmconcepts.engine.describe_split`.
    """
    src = data["sources"]
    out = []
    for t in tasks:
        train = np.unique(np.concatenate([t["train_comp"], t["train_single"], t["train_single_extra"],
                                          t["calibration"]]).astype(np.int64))
        out.append(([src[i] for i in train], [src[i] for i in t["test"]]))
    return out


def _cached_fold(task: dict, key: tuple, code: str) -> dict:
    """:func:`_fold`, cached on disk (``task`` is not hashed; ``key`` stands for it, ``code`` for the package)."""
    return _fold(task)


def _evaluate(ctx: RunContext, config: Config) -> tuple[dict, list[dict], list[dict]]:
    st = streams(config.seed)
    data = build_data(ctx, config, st)
    mfccs = utterance_mfcc(ctx, data)
    tasks = fold_tasks(data, mfccs, config, st)
    digest = (array_digest(mfccs), array_digest(data["angles"]), array_digest([data["Y"], data["fold"]]))
    keys = [(digest, f, t["train_comp"], t["train_single"], t["calibration"], config.k, config.n_iter,
             config.motion_bins, config.n_candidates, config.n_draws, t["learner_seed"], t["reference_seed"],
             t["control_seed"], config.hac_fit_frames) for f, t in enumerate(tasks)]
    memo = ctx.memory("ch7-folds").cache(_cached_fold, ignore=["task"])
    code = code_fingerprint()
    folds = ctx.parallel_cached(memo, [(t, k, code) for t, k in zip(tasks, keys)], desc="folds")
    return data, tasks, folds


# ---------------------------------------------------------------------------- summaries
def _subset_mask(subset: str, Y_te: np.ndarray, seen: np.ndarray) -> np.ndarray:
    n = Y_te.sum(axis=1)
    if subset == "":
        return n >= 2
    if subset == "seen.":
        return (n >= 2) & seen
    if subset == "unseen.":
        return (n >= 2) & ~seen
    return n == int(subset[1])


def summarise(data: dict, tasks: list[dict], folds: list[dict], config: Config) -> tuple[dict, dict, dict]:
    """Per-fold values of every metric, their means, and the per-fold sizes of the subsets."""
    from ...nmf import l_full

    Y, combos, L = data["Y"], data["combos"], data["Y"].shape[1]
    samples: dict[str, list[float]] = {}
    sizes: dict[str, list[int]] = {s: [] for s in SUBSETS}
    for task, res in zip(tasks, folds):
        te = res["test"]
        Y_te = Y[te]
        train_combos = {tuple(combos[i]) for i in task["train_comp"]}
        seen = np.array([tuple(combos[i]) in train_combos for i in te])
        # l_full chance: the most frequent label set of the calibration examples, predicted for every example
        cal_sets = [tuple(combos[i]) for i in task["calibration"]]
        uniq, cnt = np.unique(np.array([",".join(map(str, c)) for c in cal_sets]), return_counts=True)
        top = [int(x) for x in uniq[np.argmax(cnt)].split(",")]
        pred = np.zeros_like(Y_te)
        pred[:, top] = 1
        for subset in SUBSETS:
            mask = _subset_mask(subset, Y_te, seen)
            sizes[subset].append(int(mask.sum()))
            if not mask.any():
                raise DataError(f"fold test set has no example of the subset {SUBSET_TITLES[subset]!r}; use more "
                                "examples per fold.")
            for learner in LEARNERS:
                for d in DIRECTIONS:
                    for m in MEASURES:
                        key = f"{learner}{d}.{m}"
                        samples.setdefault(f"{subset}{key}", []).append(float(np.mean(res[key][mask])))
            for d in DIRECTIONS:
                for m in MEASURES[1:]:
                    samples.setdefault(f"{subset}observed.{d}.{m}", []).append(
                        float(np.mean(res[f"observed.{d}.{m}"][mask])))
            samples.setdefault(f"{subset}chance.l_given_number", []).append(
                common.given_number_chance(L, Y_te[mask].sum(axis=1)))
            # l_full of a useless labeller: the better of the input-blind most frequent calibration label set and a
            # random label set of the true size (which l_full does not give, so an upper bound of random labellings)
            samples.setdefault(f"{subset}chance.l_full", []).append(
                max(float(l_full(Y_te[mask], pred[mask])), common.given_number_chance(L, Y_te[mask].sum(axis=1))))
        for learner in LEARNERS:
            for d in DIRECTIONS:
                samples.setdefault(f"{learner}{d}.threshold", []).append(float(res[f"{learner}{d}.threshold"]))
    metrics = {k: float(np.mean(v)) for k, v in samples.items()}
    metrics["chance.retrieval"] = 1.0 / config.n_candidates
    return metrics, samples, sizes


# ---------------------------------------------------------------------------- compute / present
def _source_notes(ctx: RunContext, data: dict, config: Config, sizes: dict, metrics: dict) -> list[str]:
    kws = ", ".join(f"{k} -> {g} ({s})" for k, g, s in zip(data["keywords"], data["gestures"], data["slots"]))
    if data["speech_source"] == "fsdd":
        sound = (f"Sound: real FSDD recordings of speaker {data['speaker']} (the first by name of the data root's "
                 f"speakers; {data['n_recordings']} recordings of the ten digit words), put end to end.")
    elif data["speech_source"] == "synthetic":
        sound = (f"Sound: the generated Caregiver-like corpus (offline TTS), speaker {data['speaker']}'s "
                 f"{data['n_recordings']} one-keyword sentences, put end to end (the generator says at most two "
                 "keywords per sentence, so utterances of 2-3 keywords are made as the real ones are: 2-3 sentences of "
                 "one speaker in a row).")
    else:
        sound = f"Sound: real recordings ({data['speech_source']}) of speaker {data['speaker']}, put end to end."
    if data["real_motion"]:
        info = data["motion_info"]
        motion = (f"Motion: limb collages of real MSR Action3D skeletons ({info['n_recordings']} recordings of the "
                  f"vocabulary and idle-donor actions, subjects {info['subjects']}): right arm of one recording, "
                  "right arm of another mirrored onto the left arm, torso and legs of a third; idle limbs from a "
                  f"recording of a one-arm action outside the vocabulary ({common.MSR_IDLE_DONORS}). Unlike the "
                  "chapter 3 sets, the limbs of one motion may come from different subjects (the recordings are "
                  "split into folds first, and a fold rarely holds every action of one subject).")
    else:
        motion = ("Motion: the synthetic dancer of chapter 3 (mmconcepts.motion.synthetic.simulate_choreography) "
                  "performing the gestures on their limbs simultaneously, the other limbs idle.")
    n_te = {s: int(np.sum(v)) for s, v in sizes.items()}
    return [
        sound + " " + motion,
        f"Concepts (random bijection of the data stream, seed {config.seed}): {kws}. A motion shows at most one "
        f"gesture per limb group, so {data['n_possible']} combinations of {config.min_concepts}-"
        f"{config.max_concepts} concepts are possible.",
        f"{config.n_compositional} examples of {config.min_concepts}-{config.max_concepts} concepts (counts in turn) "
        f"and {config.n_single} single-concept examples; {config.n_folds} folds: the source recordings are split "
        "into folds within each keyword / action and each fold's examples are composed from its own sources; each "
        "fold holds out a random share (1/n_folds, a partition) of the possible pairs and triples from its training "
        f"set. Test examples over the folds: {n_te[''] } of 2-3 concepts ({n_te['unseen.']} of a combination unseen "
        f"in training), {n_te['n1.']} of one concept.",
        f"Learner: MultimodalNMF (I-divergence, k = {config.k}, {config.n_iter} iterations) on HAC (22 MFCC, "
        f"codebooks 150/150/100, lags 2 and 5) stacked with joint angle-velocity histograms ({config.motion_bins} "
        "VQ bins per dof, delay 3), both fitted on the fold's training examples. The single-concept learner is the "
        "same, trained on as many single-concept pairs as the compositional one has pairs; the control on the "
        "compositional pairs with the motions shuffled.",
        f"(a) Retrieval: {config.n_candidates} candidates of distinct combinations (one matching) drawn among the "
        f"test fold's examples, {config.n_draws} draws per query; compared in the internal space with the cosine "
        "(the thesis' best comparison of Table 6.2; no other space was tried here). Chance "
        f"{1 / config.n_candidates:.2f}. Distractors may share concepts with the query.",
        "(b) Naming: the reconstructed other modality decomposed (I-divergence, 100 multiplicative updates) on the "
        "per-concept means of the test fold's single-concept examples; l_given_number: the n largest shares are the "
        "n concepts; l_full: the shares >= a threshold are exactly the concepts, the threshold maximising l_full on "
        f"{config.n_calibration} examples of the training folds (both kinds, the same set for every learner, with "
        "references from the training folds' single-concept examples). Chance: l_given_number of a random ranking "
        "(mean of 1 / C(10, n)); l_full of the better of the most frequent calibration label set (0 on unseen "
        "combinations by construction) and a random label set of the true size. Ceiling of the naming protocol "
        "('other modality observed'): the test example's own "
        "perception in the target modality decomposed the same way, on the training folds' references (the test "
        "fold's hold the very recordings the test examples are made of).",
        f"Uncertainty: every number is the mean over the {config.n_folds} folds, with the per-fold values as samples, "
        "declared as the folds of one cross-validation (corrected resampled t); all metrics come from the same folds, "
        "so claims compare them pairwise. chance.retrieval is exact. The split is grouped by recording "
        "(split_groups): no utterance recording and no motion recording is behind both a training-side example "
        "(training pairs, calibration set, calibration references) and a test example of a fold.",
        f"Bars: every claim 'above chance' asks for a chance-corrected score (p - p0) / (1 - p0) above "
        f"{common.FAIR_AGREEMENT} (p0: the score of a useless learner), the lower end of 'fair' agreement on Landis "
        "and Koch's scale of Cohen's kappa, fixed from the chance values before any result was seen. Retrieval: a "
        f"random ranking succeeds {1 / config.n_candidates:.2f} of the time, bar "
        f"{common.fair_bar(1 / config.n_candidates):.2f}. l_given_number: a random ranking names the n concepts "
        f"with probability 1 / C(10, n) (0.022 for pairs, 0.008 for triples; {metrics['chance.l_given_number']:.3f} "
        f"over the 2-3-concept test examples), bar {common.fair_bar(metrics['chance.l_given_number']):.2f}. l_full: "
        "the better of two useless labellers, the most frequent calibration label set for every example and a "
        f"random label set of the true size ({metrics['chance.l_full']:.3f}), bar "
        f"{common.fair_bar(metrics['chance.l_full']):.2f}. A learner at chance passes none of these bars (it scores "
        "0 chance-corrected); the rules compute each bar fold by fold from that fold's chance.",
        "Every claim is ours (the thesis does not run this experiment; the first ones restate its perspective, "
        "lines 6113-6118). Reclassified: 'retrieval beats the shuffled-pairs control' is now a check (the control "
        "is at chance by construction, so beating it says no more than the bar of the first claim; kept to show "
        "that the protocol does not leak: a shuffled control above the bar would); the shuffled-control part of the "
        "l_full claim is dropped for the same reason. 'Above chance' claims now ask for the bar above instead of "
        "any margin above chance (a learner barely better than a random ranking passed them). 'Naming from the "
        "observed other modality passes the bar' is a check of the naming protocol (references, decomposition, "
        "threshold), which tells whether a naming failure is the learner's.",
        "The claim that 3 concepts are harder than 2 could go either way (a triple fills every limb, so the "
        "motion has no idle limb to confuse with another triple's; the HAC of three words is denser): it is a "
        "question asked, not a thesis claim. Likewise the comparison with the single-concept learner is reported "
        "whichever way it falls.",
    ]


#: MSR Action3D's frame rate (its recordings: 15 frames per second).
_MSR_RATE = 15.0


def _explorer(data: dict, rows: np.ndarray, W: np.ndarray) -> Explorer:
    """The concept explorer: the atoms of the first fold's compositional learner, from its coefficients of its
    training pairs (each pair's utterance, cut around the atom's keyword, and the joint angles of its motion)."""
    from ...motion.synthetic import FRAME_RATE
    from ...sound.audio import load_audio

    def clip(i: int, label: str) -> AudioClip:
        e = int(rows[i])
        srcs, pauses = data["sound_plan"][e]
        pieces = [load_audio(data["files"][j], sr=CLIP_RATE, min_duration=0.0) for j in srcs]
        said = data["keyword_sets"][e]
        span = None
        if label in said:  # where the atom's keyword is said in the utterance
            p = said.index(label)
            start = sum(len(x) + int(round(q * CLIP_RATE)) for x, q in zip(pieces[:p], pauses[:p])) / CLIP_RATE
            span = (start, start + len(pieces[p]) / CLIP_RATE)
        return cut_clip(common.compose_utterance(pieces, pauses, CLIP_RATE), CLIP_RATE, span,
                        caption=" + ".join(said))

    def motion(i: int) -> MotionClip:
        e = int(rows[i])
        return angle_curves(data["angles"][e], _MSR_RATE if data["real_motion"] else FRAME_RATE,
                            caption=f"16 joint angles of gestures {', '.join(map(str, data['gesture_sets'][e]))}")

    keywords = data["keywords"]
    note = explorer_note(f"the compositional learner of fold 1 (k = {W.shape[1]}), fitted on its {len(rows)} training "
                         "pairs of 2-3 concepts (sound and motion)", "pairs",
                         f"their utterances (at most {CLIP_SECONDS:g} s, around the atom's keyword where it is said) "
                         "and the first pair's 16 joint angles (a collage of limbs has no single skeleton to draw)",
                         counts=" (a pair counts for each of its keywords, with an equal part of its coefficients)")
    return concept_cards(W, [tuple(keywords[c] for c in data["combos"][int(e)]) for e in rows], note=note, clip=clip,
                         motion=motion)


def compute(config: Config, ctx: RunContext) -> Result:
    """Every score of the five tests, per fold, with chance levels and the shuffled control."""
    data, tasks, folds = _evaluate(ctx, config)
    metrics, samples, sizes = summarise(data, tasks, folds, config)
    rows = []
    for subset in SUBSETS:
        for learner in LEARNERS:
            rows.append([SUBSET_TITLES[subset], LEARNER_TITLES[learner]]
                        + [metrics[f"{subset}{learner}{d}.{m}"] for d in DIRECTIONS for m in MEASURES])
        rows.append([SUBSET_TITLES[subset], "chance"] + [metrics["chance.retrieval"],
                     metrics[f"{subset}chance.l_given_number"], metrics[f"{subset}chance.l_full"]] * 2)
        rows.append([SUBSET_TITLES[subset], "other modality observed (naming ceiling)"]
                    + [v for d in DIRECTIONS for v in (None, metrics[f"{subset}observed.{d}.l_given_number"],
                                                       metrics[f"{subset}observed.{d}.l_full"])])
    columns = ["test examples", "learner"] + [f"{d} {m}" for d in ("sound->motion", "motion->sound") for m in MEASURES]
    table = Table("Compositional learning: retrieval and naming (mean over folds)", columns, rows,
                  note="s2m: from the utterance (retrieve the motion; name the concepts from the reconstructed "
                       "motion); m2s: from the motion.")
    sizes_table = Table("Test examples per fold", ["subset"] + [f"fold {f}" for f in range(config.n_folds)],
                        [[SUBSET_TITLES[s]] + sizes[s] for s in SUBSETS])
    notes = _source_notes(ctx, data, config, sizes, metrics)
    notes.append("Thresholds chosen on the calibration set (mean over folds): "
                 + ", ".join(f"{LEARNER_TITLES[n]} {d} {metrics[f'{n}{d}.threshold']:.2f}"
                             for n in LEARNERS for d in DIRECTIONS) + ".")
    fd = {"n_folds": config.n_folds}
    by = ("source recordings: each example's utterance recordings and motion recordings (" +
          ("MSR Action3D limbs and idle donor" if data["real_motion"] else "one generated motion each") + ")")
    unit = SampleUnit.folds(config.n_folds, f"{config.n_folds} folds of the paired examples, grouped by recording")
    return Result(metrics=metrics, samples=samples, tables={"scores": table, "sizes": sizes_table}, notes=notes,
                  extra={"mapping": data["mapping"], "slots": dict(zip(data["keywords"], data["slots"])),
                         "subset_sizes": sizes},
                  sample_units={name: "folds" for name in samples}, units={"folds": unit},
                  split_groups={"folds": describe_split(by, split_sources(data, tasks))},
                  figure_data=fd, explorer=_explorer(data, tasks[0]["train_comp"], folds[0]["coefficients"]))


def _err(result: Result, key: str) -> float:
    from ...engine.uncertainty import t_interval

    ci = t_interval(result.metrics[key], result.samples.get(key))
    return float("nan") if ci is None else (ci[1] - ci[0]) / 2


def present(result: Result, config: Config) -> dict[str, Figure]:
    """Bars with 95 % intervals: retrieval and naming by test subset and learner, with chance."""
    figs: dict[str, Figure] = {}
    m = result.metrics
    for measure in MEASURES:
        fig = Figure(figsize=(9, 4), layout="constrained")
        axes = fig.subplots(1, 2, sharey=True)
        for ax, d in zip(axes, DIRECTIONS):
            x = np.arange(len(SUBSETS))
            w = 0.8 / len(LEARNERS)
            for j, learner in enumerate(LEARNERS):
                keys = [f"{s}{learner}{d}.{measure}" for s in SUBSETS]
                err = np.array([_err(result, k) for k in keys])
                ax.bar(x + (j - 1) * w, [m[k] for k in keys], w, yerr=np.where(np.isfinite(err), err, 0), capsize=2,
                       label=LEARNER_TITLES[learner])
            if measure == "retrieval":
                ax.axhline(m["chance.retrieval"], color="k", ls=":", lw=1, label="chance")
            else:
                ax.scatter(x, [m[f"{s}chance.{measure}"] for s in SUBSETS], color="k", marker="_", s=200, zorder=3,
                           label="chance")
                ax.scatter(x, [m[f"{s}observed.{d}.{measure}"] for s in SUBSETS], color="0.4", marker="x", zorder=3,
                           label="other modality observed (ceiling of the naming protocol)")
            ax.set_xticks(x, [SHORT_TITLES[s] for s in SUBSETS], fontsize=7)
            ax.set_title({"s2m": "from the utterance (sound -> motion)", "m2s": "from the motion (motion -> sound)"}[d],
                         fontsize=9)
            ax.set_ylim(0, 1)
        axes[0].set_ylabel(measure.replace("_", " "))
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize=7)
        fig.suptitle(f"Compositional learning: {measure.replace('_', ' ')} (mean over {config.n_folds} folds, 95 % "
                     "interval)", fontsize=9)
        figs[measure] = fig
    return figs


#: Where the thesis asks for this experiment (its perspectives); the claims stay ours.
PERSPECTIVE = "Discussion and perspectives (lines 6113-6118)"
_bar = common.bar_rule

EXPERIMENT = register(Experiment(
    id="ch7-compositional",
    title="Compositional multimodal learning: keyword sets <-> simultaneous gestures",
    thesis_ref="Beyond the thesis: Discussion and perspectives; protocol of sections 6.5-6.6 (Tables 6.1, 6.2) "
               "and 3.3 (l_given_number, l_full, Table 3.3)",
    config_cls=Config,
    compute=compute,
    present=present,
    claims=[
        Claim("From an utterance of 2-3 keywords the motion showing the matching gestures is retrieved well above "
              "chance, and back: a chance-corrected success above 0.2 in both directions (among 10 candidates a "
              "random ranking succeeds 0.10 of the time; the bar is 0.28).",
              f"{_bar('s2m.retrieval', 'chance.retrieval')} and {_bar('m2s.retrieval', 'chance.retrieval')}",
              source=PERSPECTIVE),
        Claim("The concepts of a 2-3-concept example are named from the other modality well above chance when "
              "their number is given: l_given_number above the bar in both directions (a random ranking names them "
              "with probability 1 / C(10, n), under 0.03; the bar is about 0.21).",
              f"{_bar('s2m.l_given_number', 'chance.l_given_number')} and "
              f"{_bar('m2s.l_given_number', 'chance.l_given_number')}", source=PERSPECTIVE),
        Claim("The concept sets of 2-3-concept examples are named exactly (l_full) well above chance in both "
              "directions (bar: a chance-corrected l_full of 0.2 over the better of two useless labellers, the "
              "most frequent label set and a random set of the true size; about 0.21).",
              f"{_bar('s2m.l_full', 'chance.l_full')} and {_bar('m2s.l_full', 'chance.l_full')}",
              source=PERSPECTIVE),
        Claim("Combinations never seen together in training are retrieved well above chance, in both directions "
              "(the retrieval bar, 0.28 against a random ranking's 0.10).",
              f"{_bar('unseen.s2m.retrieval', 'chance.retrieval')} and "
              f"{_bar('unseen.m2s.retrieval', 'chance.retrieval')}"),
        Claim("The concepts of combinations never seen together in training are named well above chance "
              "(l_given_number above the bar, about 0.21 against a random ranking's under 0.03), in both "
              "directions.",
              f"{_bar('unseen.s2m.l_given_number', 'unseen.chance.l_given_number')} and "
              f"{_bar('unseen.m2s.l_given_number', 'unseen.chance.l_given_number')}"),
        Claim("Examples of 3 concepts are retrieved less well than examples of 2 (a question: it could go either "
              "way).", "n3.s2m.retrieval < n2.s2m.retrieval and n3.m2s.retrieval < n2.m2s.retrieval"),
        Claim("Trained on compositions, the learner names the concepts of 2-3-concept examples better than the same "
              "learner trained on as many single-concept pairs (reported either way).",
              "s2m.l_given_number > single_trained.s2m.l_given_number and "
              "m2s.l_given_number > single_trained.m2s.l_given_number"),
        Claim("Sanity check: the learner trained on shuffled pairs stays below the retrieval bar in both directions "
              "(a leak of test recordings into training would lift it).",
              f"{_bar('shuffled.s2m.retrieval', 'chance.retrieval', below=True)} and "
              f"{_bar('shuffled.m2s.retrieval', 'chance.retrieval', below=True)}", kind="check"),
        Claim("Sanity check of the naming protocol: naming from the observed (not reconstructed) other modality "
              "passes the l_given_number bar in both directions.",
              f"{_bar('observed.s2m.l_given_number', 'chance.l_given_number')} and "
              f"{_bar('observed.m2s.l_given_number', 'chance.l_given_number')}", kind="check"),
    ],
    datasets=("fsdd", "msr-action3d", "acorns", "audio"),
    description="Utterances of 2-3 keywords paired with motions of 2-3 simultaneous gestures: retrieval, naming, "
                "unseen combinations, number of concepts, and training on single concepts (beyond the thesis).",
))
run = EXPERIMENT.run
