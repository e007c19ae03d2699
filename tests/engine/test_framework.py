"""The experiment framework: definitions, registry, runner, records, data arguments."""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from conftest import fsdd_like
from mmconcepts import __version__
from mmconcepts.errors import ExperimentError, ParameterError
from mmconcepts.experiments import (
    RECORD_KEYS,
    Claim,
    Experiment,
    ExperimentSkipped,
    Result,
    RunContext,
    Table,
    all_experiments,
    get,
    load_record,
    parse_data_args,
    register,
    reproduce,
    run_experiment,
)


def _strict_json(path):
    """Parse JSON refusing NaN/Infinity tokens, as a strict reader would."""

    def refuse(token):
        raise ValueError(f"invalid JSON constant {token}")

    return json.loads(path.read_text(), parse_constant=refuse)


# --------------------------------------------------------------------------- definitions


@dataclass(frozen=True)
class _Cfg:
    seed: int = 0

    @classmethod
    def quick(cls):
        return cls()

    @classmethod
    def full(cls):
        return cls(seed=1)


@dataclass
class _MutableCfg:
    seed: int = 0

    @classmethod
    def quick(cls):
        return cls()

    @classmethod
    def full(cls):
        return cls()


@dataclass(frozen=True)
class _NoPresets:
    seed: int = 0


def _noop(config, ctx):
    return Result()


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"id": "Bad_Id"}, "lowercase"),
        ({"config_cls": _MutableCfg}, "frozen"),
        ({"config_cls": _NoPresets}, "quick()"),
        ({"config_cls": dict}, "dataclass"),
        ({"run": 3}, "callable"),
        ({"reference": {"a b": 1.0}}, "metric name"),
        ({"reference": {"a": "high"}}, "number"),
        ({"datasets": "choreo1"}, "tuple"),
        ({"claims": ["a > b"]}, "Claim"),
    ],
)
def test_experiment_definition_errors(kwargs, fragment):
    base = dict(id="x-1", title="t", thesis_ref="r", config_cls=_Cfg, run=_noop)
    with pytest.raises(ExperimentError) as info:
        Experiment(**{**base, **kwargs})
    assert fragment in str(info.value)


def test_claim_rule_syntax_checked_at_definition():
    with pytest.raises(ExperimentError, match="claim rule"):
        Claim("broken", "a > > b")
    assert Claim("fine", "16.x.y >= 0.5").rule == "16.x.y >= 0.5"


def test_make_config_presets_and_seed():
    exp = Experiment(id="x-1", title="t", thesis_ref="r", config_cls=_Cfg, run=_noop)
    assert exp.make_config("quick") == _Cfg(seed=0)
    assert exp.make_config("full") == _Cfg(seed=1)
    assert exp.make_config("full", seed=7) == _Cfg(seed=7)
    with pytest.raises(ParameterError, match="preset"):
        exp.make_config("medium")
    with pytest.raises(ParameterError, match="seed"):
        exp.make_config("quick", seed=-1)


def test_table_rows_must_match_columns():
    with pytest.raises(ExperimentError, match="row 1 has 1 cells"):
        Table("t", ["a", "b"], [[1, 2], [3]])


# --------------------------------------------------------------------------- registry


def test_registry_lazy_load_sorted_and_lookup(registry):
    assert registry._REGISTRY == {}  # nothing imported until asked
    ids = [e.id for e in all_experiments()]
    assert ids == ["toy-data", "toy-mean"]
    assert get("toy-mean").title.startswith("Toy")
    with pytest.raises(ExperimentError) as info:
        get("toy-maen")
    assert "Did you mean 'toy-mean'" in str(info.value)
    assert "toy-data" in str(info.value)


def test_register_rejects_duplicate_ids(toy):
    register(toy.TOY)  # the same object again is a no-op
    clone = toy.make_experiment("toy-mean", toy._fail)
    with pytest.raises(ExperimentError, match="already registered"):
        register(clone)
    assert get("toy-mean") is toy.TOY


def test_broken_experiment_module_is_an_error_not_skipped(registry, monkeypatch):
    monkeypatch.setattr(registry, "EXPERIMENT_PACKAGES", ("_toy_experiment", "_no_such_module_xyz"))
    with pytest.raises(ExperimentError, match="_no_such_module_xyz"):
        all_experiments()


# --------------------------------------------------------------------------- runner


