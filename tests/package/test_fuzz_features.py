"""Fuzz tests of the motion and sound feature entry points.

MotionHistograms and delayed_velocity (mmconcepts.motion), mfcc / MFCCConfig, deltas and
windows, HAC and cooccurrence_counts, DTW, the cluster tree and the voting classifiers
(mmconcepts.sound), on small inputs. Every example ends in a typed mmconcepts error or a
finite result that passes a check of what correct means.
"""

from __future__ import annotations

import numpy as np
import pytest
from _fuzz import assert_typed_or_good, fuzz_settings
from hypothesis import HealthCheck, given
from hypothesis import strategies as st

from mmconcepts.motion.histograms import MotionHistograms
from mmconcepts.motion.kinematics import delayed_velocity
from mmconcepts.sound.dtw import dtw, dtw_distance_matrix, dtw_one_to_many
from mmconcepts.sound.features import MFCCConfig, add_deltas, delta, mfcc, mfcc_windows, sliding_windows, window_frames
from mmconcepts.sound.hac import HAC, cooccurrence_counts
from mmconcepts.sound.tree import ClusterTree
from mmconcepts.sound.voting import EventVoting, TreeVotingClassifier

pytestmark = [pytest.mark.fuzz, pytest.mark.filterwarnings("ignore")]

ODD = [np.nan, np.inf, -np.inf, 0, -1, 0.0, 1e308, 1e-320, True, "a", None, 10**9]
HS = dict(suppress_health_check=list(HealthCheck))


def _sequences(rng, kind: str, n_seq: int, d: int, scale: float):
    seqs = [rng.standard_normal((int(rng.integers(1, 30)), d)) * scale for _ in range(n_seq)]
    if kind == "nan" and seqs:
        seqs[0][0, 0] = np.nan
    elif kind == "inf" and seqs:
        seqs[0][-1, -1] = np.inf
    elif kind == "constant":
        seqs = [np.ones_like(s) for s in seqs]
    elif kind == "short":
        seqs = [s[:1] for s in seqs]
    elif kind == "1d":
        seqs = [s[:, 0] for s in seqs]
    elif kind == "ragged_dims" and len(seqs) > 1:
        seqs[1] = np.ones((5, d + 1))
    elif kind == "empty":
        seqs = [s[:0] for s in seqs]
    return seqs


@fuzz_settings(150, **HS)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_seq=st.integers(0, 5),
    d=st.integers(1, 3),
    kind=st.sampled_from(["ok"] * 6 + ["nan", "inf", "constant", "short", "1d", "ragged_dims", "empty"]),
    scale=st.sampled_from([1.0, 1.0, 1.0, 1e-300, 1e300, 1e-8, 1e8]),
    param=st.sampled_from([None] * 10 + ["data", "method", "n_bins", "delay", "smoothing", "range_quantile",
                                         "softness", "period", "assignment", "max_fit_samples"]),
    value=st.sampled_from(ODD + [2, 3, (3, 4), "vq", "kde", "soft", "angles", "velocities", "separate", 0.4]),
    other=st.sampled_from([dict(), dict(method="vq", n_bins=3), dict(method="vq", n_bins=3, assignment="soft"),
                           dict(data="separate"), dict(data="angles", n_bins=4), dict(period=2 * np.pi)]),
)
def test_fuzz_motion_histograms(seed, n_seq, d, kind, scale, param, value, other):
    rng = np.random.default_rng(seed)
    seqs = _sequences(rng, kind, n_seq, d, scale)
    kw = dict(other)
    if param is not None:
        kw[param] = value

    def run():
        mh = MotionHistograms(random_state=0, **kw).fit(seqs)
        return mh.transform(seqs), mh.get_feature_names_out()

    def check(res):
        F, names = res
        # one row per sequence, nonnegative histograms, each dof's histogram sums to 1 (or 0)
        return bool(F.shape == (len(seqs), len(names)) and (F >= 0).all())

    assert_typed_or_good("mmconcepts.motion.MotionHistograms", run, check=check)


