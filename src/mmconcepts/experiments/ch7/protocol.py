"""Data builders and scorers of the compositional multimodal experiment (``ch7-compositional``).

Beyond the thesis (its perspectives: "relating gestures that are observed combined in
complex motions to words that are observed combined in complex sentences"). An example
pairs an utterance of 1-3 keywords with a motion of as many simultaneous gestures; the
keyword set and the gesture set stand for the same *concepts* through a random keyword ->
gesture bijection (thesis Table 6.1 is one such mapping, drawn here from the data stream).

Concepts, limbs and combinations
    Gestures are done by one limb group (*slot*): the right arm, the left arm or the legs
    (with the torso). A motion shows at most one gesture per slot, the other slots idle,
    so a concept set is possible when its gestures are on distinct slots
    (:func:`draw_combinations`): with the 4 + 3 + 3 gestures used here, 10 single
    concepts, 33 pairs and 36 triples.

Motion (:func:`compose_msr_motion`, :func:`simulate_motion`)
    Real: limb collages of real MSR Action3D skeletons (Li, Zhang and Liu 2010), as the
    chapter 3 mixed sets are built (:func:`mmconcepts.experiments.ch3.protocol.msr_subset`):
    the right-arm angles of a right-arm gesture's recording, the right-arm angles of a
    left-arm gesture's recording mirrored onto the left arm (the angles are defined
    symmetrically per side), the torso and legs of a leg gesture's recording; an idle slot
    takes the idle limbs of an *idle donor* (a recording of a one-arm action outside the
    vocabulary, whose left arm and legs barely move; its left-arm angles serve as an idle
    right arm). Cropped to the shortest recording. Synthetic: the chapter 3 kinematic
    dancer (:func:`mmconcepts.motion.synthetic.simulate_choreography`) performing Table
    B.2 gestures on the slots, the others idle.

Sound (:func:`compose_utterance`)
    Recordings of one speaker, one keyword each (FSDD digit words, or the generated
    Caregiver-like sentences of one speaker), put end to end in a random order with a
    silence of 0.1-0.3 s between two of them (the pauses of
    :func:`mmconcepts.sound.data.compose_utterances`), then MFCC (22 coefficients).

Folds
    The source recordings (utterances, motion recordings) are split into folds within each
    keyword / action (:func:`mmconcepts.engine.splits.concept_parts`), the
    examples are dealt into folds (:func:`example_folds`), and the examples of fold f are
    composed from fold f's sources only (:func:`draw_sources`): a recording never serves
    in both training and test. Each fold also holds out a set of combinations
    (:func:`held_out_combinations`, a partition of the possible pairs and triples): its
    training set leaves out the other folds' examples of those combinations, so part of
    its test examples show combinations never seen together in training (as thesis
    Table 3.3).

Bars above chance
    A claim that a score is "above chance" asks for a chance-corrected score
    ``(p - p0) / (1 - p0)`` of at least :data:`FAIR_AGREEMENT` (:func:`fair_bar`), ``p0``
    the score of a useless learner (a random ranking, an input-blind labelling, a
    shuffled-concept control): the form of Cohen's kappa, whose values up to 0.2 are
    "slight" agreement on the scale of Landis and Koch (1977). Fixed from the chance
    values before any result was looked at; shared by ``ch7-compositional`` and
    ``ch7-online``.

Random streams: the data stream draws the bijection, the combinations, the sources of each
example, the pauses and the synthetic motions; the splits stream the folds of the sources
and the held-out combinations; the learner, reference and composition streams are used
by the experiment (learners, retrieval draws, shuffled control).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numba as nb
import numpy as np

from ..._jit import njit
from ...engine import FAIR_AGREEMENT, above_chance_rule, fair_bar
from ...errors import DataError, ParameterError

__all__ = ["SLOTS", "Vocabulary", "MSR_VOCABULARY", "MSR_IDLE_DONORS", "SYNTHETIC_VOCABULARY", "FAIR_AGREEMENT",
           "fair_bar", "bar_rule", "concept_bijection", "draw_combinations", "possible_combinations",
           "held_out_combinations", "example_folds", "draw_sources", "check_pairing", "compose_utterance",
           "compose_msr_motion", "simulate_motion", "combination_retrieval", "decompose_on_references",
           "example_scores", "given_number_chance", "label_matrix"]

#: The limb groups a gesture is done with; a motion shows at most one gesture per slot.
SLOTS = ("right_arm", "left_arm", "legs")

#: ``bar_rule(metric, chance, ceiling)``: the rule of a claim "above chance", a chance-corrected score ``(p - p0) /
#: (1 - p0)`` above :data:`FAIR_AGREEMENT` (the lower end of "fair" agreement on Landis and Koch's (1977) scale of
#: Cohen's kappa; :func:`mmconcepts.engine.rules.above_chance_rule`). A learner at chance scores 0, a perfect
#: one 1; 0.2 means that beyond the share a useless learner gets by luck, at least one in five of the remaining
#: examples is solved.
bar_rule = above_chance_rule


@dataclass(frozen=True)
class Vocabulary:
    """The gestures of the concepts, by slot (gesture ids of the motion data set)."""

    right_arm: tuple[int, ...]
    left_arm: tuple[int, ...]
    legs: tuple[int, ...]

    @property
    def gestures(self) -> tuple[int, ...]:
        """Every gesture id, slot by slot (right arm, left arm, legs)."""
        return self.right_arm + self.left_arm + self.legs

    @property
    def slots(self) -> tuple[str, ...]:
        """The slot of each gesture of :attr:`gestures`."""
        return tuple(s for s in SLOTS for _ in getattr(self, s))


#: MSR Action3D actions used as gestures (fixed before any run): right arm 1 high arm wave,
#: 2 horizontal arm wave, 5 forward punch, 6 high throw; on the left arm (mirrored) 3 hammer,
#: 7 draw x, 9 draw circle; legs 14 forward kick, 15 side kick, 16 jogging.
MSR_VOCABULARY = Vocabulary(right_arm=(1, 2, 5, 6), left_arm=(3, 7, 9), legs=(14, 15, 16))
#: One-arm MSR actions outside the vocabulary whose recordings give the idle limbs (4 hand catch, 8 draw tick).
MSR_IDLE_DONORS = (4, 8)
#: Table B.2 gestures of the synthetic dancer (from the 16 of Table 3.1, "stay still" left out):
#: right arm 1, 5, 6, 10; left arm 38, 40, 43; legs 23 un-squat, 24 walking, 28 flag shape.
SYNTHETIC_VOCABULARY = Vocabulary(right_arm=(1, 5, 6, 10), left_arm=(38, 40, 43), legs=(23, 24, 28))


# ---------------------------------------------------------------------------- concepts
def concept_bijection(n_concepts: int, n_gestures: int, rng: np.random.Generator) -> np.ndarray:
    """A random keyword -> gesture bijection (thesis Table 6.1): ``g[c]`` is concept c's gesture index.

    Parameters
    ----------
    n_concepts : int
        Number of keywords (concept c is the c-th keyword).
    n_gestures : int
        Number of gestures of the vocabulary; must equal ``n_concepts``.
    rng : numpy.random.Generator
        The data stream.

    Returns
    -------
    ndarray of int of shape (n_concepts,), a permutation of ``range(n_gestures)``

    Raises
    ------
    DataError
        If the two vocabularies differ in size (no bijection exists).
    """
    if int(n_concepts) != int(n_gestures):
        raise DataError(f"{n_concepts} keywords but {n_gestures} gestures: a bijection needs as many of each; "
                        "use a vocabulary of as many gestures as the speech data has keywords.")
    return rng.permutation(int(n_gestures)).astype(np.int64)


def possible_combinations(slot_of_concept: Sequence[str], n: int) -> list[tuple[int, ...]]:
    """Every set of ``n`` concepts whose gestures are on distinct slots (sorted tuples, sorted)."""
    from itertools import combinations

    return [c for c in combinations(range(len(slot_of_concept)), n)
            if len({slot_of_concept[i] for i in c}) == n]


def draw_combinations(n_examples: int, counts: Sequence[int], slot_of_concept: Sequence[str],
                      rng: np.random.Generator) -> list[tuple[int, ...]]:
    """The concept set of each example: its size cycles through ``counts``, its concepts are drawn at random.

    An example of n concepts takes n distinct slots at random, then one concept of each
    slot uniformly (so every concept of a slot is equally frequent).

    Parameters
    ----------
    n_examples : int
    counts : sequence of int
        Concept counts, used in turn (e.g. ``(2, 3)``: half pairs, half triples).
    slot_of_concept : sequence of str
        The slot of each concept's gesture (through the bijection).
    rng : numpy.random.Generator
        The data stream.

    Returns
    -------
    list of tuple of int (sorted concept indices)

    Raises
    ------
    ParameterError
        If a count is below 1, or above the vocabulary (the number of concepts) or the
        number of slots (gestures of one example must be simultaneous).
    """
    counts = [int(c) for c in counts]
    n_slots = len(set(slot_of_concept))
    if not counts:
        raise ParameterError("counts must name at least one concept count, e.g. (2, 3).")
    for c in counts:
        if c < 1:
            raise ParameterError(f"a concept count must be >= 1 (an utterance with no keyword has no concept); "
                                 f"got {c}.")
        if c > len(slot_of_concept):
            raise ParameterError(f"a concept count of {c} is above the vocabulary of {len(slot_of_concept)} "
                                 "concepts; use at most that many concepts per example.")
        if c > n_slots:
            raise ParameterError(f"a concept count of {c} is above the {n_slots} limb groups ({', '.join(SLOTS)}): "
                                 f"simultaneous gestures need one limb group each; use at most {n_slots}.")
    by_slot = {s: [i for i, t in enumerate(slot_of_concept) if t == s] for s in sorted(set(slot_of_concept))}
    names = sorted(by_slot)
    out = []
    for j in range(int(n_examples)):
        n = counts[j % len(counts)]
        slots = rng.choice(len(names), size=n, replace=False)
        out.append(tuple(sorted(int(by_slot[names[s]][rng.integers(len(by_slot[names[s]]))]) for s in slots)))
    return out


def held_out_combinations(combos: Sequence[tuple[int, ...]], n_folds: int, rng: np.random.Generator) -> list[set]:
    """A random partition of the combinations into ``n_folds`` sets (fold f's held-out combinations)."""
    order = rng.permutation(len(combos))
    out: list[set] = [set() for _ in range(int(n_folds))]
    for r, j in enumerate(order):
        out[r % int(n_folds)].add(tuple(combos[j]))
    return out


def example_folds(combos: Sequence[Sequence[int]], single: np.ndarray, n_folds: int,
                  rng: np.random.Generator) -> np.ndarray:
    """The fold of each example: the others dealt round robin in a random order, single-concept ones by concept.

    Single-concept examples are split within each concept
    (:func:`mmconcepts.engine.splits.concept_parts`), so that every fold holds
    single-concept examples of every concept that has at least ``n_folds`` of them (the
    fold's references).

    Parameters
    ----------
    combos : sequence of sequences of int
        The concept set of each example.
    single : bool ndarray of shape (n_examples,)
        Which examples are single-concept ones (their concept is ``combos[i][0]``).
    n_folds : int
    rng : numpy.random.Generator
        The splits stream.

    Returns
    -------
    ndarray of int of shape (n_examples,), values in ``range(n_folds)``
    """
    from ...engine.splits import concept_parts

    single = np.asarray(single, dtype=bool)
    if single.shape != (len(combos),):
        raise DataError(f"single must flag each of the {len(combos)} examples; got shape {single.shape}.")
    if any(len(combos[int(i)]) != 1 for i in np.flatnonzero(single)):
        raise DataError("an example flagged single-concept has several concepts.")
    fold = np.empty(len(combos), dtype=np.int64)
    idx = rng.permutation(np.flatnonzero(~single))
    fold[idx] = np.arange(idx.size) % int(n_folds)
    fold[single] = concept_parts(np.array([combos[int(i)][0] for i in np.flatnonzero(single)], dtype=np.int64),
                                 int(n_folds), rng)
    return fold


def draw_sources(wanted: Sequence[Sequence[int]], fold: np.ndarray, source_label: np.ndarray,
                 source_fold: np.ndarray, rng: np.random.Generator, *,
                 what: str = "recording") -> list[tuple[int, ...]]:
    """For each example, one source recording of each wanted label, drawn in the example's own fold.

    Parameters
    ----------
    wanted : sequence of sequences of int
        The labels whose recordings example i is made of (its keywords in the spoken order,
        its gestures and an idle donor, ...), in the order they are used.
    fold : ndarray of int of shape (n_examples,)
        Each example's fold.
    source_label, source_fold : ndarrays of int of shape (n_sources,)
        Each source recording's label and fold.
    rng : numpy.random.Generator
        The data stream.
    what : str
        What a source is, for the error message.

    Returns
    -------
    list of tuple of int
        ``out[i][j]`` is the index of the recording of ``wanted[i][j]`` behind example i,
        a recording of fold ``fold[i]`` (drawn uniformly there).

    Raises
    ------
    DataError
        If an example's fold holds no recording of a label it needs.
    """
    source_label, source_fold = np.asarray(source_label), np.asarray(source_fold)
    if len(wanted) != len(fold):
        raise DataError(f"{len(wanted)} examples but {len(fold)} folds; give one fold per example.")
    pools: dict[tuple[int, int], np.ndarray] = {}
    out = []
    for labels, f in zip(wanted, np.asarray(fold)):
        srcs = []
        for c in labels:
            key = (int(c), int(f))
            if key not in pools:
                pools[key] = np.flatnonzero((source_label == key[0]) & (source_fold == key[1]))
            pool = pools[key]
            if pool.size == 0:
                raise DataError(f"fold {key[1]} holds no {what} of label {key[0]}: too few {what}s for this many "
                                "folds; use fewer folds or more recordings.")
            srcs.append(int(pool[rng.integers(pool.size)]))
        out.append(tuple(srcs))
    return out


def label_matrix(sets: Sequence[Sequence[int]], n_labels: int) -> np.ndarray:
    """Binary (n_examples, n_labels) matrix of label sets."""
    Y = np.zeros((len(sets), int(n_labels)), dtype=np.int64)
    for i, s in enumerate(sets):
        Y[i, list(s)] = 1
    return Y


def check_pairing(keyword_sets: Sequence[Sequence[str]], gesture_sets: Sequence[Sequence[int]],
                  mapping: dict) -> None:
    """Check that example i's gesture set is the image of its keyword set under ``mapping``.

    Parameters
    ----------
    keyword_sets : sequence of sequences of str
        The keywords of each utterance.
    gesture_sets : sequence of sequences of int
        The gestures of each motion, rows aligned with ``keyword_sets``.
    mapping : dict of str to int
        The keyword -> gesture bijection.

    Raises
    ------
    DataError
        If the two modalities have different numbers of examples, an utterance has no
        keyword, a keyword is unknown, or a gesture set is not the keyword set's image.
    """
    if len(keyword_sets) != len(gesture_sets):
        raise DataError(f"the pairing has {len(keyword_sets)} utterances but {len(gesture_sets)} motions; every "
                        "example needs one of each (rows aligned).")
    for i, (kws, gs) in enumerate(zip(keyword_sets, gesture_sets)):
        if len(kws) == 0:
            raise DataError(f"utterance {i} has no keyword; every utterance must name at least one concept.")
        unknown = [k for k in kws if k not in mapping]
        if unknown:
            raise DataError(f"utterance {i}: keyword {unknown[0]!r} is not in the bijection ({sorted(mapping)}).")
        if sorted(mapping[k] for k in kws) != sorted(int(g) for g in gs):
            raise DataError(f"example {i}: keywords {list(kws)} map to gestures {sorted(mapping[k] for k in kws)} "
                            f"but the motion shows {sorted(gs)}.")


# ---------------------------------------------------------------------------- sound
def compose_utterance(pieces: Sequence[np.ndarray], pauses_s: Sequence[float], sr: int) -> np.ndarray:
    """Recordings end to end with a silence of ``pauses_s[j]`` seconds after piece j.

    Parameters
    ----------
    pieces : sequence of 1-D float arrays
        The recordings (same sample rate ``sr``), at least one.
    pauses_s : sequence of float
        ``len(pieces) - 1`` pauses, seconds.
    sr : int

    Returns
    -------
    ndarray of float32 of shape (sum of lengths + pause samples,)
    """
    if len(pieces) == 0:
        raise DataError("an utterance needs at least one recording (keyword); got none.")
    if len(pauses_s) != len(pieces) - 1:
        raise ParameterError(f"need {len(pieces) - 1} pauses for {len(pieces)} recordings; got {len(pauses_s)}.")
    out: list[np.ndarray] = []
    for j, y in enumerate(pieces):
        out.append(np.asarray(y, dtype=np.float32))
        if j < len(pauses_s):
            out.append(np.zeros(int(round(float(pauses_s[j]) * sr)), dtype=np.float32))
    return np.concatenate(out)


# ---------------------------------------------------------------------------- motion
def compose_msr_motion(parts: dict, donor: np.ndarray) -> np.ndarray:
    """A limb collage of real joint-angle trajectories (16 angles per frame, :func:`joint_angles`).

    Parameters
    ----------
    parts : dict of slot to (T_i, 16) array
        For each active slot, the recording whose gesture it shows: the right-arm columns
        of a right-arm recording (slot ``right_arm``), the right-arm columns of a recording
        mirrored onto the left arm (slot ``left_arm``), the torso and leg columns of a leg
        recording (slot ``legs``).
    donor : (T_d, 16) array
        The idle donor (a one-arm action): its legs and torso, its left arm, and its left
        arm again as the idle right arm fill the idle slots.

    Returns
    -------
    ndarray of shape (T, 16), T the shortest of the recordings used
    """
    from ...motion import ARM_COLUMNS, LEFT_ARM_COLUMNS, RIGHT_ARM_COLUMNS

    unknown = set(parts) - set(SLOTS)
    if unknown:
        raise ParameterError(f"unknown slot(s) {sorted(unknown)}; slots are {SLOTS}.")
    T = min([len(donor)] + [len(a) for a in parts.values()])
    legs_src = parts.get("legs", donor)
    x = np.array(legs_src[:T], dtype=np.float64, copy=True)  # torso and legs (and arms, overwritten below)
    if "right_arm" in parts:
        x[:, RIGHT_ARM_COLUMNS] = parts["right_arm"][:T, RIGHT_ARM_COLUMNS]
    else:
        x[:, RIGHT_ARM_COLUMNS] = donor[:T, LEFT_ARM_COLUMNS]
    if "left_arm" in parts:
        x[:, LEFT_ARM_COLUMNS] = parts["left_arm"][:T, RIGHT_ARM_COLUMNS]
    else:
        x[:, LEFT_ARM_COLUMNS] = donor[:T, LEFT_ARM_COLUMNS]
    assert set(ARM_COLUMNS) == set(RIGHT_ARM_COLUMNS) | set(LEFT_ARM_COLUMNS)
    return x


def simulate_motion(gestures: Sequence[int], seed: int) -> np.ndarray:
    """Joint angles (T, 16) of the synthetic dancer performing ``gestures`` simultaneously (Table B.2 ids)."""
    from ...motion import joint_angles
    from ...motion.synthetic import simulate_choreography

    rec = simulate_choreography(tuple(int(g) for g in gestures), random_state=np.random.default_rng(seed))
    return np.ascontiguousarray(joint_angles(rec), dtype=np.float64)


# ---------------------------------------------------------------------------- scorers
def combination_retrieval(D: np.ndarray, combo_query: Sequence, combo_cand: Sequence, *, n_candidates: int,
                          n_draws: int, rng: np.random.Generator) -> np.ndarray:
    """Per-query success rate of retrieving a candidate of the query's combination among distractors.

    For each query and each draw: one candidate of the query's combination (drawn among
    the candidates that have it) and ``n_candidates - 1`` distractors, one of each of
    ``n_candidates - 1`` other combinations drawn at random (then one candidate of each,
    at random), as thesis Fig. 6.3 draws one reference per class; the query succeeds when
    the candidate closest to it (smallest ``D``) has its combination. Chance is
    ``1 / n_candidates``. A tie for the smallest distance counts as a failure.

    Parameters
    ----------
    D : ndarray of shape (n_query, n_cand)
        Dissimilarities (queries in one modality, candidates in the other).
    combo_query, combo_cand : sequences of hashable
        The combination (concept set) of each query / candidate.
    n_candidates : int
        Candidates per draw (the matching one included), at least 2.
    n_draws : int
    rng : numpy.random.Generator
        The reference stream.

    Returns
    -------
    ndarray of shape (n_query,), fractions of draws that succeeded
    """
    D = np.asarray(D, dtype=np.float64)
    if D.shape != (len(combo_query), len(combo_cand)):
        raise DataError(f"D must be (n_query, n_cand) = ({len(combo_query)}, {len(combo_cand)}); got {D.shape}.")
    if int(n_candidates) < 2:
        raise ParameterError(f"n_candidates must be >= 2; got {n_candidates}.")
    keys = sorted(set(map(tuple, combo_cand)))
    index = {k: i for i, k in enumerate(keys)}
    cand_class = np.array([index[tuple(c)] for c in combo_cand])
    members = [np.flatnonzero(cand_class == i) for i in range(len(keys))]
    if len(keys) < int(n_candidates):
        raise DataError(f"the candidates show {len(keys)} combinations; {n_candidates} candidates per draw need at "
                        "least that many (use fewer candidates or more test examples).")
    out = np.zeros(len(combo_query))
    for q, c in enumerate(combo_query):
        own = index.get(tuple(c))
        if own is None:
            raise DataError(f"query {q}'s combination {tuple(c)} has no candidate.")
        others = np.array([i for i in range(len(keys)) if i != own])
        wins = 0
        for _ in range(int(n_draws)):
            classes = rng.choice(others, size=int(n_candidates) - 1, replace=False)
            right = members[own][rng.integers(members[own].size)]
            wrong = np.array([members[k][rng.integers(members[k].size)] for k in classes])
            d_right, d_wrong = D[q, right], D[q, wrong]
            wins += bool(d_right < d_wrong.min())
        out[q] = wins / int(n_draws)
    return out


@njit(parallel=True, nogil=True, cache=True, fastmath={"reassoc", "contract"})
def _decompose_rows(X, R, A, n_iter):  # pragma: no cover - compiled
    """``A[i] <- A[i] * ((X[i] / (A[i] R)) R^T)``, ``n_iter`` times, row by row (rows in parallel)."""
    n, p = X.shape
    k = R.shape[0]
    for i in nb.prange(n):
        v = np.empty(p, dtype=X.dtype)
        a = A[i].copy()
        for _ in range(n_iter):
            v[:] = 0.0
            for c in range(k):
                ac = a[c]
                for j in range(p):
                    v[j] += ac * R[c, j]
            for j in range(p):
                v[j] = X[i, j] / v[j] if v[j] > 0.0 else 0.0
            for c in range(k):
                acc = X.dtype.type(0.0)
                for j in range(p):
                    acc += v[j] * R[c, j]
                a[c] *= acc
        A[i] = a
    return A


def decompose_on_references(X: np.ndarray, R: np.ndarray, *, n_iter: int = 100) -> np.ndarray:
    """Nonnegative coefficients A of ``X ~ A R`` under the I-divergence, as fractions of the explained mass.

    The reconstructed perception of each example (a row of X) is decomposed on the
    single-concept references (rows of R, each normalised to sum to one) with the
    dictionary fixed, by the multiplicative update of the I-divergence (thesis eq. (2.16)
    with beta = 1; with rows of R summing to one its denominator is 1):
    ``A <- A * ((X / (A R)) R^T)``, from ``A = sum(x) / k``, in float32. Columns where
    every reference is zero carry no information on A and are left out. Each row of A is
    then divided by its sum, so ``A[i, c]`` is the share of concept c.

    Written by hand rather than through :func:`mmconcepts.nmf.beta_nmf` (``update_H=False``,
    which gives the same coefficients): it runs for every test example of every fold and
    learner, on a 10-atom dictionary of some 10^4 HAC columns, where matrix products with
    an inner dimension of 10 are bound by memory. A compiled loop (numba) runs the
    iterations of one example at a time, in parallel over examples, its row of X and
    ratios staying in the cache.

    Parameters
    ----------
    X : ndarray of shape (n_examples, n_features), nonnegative
    R : ndarray of shape (n_concepts, n_features), nonnegative, no all-zero row
    n_iter : int, default=100

    Returns
    -------
    ndarray of shape (n_examples, n_concepts), rows summing to one (zero rows stay zero)

    Notes
    -----
    The update is homogeneous in each row of X (scaling a row by c scales its coefficients
    by c and leaves its shares unchanged), and scaling by a power of two is exact: a row
    whose largest entry is below 2^-64 is first scaled by a power of two that brings that
    entry into [0.5, 1). Then the entries below the smallest normal float32 number (1.2e-38,
    as reconstructions ``W @ H`` hold where a product is tiny) are read as zero: each is at
    least 2^62 times smaller than its row's largest, far below float32's resolution beside
    it, but as a subnormal numerator each of its divisions would take about a hundred times
    as long.
    """
    X = np.asarray(X, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    if X.ndim != 2 or R.ndim != 2 or X.shape[1] != R.shape[1]:
        raise DataError(f"X (n, p) and R (k, p) must share their columns; got {X.shape} and {R.shape}.")
    if not (np.isfinite(X).all() and (X >= 0).all() and np.isfinite(R).all() and (R >= 0).all()):
        raise DataError("X and R must be finite and nonnegative.")
    mass = R.sum(axis=1)
    if (mass <= 0).any():
        raise DataError(f"reference(s) {np.flatnonzero(mass <= 0).tolist()} are all zero; every concept needs one.")
    keep = R.max(axis=0) > 0
    Rk = (R[:, keep] / mass[:, None]).astype(np.float32)
    Xk = X[:, keep]
    peak = Xk.max(axis=1)
    tiny = (peak > 0) & (peak < 2.0**-64)
    if tiny.any():  # a power of two brings the largest entry into [0.5, 1): the same shares (see the Notes)
        Xk[tiny] = np.ldexp(Xk[tiny], -np.frexp(peak[tiny])[1][:, None])
    Xk = Xk.astype(np.float32)
    Xk[Xk < np.finfo(np.float32).tiny] = 0.0  # subnormal after the cast (see the Notes)
    A = np.tile(Xk.sum(axis=1, keepdims=True) / R.shape[0], (1, R.shape[0])).astype(np.float32)
    A = _decompose_rows(np.ascontiguousarray(Xk), np.ascontiguousarray(Rk), A, int(n_iter)).astype(np.float64)
    s = A.sum(axis=1, keepdims=True)
    return np.divide(A, s, out=np.zeros_like(A), where=s > 0)


def example_scores(Y: np.ndarray, A: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-example l_given_number and l_full (thesis section 3.3.3) of concept shares ``A``.

    The per-example terms whose means are :func:`mmconcepts.nmf.l_given_number` and
    :func:`mmconcepts.nmf.l_full` (with ``threshold``), so that subsets of the test
    examples can be scored from one decomposition: an example counts for
    l_given_number when every true concept scores strictly higher than every other one,
    for l_full when the concepts scoring ``>= threshold`` are exactly the true ones.

    Parameters
    ----------
    Y : binary ndarray of shape (n_examples, n_concepts)
    A : ndarray of shape (n_examples, n_concepts)
    threshold : float

    Returns
    -------
    given_number, full : float ndarrays of shape (n_examples,), 0 or 1
    """
    Yt = np.asarray(Y).astype(bool)
    A = np.asarray(A, dtype=np.float64)
    if Yt.shape != A.shape:
        raise DataError(f"Y and A must have the same shape; got {Yt.shape} and {A.shape}.")
    min_true = np.where(Yt, A, np.inf).min(axis=1)
    max_other = np.where(Yt, -np.inf, A).max(axis=1)
    return (min_true > max_other).astype(float), ((A >= float(threshold)) == Yt).all(axis=1).astype(float)


def given_number_chance(n_labels: int, counts: Sequence[int]) -> float:
    """Chance of l_given_number for a random ranking: the mean of ``1 / C(n_labels, n)`` over the examples."""
    return float(np.mean([1.0 / math.comb(int(n_labels), int(n)) for n in counts]))
