"""The ch2-nmf-recovery experiment: data generator and a quick run through the runner."""

from __future__ import annotations

import json

import numpy as np
import pytest

import dataclasses

from mmconcepts.experiments import RunContext, get, run_experiment
from mmconcepts.experiments.ch2.nmf_recovery import Config, compute, make_data, present, run_streams
from mmconcepts.report import write_report


def test_identifiable_generator_is_separable(rng):
    X, H = make_data("identifiable", 100, 30, 3, 0.05, rng)
    assert X.shape == (100, 30) and (X > 0).all()
    assert ((H > 0).sum(axis=0) == 1).all()  # every feature belongs to one atom only
    X2, H2 = make_data("nonidentifiable", 100, 30, 3, 0.05, np.random.default_rng(0))
    assert (H2 > 0).all()
    np.testing.assert_allclose(H.mean(axis=1), 1.0)


def test_generator_is_deterministic():
    a = make_data("identifiable", 20, 10, 2, 0.1, np.random.default_rng(3))
    b = make_data("identifiable", 20, 10, 2, 0.1, np.random.default_rng(3))
    np.testing.assert_array_equal(a[0], b[0])


SMOKE = Config.smoke()


def _draws(config):
    """The state of every draw of a run: data and learner per (kind, repeat), reference per repeat."""
    st, n = run_streams(config), config.n_repeats
    state = lambda *key: tuple(st.sequence(*key).generate_state(4).tolist())  # noqa: E731
    return {"data": [state("data", k, r) for k in range(2) for r in range(n)],
            "learner": [state("learner", k, r) for k in range(2) for r in range(n)],
            "reference": [state("reference", r) for r in range(n)]}


def test_learner_seed_alone_leaves_the_data_unchanged():
    a, b = _draws(SMOKE), _draws(dataclasses.replace(SMOKE, learner_seed=5))
    assert a["data"] == b["data"] and a["reference"] == b["reference"]
    assert a["learner"] != b["learner"]


def test_data_seed_alone_leaves_the_learner_unchanged():
    a = _draws(dataclasses.replace(SMOKE, seed=1, learner_seed=5))
    b = _draws(dataclasses.replace(SMOKE, seed=2, learner_seed=5))
    assert a["learner"] == b["learner"]
    assert a["data"] != b["data"] and a["reference"] != b["reference"]


def test_no_stream_is_shared():
    st = _draws(SMOKE)
    flat = st["data"] + st["learner"] + st["reference"]
    assert len(set(flat)) == len(flat) == 2 * 2 * SMOKE.n_repeats + SMOKE.n_repeats


def test_the_tasks_carry_the_run_streams_draws(monkeypatch):
    # compute hands each fit the draws of its kind and repeat (a swapped key would fail here)
    from mmconcepts.experiments.ch2 import nmf_recovery

    seen = []

    class Stop(Exception):
        pass

    def spy(task):
        seen.append(task)
        raise Stop

    monkeypatch.setattr(nmf_recovery, "_one_run", spy)
    with pytest.raises(Stop):
        compute(SMOKE, RunContext(show_progress=False))
    config, kind, repeat, *_, data_ss, learner_ss = seen[0]
    st = run_streams(SMOKE)
    k = ("identifiable", "nonidentifiable").index(kind)
    assert data_ss.generate_state(2).tolist() == st.sequence("data", k, repeat).generate_state(2).tolist()
    assert learner_ss.generate_state(2).tolist() == st.sequence("learner", k, repeat).generate_state(2).tolist()


def test_smoke_run_keeps_per_repeat_samples():
    cfg = Config.smoke()
    res = compute(cfg, RunContext(show_progress=False))
    res.validate()
    assert res.figures == {}  # numbers only
    s = res.samples
    for name in ("identifiable.beta_1.mu.distance", "nonidentifiable.median_distance", "random_dictionary.distance"):
        assert len(s[name]) == cfg.n_repeats
    for name in ("identifiable.beta_1.mu.distance", "random_dictionary.distance"):  # medians over the repeats
        assert res.metrics[name] == pytest.approx(np.median(s[name]))
    every_run = [v for k in s if k.startswith("nonidentifiable.beta_") for v in s[k]]  # every method, every repeat
    assert res.metrics["nonidentifiable.median_distance"] == pytest.approx(np.median(every_run))
    assert len(set(s["random_dictionary.distance"])) == cfg.n_repeats  # one draw per repeat


