"""MFCC front end, the thesis' delta operator, windows, HAC and TF-IDF voting."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from sklearn.exceptions import NotFittedError

from mmconcepts.errors import DataError, ParameterError
from mmconcepts.sound.features import (
    MFCCConfig,
    add_deltas,
    delta,
    log_mel_spectrogram,
    mfcc,
    mfcc_windows,
    sliding_windows,
    window_frames,
)
from mmconcepts.sound.hac import HAC, cooccurrence_counts
from mmconcepts.sound.voting import EventVoting

pytest.importorskip("librosa")


def tone(freq, seconds=0.5, sr=16000):
    t = np.arange(int(seconds * sr)) / sr
    return (0.5 * np.sin(2 * np.pi * freq * t)).astype(np.float32)


# -- delta -------------------------------------------------------------------------------
def test_delta_matches_the_formula_with_edge_replication(rng):
    x = rng.normal(size=(9, 3))
    d = delta(x)
    T = len(x)
    for t in range(T):
        def at(i):
            return x[min(max(i, 0), T - 1)]
        expected = 2 * at(t + 2) + at(t + 1) - at(t - 1) - 2 * at(t - 2)
        np.testing.assert_allclose(d[t], expected)


def test_delta_of_a_ramp_is_constant_inside_and_zero_of_a_constant():
    ramp = np.arange(10.0)[:, None]
    assert np.allclose(delta(ramp)[2:-2], 10.0)  # 2*2 + 1 + 1 + 2*2 per unit slope
    assert np.allclose(delta(np.full((7, 2), 3.0)), 0.0)


def test_delta_is_ten_times_librosas_with_edge_replication(rng):
    """Ours is the operator as the thesis writes it; librosa divides by sum(n^2) = 10 (width 5).
    Kept, not replaced by librosa.feature.delta: dividing by 10 (100 for delta-delta) changes the
    HAC features' last bits, which the standardised k-means of HAC would see (see the note in
    :func:`mmconcepts.sound.features.delta`). librosa's default mode "interp" also differs at the
    two first and last frames (a polynomial fit instead of edge replication)."""
    import librosa

    x = rng.normal(size=(40, 6))
    theirs = librosa.feature.delta(x, width=5, order=1, axis=0, mode="nearest")
    np.testing.assert_allclose(delta(x), 10.0 * theirs, rtol=1e-12, atol=1e-12)
    theirs2 = librosa.feature.delta(theirs, width=5, order=1, axis=0, mode="nearest")
    np.testing.assert_allclose(delta(delta(x)), 100.0 * theirs2, rtol=1e-12, atol=1e-11)
    interp = librosa.feature.delta(x, width=5, order=1, axis=0)  # librosa's default
    np.testing.assert_allclose(delta(x)[2:-2], 10.0 * interp[2:-2], rtol=1e-12, atol=1e-12)
    assert not np.allclose(delta(x)[:2], 10.0 * interp[:2])


def test_add_deltas_stacks_three_streams(rng):
    x = rng.normal(size=(20, 22))
    s = add_deltas(x)
    assert s.shape == (20, 66)  # the thesis' 66 dimensions
    np.testing.assert_allclose(s[:, 22:44], delta(x))
    np.testing.assert_allclose(s[:, 44:], delta(delta(x)))


# -- MFCC --------------------------------------------------------------------------------
def test_mfcc_shape_frames_and_determinism():
    cfg = MFCCConfig(n_mfcc=22)
    y = tone(440, 1.0)
    m = mfcc(y, cfg)
    expected_frames = 1 + (len(y) - cfg.n_fft) // cfg.hop_length
    assert m.shape == (expected_frames, 22)
    assert m.dtype == np.float32
    np.testing.assert_array_equal(m, mfcc(y, cfg))


def htk_mel_filterbank(sr, n_fft, n_mels, fmin, fmax):
    """Triangular filters equally spaced on the HTK mel scale, mel(f) = 2595 log10(1 + f / 700),
    each of unit area (Slaney normalisation), written from the formula."""
    mel = lambda f: 2595.0 * np.log10(1.0 + f / 700.0)  # noqa: E731
    hz = lambda m: 700.0 * (10.0 ** (m / 2595.0) - 1.0)  # noqa: E731
    edges = hz(np.linspace(mel(fmin), mel(fmax), n_mels + 2))
    freqs = np.fft.rfftfreq(n_fft, 1.0 / sr)
    rising = (freqs[None] - edges[:-2, None]) / (edges[1:-1] - edges[:-2])[:, None]
    falling = (edges[2:, None] - freqs[None]) / (edges[2:] - edges[1:-1])[:, None]
    return np.maximum(0.0, np.minimum(rising, falling)) * (2.0 / (edges[2:] - edges[:-2]))[:, None]


def log_mel_by_formula(y, cfg):
    """dB energies of HTK-mel filters on the power spectrum of Hamming-windowed, uncentred frames,
    computed from the formulas (Thesis section 5.2.3)."""
    import scipy.signal

    window = np.zeros(cfg.n_fft)
    off = (cfg.n_fft - cfg.win_length) // 2
    window[off : off + cfg.win_length] = scipy.signal.get_window("hamming", cfg.win_length, fftbins=True)
    n_frames = 1 + (y.size - cfg.n_fft) // cfg.hop_length
    frames = np.stack([y[i * cfg.hop_length : i * cfg.hop_length + cfg.n_fft] for i in range(n_frames)])
    power = np.abs(np.fft.rfft(frames.astype(np.float64) * window, axis=1)) ** 2
    energies = power @ htk_mel_filterbank(cfg.sr, cfg.n_fft, cfg.n_mels, 0.0, cfg.sr / 2).T
    db = 10.0 * np.log10(np.maximum(energies, 1e-10))
    return np.maximum(db, db.max() - cfg.top_db)


def two_tones(cfg):
    t = np.arange(8000) / cfg.sr
    return (0.3 * np.sin(2 * np.pi * 300 * t) + 0.2 * np.sin(2 * np.pi * 2300 * t * (1 + t))
            + 0.01 * np.random.default_rng(0).normal(size=t.size)).astype(np.float32)


def test_mfcc_uses_the_htk_mel_scale():
    """MFCC = DCT-II (orthonormal) of the dB energies of HTK-mel filters (Thesis section 5.2.3)."""
    import scipy.fft

    cfg = MFCCConfig(n_mfcc=13)
    y = two_tones(cfg)
    expected = scipy.fft.dct(log_mel_by_formula(y, cfg), type=2, norm="ortho", axis=1)[:, : cfg.n_mfcc]
    got = mfcc(y, cfg)
    assert got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-3 * np.abs(expected).max())


def test_log_mel_spectrogram_is_the_front_end_before_the_dct():
    cfg = MFCCConfig(n_mels=32, top_db=30.0)
    y = two_tones(cfg)
    expected = log_mel_by_formula(y, cfg)
    got = log_mel_spectrogram(y, cfg)
    assert got.shape == expected.shape == (1 + (y.size - cfg.n_fft) // cfg.hop_length, 32)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-3 * np.abs(expected).max())
    assert got.max() - got.min() == pytest.approx(30.0, abs=1e-3)  # top_db clips the quietest bands


def test_mfcc_separates_different_sounds():
    a1, a2, b = mfcc(tone(300)), mfcc(tone(300) * 0.9), mfcc(tone(2500))
    d_same = np.linalg.norm(a1.mean(0) - a2.mean(0))
    d_diff = np.linalg.norm(a1.mean(0) - b.mean(0))
    assert d_diff > 5 * d_same


def test_mfcc_bad_input():
    with pytest.raises(DataError, match="1-D"):
        mfcc(np.zeros((100, 2)))
    with pytest.raises(DataError, match="fewer than one analysis frame"):
        mfcc(np.zeros(10))
    y = tone(300)
    y[5] = np.nan
    with pytest.raises(DataError, match="NaN"):
        mfcc(y)
    with pytest.raises(ParameterError):
        MFCCConfig(n_mfcc=50, n_mels=40)
    with pytest.raises(ParameterError):
        MFCCConfig(fmax=9000)


@pytest.mark.parametrize("peak, dtype", [(1e39, np.float64), (1e30, np.float64), (1e20, np.float64),
                                         (1e20, np.float32), (2**62, np.int64)])
def test_mfcc_of_samples_whose_power_overflows_float32_is_refused(peak, dtype):
    """The front end computes in float32 (as librosa): a sample beyond float32 (1e39), or loud enough for the
    power spectrum to overflow it, is a DataError naming the peak, never NaN coefficients or librosa's error."""
    y = tone(300).astype(np.float64)
    if dtype == np.int64:  # a whole tone of 64-bit PCM at full scale
        y = (y * 2 * peak).astype(np.int64)
    else:
        y = y.astype(dtype)
        y[1000] = peak
    with pytest.raises(DataError, match=r"audio samples reach .*divide it by its peak"):
        mfcc(y)


