"""The results folder is checked before any work."""

from __future__ import annotations

import re

import pytest

from mmconcepts.experiments import reproduce, run_experiment


def test_an_output_folder_that_cannot_be_written_fails_before_any_work(toy, tmp_path, capsys):
    from mmconcepts.cli import main
    from mmconcepts.errors import ParameterError

    a_file = tmp_path / "results.txt"
    a_file.write_text("not a folder")
    for output, message in ((a_file, "is a file, not a folder"), (a_file / "sub", f"cannot be made: {a_file} is a file")):
        with pytest.raises(ParameterError, match=re.escape(message)):
            run_experiment("toy-mean", output=output, progress=False)
        with pytest.raises(ParameterError, match="is a file"):
            reproduce(output=output, progress=False)
    with pytest.raises(ParameterError, match="empty name"):
        run_experiment("toy-mean", output="", progress=False)
    assert toy.CALLS == []  # nothing was computed
    assert main(["run", "toy-mean", "--output", ""]) == 2
    assert "empty folder name" in capsys.readouterr().err
    assert main(["run", "toy-mean", "--output", str(a_file)]) == 1
    assert "is a file, not a folder" in capsys.readouterr().err
    assert toy.CALLS == []
    # a folder that does not exist yet is fine: it is made when the first record is written
    record = run_experiment("toy-mean", output=tmp_path / "new" / "deeper", progress=False)
    assert record.status == "ok" and (tmp_path / "new" / "deeper" / "toy-mean.json").is_file()