@fuzz_settings(300)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(0, 8),
    delay=st.sampled_from([1, 2, 3, 0, -1, 1.5, True, None, 10**9]),
    period=st.sampled_from([None, None, 2 * np.pi, 360.0, 0, -1, np.nan, np.inf, "x", 1e-300]),
    kind=st.sampled_from(["ok", "ok", "nan", "scalar", "2d", "huge", "object"]),
)
def test_fuzz_delayed_velocity(seed, n, delay, period, kind):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n, 2)) * 3
    if kind == "nan" and n:
        x[0, 0] = np.nan
    elif kind == "scalar":
        x = np.float64(1.0)
    elif kind == "huge":
        x = x * 1e307
    elif kind == "object":
        x = x.astype(object)
        if n:
            x[0, 0] = "a"

    def check(v):
        xa = np.asarray(x, dtype=float)
        ref = xa[delay:] - xa[:-delay]
        if period is not None:
            # wrapped into [-period/2, period/2) and congruent to the plain difference
            ok = (v >= -period / 2 - 1e-9 * period).all() and (v < period / 2 + 1e-9 * period).all()
            k = (ref - v) / period
            return bool(ok and np.allclose(k, np.round(k), atol=1e-6))
        return bool(np.array_equal(v, ref))

    assert_typed_or_good("mmconcepts.motion.delayed_velocity", lambda: delayed_velocity(x, delay, period=period),
                         check=check)


@fuzz_settings(120, **HS)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_samples=st.sampled_from([0, 1, 100, 400, 1600, 4000, 4000, 8000]),
    kind=st.sampled_from(["noise"] * 5 + ["silence", "nan", "inf", "int16", "2d", "huge", "tiny", "stereo"]),
    param=st.sampled_from([None] * 10 + ["sr", "n_mfcc", "win_ms", "hop_ms", "n_mels", "fmin", "fmax", "top_db",
                                         "lifter", "window"]),
    value=st.sampled_from(ODD + [8000, 22, 5.0, 100.0, 2000.0, 7999.0, "hann", "nope", 3]),
)
def test_fuzz_mfcc(seed, n_samples, kind, param, value):
    rng = np.random.default_rng(seed)
    y = rng.standard_normal(n_samples) * 0.1
    if kind == "silence":
        y[:] = 0.0
    elif kind == "nan" and n_samples:
        y[0] = np.nan
    elif kind == "inf" and n_samples:
        y[-1] = np.inf
    elif kind == "int16":
        y = (y * 3000).astype(np.int16)
    elif kind == "2d":
        y = y[:, None]
    elif kind == "stereo":
        y = np.stack([y, y])
    elif kind == "huge":
        y = y * 1e300
    elif kind == "tiny":
        y = y * 1e-300
    kw = {} if param is None else {param: value}

    def run():
        cfg = MFCCConfig(**kw)
        return mfcc(y, cfg), cfg

    def check(res):
        F, cfg = res
        return bool(F.ndim == 2 and F.shape[1] == cfg.n_mfcc and F.shape[0] >= 1)

    assert_typed_or_good("mmconcepts.sound.mfcc", run, check=check)


