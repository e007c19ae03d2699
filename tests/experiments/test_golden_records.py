"""The smoke runs' records stay the same: at least one experiment per chapter, on generated data, against tests/golden/.

The experiments whose records are kept in ``tests/golden/`` (the golden set: the files there) are
run with their smoke preset (``SMOKE`` in the config), on generated data, and each record compared
with the kept one by :func:`mmconcepts.engine.compare_records`: every metric, interval, sample,
unit, split description and verdict (not the clock). A change meant to change results rewrites
them with ``make golden`` (and says so in its commit); any other difference is a regression.
Other experiments declare a smoke preset too, for their own tests; their records are not kept
(``make golden GOLDEN_IDS="ID ..."`` makes the experiments given the golden set).

Numbers are compared to a relative 1e-9. The records are written and checked in one numerical
environment (``tests/golden_platform.py``: OpenBLAS, numpy's loops and numba held to the x86-64-v3
level, in a child process), so that another CPU's kernels do not count; any larger difference, and
any verdict that changes, does. Onnxruntime, which speaks the generated speech, cannot be held: the
records of experiments on generated speech are compared on a CPU of the class that wrote them
(``tests/golden/PLATFORM``) and skipped, saying so, on another.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from mmconcepts.engine import all_experiments, compare_records, get

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import golden_platform  # noqa: E402

GOLDEN = Path(__file__).resolve().parents[1] / "golden"
RTOL = 1e-9

SMOKE_IDS = sorted(e.id for e in all_experiments() if e.has_smoke)
#: The golden set: the experiments whose smoke records are kept (``make golden`` rewrites these).
GOLDEN_IDS = sorted(p.stem for p in GOLDEN.glob("*.json"))


def test_every_chapter_has_a_golden_smoke_experiment():
    assert {i.split("-")[0] for i in GOLDEN_IDS} == {"ch2", "ch3", "ch4", "ch5", "ch6", "ch7"}


def test_every_golden_record_is_of_a_smoke_experiment():
    assert set(GOLDEN_IDS) <= set(SMOKE_IDS), "a golden record of no registered experiment with a smoke preset"


#: Data sets whose generated stand-in is speech spoken by onnxruntime (see the module docstring).
SPEECH_SETS = {"acorns", "fsdd", "audio"}


@pytest.fixture(scope="session")
def golden_cache(tmp_path_factory):
    """The cache folder of the golden runs: generated data made once, in the pinned environment."""
    return tmp_path_factory.mktemp("golden-cache")


@pytest.mark.slow
@pytest.mark.parametrize("exp_id", GOLDEN_IDS)
def test_smoke_record_is_the_golden_one(exp_id, tmp_path, golden_cache):
    ok, why = golden_platform.can_pin()
    if not ok:
        pytest.skip(why)
    written_on = golden_platform.CLASS_FILE.read_text().strip()
    on_speech = bool(SPEECH_SETS & set(get(exp_id).datasets))
    env = golden_platform.pinned_environ()
    env["MMCONCEPTS_DATA"] = str(golden_cache)
    run = subprocess.run([sys.executable, "-m", "mmconcepts", "run", exp_id, "--smoke", "--variant", "synthetic",
                          "--workers", "2", "--output", str(tmp_path), "-q"], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-3000:]
    if on_speech and golden_platform.cpu_class() != written_on:
        pytest.skip(f"{exp_id} runs on generated speech, which onnxruntime renders with this CPU's kernels "
                    f"({golden_platform.cpu_class()}); its golden record was written on {written_on}")
    differences = compare_records(GOLDEN, tmp_path, ids=[exp_id], rtol=RTOL)
    assert not differences, "\n".join(str(d) for d in differences[:20])
