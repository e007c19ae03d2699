"""A missing optional extra: the library (not only the command line) raises MissingExtraError naming the extra."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from mmconcepts.errors import MissingExtraError


def _missing(monkeypatch, *names):
    for name in names:
        monkeypatch.setitem(sys.modules, name, None)  # `import name` now raises ImportError


def test_audio_io_names_the_audio_extra(monkeypatch, tmp_path):
    from mmconcepts.sound.audio import audio_info

    _missing(monkeypatch, "soundfile")
    with pytest.raises(MissingExtraError, match=r"reading and writing audio needs the package 'soundfile' of the "
                                                r"'audio' extra, which is not installed .*Fix: pip install "
                                                r"\"mmconcepts\[audio\]\"\."):
        audio_info(tmp_path / "x.wav")


def test_mfcc_names_the_audio_extra(monkeypatch):
    from mmconcepts.sound.features import mfcc

    _missing(monkeypatch, "librosa")
    with pytest.raises(MissingExtraError, match=r'pip install "mmconcepts\[audio\]"'):
        mfcc(np.zeros(16000, dtype=np.float32))


def test_image_features_name_the_vision_extra(monkeypatch):
    from mmconcepts.vision.features import dense_sift, superpixel_colors

    _missing(monkeypatch, "skimage.color", "skimage.segmentation")
    image = np.zeros((32, 32, 3))
    for fn in (superpixel_colors, dense_sift):
        with pytest.raises(MissingExtraError, match=rf"{fn.__name__} needs the package 'skimage' of the 'vision' "
                                                    r"extra.*pip install \"mmconcepts\[vision\]\""):
            fn(image)


def test_a_dask_cluster_names_the_dask_extra(monkeypatch):
    from mmconcepts.engine.cluster import open_client

    _missing(monkeypatch, "distributed")
    with pytest.raises(MissingExtraError, match=r'pip install "mmconcepts\[dask\]"'):
        with open_client("local:1"):
            pass


def test_the_error_is_an_import_error_and_speech_engines_raise_it():
    from mmconcepts.sound.tts import MissingEngineError

    assert issubclass(MissingExtraError, ImportError) and issubclass(MissingEngineError, MissingExtraError)
