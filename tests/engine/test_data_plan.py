"""The data plan: the data root resolved once per run into which real sets each experiment uses.

:class:`mmconcepts.engine.data.DataPlan` is made once by ``reproduce`` (or by ``run_experiment``
called alone) and each run takes its experiment's entry; its record's ``variant`` and ``data``
are that entry's, and the experiment's context holds exactly those sets.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from conftest import fsdd_like
import mmconcepts.datasets as datasets_module
import mmconcepts.engine.data as data_module
from mmconcepts.engine import DataPlan, Experiment, Result, register, reproduce, run_experiment
from mmconcepts.engine.data import PlanEntry, make_data_plan
from mmconcepts.errors import ExperimentError, ParameterError


def _msr_like(root: Path) -> Path:
    folder = root / "msr-action3d"
    folder.mkdir(parents=True)
    (folder / "a01_s01_e01_skeleton3D.txt").write_text("0 0 0 1\n" * 20)
    return folder


def _seen(config, ctx):
    """The sets the run's context holds, kept in the record to compare with its ``data``."""
    return Result(metrics={"n_sets": float(len(ctx.data))}, extra={"seen": {k: str(v) for k, v in ctx.data.items()}})


def _experiments(toy, *datasets_of):
    return [register(toy.make_experiment(f"toy-plan{i}", _seen, datasets=sets)) for i, sets in enumerate(datasets_of)]


def _counting(monkeypatch, module, name):
    calls = []
    original = getattr(module, name)

    def counted(*args, **kwargs):
        calls.append(args)
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)
    return calls


def test_reproduce_resolves_the_data_root_once(toy, tmp_path, monkeypatch):
    root = tmp_path / "root"
    fsdd_like(root)
    _msr_like(root)
    _experiments(toy, ("fsdd",), ("fsdd", "msr-action3d"))
    roots = _counting(monkeypatch, data_module, "resolve_root")
    scans = _counting(monkeypatch, datasets_module, "find_datasets")
    records = reproduce(output=tmp_path / "out", ids=["toy-plan0", "toy-plan1"], data_root=root, progress=False)
    assert [(r.experiment, r.variant) for r in records] == [("toy-plan0", "real"), ("toy-plan0", "synthetic"),
                                                            ("toy-plan1", "real"), ("toy-plan1", "synthetic")]
    assert len(roots) == 1  # four runs, one resolution
    assert len(scans) == 1  # the root looked at once, for the sets of both experiments


def test_run_experiment_alone_resolves_the_data_root_once(toy, tmp_path, monkeypatch):
    root = tmp_path / "root"
    fsdd_like(root)
    (exp,) = _experiments(toy, ("fsdd",))
    roots = _counting(monkeypatch, data_module, "resolve_root")
    rec = run_experiment(exp, output=tmp_path / "out", data_root=root, progress=False)
    assert rec.variant == "real" and len(roots) == 1


def test_a_given_plan_is_used_as_it_is(toy, tmp_path, monkeypatch):
    root = tmp_path / "root"
    folder = fsdd_like(root)
    exps = _experiments(toy, ("fsdd",), ())
    plan = DataPlan.build(exps, data_root=root)

    def no_resolution(*args, **kwargs):
        raise AssertionError("the data root was resolved again")

    monkeypatch.setattr(data_module, "resolve_root", no_resolution)
    monkeypatch.setattr(datasets_module, "find_datasets", no_resolution)
    records = reproduce(output=tmp_path / "out", ids=["toy-plan0", "toy-plan1"], data_plan=plan, progress=False)
    assert [(r.experiment, r.variant, r.data) for r in records] == [
        ("toy-plan0", "real", {"fsdd": str(folder.resolve())}), ("toy-plan0", "synthetic", {}),
        ("toy-plan1", "synthetic", {})]
    rec = run_experiment(exps[0], output=tmp_path / "one", data_plan=plan, variant="real", progress=False)
    assert rec.data == {"fsdd": str(folder.resolve())}


def test_the_record_holds_the_plan_entry_and_the_sets_the_run_used(toy, tmp_path):
    root = tmp_path / "root"
    fsdd_like(root)
    _msr_like(root)
    given = tmp_path / "my-msr"
    given.mkdir()
    (given / "a02_s01_e01_skeleton3D.txt").write_text("0 0 0 1\n" * 20)
    (exp,) = _experiments(toy, ("msr-action3d", "fsdd", "eth80"))
    plan = DataPlan.build([exp], {"msr-action3d": given}, root)
    entry = plan.entry(exp)
    # the root's fsdd, the msr-action3d given by path (over the root's), no eth80; in the order declared
    assert entry == PlanEntry("toy-plan0", {"msr-action3d": given.resolve(), "fsdd": (root / "fsdd").resolve()},
                              ("real", "synthetic"))
    assert list(entry.sets) == ["msr-action3d", "fsdd"]
    records = reproduce(output=tmp_path / "out", ids=[exp.id], data_plan=plan, progress=False)
    for rec in records:
        used = {name: str(path) for name, path in entry.data(rec.variant).items()}
        assert rec.data == used == rec.extra["seen"]  # the record says what the experiment got
        assert sorted(rec.data_signature) == sorted(used)
    assert [bool(r.data) for r in records] == [True, False]


