"""Fuzzing the command line: ``mmconcepts.cli.main(argv)`` in this process.

Random subcommands, options and values (unknown ids, negative or non-numeric workers, bad
variants, empty strings, paths that are files, folders that cannot be written, bad
``--data`` items, ages, hashes...). A command line must end in one of:

- exit code 0 with some output (a good result);
- exit code 2 (usage error) or 1 (an error) with a message on stderr and no traceback
  (counted as a typed error: the wrapper raises ``SystemExit`` with the message);

never an exception out of ``main`` (an untyped error). Nothing long runs: the experiments'
computation (``runner._execute``) is replaced by one that records the run as skipped, so
everything around it (parsing, data and output checks, the record, the report) is the real
code; downloads fail at once (``pooch.retrieve`` raises ``ConnectionError``); the cache and
the current folder are a temporary folder.
"""

from __future__ import annotations

import contextlib
import io
import os
from pathlib import Path

import pytest
from _fuzz import assert_typed_or_good, fuzz_settings
from hypothesis import HealthCheck, given
from hypothesis import strategies as st

from mmconcepts.cli import main

pytestmark = pytest.mark.fuzz

IDS = ["ch2-nmf-recovery", "ch3-threshold", "ch6-symbolic", "ch5-tree"]
BAD_IDS = ["nope", "", " ", "CH2-NMF-RECOVERY", "ch2-nmf-recovery ", "../etc", "ch2", "-", "--", "ch2-nmf-recovery\0"]
DATA_NAMES = ["fsdd", "msr-action3d", "choreo1", "coil20", "images"]

_SANDBOX: dict[str, str] = {}


@pytest.fixture(scope="module", autouse=True)
def sandbox(tmp_path_factory):
    """A temporary folder as cache, home and current folder; no experiment computes; no download."""
    root = tmp_path_factory.mktemp("fuzz-cli")
    folder = root / "folder"
    folder.mkdir()
    (root / "results").mkdir()
    afile = root / "afile.txt"
    afile.write_text("not a folder")
    data_root = root / "data"
    (data_root / "fsdd").mkdir(parents=True)  # present but empty: a wrong layout
    corrupt = root / "corrupt"
    corrupt.mkdir()
    (corrupt / "x.json").write_text('{"schema_version": 2, "experiment": ')
    _SANDBOX.update(
        folder=str(folder), file=str(afile), through_file=str(afile / "sub"), missing=str(root / "missing" / "deep"),
        data_root=str(data_root), corrupt=str(corrupt), proc="/proc/self/no-such-folder",
        unwritable="/proc/self",  # a folder no one can write to (chmod does not stop root); never given to `cache`
        fsdd=str(data_root / "fsdd"),
    )

    from mmconcepts.engine import runner

    def no_compute(exp, config, ctx, record, target):
        record.status, record.message = "skipped", "not run by the fuzz test"
        return None, {}

    def no_download(*args, **kwargs):
        raise ConnectionError("no network in the fuzz test")

    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MMCONCEPTS_DATA", str(root / "cache"))
        mp.setenv("XDG_CACHE_HOME", str(root / "xdg"))
        mp.delenv("MMCONCEPTS_DATA_ROOT", raising=False)
        mp.chdir(root)
        mp.setattr(runner, "_execute", no_compute)
        import pooch

        mp.setattr(pooch, "retrieve", no_download)
        yield root


def _paths():
    return st.sampled_from(["folder", "file", "through_file", "missing", "corrupt", "proc", "unwritable", "empty",
                            "dot"]).map(
        lambda k: {"empty": "", "dot": ".", **_SANDBOX}[k])


_TEXT = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\0"), max_size=12)
_INTS = st.integers(-5, 5).map(str) | st.sampled_from(["0", "-1", "1e3", "x", "", " 2", "99999999999999999999"])


def _option(flag, values):
    return st.tuples(st.just(flag), values).map(list)


def _flags(*options):
    return st.lists(st.one_of(*options), max_size=4).map(lambda parts: [a for p in parts for a in p])


_DATA_ITEMS = st.one_of(
    st.sampled_from(DATA_NAMES).flatmap(lambda n: _paths().map(lambda p: f"{n}={p}")),
    st.sampled_from(["noequals", "=", "fsdd=", "=folder", "bogus=/tmp", "fsdd==x", "FSDD=/tmp"]),
    _TEXT,
)
_RUN_OPTIONS = [
    _option("--seed", _INTS), _option("--variant", st.sampled_from(["auto", "real", "synthetic", "bad", "", "REAL"])),
    st.sampled_from([["--quick"], ["--full"], ["--quick", "--full"]]), _option("-o", _paths()),
    _option("--output", _paths()), _option("--data-root", _paths()), _option("--data", _DATA_ITEMS),
    _option("--workers", _INTS), _option("-j", _INTS), st.just(["--force"]), st.just(["-q"]), st.just(["--bogus"]),
    st.just(["--seed"]), st.just(["-o"]),
]


