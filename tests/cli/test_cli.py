"""The command line, through ``main([...])`` and ``python -m mmconcepts``."""

from __future__ import annotations

import json
import re
import os
import subprocess
import sys

import pytest

from mmconcepts._progress import QUIET_ENV
from mmconcepts.cli import main
from mmconcepts.experiments import Result, register


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_list(toy, capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].split() == ["id", "title", "thesis", "data"]
    assert any(line.startswith("toy-mean") and "Section 0.0 (test fixture)" in line for line in lines)
    assert any(line.startswith("toy-data") and line.rstrip().endswith("toyfile") for line in lines)


def test_list_fits_the_terminal_width(toy, capsys, monkeypatch):
    from mmconcepts.experiments import Result

    title = "A very long title of a toy experiment that goes on and on well past any sensible width of a terminal"
    exp = toy.make_experiment("toy-long", lambda config, ctx: Result(metrics={}), datasets=("fsdd", "msr-action3d",
                                                                                          "eth80", "acorns", "audio"))
    register(type(exp)(**{**{f: getattr(exp, f) for f in ("id", "thesis_ref", "config_cls", "run", "datasets")},
                          "title": title}))
    for columns in ("100", "60"):
        monkeypatch.setenv("COLUMNS", columns)
        assert main(["list"]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert max(len(line) for line in lines) <= int(columns)
        start = next(i for i, line in enumerate(lines) if line.startswith("toy-long "))
        end = next((i for i in range(start + 1, len(lines)) if not lines[i].startswith(" ")), len(lines))
        block = lines[start:end]  # the experiment's line and its continuation lines
        column = lines[0].index("title")
        assert " ".join(line[column:].split("  ")[0].strip() for line in block) == title  # wrapped, not cut
    monkeypatch.setenv("COLUMNS", "300")  # a wide terminal: one line per experiment, as before
    assert main(["list"]) == 0
    assert any(title in line for line in capsys.readouterr().out.splitlines())


def test_run_prints_summary_and_writes_result(toy, in_tmp, capsys):
    assert main(["run", "toy-mean"]) == 0
    out = capsys.readouterr().out
    record = json.loads((in_tmp / "results" / "toy-mean.json").read_text())
    assert record["status"] == "ok" and record["preset"] == "quick"
    assert "results/toy-mean.json" in out
    assert "claims: thesis: 1 holds; magnitude: 1 inconclusive; ours: 1 fails" in out
    assert "[thesis: holds] The sample mean is close to one half." in out and "[ours: fails] The sample mean exceeds one" in out
    assert "data: synthetic" in out
    mean_line = next(line for line in out.splitlines() if line.split()[:1] == ["mean"])
    assert mean_line.split() == ["mean", f"{record['metrics']['mean']:.4g}", "0.5"]


def test_run_options_and_rerun_skip(toy, in_tmp, capsys):
    assert main(["run", "toy-mean", "--full", "--seed", "4", "-o", "out", "--workers", "1"]) == 0
    record = json.loads((in_tmp / "out" / "toy-mean.json").read_text())
    assert record["preset"] == "full" and record["seed"] == 4 and record["config"]["n"] == 4000
    assert main(["-q", "run", "toy-mean", "--full", "--seed", "4", "-o", "out"]) == 0
    assert toy.CALLS == [4]  # second run was up to date
    assert main(["run", "toy-mean", "--full", "--seed", "4", "-o", "out", "--force"]) == 0
    assert toy.CALLS == [4, 4]
    err = capsys.readouterr().err
    assert "skipped: up to date" not in err  # -q hides info logs ...
    main(["run", "toy-mean", "--full", "--seed", "4", "-o", "out"])
    assert "skipped: up to date" in capsys.readouterr().err  # ... the default shows them


@pytest.mark.parametrize(("argv", "terminal", "bar"), [
    (["run", "toy-mean"], True, True),
    (["-q", "run", "toy-mean"], True, False),
    (["run", "toy-mean", "--quiet"], True, False),
    (["run", "toy-mean"], False, False),
])
def test_progress_bars_only_on_a_terminal_and_not_under_quiet(toy, in_tmp, capsys, monkeypatch, argv, terminal, bar):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal)
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert ("chunks: " in err and "|" in err) is bar  # the toy's ctx.parallel(..., desc="chunks")
    assert toy.CALLS == [0]


