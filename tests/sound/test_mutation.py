"""Tests written from the mutation run on ``mmconcepts.sound``.

Each test kills mutants that the rest of the suite let survive (see /work/notes/mutation13.md):
the synthetic room impulse response against the acoustic definitions of its two parameters,
the direct-to-reverberant ratio (energy of the direct path over that of the tail) and the
reverberation time (Schroeder's backward integration, T20 extrapolated to 60 dB, ISO 3382);
the documented keyword balance of the caregiver transcripts, and the message for repeated keywords.
"""

from __future__ import annotations

import collections

import numpy as np
import pytest

from mmconcepts.errors import ParameterError

from mmconcepts.sound.synthetic import (
    CAREGIVER_KEYWORDS,
    SAMPLE_RATE,
    SpeakerProfile,
    _room_ir,
    caregiver_transcripts,
)

pytestmark = pytest.mark.mutation


@pytest.mark.parametrize("rt60, drr_db", [(0.35, 7.0), (0.6, 2.0), (0.2, 12.0)])
def test_room_impulse_response_has_the_profile_drr_and_rt60(rt60, drr_db):
    profile = SpeakerProfile("s", "test room", "espeak", rt60=rt60, drr_db=drr_db)
    h = _room_ir(profile, np.random.default_rng(0))
    sr = SAMPLE_RATE
    assert h.shape == (round(rt60 * 1.2 * sr),)
    # the direct path is the first sample; the tail starts after a few milliseconds
    assert h[0] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(h[1:int(0.004 * sr)], 0.0)
    drr = 10 * np.log10(h[0] ** 2 / np.sum(h[1:] ** 2))
    assert drr == pytest.approx(drr_db, abs=1e-9)
    # Schroeder energy decay curve of the reverberant part, T20 fit (-5 to -25 dB), x3
    edc = np.cumsum(h[1:][::-1] ** 2)[::-1]
    edc_db = 10 * np.log10(edc / edc[0])
    t = np.arange(1, h.size) / sr
    sel = (edc_db <= -5) & (edc_db >= -25)
    slope = np.polyfit(t[sel], edc_db[sel], 1)[0]  # dB per second
    assert -60.0 / slope == pytest.approx(rt60, rel=0.1)


@pytest.mark.parametrize("seed", range(8))
def test_caregiver_transcripts_keep_keyword_pairs_balanced_and_distinct(seed):
    """The documented balance: each keyword is used n * kpu / len(keywords) times, +-1, and an
    utterance never holds one keyword twice (three keywords in pairs make repeats frequent)."""
    kws = CAREGIVER_KEYWORDS[:3]
    out = caregiver_transcripts(40, keywords=kws, keywords_per_utterance=2, random_state=seed)
    counts = collections.Counter(k for labels, _ in out for k in labels)
    assert set(counts) == set(kws) and sum(counts.values()) == 80
    assert max(counts.values()) - min(counts.values()) <= 1
    assert all(len(set(labels)) == 2 for labels, _ in out)


def test_repeated_keywords_are_refused_with_the_rule():
    with pytest.raises(ParameterError, match=r"^keywords must be distinct non-empty strings; got \['ball', 'ball'\]"):
        caregiver_transcripts(4, keywords=["ball", "ball"])