def _call(argv):
    """``main(argv)``: its result when it exits 0; a SystemExit carrying the message when it exits 1 or 2."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    stdout, stderr = out.getvalue(), err.getvalue()
    verbose = any(a in ("-v", "--verbose") or (a.startswith("-v") and set(a[1:]) == {"v"}) for a in argv)
    if code == 0:
        return code, stdout, stderr
    if code not in (1, 2):
        raise AssertionError(f"exit code {code!r} (expected 0, 1 or 2)")
    if not stderr.strip():
        raise AssertionError(f"exit code {code} without a message on stderr")
    if "Traceback" in stderr and not verbose:
        raise AssertionError(f"a traceback on stderr: {stderr[-300:]}")
    raise SystemExit(f"exit {code}: {stderr.strip().splitlines()[-1]}")


_PATH_OPTIONS = ("-o", "--output", "--data-root", "--cache-dir")


def _empty_path(argv):
    """Whether ``argv`` gives an empty folder name (which must not silently mean the current folder)."""
    if {"-h", "--help", "--version"} & set(argv):  # help (or the version) is all that is done
        return False
    if any(a == "" and i and argv[i - 1] in _PATH_OPTIONS for i, a in enumerate(argv)):
        return True
    return argv[:1] == ["report"] and "" in argv[1:] and argv[argv.index("", 1) - 1] not in ("--bogus",)


def assert_cli_typed_or_good(name, argv):
    """The command ends with a typed error (SystemExit) or a good result: exit 0, some output, no empty path."""
    def check(result):
        code, stdout, stderr = result
        return code == 0 and bool(stdout.strip() or stderr.strip()) and not _empty_path(argv)

    assert_typed_or_good(f"mmconcepts.cli.main {name}", lambda: _call(argv), check=check, typed=(SystemExit,),
                         timeout=60)


_SETTINGS = dict(suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


@fuzz_settings(120, **_SETTINGS)
@given(exp_id=st.sampled_from(IDS) | st.sampled_from(BAD_IDS) | _TEXT, options=_flags(*_RUN_OPTIONS),
       before=st.booleans())
def test_fuzz_run(exp_id, options, before):
    argv = ["run", *options, exp_id] if before else ["run", exp_id, *options]
    assert_cli_typed_or_good("run", argv)


@fuzz_settings(80, **_SETTINGS)
@given(options=_flags(*_RUN_OPTIONS, st.just(["--no-synthetic"]),
                      st.lists(st.sampled_from(IDS) | st.sampled_from(BAD_IDS), min_size=0, max_size=3)
                      .map(lambda ids: ["--only", *ids])))
def test_fuzz_reproduce(options):
    if "--only" not in options or "--help" in options:  # the full reproduce is long even without computing
        options = [*options, "--only", "ch3-threshold"]
    assert_cli_typed_or_good("reproduce", ["reproduce", *options])


@fuzz_settings(100, **_SETTINGS)
@given(args=st.lists(_paths() | _TEXT | st.sampled_from(["-q", "-v", "--help", "--bogus"]), max_size=3))
def test_fuzz_report(args):
    assert_cli_typed_or_good("report", ["report", *args])


@fuzz_settings(100, **_SETTINGS)
@given(action=st.sampled_from(["list", "fetch", "", "bogus", "--help"]),
       rest=st.lists(st.sampled_from(DATA_NAMES + ["nope", "", "--help"]).map(lambda a: [a])
                     | _option("--data-root", _paths() | st.just("data_root"))
                     | _option("--url", st.sampled_from(["http://127.0.0.1:9/x.zip", "", "notaurl", "file:///etc/passwd"])
                               | _TEXT)
                     | _option("--sha256", st.sampled_from(["0" * 64, "sha256:" + "a" * 64, "xyz", "", "A" * 64])
                               | _TEXT)
                     | _option("--max-size", st.sampled_from(["1", "500MB", "2GiB", "1.5kB", "0", "-1", "0.1B", "1e9",
                                                              "12XB", "", "GB", " 3 MB ", ".5G", "9" * 400 + "TB"])
                               | _TEXT)
                     | _option("--max-files", st.sampled_from(["1", "100000", "0", "-3", "1.5", "", "x"]) | _TEXT),
                     max_size=4).map(lambda parts: [a for p in parts for a in p]))
def test_fuzz_data(action, rest):
    rest = [_SANDBOX["data_root"] if a == "data_root" else a for a in rest]
    assert_cli_typed_or_good("data", ["data", action, *rest] if action else ["data", *rest])


@fuzz_settings(100, **_SETTINGS)
@given(action=st.sampled_from(["list", "clear", "", "bogus"]),
       rest=st.lists(_option("--cache-dir", st.sampled_from(["cache", "folder", "file", "through_file", "missing",
                                                              "proc", "empty"])) | _option("--older-than", st.sampled_from(
           ["12h", "7d", "1d12h", "0s", "-1d", "d", "", "1y", "nan", "inf", "1e400s", "999999999999w"]) | _TEXT)
           | st.sampled_from(["ch3-folds", "nope", "", "..", "/", "../x", "--help"]).map(lambda a: [a]), max_size=4)
       .map(lambda parts: [a for p in parts for a in p]))
def test_fuzz_cache(action, rest, sandbox):
    # only the sandbox's folders are ever cleared: the cache, the fuzz folders, or a path that is no folder
    names = {"cache": str(sandbox / "cache"), "empty": "", **_SANDBOX}
    rest = [names.get(a, a) if i and rest[i - 1] == "--cache-dir" else a for i, a in enumerate(rest)]
    assert_cli_typed_or_good("cache", ["cache", action, *rest] if action else ["cache", *rest])


@fuzz_settings(100, **_SETTINGS)
@given(argv=st.lists(st.sampled_from(["list", "run", "reproduce", "report", "data", "cache", "-v", "-q", "--version",
                                      "--help", "-h", "--bogus", "", "-", "--", "list"]) | _TEXT, max_size=4))
def test_fuzz_top_level(argv):
    if argv and argv[0] == "reproduce" and "--help" not in argv and "-h" not in argv:
        argv = [*argv, "--only", "ch3-threshold"]
    assert_cli_typed_or_good("top level", argv)


def test_the_cache_and_the_current_folder_are_the_sandbox(sandbox):
    """The fuzz tests write nowhere else (the current folder is the sandbox: ``--output .`` and ``report .``)."""
    assert Path.cwd() == sandbox and os.environ["MMCONCEPTS_DATA"] == str(sandbox / "cache")
