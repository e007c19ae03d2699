"""The README's library examples run as written (a new user copies them first)."""

from __future__ import annotations

import re
import runpy
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[2] / "README.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", README.read_text(), re.M | re.S)


def test_the_readme_has_its_four_library_examples():
    assert len(BLOCKS) == 4 and "NMF" in BLOCKS[0] and "ClusterTree" in BLOCKS[1] and "MultimodalNMF" in BLOCKS[2]
    assert "beta_nmf_out_of_core" in BLOCKS[3]


@pytest.mark.parametrize("index", [0, 2, pytest.param(3, marks=pytest.mark.slow)], ids=["nmf", "multimodal", "dask"])
def test_readme_example_runs(index, tmp_path, monkeypatch, capsys):
    # The sound example (index 1) generates a 4 x 250-utterance corpus by text-to-speech first (minutes):
    # its pieces are run by the chapter-5 tests and the gallery's keyword example.
    monkeypatch.chdir(tmp_path)  # the multimodal example saves learner.npz in the current folder
    path = tmp_path / "example.py"
    path.write_text(BLOCKS[index])
    runpy.run_path(str(path), run_name="__main__")
    printed = capsys.readouterr().out.split()
    assert printed and 0.0 <= float(printed[-1])  # each example ends by printing a number
    if index == 2:
        from mmconcepts.multimodal import MultimodalNMF

        assert 0.5 < float(printed[-1]) <= 1.0  # ten well-separated concepts: far above chance (0.1)
        assert MultimodalNMF.load(tmp_path / "learner.npz").n_components == 50
    if index == 3:  # the distributed and the out-of-core fits from the same start: the same iterates
        assert float(printed[-1]) < 1e-10 and (tmp_path / "W_chunks" / "manifest.json").exists()
