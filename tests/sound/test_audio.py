"""Audio file reading and writing (mmconcepts.sound.audio)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("soundfile", reason="audio I/O needs the 'audio' extra (soundfile)")

import soundfile as sf

from mmconcepts.errors import DataError, DataFormatError, ParameterError
from mmconcepts.sound.audio import audio_info, load_audio, resample, write_audio


def _pcm16_signal(rng, n):
    """Samples exactly representable in 16-bit PCM."""
    return (rng.integers(-32768, 32767, size=n) / 32768.0).astype(np.float32)


def test_round_trip_pcm16_gives_the_same_samples(tmp_path, rng):
    y = _pcm16_signal(rng, 8000)
    path = write_audio(tmp_path / "a.wav", y, 16000)
    z = load_audio(path, sr=16000)
    assert z.dtype == np.float32 and z.ndim == 1
    np.testing.assert_array_equal(z, y)
    assert audio_info(path) == (16000, 8000, 1)


@pytest.mark.parametrize("name, subtype", [("a.wav", "FLOAT"), ("a.flac", None)])
def test_round_trip_float_and_flac(tmp_path, rng, name, subtype):
    y = rng.uniform(-0.9, 0.9, 4000).astype(np.float32) if subtype == "FLOAT" else _pcm16_signal(rng, 4000)
    z = load_audio(write_audio(tmp_path / name, y, 22050, subtype=subtype), sr=None)
    np.testing.assert_array_equal(z, y)


def test_resampling_length_and_frequency(tmp_path):
    sr_in = 22050
    t = np.arange(sr_in) / sr_in  # 1 s
    y = 0.5 * np.sin(2 * np.pi * 440.0 * t)
    write_audio(tmp_path / "s.wav", y, sr_in, subtype="FLOAT")
    z = load_audio(tmp_path / "s.wav", sr=16000)
    assert abs(z.size - 16000) <= 1
    spec = np.abs(np.fft.rfft(z * np.hanning(z.size)))
    f_peak = np.argmax(spec) * 16000 / z.size
    assert abs(f_peak - 440.0) < 2.0
    # the in-memory resampler gives soxr's length
    assert resample(y, sr_in, 8000).size == int(np.ceil(y.size * 8000 / sr_in))


def test_stereo_is_averaged_to_mono(tmp_path, rng):
    left, right = _pcm16_signal(rng, 3000), _pcm16_signal(rng, 3000)
    write_audio(tmp_path / "st.wav", np.stack([left, right]), 16000, subtype="FLOAT")
    mono = load_audio(tmp_path / "st.wav")
    np.testing.assert_allclose(mono, (left + right) / 2, atol=1e-7)
    both = load_audio(tmp_path / "st.wav", mono=False)
    assert both.shape == (2, 3000)
    np.testing.assert_array_equal(both[1], right)


def test_corrupt_file_raises_naming_the_file(tmp_path, rng):
    bad = tmp_path / "corrupt.wav"
    bad.write_bytes(b"RIFF" + rng.integers(0, 256, 200, dtype=np.uint8).tobytes())
    with pytest.raises(DataFormatError, match="corrupt.wav"):
        load_audio(bad)


def test_truncated_wav_raises(tmp_path):
    full = write_audio(tmp_path / "full.wav", np.full(16000, 0.1), 16000).read_bytes()
    (tmp_path / "cut.wav").write_bytes(full[:5000])  # a recording cut short: libsndfile alone would not say
    with pytest.raises(DataFormatError, match=r"cut\.wav.*truncated"):
        load_audio(tmp_path / "cut.wav")


def test_empty_files_raise_naming_the_file(tmp_path):
    zero_bytes = tmp_path / "zero.wav"
    zero_bytes.write_bytes(b"")
    with pytest.raises(DataFormatError, match=r"zero\.wav.*empty"):
        load_audio(zero_bytes)
    no_samples = tmp_path / "nosamples.wav"
    sf.write(no_samples, np.zeros(0, dtype=np.float32), 16000, subtype="PCM_16")
    with pytest.raises(DataFormatError, match=r"nosamples\.wav.*empty"):
        load_audio(no_samples)


def test_too_short_file_raises(tmp_path):
    write_audio(tmp_path / "short.wav", np.zeros(100), 16000)  # 6 ms
    with pytest.raises(DataFormatError, match=r"short\.wav.*too short"):
        load_audio(tmp_path / "short.wav")
    assert load_audio(tmp_path / "short.wav", min_duration=0.0).size == 100


def test_missing_file_and_bad_parameters(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.wav"):
        load_audio(tmp_path / "nothere.wav")
    write_audio(tmp_path / "ok.wav", np.zeros(1000), 16000)
    with pytest.raises(ParameterError, match="sr"):
        load_audio(tmp_path / "ok.wav", sr=0)
    with pytest.raises(ParameterError, match="min_duration"):
        load_audio(tmp_path / "ok.wav", min_duration=-1)


def test_write_audio_refuses_bad_data_and_leaves_nothing(tmp_path):
    with pytest.raises(DataError, match="clip"):
        write_audio(tmp_path / "loud.wav", np.full(100, 1.5), 16000)
    with pytest.raises(DataError, match="NaN"):
        write_audio(tmp_path / "nan.wav", np.array([0.0, np.nan]), 16000)
    with pytest.raises(DataError, match="non-empty"):
        write_audio(tmp_path / "empty.wav", np.zeros(0), 16000)
    with pytest.raises(ParameterError, match=".wav or .flac"):
        write_audio(tmp_path / "a.mp3", np.zeros(10), 16000)
    assert list(tmp_path.iterdir()) == []  # no partial or temporary file left behind


def test_write_audio_is_atomic_replace(tmp_path, rng):
    path = tmp_path / "sub" / "x.wav"
    write_audio(path, np.zeros(1000), 16000)
    y = _pcm16_signal(rng, 500)
    write_audio(path, y, 16000)
    np.testing.assert_array_equal(load_audio(path, min_duration=0), y)
    assert [p.name for p in path.parent.iterdir()] == ["x.wav"]