def test_quiet_silences_the_compile_notice_of_the_run_s_processes(toy, in_tmp, monkeypatch):
    """-q sets MMCONCEPTS_QUIET while the command runs (the processes it starts inherit it), then puts it back."""
    monkeypatch.delenv(QUIET_ENV, raising=False)
    seen = []

    def run(config, ctx):
        seen.append(os.environ.get(QUIET_ENV))
        return Result(metrics={})

    register(toy.make_experiment("toy-env", run))
    assert main(["-q", "run", "toy-env"]) == 0
    assert QUIET_ENV not in os.environ
    assert main(["run", "toy-env", "--force"]) == 0
    monkeypatch.setenv(QUIET_ENV, "0")
    assert main(["--quiet", "run", "toy-env", "--force"]) == 0
    assert os.environ[QUIET_ENV] == "0"
    assert seen == ["1", None, "1"]


def test_usage_errors_exit_2_with_one_line(toy, in_tmp, capsys):
    assert main(["run", "toy-maen"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: unknown experiment 'toy-maen'") and "Did you mean 'toy-mean'" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1

    missing = in_tmp / "no" / "such" / "dir"
    assert main(["run", "toy-data", "--data", f"toyfile={missing}"]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "does not exist" in err and "Traceback" not in err
    assert not (in_tmp / "results" / "toy-data.json").exists()

    assert main(["run", "toy-mean", "--data", "nonsense"]) == 2
    assert "NAME=PATH" in capsys.readouterr().err
    assert main(["reproduce", "--data", f"choreo9={in_tmp}"]) == 2
    assert "no experiment uses a data set named 'choreo9'" in capsys.readouterr().err
    assert main(["run", "toy-mean", "--quick", "--full"]) == 2  # argparse: not allowed together
    assert "not allowed with argument" in capsys.readouterr().err
    assert main(["frobnicate"]) == 2
    assert "invalid choice: 'frobnicate'" in capsys.readouterr().err
    assert main(["run", "toy-mean", "--workers", "0"]) == 2
    assert "--workers/-j: expected an int >= 1 or -1" in capsys.readouterr().err
    assert toy.CALLS == []


def test_run_with_data(toy, in_tmp, capsys):
    (in_tmp / "v.txt").write_text("2.5")
    assert main(["run", "toy-data", "--data", "toyfile=v.txt"]) == 0
    record = json.loads((in_tmp / "results" / "toy-data.json").read_text())
    assert record["metrics"] == {"value": 2.5}
    assert record["data"] == {"toyfile": str((in_tmp / "v.txt").resolve())}
    assert main(["run", "toy-data", "-o", "other"]) == 0  # without data: skipped, not failed
    assert "skipped: needs the real data set 'toyfile'" in capsys.readouterr().out


def test_run_and_reproduce_resolve_the_data_root_once_and_refuse_a_mistyped_one(toy, in_tmp, capsys, monkeypatch):
    import mmconcepts.engine.data as data_module
    from mmconcepts.experiments import Result

    fsdd = in_tmp / "data" / "fsdd"
    fsdd.mkdir(parents=True)
    (fsdd / "labels.csv").write_text("file,speaker,labels,transcription\n0_alice_0.wav,alice,zero,zero\n")
    (fsdd / "0_alice_0.wav").write_bytes(b"RIFF")
    register(toy.make_experiment("toy-fsdd", lambda config, ctx: Result(metrics={"n": float(len(ctx.data))}),
                                 datasets=("fsdd",)))
    calls = []
    resolve_root = data_module.resolve_root
    monkeypatch.setattr(data_module, "resolve_root", lambda *args: calls.append(args) or resolve_root(*args))
    assert main(["run", "toy-fsdd", "--data-root", "data", "--variant", "synthetic"]) == 0
    assert "result: results/toy-fsdd.synthetic.json" in capsys.readouterr().out  # the plan's entry has real data
    assert len(calls) == 1
    calls.clear()
    assert main(["reproduce", "--only", "toy-fsdd", "--data-root", "data", "-o", "both"]) == 0
    assert len(calls) == 1
    assert json.loads((in_tmp / "both" / "toy-fsdd.json").read_text())["data"] == {"fsdd": str(fsdd.resolve())}
    assert (in_tmp / "both" / "toy-fsdd.synthetic.json").exists()
    capsys.readouterr()
    for command in (["run", "toy-fsdd"], ["reproduce", "--only", "toy-fsdd"]):
        assert main([*command, "--data-root", "dta", "-o", "typo"]) == 2
        err = capsys.readouterr().err
        assert "the data root" in err and "does not exist" in err and "Did you mean" in err and "data'?" in err
        assert "Traceback" not in err and not (in_tmp / "typo").exists()


def _fsdd_like(folder):
    folder.mkdir(parents=True)
    (folder / "labels.csv").write_text("file,speaker,labels,transcription\n0_alice_0.wav,alice,zero,zero\n")
    (folder / "0_alice_0.wav").write_bytes(b"RIFF")
    return folder


def _register_fsdd_experiment(toy):
    from mmconcepts.experiments import Result

    return register(toy.make_experiment("toy-fsdd", lambda config, ctx: Result(metrics={"n": float(len(ctx.data))}),
                                        datasets=("fsdd",)))


def test_a_data_root_that_holds_no_known_set_exits_2_unless_generated_data_is_allowed(toy, in_tmp, capsys,
                                                                                        monkeypatch):
    _register_fsdd_experiment(toy)
    empty = in_tmp / "empty"
    empty.mkdir()
    wrong = in_tmp / "wrong"
    (wrong / "fsdd").mkdir(parents=True)  # present, but no labels.csv
    for command in (["run", "toy-fsdd"], ["reproduce", "--only", "toy-fsdd"]):
        assert main([*command, "--data-root", "empty", "-o", "out"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: --data-root 'empty': the folder ") and str(empty) in err
        assert "holds no known data set" in err and "fsdd/, msr-action3d/, eth80/ or eth80-96px/" in err
        assert "None of these folders is in it" in err and "--allow-generated" in err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
        assert main([*command, "--data-root", "wrong", "-o", "out"]) == 2
        err = capsys.readouterr().err
        assert f"Refused: {wrong / 'fsdd'}: no labels.csv" in err
        assert not (in_tmp / "out").exists()  # refused before any work
    # a set's own folder given as the root: the message names its parent
    fsdd = _fsdd_like(in_tmp / "data" / "fsdd")
    assert main(["run", "toy-fsdd", "--data-root", str(fsdd), "-o", "out"]) == 2
    assert f"looks like the set 'fsdd' itself: give the folder that holds it ({str(fsdd.parent)!r})" in \
        capsys.readouterr().err
    # --allow-generated: the same roots run on generated data
    assert main(["run", "toy-fsdd", "--data-root", "empty", "--allow-generated", "-o", "out"]) == 0
    assert json.loads((in_tmp / "out" / "toy-fsdd.json").read_text())["variant"] == "synthetic"
    assert main(["reproduce", "--only", "toy-fsdd", "--data-root", "wrong", "--allow-generated", "-o", "out2"]) == 0
    # a root holding a known set is accepted, also when the experiment does not use it
    assert main(["run", "toy-mean", "--data-root", "data", "-o", "out3"]) == 0
    # a data root from the environment is not refused (no option named it)
    monkeypatch.setenv("MMCONCEPTS_DATA_ROOT", str(empty))
    assert main(["run", "toy-fsdd", "-o", "out4"]) == 0


def test_a_data_path_that_does_not_hold_its_set_exits_2(toy, in_tmp, capsys):
    _register_fsdd_experiment(toy)
    bad = in_tmp / "my-fsdd"
    bad.mkdir()
    (bad / "labels.csv").write_text("file,tags\n0_alice_0.wav,zero\n")
    assert main(["run", "toy-fsdd", "--data", f"fsdd={bad}", "-o", "out"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --data fsdd={bad}: the folder does not hold 'fsdd' in its layout (")
    assert "lacks column(s) ['labels', 'speaker']" in err and "Expected: Mono 8 kHz WAV files" in err
    assert main(["run", "toy-fsdd", "--data", f"fsdd={in_tmp / 'nowhere'}", "-o", "out"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (in_tmp / "out").exists()
    good = _fsdd_like(in_tmp / "good")
    assert main(["run", "toy-fsdd", "--data", f"fsdd={good}", "-o", "out"]) == 0


def test_a_variant_that_cannot_run_exits_2_naming_the_sets_it_needs(toy, in_tmp, capsys, monkeypatch):
    from mmconcepts.experiments import Experiment, Result

    monkeypatch.delenv("MMCONCEPTS_DATA_ROOT", raising=False)
    _register_fsdd_experiment(toy)
    assert main(["run", "toy-fsdd", "--variant", "real", "-o", "out"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --variant real: toy-fsdd runs on real data of 'fsdd', and no data root was given")
    (in_tmp / "root" / "fsdd").mkdir(parents=True)
    _fsdd_like(in_tmp / "root" / "audio")  # a known set, not one the experiment uses
    (in_tmp / "root" / "audio").rename(in_tmp / "root" / "images")
    (in_tmp / "root" / "images" / "labels.csv").write_text("file,labels\n0_alice_0.wav,zero\n")
    assert main(["run", "toy-fsdd", "--variant", "real", "--data-root", "root", "-o", "out"]) == 2
    err = capsys.readouterr().err
    assert f"and none is in the data root {str(in_tmp / 'root')!r} ({in_tmp / 'root' / 'fsdd'}: no labels.csv" in err
    assert not (in_tmp / "out").exists()
    register(Experiment(id="toy-real-only", title="Toy", thesis_ref="none", config_cls=toy.SmallConfig,
                        run=lambda config, ctx: Result(metrics={}), datasets=("fsdd",), synthetic=False))
    assert main(["run", "toy-real-only", "--variant", "synthetic", "-o", "out"]) == 2
    assert "toy-real-only runs only on real data (fsdd)" in capsys.readouterr().err
    assert main(["run", "toy-fsdd", "--variant", "real", "--data", f"fsdd={_fsdd_like(in_tmp / 'f')}"]) == 0


def test_failed_experiment_exits_1(toy, in_tmp, capsys):
    register(toy.FAIL)
    assert main(["run", "toy-fail"]) == 1
    captured = capsys.readouterr()
    assert "failed: RuntimeError: the toy experiment broke on purpose" in captured.out
    assert "Traceback" not in captured.err
    assert main(["-v", "run", "toy-fail"]) == 1
    assert "Traceback" in capsys.readouterr().err  # -v shows it


def test_reproduce_then_report(toy, in_tmp, capsys):
    register(toy.FAIL)
    assert main(["reproduce", "--only", "toy-mean", "toy-data"]) == 0
    out = capsys.readouterr().out
    assert "report: results/report.html" in out
    assert (in_tmp / "results" / "report.md").exists()
    assert not (in_tmp / "results" / "toy-fail.json").exists()
    assert main(["reproduce", "-o", "all"]) == 1  # toy-fail failed, the rest ran
    out = capsys.readouterr().out
    assert re.search(r"toy-fail +synthetic +failed", out) and re.search(r"toy-mean +synthetic +ok +thesis: 1 holds; magnitude: 1 inconclusive; ours: 1 fails", out)
    md = (in_tmp / "all" / "report.md").read_text()
    assert "thesis statements: 1 holds; magnitudes (ours / thesis): 1 inconclusive; our checks: 1 fails" in md and "FAILED" in md

    (in_tmp / "all" / "report.md").unlink()
    assert main(["report", "all"]) == 0
    assert "report: all/report.html" in capsys.readouterr().out
    assert "toy-mean" in (in_tmp / "all" / "report.md").read_text()
    assert main(["report", "missing-dir"]) == 1
    assert "error: results folder 'missing-dir' does not exist" in capsys.readouterr().err


def test_help_exits_0(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for command in ("list", "run", "reproduce", "report"):
        assert command in out
    assert main(["run", "--help"]) == 0
    assert "--data NAME=PATH" in capsys.readouterr().out


def test_python_dash_m_help():
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.run(
        [sys.executable, "-m", "mmconcepts", "--help"], capture_output=True, text=True, env=env, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("usage: mmconcepts")
    assert "reproduce" in proc.stdout
    proc = subprocess.run([sys.executable, "-m", "mmconcepts", "run"], capture_output=True, text=True, env=env, timeout=60)
    assert proc.returncode == 2 and "ID" in proc.stderr


def test_data_list_shows_every_set_and_where_it_is(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("MMCONCEPTS_DATA_ROOT", raising=False)
    assert main(["data", "list"]) == 0
    out = capsys.readouterr().out
    assert "data root: (none" in out
    for name in ("fsdd", "msr-action3d", "eth80", "coil20", "choreo1", "choreo2", "acorns"):
        assert re.search(rf"^{re.escape(name)} +- ", out, re.M), name
    msr = tmp_path / "msr-action3d"
    msr.mkdir()
    (msr / "a01_s01_e01_skeleton3D.txt").write_text("0 0 0 0\n" * 20)
    assert main(["data", "list", "--data-root", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert re.search(rf"^msr-action3d +{re.escape(str(msr))} +1 ", out, re.M)


def test_data_list_on_the_real_data_root(capsys):
    from conftest import DATA_ROOT

    if DATA_ROOT is None:
        pytest.skip("no data root (set MMCONCEPTS_DATA_ROOT or put ../shared/data beside the checkout)")
    assert main(["data", "list", "--data-root", str(DATA_ROOT)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^fsdd +\S+ +1500 ", out, re.M) and re.search(r"^msr-action3d +\S+ +567 ", out, re.M)


@pytest.mark.parametrize("text, n_bytes", [("7", 7), ("500MB", 500 * 10**6), ("1.5kB", 1500), ("2GiB", 2 * 2**30),
                                           (" 3 mb ", 3 * 10**6), (".5G", 5 * 10**8), ("1TiB", 2**40), ("10b", 10)])
def test_data_fetch_max_size_reads_units(text, n_bytes, monkeypatch, tmp_path):
    from mmconcepts import datasets

    seen = {}
    monkeypatch.setattr(datasets, "fetch_dataset", lambda *a, **k: seen.update(k) or tmp_path)
    assert main(["data", "fetch", "fsdd", "--data-root", str(tmp_path), "--max-size", text, "--max-files", "3"]) == 0
    assert seen["max_unpacked_bytes"] == n_bytes and seen["max_files"] == 3


@pytest.mark.parametrize("args", [["--max-size", "12XB"], ["--max-size", "0"], ["--max-size", "0.1B"],
                                  ["--max-size", "1e9"], ["--max-size", ""], ["--max-files", "0"],
                                  ["--max-files", "1.5"]])
def test_data_fetch_bad_bounds_are_usage_errors(args, tmp_path, capsys):
    assert main(["data", "fetch", "fsdd", "--data-root", str(tmp_path), *args]) == 2
    err = capsys.readouterr().err
    assert ("expected a size" in err or "expected an int >= 1" in err) and "Traceback" not in err


def test_data_fetch_usage_errors(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("MMCONCEPTS_DATA_ROOT", raising=False)
    assert main(["data", "fetch", "nosuchset", "--data-root", str(tmp_path)]) == 2
    assert "unknown data set 'nosuchset'" in capsys.readouterr().err
    assert main(["data", "fetch", "fsdd"]) == 2
    assert "no data root" in capsys.readouterr().err
    assert main(["data", "fetch", "msr-action3d", "--data-root", str(tmp_path)]) == 1
    assert "no public download" in capsys.readouterr().err