def test_smoke_run_keeps_samples_behind_every_claim():
    from mmconcepts.engine.rules import parse_rule
    from mmconcepts.engine.evidence import claim_verdict

    cfg = Config.smoke()
    res = compute(cfg, RunContext(show_progress=False))
    m, s = res.metrics, res.samples
    # the sanity check is a fact of the run (the largest increase over every MM run), decided without samples
    assert "mu_mm.max_relative_increase" not in s and m["mu_mm.max_relative_increase"] >= 0.0
    # every other sample is per repetition, of one declared unit: independent repetitions
    assert set(res.sample_units) == set(s) and set(res.sample_units.values()) == {"repeats"}
    assert res.units["repeats"].kind == "independent"
    assert all(len(v) == cfg.n_repeats for v in s.values())
    # worst cases over repeats: per-repeat samples, paired with the other per-repeat samples
    assert m["identifiable.max_distance"] == max(s["identifiable.max_distance"])
    methods = [k for k in m if k.startswith("identifiable.beta_") and k.endswith(".distance")]
    assert len(methods) > 1  # several betas and solvers: the worst method is a choice
    worst = max(methods, key=m.get)  # the method with the worst median distance: its per-repeat distances
    assert s["identifiable.worst_method_median_distance"] == s[worst]
    assert m["identifiable.worst_method_median_distance"] == pytest.approx(np.median(s[worst]))
    for claim in get("ch2-nmf-recovery").claims:
        v = claim_verdict(claim.rule, m, s, units=res.sample_units, unit_kinds=res.units)
        if claim.kind == "check":
            assert v.basis.startswith("reported numbers"), v.basis
            continue
        for name in parse_rule(claim.rule).metrics:
            assert len(s[name]) == cfg.n_repeats, name
        assert v.verdict == "inconclusive" and "fewer than 5 units" in v.tests[0].note  # two repeats decide nothing


def test_median_distances_are_per_repeat_medians_over_methods():
    cfg = Config.smoke()
    res = compute(cfg, RunContext(show_progress=False))
    s = res.samples
    for kind in ("identifiable", "nonidentifiable"):
        methods = [k for k in s if k.startswith(f"{kind}.beta_") and k.endswith(".distance")]
        heuristic = sum(b < 1 or b > 2 for b in cfg.betas)  # the heuristic MU exponent differs outside [1, 2]
        assert len(methods) == len(cfg.betas) + heuristic + len(cfg.pg_betas) > 2
        for rep in range(cfg.n_repeats):
            per_method = [s[name][rep] for name in methods]
            assert s[f"{kind}.median_distance"][rep] == pytest.approx(np.median(per_method))


def test_claims_declare_their_kind_and_source():
    import re

    claims = get("ch2-nmf-recovery").claims
    # chapter 2 runs no experiment in the thesis: Appendix A.2.3 states uniqueness, not how close a solver comes, so
    # the comparison of recovery on identifiable and non-identifiable data is ours
    assert [c.kind for c in claims] == ["check", "ours", "ours"]
    assert claims[1].rule == "identifiable.median_distance < nonidentifiable.median_distance"
    assert not re.search(r"\d", claims[1].rule)
    assert get("ch2-nmf-recovery").reference == {}  # the thesis gives no numbers here: no magnitude claim


def test_quick_preset_has_five_independent_repetitions():
    assert Config.quick().n_repeats >= 5 and Config.full().n_repeats >= 5


def test_uniqueness_claim_can_fail():
    """Recovered dictionaries closer to the truth on the non-identifiable data fail the thesis' statement."""
    from mmconcepts.engine.uncertainty import SampleUnit
    from mmconcepts.engine.evidence import claim_verdict

    rule = get("ch2-nmf-recovery").claims[1].rule
    ident = [0.05, 0.06, 0.04, 0.07, 0.05]
    nonident = [1e-4, 2e-4, 1e-4, 3e-4, 2e-4]
    m = {"identifiable.median_distance": 0.05, "nonidentifiable.median_distance": 2e-4}
    s = {"identifiable.median_distance": ident, "nonidentifiable.median_distance": nonident}
    units = {k: "repeats" for k in s}
    kinds = {"repeats": SampleUnit.seeds()}
    assert claim_verdict(rule, m, s, units=units, unit_kinds=kinds).verdict == "fails"
    m2 = {"identifiable.median_distance": 2e-4, "nonidentifiable.median_distance": 0.05}
    s2 = {"identifiable.median_distance": nonident, "nonidentifiable.median_distance": ident}
    assert claim_verdict(rule, m2, s2, units=units, unit_kinds=kinds).verdict == "holds"


