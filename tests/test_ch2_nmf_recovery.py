"""The ch2-nmf-recovery experiment: data generator and a quick run through the runner."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mmconcepts.experiments import get, run_experiment
from mmconcepts.experiments.ch2_nmf_recovery import Config, make_data
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


@pytest.mark.slow
def test_quick_run_writes_result_and_report(tmp_path):
    record = run_experiment("ch2-nmf-recovery", preset="quick", output=tmp_path, workers=2, progress=False)
    assert record["status"] == "ok"
    on_disk = json.loads((tmp_path / "ch2-nmf-recovery.json").read_text())
    assert on_disk["config"]["n_samples"] == Config.quick().n_samples
    claims = {c["rule"].split()[0]: c["holds"] for c in on_disk["claims"]}
    assert claims["mu_mm.max_relative_increase"] is True  # the MM updates are monotone
    assert on_disk["metrics"]["mu_mm.max_relative_increase"] <= 1e-9
    assert on_disk["metrics"]["identifiable.median_distance"] < on_disk["metrics"]["random_dictionary.distance"] / 10
    for name in ("loss_curves", "distances"):
        assert (tmp_path / on_disk["figures"][name]).stat().st_size > 1000
    html, md = write_report(tmp_path)
    assert "ch2-nmf-recovery" in html.read_text() and "holds" in md.read_text()
    assert get("ch2-nmf-recovery").thesis_ref.startswith("Section 2.1")