def test_mfcc_of_loud_integer_pcm_is_finite():
    y = (tone(300) * 32767).astype(np.int16)
    y[::50] = np.iinfo(np.int16).min
    assert np.isfinite(mfcc(y)).all()
    y = (tone(300) * 1e12)  # loud, yet its power spectrum fits float32
    assert np.isfinite(mfcc(y)).all()


# -- windows -----------------------------------------------------------------------------
def test_sliding_windows_default_shift_is_a_third(rng):
    seq = rng.normal(size=(30, 4))
    w = sliding_windows(seq, 9)
    assert w.shape == (8, 9, 4)  # starts 0, 3, ..., 21
    np.testing.assert_array_equal(w[2], seq[6:15])
    assert sliding_windows(seq[:5], 9).shape == (0, 9, 4)


def test_mfcc_windows_80_and_150_ms():
    y = tone(500, 1.0)
    assert window_frames(80) == 8 and window_frames(150) == 15
    w80 = mfcc_windows(y, window_ms=80)
    w150 = mfcc_windows(y, window_ms=150)
    assert w80.shape[1:] == (8, 13) and w150.shape[1:] == (15, 13)
    assert w80.shape[0] > w150.shape[0]


# -- HAC ---------------------------------------------------------------------------------
def test_cooccurrence_counts_by_hand():
    ev = [np.array([0, 1, 2, 0, 1]), np.array([2])]
    c = cooccurrence_counts(ev, 3, 2).toarray()
    expected = np.zeros((2, 9))
    for a, b in [(0, 2), (1, 0), (2, 1)]:
        expected[0, a * 3 + b] += 1
    np.testing.assert_array_equal(c, expected)


