"""MFCC sequences, the thesis' delta operator and fixed-length MFCC windows.

Thesis sections 5.2.3 (MFCC, windows of 80 or 150 ms sliding by a third of their length)
and 5.3 (delta operator, 22 coefficients for HAC).

Every MFCC parameter is explicit in :class:`MFCCConfig`; the defaults are the usual
speech front end: 16 kHz audio, 25 ms Hamming windows every 10 ms, 40 mel bands between
0 Hz and the Nyquist frequency, log (dB) mel energies, DCT-II with orthonormal scaling.
The computation itself is librosa's (:func:`librosa.feature.mfcc`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .._optional import optional_import
from .._validation import InstanceOf, Interval, validate_params
from ..errors import DataError, ParameterError

__all__ = [
    "MFCCConfig",
    "log_mel_spectrogram",
    "mfcc",
    "delta",
    "add_deltas",
    "window_frames",
    "sliding_windows",
    "mfcc_windows",
]


_MFCC_CONSTRAINTS: dict[str, list] = {
    "sr": [Interval("int", 1, None)],
    "n_mfcc": [Interval("int", 1, None)],
    "win_ms": [Interval("real", 0, None, closed="neither")],
    "hop_ms": [Interval("real", 0, None, closed="neither")],
    "n_mels": [Interval("int", 1, None)],
    "fmin": [Interval("real", 0, None)],
    "fmax": [Interval("real", 0, None, closed="neither"), None],
    "window": [InstanceOf(str, tuple, description="a scipy.signal.get_window name or (name, parameter) tuple")],
    "top_db": [Interval("real", 0, None), None],
    "lifter": [Interval("real", 0, None)],
}

#: The parameters of the window functions below.
#: Longest analysis window or hop accepted, in samples (about 17 minutes at 16 kHz).
_MAX_FRAME_SAMPLES = 2**24

#: Largest sample magnitude accepted before the spectrum is computed: the front end computes in
#: float32 (as librosa), which holds no larger number; the power spectrum is checked after.
_MAX_SAMPLE = float(np.finfo(np.float32).max)

_WINDOW_CONSTRAINTS: dict[str, list] = {
    "duration_ms": [Interval("real", 0, None, closed="neither")],
    "hop_ms": [Interval("real", 0, None, closed="neither")],
    "width": [Interval("int", 1, None)],
    "shift": [Interval("int", 1, None), None],
    "window_ms": [Interval("real", 0, None, closed="neither")],
}


@dataclass(frozen=True)
class MFCCConfig:
    """Parameters of the MFCC front end (Thesis section 5.2.3).

    Parameters
    ----------
    sr : int, default=16000
        Sample rate (Hz) the audio is at.
    n_mfcc : int, default=13
        Number of cepstral coefficients kept (coefficient 0, the log energy, included).
        The HAC of the thesis keeps 22 (section 5.3).
    win_ms : float, default=25.0
        Analysis window length in milliseconds (the FFT size is the next power of two).
    hop_ms : float, default=10.0
        Hop between frames in milliseconds.
    n_mels : int, default=40
        Number of triangular mel filters (HTK mel scale, ``mel(f) = 2595 log10(1 + f/700)``
        as in the thesis).
    fmin, fmax : float, default=0, None
        Band of the mel filters (Hz); None means the Nyquist frequency.
    window : str, default="hamming"
        Analysis window (any :func:`scipy.signal.get_window` name).
    top_db : float, default=80.0
        Dynamic range of the log mel energies (librosa's ``power_to_db`` clipping).
    lifter : int, default=0
        Cepstral liftering (0: none).
    """

    sr: int = 16000
    n_mfcc: int = 13
    win_ms: float = 25.0
    hop_ms: float = 10.0
    n_mels: int = 40
    fmin: float = 0.0
    fmax: float | None = None
    window: str = "hamming"
    top_db: float = 80.0
    lifter: int = 0

    def __post_init__(self) -> None:
        validate_params(asdict(self), _MFCC_CONSTRAINTS, owner="MFCCConfig")
        if self.n_mfcc > self.n_mels:
            raise ParameterError(
                f"MFCCConfig: n_mfcc ({self.n_mfcc}) cannot exceed n_mels ({self.n_mels}); lower n_mfcc or raise "
                "n_mels."
            )
        fmax = self.sr / 2 if self.fmax is None else self.fmax
        if not 0 <= self.fmin < fmax <= self.sr / 2:
            raise ParameterError(
                f"MFCCConfig needs 0 <= fmin < fmax <= sr/2; got fmin={self.fmin}, fmax={self.fmax}, sr={self.sr}."
            )
        for name in ("win_ms", "hop_ms"):
            samples = getattr(self, name) * self.sr / 1000
            if not samples <= _MAX_FRAME_SAMPLES:
                raise ParameterError(
                    f"MFCCConfig: {name}={getattr(self, name)} ms is {samples:.3g} samples at sr={self.sr}, more than "
                    f"{_MAX_FRAME_SAMPLES:.0e}; frames and hops are milliseconds long (25 and 10 in the thesis)."
                )
        if self.win_length < 1:
            raise ParameterError(
                f"MFCCConfig: win_ms={self.win_ms} ms is less than one sample at sr={self.sr}; raise win_ms."
            )
        if not (self.lifter == 0 or 1 <= self.lifter <= _MAX_FRAME_SAMPLES):
            raise ParameterError(
                f"MFCCConfig: lifter must be 0 (none) or a finite number >= 1 (22 is usual); got {self.lifter}."
            )
        if fmax - self.fmin < 1.0:
            raise ParameterError(
                f"MFCCConfig: the mel band [fmin, fmax] = [{self.fmin}, {fmax}] Hz is narrower than 1 Hz; widen it."
            )
        if self.n_mels > 1 + self.n_fft // 2:
            raise ParameterError(
                f"MFCCConfig: n_mels={self.n_mels} mel filters on {1 + self.n_fft // 2} FFT bins (n_fft={self.n_fft}) "
                "leave filters empty; lower n_mels or lengthen win_ms."
            )
        from scipy.signal import get_window

        try:
            get_window(self.window, 8)
        except (ValueError, TypeError) as exc:
            raise ParameterError(
                f"MFCCConfig: window={self.window!r} is not a scipy.signal.get_window window ({exc}); e.g. 'hamming'."
            ) from exc

    @property
    def win_length(self) -> int:
        """Window length in samples."""
        return int(round(self.win_ms * self.sr / 1000))

    @property
    def hop_length(self) -> int:
        """Hop in samples."""
        return max(1, int(round(self.hop_ms * self.sr / 1000)))

    @property
    def n_fft(self) -> int:
        """FFT size: the smallest power of two >= the window length."""
        return 1 << max(0, int(np.ceil(np.log2(self.win_length))))

    def to_dict(self) -> dict:
        return asdict(self)


def _check_audio(y: np.ndarray, config: MFCCConfig) -> np.ndarray:
    y = np.asarray(y)
    if y.ndim != 1:
        raise DataError(f"audio must be a 1-D array of samples (mono); got shape {y.shape}.")
    if not np.issubdtype(y.dtype, np.floating):
        y = y.astype(np.float32)
    if y.size < config.n_fft:
        raise DataError(
            f"audio has {y.size} samples, fewer than one analysis frame "
            f"({config.n_fft} samples at {config.sr} Hz)."
        )
    if not np.all(np.isfinite(y)):
        raise DataError("audio contains NaN or infinite samples.")
    if y.size and float(np.max(np.abs(y))) > _MAX_SAMPLE:
        raise _too_loud(y)
    return y


def _too_loud(y: np.ndarray) -> DataError:
    return DataError(
        f"audio samples reach {float(np.max(np.abs(y))):.3g}: their power spectrum overflows float32, in which the "
        "MFCC front end computes. Audio is expected as floats in [-1, 1] (or integer PCM); divide it by its peak."
    )


def log_mel_spectrogram(y: np.ndarray, config: MFCCConfig | None = None) -> np.ndarray:
    """Log (dB) mel energies of a mono signal: the MFCC front end before its DCT (Thesis section 5.2.3).

    Power spectrum of Hamming-windowed frames, triangular mel filters (HTK mel scale),
    ``power_to_db`` with ``config.top_db`` of dynamic range. Frames are not centred: frame
    ``t`` is the FFT block ``[t * hop, t * hop + n_fft)`` with the ``win_length`` window in
    its middle, so there are ``1 + (n_samples - n_fft) // hop`` frames. The computation is
    librosa's (:func:`librosa.feature.melspectrogram`, :func:`librosa.power_to_db`).

    Parameters
    ----------
    y : ndarray of shape (n_samples,)
        Mono audio at ``config.sr``.
    config : MFCCConfig, optional
        Front-end parameters (defaults of :class:`MFCCConfig` when None).

    Returns
    -------
    ndarray of shape (n_frames, n_mels), float32
        Frame ``t``'s energy in mel band ``b`` (dB relative to 1, the lowest ``top_db``
        below the loudest).
    """
    config = MFCCConfig() if config is None else config
    y = _check_audio(y, config)
    from .._jit import first_use

    # librosa compiles numba ufuncs when its modules load: once per machine, not in every worker at once
    with first_use("librosa"):
        librosa = optional_import("librosa", "audio", "the MFCC front end")

        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused just below, named
            mel = librosa.feature.melspectrogram(
                y=y.astype(np.float32, copy=False),
                sr=config.sr,
                n_fft=config.n_fft,
                hop_length=config.hop_length,
                win_length=config.win_length,
                window=config.window,
                center=False,
                power=2.0,
                n_mels=config.n_mels,
                fmin=config.fmin,
                fmax=config.fmax,
                htk=True,
            )
        if not np.all(np.isfinite(mel)):  # finite samples, but their power overflows float32
            raise _too_loud(y)
        log_mel = librosa.power_to_db(mel, ref=1.0, amin=1e-10, top_db=config.top_db)
    return np.ascontiguousarray(log_mel.T, dtype=np.float32)


def mfcc(y: np.ndarray, config: MFCCConfig | None = None) -> np.ndarray:
    """MFCC sequence of a mono signal (Thesis section 5.2.3).

    ``MFCC = DCT[log MFSC]``: the DCT-II (orthonormal) of the log mel energies of
    :func:`log_mel_spectrogram`, frame by frame (same frames).

    Parameters
    ----------
    y : ndarray of shape (n_samples,)
        Mono audio at ``config.sr``.
    config : MFCCConfig, optional
        Front-end parameters (defaults of :class:`MFCCConfig` when None).

    Returns
    -------
    ndarray of shape (n_frames, n_mfcc), float32
    """
    config = MFCCConfig() if config is None else config
    log_mel = np.ascontiguousarray(log_mel_spectrogram(y, config).T)
    librosa = optional_import("librosa", "audio", "the MFCC front end")
    m = librosa.feature.mfcc(S=log_mel, sr=config.sr, n_mfcc=config.n_mfcc, dct_type=2, norm="ortho",
                             lifter=config.lifter)
    return np.ascontiguousarray(m.T, dtype=np.float32)


def delta(x: np.ndarray) -> np.ndarray:
    """The thesis' time-difference operator along axis 0 (Thesis section 5.3).

    .. math:: \\Delta x_t = 2 x_{t+2} + x_{t+1} - x_{t-1} - 2 x_{t-2}

    with edge replication (``x_i = x_1`` for ``i <= 0`` and ``x_i = x_T`` for ``i > T``).
    This is ``10 * librosa.feature.delta(x, width=5, order=1, axis=0, mode="nearest")``
    (librosa divides by :math:`\\sum_n n^2 = 10`; its default ``mode="interp"`` also
    differs on the first and last two frames). It is kept rather than replaced by librosa's:
    the division changes the last bits of the delta streams (of about 95 % of the
    standardised values on random frames), which the k-means codebooks of
    :class:`~mmconcepts.sound.hac.HAC` are fitted on, and the experiments' numbers must not
    move; ``tests/sound/test_features.py`` checks the factor.

    Parameters
    ----------
    x : ndarray of shape (n_frames, ...)

    Returns
    -------
    ndarray of the same shape and dtype
    """
    x = np.asarray(x)
    if x.ndim == 0 or x.shape[0] == 0:
        raise DataError(f"delta needs at least one frame along axis 0; got shape {x.shape}.")
    if not np.issubdtype(x.dtype, np.number) or not np.all(np.isfinite(x)):
        raise DataError("delta needs finite numbers; the frames hold NaN, infinite or non-numeric values.")
    pad = [(2, 2)] + [(0, 0)] * (x.ndim - 1)
    p = np.pad(x, pad, mode="edge")
    n = x.shape[0]
    return 2 * p[4 : n + 4] + p[3 : n + 3] - p[1 : n + 1] - 2 * p[0:n]


def add_deltas(x: np.ndarray) -> np.ndarray:
    """Stack a sequence with its delta and delta-delta: (n, d) -> (n, 3 d) (Thesis 5.3)."""
    if np.ndim(x) != 2:
        raise DataError(f"add_deltas needs a (n_frames, d) sequence; got shape {np.shape(x)}.")
    d1 = delta(x)
    return np.concatenate([x, d1, delta(d1)], axis=1)


def window_frames(duration_ms: float, hop_ms: float = 10.0) -> int:
    """Number of MFCC frames in a window of ``duration_ms`` (at least 1)."""
    validate_params({"duration_ms": duration_ms, "hop_ms": hop_ms}, _WINDOW_CONSTRAINTS, owner="window_frames")
    frames = duration_ms / hop_ms
    if not frames <= _MAX_FRAME_SAMPLES:
        raise ParameterError(
            f"window_frames: a {duration_ms} ms window at a {hop_ms} ms hop is {frames:.3g} frames, more than "
            f"{_MAX_FRAME_SAMPLES:.0e}; give both in milliseconds."
        )
    return max(1, int(round(frames)))


def sliding_windows(seq: np.ndarray, width: int, shift: int | None = None) -> np.ndarray:
    """Cut a frame sequence into fixed-length windows (Thesis section 5.2.3).

    Parameters
    ----------
    seq : ndarray of shape (n_frames, d)
    width : int
        Frames per window.
    shift : int, optional
        Frames between window starts; default ``max(1, round(width / 3))`` (the thesis'
        slide of one third of the window).

    Returns
    -------
    ndarray of shape (n_windows, width, d)
        A copy (contiguous). A sequence shorter than ``width`` gives zero windows.
    """
    seq = np.asarray(seq)
    if seq.ndim != 2:
        raise DataError(f"seq must be (n_frames, d); got shape {seq.shape}.")
    if not np.issubdtype(seq.dtype, np.number) or not np.all(np.isfinite(seq)):
        raise DataError("seq must hold finite numbers; it holds NaN, infinite or non-numeric values.")
    validate_params({"width": width, "shift": shift}, _WINDOW_CONSTRAINTS, owner="sliding_windows")
    shift = max(1, int(round(width / 3))) if shift is None else shift
    n, d = seq.shape
    if n < width:
        return np.empty((0, width, d), dtype=seq.dtype)
    view = np.lib.stride_tricks.sliding_window_view(seq, width, axis=0)[::shift]
    return np.ascontiguousarray(view.transpose(0, 2, 1))


def mfcc_windows(
    y: np.ndarray,
    config: MFCCConfig | None = None,
    *,
    window_ms: float = 80.0,
    shift: float = 1 / 3,
) -> np.ndarray:
    """MFCC windows of one utterance: the local descriptors of Thesis section 5.2.3.

    Parameters
    ----------
    y : ndarray of shape (n_samples,)
    config : MFCCConfig, optional
    window_ms : float, default=80
        Window length (the thesis uses 80 or 150 ms).
    shift : float, default=1/3
        Slide as a fraction of the window length.

    Returns
    -------
    ndarray of shape (n_windows, width, n_mfcc)
    """
    config = MFCCConfig() if config is None else config
    validate_params({"window_ms": window_ms, "shift": shift},
                    {"window_ms": _WINDOW_CONSTRAINTS["window_ms"], "shift": [Interval("real", 0, 1, closed="right")]},
                    owner="mfcc_windows", hints={"shift": "It is a fraction of the window length."})
    width = window_frames(window_ms, config.hop_ms)
    return sliding_windows(mfcc(y, config), width, max(1, int(round(width * shift))))