def test_run_writes_complete_record_and_figures(toy, tmp_path):
    out = tmp_path / "results"
    record = run_experiment("toy-mean", output=out, progress=False)
    path = out / "toy-mean.json"
    stored = _strict_json(path)
    assert set(RECORD_KEYS) <= stored.keys()
    assert stored["schema_version"] == 5
    assert stored["explorer"] == {}  # toy-mean has no concept explorer
    assert stored["status"] == "ok" and record["status"] == "ok"
    assert stored["experiment"] == "toy-mean"
    assert stored["preset"] == "quick"
    assert stored["config"] == {"n": 400, "n_chunks": 4, "sizes": [1, 2, 3], "seed": 0}
    assert stored["seed"] == 0
    assert stored["version"] == __version__
    assert stored["reference"] == {"mean": 0.5, "std": 0.2887}
    assert [c["holds"] for c in stored["claims"]] == [True, False, None]
    assert [c["kind"] for c in stored["claims"]] == ["thesis", "ours", "magnitude"]
    assert stored["claims"][0]["source"] == "Section 0.0 (line 1)"
    assert stored["claims"][2]["text"] == "The sample mean against the thesis' 0.5."  # filled from the reference
    assert stored["claims"][2]["ratio"] == pytest.approx(stored["metrics"]["mean"] / 0.5)
    assert 0.4 < stored["metrics"]["mean"] < 0.6
    assert stored["metrics"]["n"] == 400
    assert "1.chunk_mean" in stored["metrics"]
    assert stored["tables"]["quantiles"]["columns"] == ["q", "value"]
    assert len(stored["tables"]["quantiles"]["rows"]) == 3
    assert stored["figures"] == {"hist": "toy-mean/hist.png"}
    assert (out / "toy-mean" / "hist.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(stored["extra"]["chunk_means"]) == 4
    assert stored["started_at"].endswith("+00:00")
    assert stored["elapsed_s"] >= 0
    # atomic writes leave no temporary files behind
    leftovers = [p.name for p in out.rglob("*") if (p.name.startswith(".") or p.suffix == ".tmp") and
                 ".locks" not in p.parts]  # the record's lock file stays (empty), as the report's
    assert leftovers == []
    assert record["metrics"]["mean"] == stored["metrics"]["mean"]


def test_same_seed_same_numbers(toy, tmp_path):
    a = run_experiment("toy-mean", output=tmp_path / "a", progress=False, seed=5)
    b = run_experiment("toy-mean", output=tmp_path / "b", progress=False, seed=5)
    c = run_experiment("toy-mean", output=tmp_path / "c", progress=False, seed=6)
    assert a["metrics"] == b["metrics"]
    assert a["metrics"] != c["metrics"]


def test_rerun_is_skipped_unless_config_changes_or_forced(toy, tmp_path, caplog):
    out = tmp_path / "r"
    first = run_experiment("toy-mean", output=out, progress=False)
    assert toy.CALLS == [0]
    with caplog.at_level("INFO", logger="mmconcepts"):
        again = run_experiment("toy-mean", output=out, progress=False)
    assert toy.CALLS == [0]  # not recomputed
    assert again["started_at"] == first["started_at"]
    assert "skipped: up to date" in caplog.text
    run_experiment("toy-mean", output=out, progress=False, seed=1)
    assert toy.CALLS == [0, 1]  # different seed: recomputed
    assert _strict_json(out / "toy-mean.json")["seed"] == 1
    run_experiment("toy-mean", output=out, progress=False, seed=1, force=True)
    assert toy.CALLS == [0, 1, 1]  # forced
    run_experiment("toy-mean", output=out, progress=False, seed=1, preset="full")
    assert toy.CALLS == [0, 1, 1, 1]  # another preset, another config
    (out / "toy-mean" / "hist.png").unlink()
    run_experiment("toy-mean", output=out, progress=False, seed=1, preset="full")
    assert toy.CALLS == [0, 1, 1, 1, 1]  # a missing figure is not up to date
    assert (out / "toy-mean" / "hist.png").exists()


def test_rerun_after_code_change_recomputes(toy, tmp_path):
    out = tmp_path / "v"
    run_experiment("toy-mean", output=out, progress=False)
    stored = _strict_json(out / "toy-mean.json")
    from mmconcepts._fingerprint import code_fingerprint

    assert stored["code"] == code_fingerprint()
    stored["code"] = "0123456789abcdef"  # made by other code, same package version
    (out / "toy-mean.json").write_text(json.dumps(stored))
    run_experiment("toy-mean", output=out, progress=False)
    assert toy.CALLS == [0, 0]
    run_experiment("toy-mean", output=out, progress=False)  # now up to date
    assert toy.CALLS == [0, 0]


def test_code_fingerprint_changes_with_any_source_file(tmp_path):
    """Regression: results were keyed on the package version, never bumped."""
    import shutil

    import mmconcepts
    from mmconcepts._fingerprint import code_fingerprint, fingerprint_parts

    pkg = tmp_path / "pkg"
    shutil.copytree(Path(mmconcepts.__file__).parent, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    before = code_fingerprint(pkg)
    assert before == code_fingerprint(pkg) and len(before) == 16
    target = pkg / "nmf" / "_beta.py"
    target.write_text(target.read_text() + "\n# an edit\n")
    edited = fingerprint_parts(pkg)["source"]
    from mmconcepts import _fingerprint

    _fingerprint._cached.cache_clear()
    after = code_fingerprint(pkg)
    assert after != before
    assert edited != fingerprint_parts(Path(mmconcepts.__file__).parent)["source"]
    assert "numpy" in fingerprint_parts(pkg)["dependencies"]


def test_nan_metrics_are_null_in_json_and_nan_when_read(registry, tmp_path):
    import _toy_experiment as toy_mod  # noqa: F401 - imported by the fixture path

    def run(config, ctx):
        return Result(metrics={"good": 1.0, "missing": float("nan"), "huge": float("inf")})

    exp = toy_mod.make_experiment(
        "toy-nan", run, claims=[Claim("uses NaN", "missing > 0"), Claim("fine", "good > 0")]
    )
    record = run_experiment(exp, output=tmp_path, progress=False)
    stored = _strict_json(tmp_path / "toy-nan.json")  # valid strict JSON
    assert stored["metrics"] == {"good": 1.0, "missing": None, "huge": None}
    assert [c["holds"] for c in stored["claims"]] == [None, True]
    assert math.isnan(record["metrics"]["missing"])
    assert math.isnan(load_record(tmp_path / "toy-nan.json")["metrics"]["missing"])


def test_failure_is_recorded_and_raised(toy, tmp_path):
    with pytest.raises(RuntimeError, match="broke on purpose"):
        run_experiment(toy.FAIL, output=tmp_path, progress=False)
    stored = _strict_json(tmp_path / "toy-fail.json")
    assert stored["status"] == "failed"
    assert "broke on purpose" in stored["message"]
    assert "Traceback" in stored["traceback"] and "_fail" in stored["traceback"]
    assert stored["metrics"] == {} and stored["claims"][0]["holds"] is None
    # a failed record is never taken as up to date
    with pytest.raises(RuntimeError):
        run_experiment(toy.FAIL, output=tmp_path, progress=False)


def test_unknown_metric_in_claim_fails_the_run(toy, tmp_path):
    exp = toy.make_experiment("toy-typo", lambda c, x: Result(metrics={"score": 1.0}),
                              claims=[Claim("typo", "scroe > 0")])
    record = run_experiment(exp, output=tmp_path, progress=False, raise_errors=False)
    assert record["status"] == "failed"
    assert "unknown metric 'scroe'" in record["message"] and "score" in record["message"]


def test_bad_result_types_fail_clearly(toy, tmp_path):
    exp = toy.make_experiment("toy-bad", lambda c, x: Result(metrics={"16": 1.0}))
    record = run_experiment(exp, output=tmp_path, progress=False, raise_errors=False)
    assert record["status"] == "failed" and "metric name '16'" in record["message"]
    exp = toy.make_experiment("toy-bad2", lambda c, x: {"score": 1.0})
    record = run_experiment(exp, output=tmp_path, progress=False, raise_errors=False)
    assert "must return a Result" in record["message"]
    exp = toy.make_experiment("toy-bad3", lambda c, x: Result(metrics={"a": 1.0}, extra={"f": object()}))
    record = run_experiment(exp, output=tmp_path, progress=False, raise_errors=False)
    assert "extra['f']: a object value" in record["message"]
    assert "cannot be stored in a JSON result" in record["message"]
    assert not (tmp_path / "toy-bad3").exists()


def test_reproduce_records_failures_and_skips_and_keeps_going(toy, tmp_path):
    register(toy.FAIL)
    register(toy.SKIP)
    records = reproduce(output=tmp_path, progress=False)
    status = {r["experiment"]: r["status"] for r in records}
    assert status == {"toy-data": "skipped", "toy-fail": "failed", "toy-mean": "ok", "toy-skip": "skipped"}
    assert [r["experiment"] for r in records] == sorted(status)
    assert toy.CALLS == [0]  # toy-mean ran after toy-fail failed
    assert _strict_json(tmp_path / "toy-fail.json")["status"] == "failed"
    skipped = _strict_json(tmp_path / "toy-skip.json")
    assert skipped["status"] == "skipped" and skipped["message"] == "no real data here"
    assert skipped["traceback"] is None
    assert "--data toyfile=PATH" in _strict_json(tmp_path / "toy-data.json")["message"]
    assert _strict_json(tmp_path / "toy-mean.json")["status"] == "ok"
    # only the requested ones, in the given order
    records = reproduce(output=tmp_path, progress=False, ids=["toy-skip", "toy-mean"])
    assert [r["experiment"] for r in records] == ["toy-skip", "toy-mean"]


def test_a_missing_extra_skips_the_experiment_naming_the_extra(toy, tmp_path):
    """A user with "mmconcepts[all]" (no text-to-speech) sees the generated-speech runs skipped, not failed."""
    from mmconcepts.errors import MissingExtraError

    def needs_speech(config, ctx):
        raise MissingExtraError('piper is not installed: pip install "mmconcepts[speech]"')

    record = run_experiment(toy.make_experiment("toy-extra", needs_speech), output=tmp_path, progress=False)
    assert record["status"] == "skipped" and record["traceback"] is None
    assert 'needs an optional extra' in record["message"] and '"mmconcepts[speech]"' in record["message"]


def test_skipped_experiment_returns_record_without_raising(toy, tmp_path):
    record = run_experiment(toy.SKIP, output=tmp_path, progress=False)
    assert record["status"] == "skipped"
    assert isinstance(ExperimentSkipped("x"), ExperimentError)


# --------------------------------------------------------------------------- data


def test_parse_data_args():
    assert parse_data_args(["a=/x", "b.c=rel/p=q"]) == {"a": __import__("pathlib").Path("/x"),
                                                       "b.c": __import__("pathlib").Path("rel/p=q")}
    for bad, fragment in [(["nope"], "NAME=PATH"), (["=p"], "NAME=PATH"), (["a="], "NAME=PATH"),
                          (["a b=p"], "must be a word"), (["a=1", "a=2"], "twice")]:
        with pytest.raises(ExperimentError, match=fragment):
            parse_data_args(bad)


def test_data_paths_are_checked_and_passed(toy, tmp_path):
    value = tmp_path / "value.txt"
    value.write_text("4.25")
    missing = tmp_path / "absent"
    with pytest.raises(ExperimentError) as info:
        run_experiment("toy-data", output=tmp_path / "o", data={"toyfile": missing})
    assert str(missing) in str(info.value) and "does not exist" in str(info.value)
    with pytest.raises(ExperimentError, match="no experiment uses a data set named 'choreo9'"):
        run_experiment("toy-data", output=tmp_path / "o", data={"choreo9": value})
    record = run_experiment("toy-data", output=tmp_path / "o", data={"toyfile": value}, progress=False)
    assert record["status"] == "ok" and record["metrics"]["value"] == 4.25
    assert record["data"] == {"toyfile": str(value.resolve())}
    # a name declared by another experiment is ignored by toy-mean, not an error
    record = run_experiment("toy-mean", output=tmp_path / "o", data={"toyfile": value}, progress=False)
    assert record["status"] == "ok" and record["data"] == {}
    # changing the data path makes toy-data's result out of date
    other = tmp_path / "other.txt"
    other.write_text("1.5")
    record = run_experiment("toy-data", output=tmp_path / "o", data={"toyfile": other}, progress=False)
    assert record["metrics"]["value"] == 1.5


# --------------------------------------------------------------------------- context


def _square(x):
    return x * x


def test_context_parallel_keeps_order(tmp_path):
    items = list(range(7))
    serial = RunContext(workers=1, cache_dir=tmp_path, show_progress=False).parallel(_square, items)
    pooled = RunContext(workers=2, cache_dir=tmp_path, show_progress=False).parallel(abs, [-3, 2, -1, 5])
    assert serial == [x * x for x in items]
    assert pooled == [3, 2, 1, 5]
    for workers in (1, 2):  # on_result sees each result, in order, as it comes back
        seen = []
        ctx = RunContext(workers=workers, cache_dir=tmp_path, show_progress=False)
        assert ctx.parallel(abs, [-3, 2, -1, 5], on_result=lambda i, r: seen.append((i, r))) == [3, 2, 1, 5]
        assert seen == [(0, 3), (1, 2), (2, 1), (3, 5)]


def test_context_validates_workers_and_requires_data(tmp_path):
    with pytest.raises(ParameterError, match="workers"):
        RunContext(workers=0, cache_dir=tmp_path)
    assert RunContext(workers=-1, cache_dir=tmp_path).workers >= 1
    ctx = RunContext(cache_dir=tmp_path, data={"choreo1": str(tmp_path)})
    assert ctx.require_data("choreo1") == tmp_path
    with pytest.raises(ExperimentSkipped, match="--data choreo2=PATH"):
        ctx.require_data("choreo2")
    assert list(ctx.progress(iter([1, 2]), total=2, desc="x")) == [1, 2]


def test_toy_module_not_leaked(registry):
    # the fixture gives a fresh import each time; nothing stays registered afterwards
    assert "_toy_experiment" not in sys.modules


# --------------------------------------------------------------------------- data variants


def _variant_experiment(toy):
    def run(config, ctx):
        path = ctx.data.get("fsdd")
        return Result(
            metrics={"acc": 0.9 if path is not None else 0.5, "n_sets": float(len(ctx.data))},
            samples={"acc": [0.88, 0.9, 0.92, 0.89, 0.91] if path is not None else [0.4, 0.5, 0.6, 0.45, 0.55]},
        )

    return toy.make_experiment("toy-variant", run, datasets=("fsdd", "toyfile"),
                               claims=[Claim("accuracy above 0.7", "acc > 0.7")])


def test_reproduce_runs_real_and_synthetic_side_by_side(toy, tmp_path, monkeypatch):
    exp = _variant_experiment(toy)
    root = tmp_path / "root"
    folder = fsdd_like(root)
    monkeypatch.setenv("MMCONCEPTS_DATA_ROOT", str(root))
    register(exp)
    out = tmp_path / "res"
    records = reproduce(output=out, ids=["toy-variant"], progress=False)
    assert [(r["variant"], r["metrics"]["acc"]) for r in records] == [("real", 0.9), ("synthetic", 0.5)]
    real, synth = _strict_json(out / "toy-variant.json"), _strict_json(out / "toy-variant.synthetic.json")
    assert real["data"] == {"fsdd": str(folder.resolve())} and synth["data"] == {}
    assert real["claims"][0]["verdict"] == "holds" and synth["claims"][0]["verdict"] == "fails"
    assert real["intervals"]["acc"][0] < 0.9 < real["intervals"]["acc"][1]
    assert real["samples"]["acc"] == [0.88, 0.9, 0.92, 0.89, 0.91]
    # without the data root the default run is on generated data, and the stale secondary record goes
    monkeypatch.delenv("MMCONCEPTS_DATA_ROOT")
    records = reproduce(output=out, ids=["toy-variant"], progress=False)
    assert [r["variant"] for r in records] == ["synthetic"]
    assert not (out / "toy-variant.synthetic.json").exists()
    assert _strict_json(out / "toy-variant.json")["variant"] == "synthetic"


def test_explicit_data_overrides_the_root_and_real_variant_skips_without_data(toy, tmp_path, monkeypatch):
    exp = _variant_experiment(toy)
    monkeypatch.delenv("MMCONCEPTS_DATA_ROOT", raising=False)
    rec = run_experiment(exp, output=tmp_path / "a", variant="real", progress=False)
    assert rec["status"] == "skipped" and "--data-root" in rec["message"]
    other = tmp_path / "elsewhere"
    other.mkdir()
    (other / "labels.csv").write_text("file,labels,speaker,transcription\n0_alice_0.wav,zero,alice,zero\n")
    (other / "0_alice_0.wav").write_bytes(b"RIFF")  # a set given by path must hold its layout
    rec = run_experiment(exp, output=tmp_path / "b", data={"fsdd": other, "toyfile": other}, progress=False)
    assert rec["variant"] == "real" and rec["data"] == {"fsdd": str(other.resolve()), "toyfile": str(other.resolve())}
    assert rec["metrics"]["n_sets"] == 2.0
    with pytest.raises(ParameterError, match="variant"):
        run_experiment(exp, output=tmp_path, variant="both")


def test_schema_1_records_are_read_with_verdicts(tmp_path):
    old = {"schema_version": 1, "experiment": "x", "status": "ok", "metrics": {"a": 1.0}, "data": {},
           "claims": [{"text": "t", "rule": "a > 0", "holds": True}, {"text": "u", "rule": "a > 2", "holds": False}]}
    (tmp_path / "x.json").write_text(json.dumps(old))
    rec = load_record(tmp_path / "x.json")
    assert rec["variant"] == "synthetic" and rec["intervals"] == {} and rec["code"] is None
    assert [c["verdict"] for c in rec["claims"]] == ["holds", "fails"]


def test_samples_must_belong_to_a_metric():
    with pytest.raises(ExperimentError, match="not a metric"):
        Result(metrics={"a": 1.0}, samples={"b": [1.0, 2.0]}).validate()
    with pytest.raises(ExperimentError, match="real numbers"):
        Result(metrics={"a": 1.0}, samples={"a": "12"}).validate()


def test_warnings_of_a_run_are_recorded_and_reported(toy, tmp_path):
    import warnings as _w

    from mmconcepts.report import write_report

    def run(config, ctx):
        _w.warn("1 file(s) of the toy set could not be read and were skipped: bad.wav", RuntimeWarning)
        return Result(metrics={"a": 1.0})

    exp = toy.make_experiment("toy-warn", run)
    with pytest.warns(RuntimeWarning, match="skipped"):  # still shown to the caller
        rec = run_experiment(exp, output=tmp_path, progress=False)
    assert rec["warnings"] == ["RuntimeWarning: 1 file(s) of the toy set could not be read and were skipped: bad.wav"]
    assert "bad.wav" in write_report(tmp_path)[1].read_text()


def test_an_asked_variant_that_cannot_run_overwrites_nothing(toy, tmp_path):
    exp = _variant_experiment(toy)
    out = tmp_path / "res"
    good = run_experiment(exp, output=out, progress=False)  # auto: generated data
    assert good["variant"] == "synthetic" and good["status"] == "ok"
    before = (out / "toy-variant.json").read_bytes()
    rec = run_experiment(exp, output=out, variant="real", progress=False)
    assert rec["status"] == "skipped" and "--data-root" in rec["message"]
    assert (out / "toy-variant.json").read_bytes() == before


def test_reproduce_removes_a_secondary_record_it_does_not_refresh(toy, tmp_path, monkeypatch):
    exp = _variant_experiment(toy)
    register(exp)
    folder = fsdd_like(tmp_path / "root")
    out = tmp_path / "res"
    reproduce(output=out, ids=["toy-variant"], data={"fsdd": folder}, progress=False)
    assert (out / "toy-variant.synthetic.json").exists()
    records = reproduce(output=out, ids=["toy-variant"], data={"fsdd": folder}, synthetic=False, progress=False)
    assert [r["variant"] for r in records] == ["real"]
    assert not (out / "toy-variant.synthetic.json").exists()


def test_changed_recordings_recompute_the_result(toy, tmp_path):
    calls = []

    def run(config, ctx):
        calls.append(1)
        return Result(metrics={"n": float(len(list(ctx.data["fsdd"].iterdir())))})

    exp = toy.make_experiment("toy-sig", run, datasets=("fsdd",))
    folder = fsdd_like(tmp_path / "root")
    out = tmp_path / "res"
    assert run_experiment(exp, output=out, data={"fsdd": folder}, progress=False)["metrics"]["n"] == 2
    run_experiment(exp, output=out, data={"fsdd": folder}, progress=False)
    assert len(calls) == 1  # up to date
    (folder / "1_alice_0.wav").write_bytes(b"RIFF")  # one more recording, same folder
    assert run_experiment(exp, output=out, data={"fsdd": folder}, progress=False)["metrics"]["n"] == 3
    assert len(calls) == 2


def _warn_in_worker(i):
    import warnings as _w

    _w.warn(f"worker {i} skipped a file", RuntimeWarning)
    return i


def test_warnings_raised_in_worker_processes_are_recorded(toy, tmp_path):
    def run(config, ctx):
        return Result(metrics={"s": float(sum(ctx.parallel(_warn_in_worker, [1, 2])))})

    exp = toy.make_experiment("toy-warn2", run)
    with pytest.warns(RuntimeWarning):
        rec = run_experiment(exp, output=tmp_path, workers=2, progress=False)
    assert rec["metrics"]["s"] == 3.0
    assert sorted(rec["warnings"]) == ["RuntimeWarning: worker 1 skipped a file", "RuntimeWarning: worker 2 skipped a file"]


def _leak_guard(_):
    from joblib.externals.loky import process_executor

    return process_executor._MAX_MEMORY_LEAK_SIZE


def _leak_check_delay(_):
    from joblib.externals.loky import process_executor

    return process_executor._MEMORY_LEAK_CHECK_DELAY


def test_a_runs_workers_keep_what_they_load(toy, tmp_path):
    """loky replaces a worker whose memory grew by 300 MB since its first task (its guard against
    leaks), and checks for that, or runs a full garbage collection without psutil, after any task
    that ends a second after the last check; a run's workers keep the voice, librosa and numba
    kernels they load, so the guard is raised and the checks spaced out in every worker of the
    run, those of ctx.parallel and of the library's own joblib calls."""
    from joblib import Parallel, delayed
    from joblib.externals.loky import process_executor

    from mmconcepts.engine.workers import WORKER_GC_INTERVAL, WORKER_MEMORY_GROWTH

    assert WORKER_MEMORY_GROWTH > process_executor._MAX_MEMORY_LEAK_SIZE  # loky's own, in this process
    assert WORKER_GC_INTERVAL > process_executor._MEMORY_LEAK_CHECK_DELAY

    def run(config, ctx):
        metrics = {}
        for name, fn in (("size", _leak_guard), ("delay", _leak_check_delay)):
            own = Parallel(n_jobs=2)(delayed(fn)(i) for i in range(4))
            metrics[f"{name}.ctx"] = float(min(ctx.parallel(fn, range(4))))
            metrics[f"{name}.own"] = float(min(own))
        return Result(metrics=metrics)

    rec = run_experiment(toy.make_experiment("toy-leak", run), output=tmp_path, workers=2, progress=False)
    assert rec["metrics"] == {"size.ctx": float(WORKER_MEMORY_GROWTH), "size.own": float(WORKER_MEMORY_GROWTH),
                              "delay.ctx": WORKER_GC_INTERVAL, "delay.own": WORKER_GC_INTERVAL}


# --------------------------------------------------------------------------- a config instead of a preset


def test_run_with_a_config_object(toy, tmp_path):
    out = tmp_path / "c"
    record = run_experiment("toy-mean", config=toy.ToyConfig(n=50, n_chunks=2), output=out, progress=False)
    stored = _strict_json(out / "toy-mean.json")
    assert record.preset == stored["preset"] == "custom"  # no preset equals it
    assert stored["config"] == {"n": 50, "n_chunks": 2, "sizes": [1, 2, 3], "seed": 0} and stored["seed"] == 0
    assert record.metrics["n"] == 50.0 and toy.CALLS == [0]
    run_experiment("toy-mean", config=toy.ToyConfig(n=50, n_chunks=2), output=out, progress=False)
    assert toy.CALLS == [0]  # the same config: up to date
    run_experiment("toy-mean", config=toy.ToyConfig(n=60, n_chunks=2), output=out, progress=False)
    assert toy.CALLS == [0, 0] and _strict_json(out / "toy-mean.json")["config"]["n"] == 60
    # a config equal to a preset is recorded under its name; seed= replaces the config's seed
    assert run_experiment("toy-mean", config=toy.ToyConfig.full(), output=out, progress=False).preset == "full"
    rec = run_experiment("toy-mean", config=toy.ToyConfig.quick(), seed=7, output=out, progress=False)
    assert rec.preset == "quick" and rec.seed == 7 and rec.config["seed"] == 7 and toy.CALLS[-1] == 7
    # the same record as the preset's: a run by preset name is up to date
    n_calls = len(toy.CALLS)
    assert run_experiment("toy-mean", preset="quick", seed=7, output=out, progress=False).started_at == rec.started_at
    assert len(toy.CALLS) == n_calls


def test_a_config_of_another_class_or_with_a_preset_is_refused(toy, tmp_path):
    with pytest.raises(ParameterError, match=r"config must be a _toy_experiment\.ToyConfig.*got _toy_experiment"
                                             r"\.SmallConfig"):
        run_experiment("toy-mean", config=toy.SmallConfig(), output=tmp_path, progress=False)
    with pytest.raises(ParameterError, match="a preset or a config, not both"):
        run_experiment("toy-mean", preset="full", config=toy.ToyConfig(), output=tmp_path, progress=False)
    with pytest.raises(ParameterError, match="seed"):
        run_experiment("toy-mean", config=toy.ToyConfig(), seed=-2, output=tmp_path, progress=False)
    assert toy.CALLS == [] and not (tmp_path / "toy-mean.json").exists()


def test_returned_record_is_the_file_written(toy, tmp_path):
    from mmconcepts.experiments import ResultRecord

    record = run_experiment("toy-mean", output=tmp_path, progress=False)
    text = (tmp_path / "toy-mean.json").read_text(encoding="utf-8")
    assert isinstance(record, ResultRecord) and record.to_json() == text
    assert load_record(tmp_path / "toy-mean.json").to_json() == text
    assert record["metrics"] == record.metrics and record["claims"] == [c.to_dict() for c in record.claims]


# --------------------------------------------------------------------------- compute and present


def _compute(config, ctx):
    return Result(metrics={"a": 1.0, "b": 2.0}, figure_data={"curve": [3.0, 1.0, 2.0]})


def _present(result, config):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2, 2))
    fig.subplots().plot(result.figure_data["curve"], label=f"a = {result.metrics['a']}")
    return {"curve": fig}