def make_mfcc_corpus(rng, n=40, d=6):
    """Utterances built from 4 'phones' (Gaussian frame clusters) in random order."""
    phones = rng.normal(scale=3, size=(4, d))
    seqs = []
    for _ in range(n):
        order = rng.integers(0, 4, size=rng.integers(3, 7))
        seqs.append(np.concatenate([phones[p] + 0.1 * rng.normal(size=(12, d)) for p in order]))
    return seqs


def test_hac_shape_sparse_counts_and_train_only_codebooks(rng):
    seqs = make_mfcc_corpus(rng)
    hac = HAC(n_clusters=(5, 4, 3), lags=(2, 5), random_state=0).fit(seqs[:30])
    H = hac.transform(seqs[30:])
    assert sp.issparse(H) and H.shape == (10, 2 * (25 + 16 + 9)) == (10, hac.n_features_out_)
    assert (H.data > 0).all()
    # each block holds exactly n_frames - lag pairs
    lengths = np.array([len(s) for s in seqs[30:]])
    widths = [25, 16, 9]
    start = 0
    for lag in (2, 5):
        for w in widths:
            np.testing.assert_array_equal(np.asarray(H[:, start : start + w].sum(1)).ravel(), lengths - lag)
            start += w
    # codebooks do not change when transforming
    cb = [c.copy() for c in hac.codebooks_]
    hac.transform(seqs)
    for a, b in zip(cb, hac.codebooks_):
        np.testing.assert_array_equal(a, b)


