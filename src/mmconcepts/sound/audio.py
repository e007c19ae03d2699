"""Reading and writing audio files (WAV, FLAC) for the speech data of thesis chapter 5.

Decoding is soundfile's (libsndfile), resampling soxr's (the resampler librosa uses by
default; :func:`librosa.resample` when soxr is missing). Both are in the ``audio`` extra
(``pip install "mmconcepts[audio]"``); without them, these functions raise
:class:`~mmconcepts.errors.MissingExtraError` naming the extra.

Every file problem is a :class:`~mmconcepts.errors.DataFormatError` whose message names
the file and says what is wrong with it (corrupt, empty, too short, non-finite samples),
so a corpus loader can report it or skip the file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._io import atomic_path
from .._optional import optional_import
from .._validation import check_scalar
from ..errors import DataError, DataFormatError, ParameterError

__all__ = ["DEFAULT_SR", "MIN_DURATION", "audio_info", "load_audio", "resample", "write_audio"]

#: Sample rate (Hz) every speech loader and feature of this package works at by default
#: (the usual speech front end; Thesis section 5.2.3).
DEFAULT_SR = 16000

#: Shortest file :func:`load_audio` accepts by default, in seconds: one 25 ms analysis
#: window of the MFCC front end (:class:`~mmconcepts.sound.features.MFCCConfig`).
MIN_DURATION = 0.025

_FORMATS = {".wav": "WAV", ".flac": "FLAC"}


def _soundfile():
    return optional_import("soundfile", "audio", "reading and writing audio")


def audio_info(path: str | os.PathLike[str]) -> tuple[int, int, int]:
    """Sample rate, number of frames and number of channels of an audio file (header only).

    Parameters
    ----------
    path : path-like
        A WAV or FLAC file (any format libsndfile reads).

    Returns
    -------
    sr : int
    n_frames : int
    n_channels : int

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    DataFormatError
        If the file is not a readable audio file (the message names it).
    """
    sf = _soundfile()
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"Audio file not found: {path}")
    if path.is_dir():
        raise DataFormatError(f"{path} is a folder, not an audio file.")
    try:
        info = sf.info(str(path))
    except Exception as exc:  # libsndfile raises LibsndfileError/RuntimeError/TypeError
        raise DataFormatError(f"Cannot read audio file {path}: {_describe(path, exc)}") from exc
    if str(info.format).upper() in ("WAV", "WAVEX"):
        _check_wav_complete(path)
    return int(info.samplerate), int(info.frames), int(info.channels)


def _check_wav_complete(path: Path) -> None:
    """Raise if a RIFF/WAVE file's data chunk announces more bytes than the file holds.

    libsndfile silently reads what is there; a cut recording should be reported.
    Streaming writers leave the size at 0 or 0xFFFFFFFF: those are not checked.
    """
    import struct

    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(12)
        if len(head) < 12 or head[:4] != b"RIFF" or head[8:12] != b"WAVE":
            return
        pos = 12
        while pos + 8 <= size:
            f.seek(pos)
            cid, clen = struct.unpack("<4sI", f.read(8))
            if cid == b"data":
                if 0 < clen < 0xFFFFFFFF and pos + 8 + clen > size:
                    raise DataFormatError(
                        f"Audio file {path} is truncated: its data chunk announces {clen} bytes, the file holds "
                        f"{size - pos - 8}."
                    )
                return
            pos += 8 + clen + (clen & 1)


def _describe(path: Path, exc: Exception) -> str:
    try:
        size = path.stat().st_size
    except OSError:
        size = -1
    if size == 0:
        return "the file is empty (0 bytes)."
    return f"not a valid WAV/FLAC file or corrupt ({exc})."


def resample(y: np.ndarray, orig_sr: float, target_sr: float) -> np.ndarray:
    """Resample a signal along its last axis (soxr "HQ", or librosa when soxr is absent).

    Parameters
    ----------
    y : ndarray of shape (n_samples,) or (n_channels, n_samples)
    orig_sr, target_sr : float
        Sample rates in Hz (need not be integers: a non-integer ``orig_sr`` is how the
        speech generator shifts pitch and formants together).

    Returns
    -------
    ndarray of shape (n_samples_out,) or (n_channels, n_samples_out), float32
        ``n_samples_out = ceil(n_samples * target_sr / orig_sr)`` (soxr's length).
    """
    orig_sr = check_scalar(orig_sr, "orig_sr", low=0.0, low_inclusive=False)
    target_sr = check_scalar(target_sr, "target_sr", low=0.0, low_inclusive=False)
    y = np.asarray(y, dtype=np.float32)
    if orig_sr == target_sr:
        return y
    try:
        import soxr
    except ImportError:  # soxr comes with librosa
        librosa = optional_import("librosa", "audio", "resampling audio")
        return librosa.resample(y, orig_sr=orig_sr, target_sr=target_sr).astype(np.float32)
    if y.ndim == 1:
        return soxr.resample(y, orig_sr, target_sr, quality="HQ").astype(np.float32, copy=False)
    # soxr wants (n_samples, n_channels)
    return np.ascontiguousarray(soxr.resample(y.T, orig_sr, target_sr, quality="HQ").T, dtype=np.float32)


def load_audio(
    path: str | os.PathLike[str],
    *,
    sr: int | None = DEFAULT_SR,
    mono: bool = True,
    min_duration: float = MIN_DURATION,
) -> np.ndarray:
    """Read an audio file as float32 samples in [-1, 1], resampled to ``sr``.

    Parameters
    ----------
    path : path-like
        A WAV or FLAC file (any format libsndfile reads).
    sr : int or None, default=16000
        Sample rate to return (Hz); None keeps the file's rate.
    mono : bool, default=True
        Average the channels of a multi-channel file into one.
    min_duration : float, default=0.025
        Shortest accepted length in seconds (of the file, before resampling); 0 accepts
        any non-empty file.

    Returns
    -------
    y : ndarray of shape (n_samples,) or (n_channels, n_samples), float32
        1-D when ``mono`` (or the file has one channel), else channels first as in
        librosa.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    DataFormatError
        If the file is corrupt, empty, shorter than ``min_duration``, or holds NaN or
        infinite samples; the message names the file and the problem.
    ParameterError
        If ``sr`` or ``min_duration`` is not valid.
    """
    if sr is not None and (isinstance(sr, bool) or not isinstance(sr, (int, np.integer)) or sr <= 0):
        raise ParameterError(f"sr must be a positive int (Hz) or None; got {sr!r}.")
    min_duration = check_scalar(min_duration, "min_duration", low=0.0)
    sf = _soundfile()
    path = Path(path)
    file_sr, n_frames, _ = audio_info(path)
    if n_frames == 0:
        raise DataFormatError(f"Audio file {path} is empty: it holds no samples.")
    if n_frames < max(1, min_duration * file_sr):
        raise DataFormatError(
            f"Audio file {path} is too short: {n_frames / file_sr:.4f} s ({n_frames} samples at {file_sr} Hz), "
            f"shorter than min_duration={min_duration} s."
        )
    try:
        data, file_sr = sf.read(str(path), dtype="float32", always_2d=True)
    except Exception as exc:
        raise DataFormatError(f"Cannot decode audio file {path}: {_describe(path, exc)}") from exc
    if data.shape[0] == 0:
        raise DataFormatError(f"Audio file {path} is empty or truncated: no sample could be decoded.")
    if data.shape[0] < n_frames:  # libsndfile stopped early
        raise DataFormatError(
            f"Audio file {path} is truncated: its header announces {n_frames} samples, only "
            f"{data.shape[0]} could be read."
        )
    if not np.isfinite(data).all():
        raise DataFormatError(f"Audio file {path} holds NaN or infinite samples.")
    y = data.T  # (n_channels, n_samples)
    if mono or y.shape[0] == 1:
        y = y.mean(axis=0) if y.shape[0] > 1 else y[0]
    y = np.ascontiguousarray(y, dtype=np.float32)
    if sr is not None and sr != file_sr:
        y = resample(y, file_sr, sr)
    return y


def write_audio(
    path: str | os.PathLike[str],
    y: np.ndarray,
    sr: int,
    *,
    subtype: str | None = None,
) -> Path:
    """Write samples to a WAV or FLAC file, atomically (temporary file, then rename).

    Parameters
    ----------
    path : path-like
        Destination; ``.wav`` or ``.flac`` (the format follows the extension). Parent
        folders are created.
    y : array-like of shape (n_samples,) or (n_channels, n_samples)
        Samples in [-1, 1] (channels first, as :func:`load_audio` returns them).
    sr : int
        Sample rate in Hz.
    subtype : str, optional
        libsndfile subtype; default ``"PCM_16"`` (what speech corpora store). ``"FLOAT"``
        (WAV only) stores float32 exactly.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    DataError
        If ``y`` is empty, not 1-D/2-D, holds NaN/inf, or exceeds [-1, 1] with an
        integer subtype (which would clip).
    ParameterError
        If the extension, ``sr`` or ``subtype`` is not supported.
    """
    sf = _soundfile()
    path = Path(path)
    fmt = _FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise ParameterError(f"write_audio writes .wav or .flac files; got {path.name!r}.")
    if isinstance(sr, bool) or not isinstance(sr, (int, np.integer)) or sr <= 0:
        raise ParameterError(f"sr must be a positive int (Hz); got {sr!r}.")
    subtype = "PCM_16" if subtype is None else str(subtype).upper()
    if not sf.check_format(fmt, subtype):
        raise ParameterError(f"Subtype {subtype!r} cannot be written in a {fmt} file.")
    y = np.asarray(y)
    if y.ndim not in (1, 2) or y.size == 0:
        raise DataError(f"y must be a non-empty (n_samples,) or (n_channels, n_samples) array; got shape {y.shape}.")
    if not np.issubdtype(y.dtype, np.number) or np.iscomplexobj(y):
        raise DataError(f"y must hold real numbers; got dtype {y.dtype}.")
    y = y.astype(np.float32 if subtype in ("FLOAT", "PCM_16", "PCM_U8", "PCM_S8") else np.float64)
    if not np.isfinite(y).all():
        raise DataError("y holds NaN or infinite samples.")
    peak = float(np.abs(y).max())
    if subtype.startswith("PCM") and peak > 1.0:
        raise DataError(
            f"Samples exceed [-1, 1] (peak {peak:.3f}) and would clip in {subtype}; scale y down or use subtype='FLOAT'."
        )
    data = y if y.ndim == 1 else y.T
    with atomic_path(path, suffix=".tmp" + path.suffix) as tmp:
        sf.write(str(tmp), data, int(sr), subtype=subtype, format=fmt)
    return path