def test_compute_and_present_are_run_in_turn(registry, tmp_path):
    exp = Experiment(id="x-split", title="t", thesis_ref="r", config_cls=_Cfg, compute=_compute, present=_present,
                     claims=[Claim("a below b", "a < b")])
    numbers = exp.compute(_Cfg(), RunContext(cache_dir=tmp_path, show_progress=False))
    assert numbers.figures == {} and numbers.metrics == {"a": 1.0, "b": 2.0}  # nothing drawn
    drawn = exp.run(_Cfg(), RunContext(cache_dir=tmp_path, show_progress=False))
    assert set(drawn.figures) == {"curve"} and drawn.metrics == numbers.metrics
    record = run_experiment(exp, output=tmp_path / "o", progress=False)
    assert record.status == "ok" and record.figures == {"curve": "x-split/curve.png"}
    assert (tmp_path / "o" / "x-split" / "curve.png").read_bytes()[:4] == b"\x89PNG"
    assert "figure_data" not in (tmp_path / "o" / "x-split.json").read_text()  # never written
    # an experiment without figures has no present
    plain = Experiment(id="x-plain", title="t", thesis_ref="r", config_cls=_Cfg, compute=_compute)
    assert plain.run(_Cfg(), RunContext(cache_dir=tmp_path, show_progress=False)).figures == {}