def test_hac_additive_property(rng):
    """HAC(w1 + w2) = HAC(w1) + HAC(w2) up to the pairs straddling the boundary (Thesis 5.3.2)."""
    seqs = make_mfcc_corpus(rng)
    hac = HAC(n_clusters=(5, 4, 3), lags=(2,), random_state=0).fit(seqs)
    w1, w2 = seqs[0], seqs[1]
    s = hac.transform([np.concatenate([w1, w2])]).toarray()[0]
    parts = hac.transform([w1, w2]).toarray().sum(0)
    diff = np.abs(s - parts).sum()
    # delta streams near the boundary change too (the operator looks 2 frames away):
    # at most a few frames around the join may differ per stream
    assert diff <= 3 * 2 * (2 + 4)
    assert s.sum() == parts.sum() + 3 * 2


def test_hac_default_dimension_is_110000(rng):
    seqs = [rng.normal(size=(400, 22)) for _ in range(3)]
    hac = HAC(random_state=0, max_iter=5).fit(seqs)
    assert hac.n_features_out_ == 110_000
    assert hac.transform(seqs[:1]).shape == (1, 110_000)


def test_hac_deterministic_and_bad_input(rng):
    seqs = make_mfcc_corpus(rng, n=10)
    a = HAC(n_clusters=(3, 3, 3), random_state=3).fit_transform(seqs)
    b = HAC(n_clusters=(3, 3, 3), random_state=3).fit_transform(seqs)
    assert (a != b).nnz == 0
    with pytest.raises(DataError, match="list of MFCC"):
        HAC().fit(np.zeros((10, 22)))
    with pytest.raises(DataError, match="utterance 1"):
        HAC(n_clusters=(3, 3, 3)).fit([seqs[0], seqs[1][:, :3]])
    bad = [s.copy() for s in seqs]
    bad[2][0, 0] = np.nan
    with pytest.raises(DataError, match="utterance 2"):
        HAC(n_clusters=(3, 3, 3)).fit(bad)
    with pytest.raises(ParameterError):
        HAC(n_clusters=(3, 3)).fit(seqs)
    with pytest.raises(DataError, match="training frames"):
        HAC(n_clusters=(500, 3, 3)).fit(seqs[:1])


# -- voting ------------------------------------------------------------------------------
def test_voting_counts_weights_and_prediction():
    bags = [np.array([0, 1, 1]), np.array([0, 2]), np.array([0, 3]), np.array([0, 3, 3])]
    tags = ["a", "a", "b", "b"]
    v = EventVoting().fit(bags, tags)
    assert v.classes_ == ["a", "b"]
    np.testing.assert_array_equal(v.counts_[:4, :2], [[2, 2], [1, 0], [1, 0], [0, 2]])
    w = v.weights()[:4]
    np.testing.assert_allclose(w, [0.0, np.log(2), np.log(2), np.log(2)])  # eq. 5.1
    # event 0 appears everywhere: weight 0, no vote; event 3 votes for b with f = 1
    scores = v.decision_function([np.array([0, 3, 3])])
    np.testing.assert_allclose(scores, [[0.0, 2 * 1.0 * np.log(2)]])
    assert v.predict([np.array([1]), np.array([3]), np.array([99])])[:2] == ["a", "b"]
    assert v.score([np.array([1]), np.array([3])], ["a", "b"]) == 1.0


def test_voting_partial_fit_equals_fit_and_multi_tags(rng):
    bags = [rng.integers(0, 50, size=20) for _ in range(30)]
    tags = [("x",) if i % 3 else ("x", "y") for i in range(30)]
    a = EventVoting().fit(bags, tags)
    b = EventVoting()
    for i in range(0, 30, 7):
        b.partial_fit(bags[i : i + 7], tags[i : i + 7])
    np.testing.assert_array_equal(a.decision_function(bags), b.decision_function(bags))
    assert a.tag_counts_[:2].tolist() == [30, 10]


def test_voting_bad_input():
    with pytest.raises(NotFittedError, match="not seen"):
        EventVoting().predict([np.array([1])])
    with pytest.raises(DataError, match="negative"):
        EventVoting().fit([np.array([-1])], ["a"])
    with pytest.raises(DataError, match="2 bags but 1"):
        EventVoting().fit([np.array([1]), np.array([2])], ["a"])
    with pytest.raises(ParameterError):
        EventVoting(weighting="bm25").fit([np.array([1])], ["a"])
