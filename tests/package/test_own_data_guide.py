"""The guide page "Your own data" works end to end: its Python blocks run in order, in an empty folder."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import pytest

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide" / "own_data.rst"


def _python_blocks(text: str) -> list[str]:
    blocks = []
    for m in re.finditer(r"^\.\. code-block:: python\n\n((?:   .*\n|\n)+)", text, flags=re.M):
        lines = [line[3:] if line.startswith("   ") else line for line in m.group(1).splitlines()]
        blocks.append("\n".join(lines).strip() + "\n")
    return blocks


def test_the_page_has_its_steps():
    blocks = _python_blocks(GUIDE.read_text())
    assert len(blocks) == 6
    assert "paired_dataset" in blocks[2] and "matching_success_rate" in blocks[4]


@pytest.mark.slow
def test_every_python_block_runs_in_order(tmp_path, monkeypatch, capsys):
    pytest.importorskip("soundfile")
    pytest.importorskip("skimage")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the page shows its DataWarnings itself
        for i, block in enumerate(_python_blocks(GUIDE.read_text())):
            exec(compile(block, f"{GUIDE.name} block {i + 1}", "exec"), namespace)
    out = capsys.readouterr().out
    rates = [float(x) for x in re.findall(r"-> \w+: ([0-9.]+) \(chance", out)]
    assert len(rates) == 3
    assert (tmp_path / "learner.npz").is_file()
    data = namespace["data"]
    assert len(data.concepts) == 8 and not data.shared_recordings()
    # what the page says: the two gestures without a word are counted in a warning
    messages = [str(w.message) for w in namespace["left_out"]]
    assert any("motion: " in m and "without a counterpart" in m for m in messages)
