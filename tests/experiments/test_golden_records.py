"""The smoke runs' records stay the same: at least one experiment per chapter, on generated data, against tests/golden/.

The experiments whose records are kept in ``tests/golden/`` (the golden set: the files there) are
run with their smoke preset (``SMOKE`` in the config), on generated data, and each record compared
with the kept one by :func:`mmconcepts.engine.compare_records`: every metric, interval, sample,
unit, split description and verdict (not the clock). A change meant to change results rewrites
them with ``make golden`` (and says so in its commit); any other difference is a regression.
Other experiments declare a smoke preset too, for their own tests; their records are not kept
(``make golden GOLDEN_IDS="ID ..."`` makes the experiments given the golden set).

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
#: The golden set: the experiments whose smoke records are kept (``make golden`` rewrites these).
GOLDEN_IDS = sorted(p.stem for p in GOLDEN.glob("*.json"))


def test_every_chapter_has_a_golden_smoke_experiment():
    assert {i.split("-")[0] for i in GOLDEN_IDS} == {"ch2", "ch3", "ch4", "ch5", "ch6", "ch7"}


def test_every_golden_record_is_of_a_smoke_experiment():
    assert set(GOLDEN_IDS) <= set(SMOKE_IDS), "a golden record of no registered experiment with a smoke preset"


@pytest.mark.slow
@pytest.mark.parametrize("exp_id", GOLDEN_IDS)
def test_smoke_record_is_the_golden_one(exp_id, tmp_path):
    record = run_experiment(exp_id, preset="smoke", output=tmp_path, variant="synthetic", workers=2, progress=False)
    assert record.status == "ok", record.message
    differences = compare_records(GOLDEN, tmp_path, ids=[exp_id], rtol=RTOL)
    assert not differences, "\n".join(str(d) for d in differences[:20])
