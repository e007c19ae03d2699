"""A fake FSDD for the chapter-5 tests: FSDD-named 8 kHz WAVs (a tone per digit, plus noise), generic layout."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def fake_fsdd(root: Path, rng: np.random.Generator, *, speakers=("bob", "amy"), per_digit: int = 4,
              seconds: float = 0.25) -> Path:
    """Write ``{digit}_{speaker}_{k}.wav`` files and ``labels.csv`` under ``root`` (created); return ``root``."""
    from mmconcepts.sound.audio import write_audio
    from mmconcepts.sound.data import FSDD_WORDS

    root.mkdir(parents=True, exist_ok=True)
    rows = ["file,speaker,labels,transcription"]
    t = np.arange(int(seconds * 8000)) / 8000
    for spk in speakers:
        for d in range(10):
            for k in range(per_digit):
                name = f"{d}_{spk}_{k}.wav"
                y = 0.3 * np.sin(2 * np.pi * (200 + 150 * d) * t) + 0.05 * rng.standard_normal(t.size)
                write_audio(root / name, np.clip(y, -1, 1), 8000)
                rows.append(f"{name},{spk},{FSDD_WORDS[d]},{FSDD_WORDS[d]}")
    (root / "labels.csv").write_text("\n".join(rows) + "\n")
    return root