def test_compute_that_draws_or_present_that_returns_no_figures_fails_the_run(registry, tmp_path):
    def drawing(config, ctx):
        return Result(metrics={"a": 1.0}, figures=_present(Result(metrics={"a": 1.0}, figure_data={"curve": [1]}),
                                                            config))

    exp = Experiment(id="x-draws", title="t", thesis_ref="r", config_cls=_Cfg, compute=drawing, present=_present)
    record = run_experiment(exp, output=tmp_path, progress=False, raise_errors=False)
    assert record.status == "failed" and "compute() returned figures (curve)" in record.message
    exp = Experiment(id="x-bad-present", title="t", thesis_ref="r", config_cls=_Cfg, compute=_compute,
                     present=lambda result, config: ["not", "a", "dict"])
    record = run_experiment(exp, output=tmp_path, progress=False, raise_errors=False)
    assert record.status == "failed" and "present() must return a dict of figures" in record.message
    exp = Experiment(id="x-no-result", title="t", thesis_ref="r", config_cls=_Cfg, compute=lambda c, x: {"a": 1.0},
                     present=_present)
    record = run_experiment(exp, output=tmp_path, progress=False, raise_errors=False)
    assert record.status == "failed" and "compute() must return a Result" in record.message


@pytest.mark.parametrize("kwargs, fragment", [
    ({"run": _noop, "compute": _compute}, "not both"),
    ({}, "needs compute"),
    ({"run": _noop, "present": _present}, "present goes with compute"),
    ({"compute": 3}, "compute must be callable"),
    ({"compute": _compute, "present": "draw"}, "present must be callable"),
])
def test_experiment_run_compute_present_combinations(kwargs, fragment):
    with pytest.raises(ExperimentError, match=fragment):
        Experiment(id="x-1", title="t", thesis_ref="r", config_cls=_Cfg, **kwargs)
    legacy = Experiment(id="x-1", title="t", thesis_ref="r", config_cls=_Cfg, run=_noop)
    assert legacy.compute is _noop and legacy.run is _noop and legacy.present is None