def test_plan_entries_say_which_variants_run(toy, tmp_path):
    root = tmp_path / "root"
    fsdd_like(root)
    real, none = _experiments(toy, ("fsdd",), ("eth80",))
    real_only = Experiment(id="toy-real-only", title="Toy", thesis_ref="none", config_cls=toy.SmallConfig, run=_seen,
                           datasets=("fsdd",), synthetic=False)
    plan = DataPlan.build([real, none, real_only], data_root=root)
    assert plan.entry(real).variants == ("real", "synthetic")
    assert plan.entry("toy-plan1").variants == ("synthetic",) and plan.entry("toy-plan1").sets == {}
    assert plan.entry(real_only).variants == ("real",)
    assert plan.root == root.absolute() and plan.given == {}
    entry = plan.entry(real)
    assert entry.chosen("auto") == "real" and plan.entry(none).chosen("auto") == "synthetic"
    assert entry.secondary("synthetic") and not entry.secondary("real") and not plan.entry(none).secondary("synthetic")
    with pytest.raises(ExperimentError, match="no entry for 'toy-mean'"):
        plan.entry("toy-mean")


def test_reproduce_without_synthetic_runs_the_default_variant_only(toy, tmp_path):
    root = tmp_path / "root"
    fsdd_like(root)
    _experiments(toy, ("fsdd",))
    records = reproduce(output=tmp_path / "out", ids=["toy-plan0"], data_root=root, synthetic=False, progress=False)
    assert [r.variant for r in records] == ["real"]


def test_a_mistyped_data_root_is_reported_before_any_work(toy, tmp_path):
    root = tmp_path / "data"
    fsdd_like(root)
    exps = _experiments(toy, ("fsdd",))
    out = tmp_path / "out"
    typo = tmp_path / "dat"
    with pytest.raises(ExperimentError, match=r"the data root '.*dat' does not exist.*Did you mean '.*data'\?"):
        reproduce(output=out, ids=["toy-plan0"], data_root=typo, progress=False)
    with pytest.raises(ExperimentError, match="does not exist"):
        run_experiment(exps[0], output=out, data_root=typo, progress=False)
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(ExperimentError, match="is not a folder"):
        DataPlan.build(exps, data_root=afile)
    assert not out.exists() or not list(out.glob("*.json"))  # nothing ran


def test_a_data_root_from_the_environment_that_is_no_folder_is_warned_once(toy, tmp_path, monkeypatch, caplog):
    _experiments(toy, ("fsdd",), ("fsdd", "msr-action3d"))
    monkeypatch.setenv("MMCONCEPTS_DATA_ROOT", str(tmp_path / "nowhere"))
    with caplog.at_level(logging.WARNING, logger="mmconcepts"):
        records = reproduce(output=tmp_path / "out", ids=["toy-plan0", "toy-plan1"], progress=False)
    assert [r.variant for r in records] == ["synthetic", "synthetic"]
    warned = [r.getMessage() for r in caplog.records if "nowhere" in r.getMessage()]
    assert len(warned) == 1 and "MMCONCEPTS_DATA_ROOT" in warned[0]


def test_a_plan_is_not_given_with_the_data_it_was_made_from(toy, tmp_path):
    exps = _experiments(toy, ("fsdd",))
    plan = DataPlan.build(exps)
    with pytest.raises(ParameterError, match="not both"):
        make_data_plan(exps, None, tmp_path, plan)
    with pytest.raises(ParameterError, match="not both"):
        run_experiment(exps[0], output=tmp_path, data={"fsdd": tmp_path}, data_plan=plan)
    with pytest.raises(ParameterError, match="must be a DataPlan"):
        run_experiment(exps[0], output=tmp_path, data_plan={"fsdd": tmp_path})
    with pytest.raises(ExperimentError, match="no entry for 'toy-mean'"):
        run_experiment("toy-mean", output=tmp_path, data_plan=plan)


def test_a_given_data_root_that_holds_no_known_set_is_refused_unless_generated_data_is_allowed(toy, tmp_path):
    exps = _experiments(toy, ("fsdd",))
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ExperimentError, match=r"holds no known data set; looked for fsdd/, .*allow_generated=True"):
        DataPlan.build(exps, data_root=empty)
    with pytest.raises(ExperimentError, match="holds no known data set"):
        run_experiment(exps[0], output=tmp_path / "out", data_root=empty, progress=False)
    plan = DataPlan.build(exps, data_root=empty, allow_generated=True)
    assert plan.entry(exps[0]).variants == ("synthetic",)
    assert "none is in the data root" in plan.missing(exps[0])
    _msr_like(empty)  # a known set the experiment does not use: the root is accepted
    assert DataPlan.build(exps, data_root=empty).entry(exps[0]).sets == {}


def test_a_given_set_path_is_checked_against_its_layout(toy, tmp_path):
    exps = _experiments(toy, ("msr-action3d",))
    with pytest.raises(ExperimentError, match=r"does not hold 'msr-action3d' in its layout \(no aAA_sSS_eEE"):
        DataPlan.build(exps, {"msr-action3d": tmp_path})
    folder = _msr_like(tmp_path / "root")
    assert DataPlan.build(exps, {"msr-action3d": folder}).entry(exps[0]).sets == {"msr-action3d": folder.resolve()}