@fuzz_settings(200)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(0, 12),
    d=st.integers(0, 3),
    width=st.sampled_from([1, 2, 5, 0, -1, 1.5, None, 10**9]),
    shift=st.sampled_from([None, 1, 2, 0, -2, 2.5]),
    duration=st.sampled_from([80.0, 10.0, 0.0, -5.0, np.nan, np.inf, 1e308]),
    hop=st.sampled_from([10.0, 1e-300, 0.0, np.nan, np.inf]),
    kind=st.sampled_from(["ok", "ok", "nan", "1d"]),
)
def test_fuzz_deltas_and_windows(seed, n, d, width, shift, duration, hop, kind):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n, d))
    if kind == "nan" and x.size:
        x.flat[0] = np.nan
    elif kind == "1d":
        x = x.ravel()
    assert_typed_or_good("mmconcepts.sound.delta", lambda: delta(x),
                         check=lambda v: bool(v.shape == np.shape(x)))
    assert_typed_or_good("mmconcepts.sound.add_deltas", lambda: add_deltas(x),
                         check=lambda v: bool(v.shape == (x.shape[0], 3 * x.shape[1]) and np.array_equal(
                             v[:, : x.shape[1]], x)))

    def win_check(w):
        s = shift if shift is not None else max(1, round(width / 3))
        return bool(w.ndim == 3 and w.shape[1] == width and w.shape[2] == x.shape[1]
                    and all(np.array_equal(w[i], x[i * s: i * s + width]) for i in range(w.shape[0])))

    assert_typed_or_good("mmconcepts.sound.sliding_windows", lambda: sliding_windows(x, width, shift), check=win_check)
    assert_typed_or_good("mmconcepts.sound.window_frames", lambda: window_frames(duration, hop),
                         check=lambda k: bool(isinstance(k, int) and k >= 1))


@fuzz_settings(40, **HS)
@given(seed=st.integers(0, 2**31 - 1), n_samples=st.sampled_from([0, 100, 2000, 4000]),
       window_ms=st.sampled_from([80.0, 10.0, 0.0, np.nan, np.inf, 1e6]),
       shift=st.sampled_from([1 / 3, 1.0, 0.0, -1.0, np.nan, 2.0]))
def test_fuzz_mfcc_windows(seed, n_samples, window_ms, shift):
    y = np.random.default_rng(seed).standard_normal(n_samples) * 0.1
    assert_typed_or_good("mmconcepts.sound.mfcc_windows", lambda: mfcc_windows(y, window_ms=window_ms, shift=shift),
                         check=lambda w: bool(w.ndim == 3))  # zero windows when the utterance is shorter


@fuzz_settings(300)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_seq=st.integers(0, 4),
    n_events=st.sampled_from([1, 3, 5, 0, -1, 1.5, 10**6]),
    lag=st.sampled_from([1, 2, 5, 0, -1, 2.5, None]),
    kind=st.sampled_from(["ok", "ok", "out_of_range", "negative", "float", "2d", "empty"]),
)
def test_fuzz_cooccurrence_counts(seed, n_seq, n_events, lag, kind):
    rng = np.random.default_rng(seed)
    k = n_events if isinstance(n_events, int) and n_events > 0 else 3
    events = [rng.integers(0, k, int(rng.integers(0, 10))) for _ in range(n_seq)]
    if kind == "out_of_range" and events:
        events[0] = np.append(events[0], k)
    elif kind == "negative" and events:
        events[0] = np.append(events[0], -1)
    elif kind == "float" and events:
        events[0] = events[0] + 0.5
    elif kind == "2d" and events:
        events[0] = events[0][:, None]
    elif kind == "empty":
        events = [np.zeros(0, int) for _ in events]

    def check(C):
        if C.shape != (len(events), k * k):
            return False
        for i, e in enumerate(events):  # a direct count
            ref: dict = {}
            for a, b in zip(e[:-lag] if lag < len(e) else [], e[lag:]):
                ref[int(a) * k + int(b)] = ref.get(int(a) * k + int(b), 0) + 1
            row = C[[i]].tocoo()
            if dict(zip(row.col.tolist(), row.data.tolist())) != ref:
                return False
        return True

    assert_typed_or_good("mmconcepts.sound.cooccurrence_counts", lambda: cooccurrence_counts(events, n_events, lag),
                         check=check)