def test_every_registered_experiment_computes_and_presents_apart():
    """Numbers from compute, figures from present (none for a table alone)."""
    import importlib

    from mmconcepts.engine.registry import EXPERIMENT_PACKAGES, experiment_modules

    exps = [obj for name in experiment_modules(EXPERIMENT_PACKAGES) for obj in vars(importlib.import_module(name)).values()
            if isinstance(obj, Experiment)]
    assert len(exps) >= 19
    for exp in exps:
        assert exp.compute is not exp.run and exp.compute.__module__.startswith("mmconcepts.experiments."), exp.id
        assert exp.run == exp._compute_and_present, exp.id
        assert (exp.present is None) == (exp.id == "ch6-labels"), exp.id  # Table 6.4 has no figure


def test_a_run_context_gives_real_sets_by_their_registry_name(tmp_path):
    ctx = RunContext(data={"fsdd": str(tmp_path)}, cache_dir=tmp_path)
    assert ctx.has_dataset("fsdd") and not ctx.has_dataset("eth80")
    assert ctx.dataset("fsdd") == tmp_path and isinstance(ctx.dataset("fsdd"), Path)
    with pytest.raises(ExperimentError, match="Did you mean 'fsdd'"):
        ctx.has_dataset("fssd")  # a misspelt name fails, it does not fall back to generated data
    with pytest.raises(ExperimentError, match="has no real data set 'eth80'"):
        ctx.dataset("eth80")
    with pytest.raises(ExperimentSkipped, match="needs the real data set 'eth80'"):
        ctx.require_data("eth80")
    assert ctx.require_data("fsdd") == tmp_path


def test_an_experiment_asks_for_the_sets_it_declares(tmp_path):
    """The runner's context knows the experiment's declared sets: its own names (not in the registry) are accepted
    beside the registry's, any other name is an error."""
    ctx = RunContext(data={}, cache_dir=tmp_path, datasets=("toyfile",))
    assert not ctx.has_dataset("toyfile") and not ctx.has_dataset("fsdd")
    with pytest.raises(ExperimentError, match="no data set named 'toyfil' among .*toyfile.*Did you mean 'toyfile'"):
        ctx.has_dataset("toyfil")
