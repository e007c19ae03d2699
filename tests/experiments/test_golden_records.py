"""The smoke runs' records stay the same: one experiment per chapter, on generated data, against tests/golden/.

Every experiment that declares a smoke preset (``SMOKE`` in its config) is run with it, on
generated data, and its record compared with the one kept in ``tests/golden/`` by
:func:`mmconcepts.engine.compare_records`: every metric, interval, sample, unit, split
description and verdict (not the clock). A change meant to change results rewrites them with
``make golden`` (and says so in its commit); any other difference is a regression.

Numbers are compared to a relative 1e-9, so that another CPU's floating-point rounding in
BLAS does not count; any larger difference, and any verdict that changes, does.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from mmconcepts.engine import all_experiments, compare_records, run_experiment

GOLDEN = Path(__file__).resolve().parents[1] / "golden"
RTOL = 1e-9

SMOKE_IDS = sorted(e.id for e in all_experiments() if e.has_smoke)


def test_every_chapter_has_a_smoke_experiment():
    assert {i.split("-")[0] for i in SMOKE_IDS} == {"ch2", "ch3", "ch4", "ch5", "ch6", "ch7"}


def test_every_smoke_experiment_has_a_golden_record():
    kept = {p.stem for p in GOLDEN.glob("*.json")}
    assert kept == set(SMOKE_IDS), "run `make golden` to write the golden records of the smoke experiments"


@pytest.mark.slow
@pytest.mark.parametrize("exp_id", SMOKE_IDS)
def test_smoke_record_is_the_golden_one(exp_id, tmp_path):
    record = run_experiment(exp_id, preset="smoke", output=tmp_path, variant="synthetic", workers=2, progress=False)
    assert record.status == "ok", record.message
    differences = compare_records(GOLDEN, tmp_path, ids=[exp_id], rtol=RTOL)
    assert not differences, "\n".join(str(d) for d in differences[:20])