@fuzz_settings(40, **HS)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_seq=st.integers(0, 5),
    kind=st.sampled_from(["ok", "ok", "ok", "nan", "inf", "constant", "short", "1d", "ragged_dims", "empty"]),
    param=st.sampled_from([None] * 5 + ["n_clusters", "lags", "standardize", "max_fit_frames", "max_iter"]),
    value=st.sampled_from(ODD + [(2, 2, 2), (1, 1, 1), (2, 0, 2), (1,), (3,), 5]),
)
def test_fuzz_hac(seed, n_seq, kind, param, value):
    rng = np.random.default_rng(seed)
    seqs = _sequences(rng, kind, n_seq, 4, 1.0)
    kw = dict(n_clusters=(2, 2, 2), lags=(1, 2), max_iter=10)
    if param is not None:
        kw[param] = value

    def run():
        hac = HAC(random_state=0, **kw).fit(seqs)
        return hac.transform(seqs), hac.n_features_out_

    def check(res):
        C, n_out = res
        return bool(C.shape == (len(seqs), n_out) and (C.data >= 0).all())

    assert_typed_or_good("mmconcepts.sound.HAC", run, check=check)


@fuzz_settings(200)
@given(
    seed=st.integers(0, 2**31 - 1),
    na=st.integers(0, 6),
    nb=st.integers(0, 6),
    d=st.integers(1, 3),
    window=st.sampled_from([None, None, 0, 1, 3, -1, 1.5, np.nan]),
    local=st.sampled_from(["euclidean", "euclidean", "sqeuclidean", "nope"]),
    kind=st.sampled_from(["ok", "ok", "nan", "inf", "huge", "dims", "1d", "self"]),
)
def test_fuzz_dtw(seed, na, nb, d, window, local, kind):
    rng = np.random.default_rng(seed)
    a, b = rng.standard_normal((na, d)), rng.standard_normal((nb, d))
    if kind == "nan" and a.size:
        a[0, 0] = np.nan
    elif kind == "inf" and b.size:
        b[0, 0] = np.inf
    elif kind == "huge":
        a, b = a * 1e300, b * 1e300
    elif kind == "dims":
        b = rng.standard_normal((nb, d + 1))
    elif kind == "1d":
        a, b = a[:, 0], b[:, 0]
    elif kind == "self":
        b = a.copy()

    def check(v):
        ok = v >= 0
        if kind == "self":
            ok &= v == 0
        return bool(ok)

    assert_typed_or_good("mmconcepts.sound.dtw", lambda: dtw(a, b, window=window, local=local), check=check)

    seqs = [rng.standard_normal((int(rng.integers(1, 6)), d)) for _ in range(na)]
    if kind == "nan" and seqs:
        seqs[-1][0, 0] = np.nan

    def mat_check(D):
        return bool(D.shape == (na, na) and (D >= 0).all() and np.allclose(D, D.T) and np.allclose(np.diag(D), 0))

    assert_typed_or_good("mmconcepts.sound.dtw_distance_matrix",
                         lambda: dtw_distance_matrix(seqs, window=window, local=local), check=mat_check)

    def one_check(v):
        return bool(v.shape == (na,) and (v >= 0).all()
                    and np.allclose(v, [dtw(a, s, window=window, local=local) for s in seqs]))

    assert_typed_or_good("mmconcepts.sound.dtw_one_to_many",
                         lambda: dtw_one_to_many(a, seqs, window=window, local=local), check=one_check)