def test_present_draws_the_computed_numbers():
    cfg = Config.smoke()
    res = compute(cfg, RunContext(show_progress=False))
    figures = present(res, cfg)
    assert set(figures) == {"loss_curves", "distances"}
    curves = res.figure_data["loss_curves"]
    names = [r["name"] for r in curves]  # the first identifiable repeat: one curve per method, in the table's order
    assert {(r["kind"], r["repeat"]) for r in curves} == {("identifiable", 0)} and len(set(names)) == len(names) > 1
    assert {f"identifiable.{n}.distance" for n in names} == {k for k in res.metrics
                                                            if k.startswith("identifiable.beta_")}
    lines = figures["loss_curves"].axes[0].lines
    assert len(lines) == len(curves)
    for line, curve in zip(lines, curves):
        its, h = curve["history"]
        assert h[0] == 1.0 and line.get_ydata().tolist() == h and line.get_xdata().tolist() == [i + 1 for i in its]
    bars = figures["distances"].axes[0].patches  # the identifiable bars, then the non-identifiable ones
    assert [b.get_height() for b in bars] == [res.metrics[f"{kind}.{n}.distance"]
                                              for kind in ("identifiable", "nonidentifiable") for n in names]


def test_max_relative_increase_known_answer():
    from mmconcepts.experiments.ch2.nmf_recovery import max_relative_increase

    assert max_relative_increase(np.array([10.0, 8.0, 8.5, 7.0, 7.2])) == pytest.approx(0.05)
    assert max_relative_increase(np.array([10.0, 8.0, 7.0])) == 0.0  # a decrease is not an increase
    assert np.isnan(max_relative_increase(np.array([10.0])))  # nothing recorded: nothing shown


def test_monotonicity_check_can_fail():
    """An MM run whose objective rises by 1e-6 of its start fails the check (a fact of the run: no samples)."""
    from mmconcepts.engine.evidence import claim_verdict

    check = get("ch2-nmf-recovery").claims[0]
    assert check.kind == "check"
    name = "mu_mm.max_relative_increase"
    assert claim_verdict(check.rule, {name: 0.0}).verdict == "holds"
    assert claim_verdict(check.rule, {name: 1e-6}).verdict == "fails"


@pytest.mark.slow
def test_quick_run_writes_result_and_report(tmp_path):
    record = run_experiment("ch2-nmf-recovery", preset="quick", output=tmp_path, workers=2, progress=False)
    assert record["status"] == "ok"
    on_disk = json.loads((tmp_path / "ch2-nmf-recovery.json").read_text())
    assert on_disk["config"]["n_samples"] == Config.quick().n_samples
    claims = {c["rule"].split()[0]: c for c in on_disk["claims"]}
    assert len(on_disk["samples"]["identifiable.median_distance"]) == Config.quick().n_repeats >= 5
    assert on_disk["units"]["repeats"]["kind"] == "independent"
    check = claims["mu_mm.max_relative_increase"]
    assert check["kind"] == "check" and check["verdict"] == "holds"  # the MM updates are monotone
    assert on_disk["metrics"]["mu_mm.max_relative_increase"] <= 1e-9
    assert "mu_mm.max_relative_increase" not in on_disk["samples"]
    recovery = claims["identifiable.median_distance"]
    assert recovery["kind"] == "ours" and recovery["verdict"] == "holds"
    assert on_disk["metrics"]["identifiable.median_distance"] < on_disk["metrics"]["random_dictionary.distance"] / 10
    for name in ("loss_curves", "distances"):
        assert (tmp_path / on_disk["figures"][name]).stat().st_size > 1000
    html, md = write_report(tmp_path)
    assert "ch2-nmf-recovery" in html.read_text() and "holds" in md.read_text()
    assert get("ch2-nmf-recovery").thesis_ref.startswith("Section 2.1")