@fuzz_settings(60, **HS)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(0, 60),
    d=st.integers(1, 3),
    r_max=st.sampled_from([0.5, 1.0, 1.5, 0.5, 1.0, 0.0, -1.0, np.nan, np.inf, 1e-300]),
    n_max=st.sampled_from([4, 5, 24, 4, 5, 24, 2, 0]),
    k=st.sampled_from([2, 3, 2, 3, 12, 1, 0]),
    metric=st.sampled_from(["euclidean", "euclidean", "dtw", "nope"]),
    search=st.sampled_from(["greedy", "best_children", "restart", "exact", "nope"]),
    kind=st.sampled_from(["ok", "ok", "ok", "nan", "inf", "constant", "huge"]),
)
def test_fuzz_cluster_tree(seed, n, d, r_max, n_max, k, metric, search, kind):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, 3, d)) if metric == "dtw" else rng.standard_normal((n, d))
    if kind == "nan" and X.size:
        X.flat[0] = np.nan
    elif kind == "inf" and X.size:
        X.flat[-1] = np.inf
    elif kind == "constant":
        X[:] = 1.0
    elif kind == "huge":
        X = X * 1e300

    def run():
        tree = ClusterTree(r_max, n_max=n_max, k=k, metric=metric, search=search, random_state=0).fit(X)
        return tree.predict(X, search="exact"), tree.leaf_centers_, tree.n_leaves_

    def check(res):
        labels, centers, n_leaves = res
        if labels.shape != (n,) or (labels < 0).any() or (labels >= n_leaves).any():
            return False
        if metric != "euclidean" or n == 0:
            return True
        # exact search: each point is assigned to its nearest leaf centre
        dist = np.linalg.norm(X[:, None, :] - centers.reshape(n_leaves, -1)[None], axis=2)
        return bool(np.allclose(dist[np.arange(n), labels], dist.min(axis=1)))

    assert_typed_or_good("mmconcepts.sound.ClusterTree", run, check=check)


@fuzz_settings(150, **HS)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_bags=st.integers(0, 6),
    weighting=st.sampled_from(["tfidf", "uniform", "nope"]),
    kind=st.sampled_from(["ok", "ok", "ok", "empty_bag", "negative", "float", "2d", "tags_short", "multi_tags"]),
)
def test_fuzz_event_voting(seed, n_bags, weighting, kind):
    rng = np.random.default_rng(seed)
    bags = [rng.integers(0, 6, int(rng.integers(1, 8))) for _ in range(n_bags)]
    tags: list = [str(t) for t in rng.integers(0, 3, n_bags)]
    if kind == "empty_bag" and bags:
        bags[0] = np.zeros(0, int)
    elif kind == "negative" and bags:
        bags[0] = bags[0] - 10
    elif kind == "float" and bags:
        bags[0] = bags[0] + 0.5
    elif kind == "2d" and bags:
        bags[0] = bags[0][:, None]
    elif kind == "tags_short":
        tags = tags[:-1]
    elif kind == "multi_tags":
        tags = [[t, "x"] for t in tags]

    def run():
        model = EventVoting(weighting=weighting).fit(bags, tags)
        return model.decision_function(bags), model.predict(bags), len(model.classes_)

    def check(res):
        S, pred, n_classes = res
        return bool(S.shape == (len(bags), n_classes) and len(pred) == len(bags))

    assert_typed_or_good("mmconcepts.sound.EventVoting", run, check=check)


@fuzz_settings(40, **HS)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_utt=st.integers(0, 5),
    kind=st.sampled_from(["ok", "ok", "ok", "nan", "empty_utt", "dims", "tags_short"]),
    events=st.sampled_from(["leaves", "nodes", "nope"]),
)
def test_fuzz_tree_voting(seed, n_utt, kind, events):
    rng = np.random.default_rng(seed)
    utts = [rng.standard_normal((int(rng.integers(1, 6)), 3, 2)) for _ in range(n_utt)]
    tags = [str(t) for t in rng.integers(0, 2, n_utt)]
    if kind == "nan" and utts:
        utts[0][0, 0, 0] = np.nan
    elif kind == "empty_utt" and utts:
        utts[0] = utts[0][:0]
    elif kind == "dims" and len(utts) > 1:
        utts[1] = rng.standard_normal((2, 4, 2))
    elif kind == "tags_short":
        tags = tags[:-1]

    def run():
        model = TreeVotingClassifier(ClusterTree(1.0, metric="dtw", random_state=0), events=events)
        model.fit(utts, tags)
        return model.decision_function(utts), model.predict(utts), len(model.classes_)

    def check(res):
        S, pred, n_classes = res
        return bool(S.shape == (len(utts), n_classes) and len(pred) == len(utts) and set(pred) <= set(tags))

    assert_typed_or_good("mmconcepts.sound.TreeVotingClassifier", run, check=check)
