"""Figures drawn again from what a run kept (engine/redraw.py, ``mmconcepts report --redraw``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.image import imread

from mmconcepts.cli import main
from mmconcepts.engine import (
    Experiment,
    PresetConfig,
    Result,
    RunContext,
    get,
    redraw_figures,
    register,
    run_experiment,
    unregister,
)
from mmconcepts.engine.outputs import FIGURE_DATA
from mmconcepts.errors import ExperimentError


@dataclasses.dataclass(frozen=True)
class Config(PresetConfig):
    n: int = 6
    widths: tuple = (1.0, 2.0)
    seed: int = 0

    QUICK = {"n": 5}


def _compute(config: Config, ctx: RunContext) -> Result:
    curve = np.cumsum(np.random.default_rng(config.seed).random(config.n))
    return Result(metrics={"end": float(curve[-1])}, figure_data={"curve": curve, "label": "cumulative"})


def _present(result: Result, config: Config) -> dict[str, Figure]:
    assert isinstance(config.widths, tuple)  # the record's JSON list comes back as the field's tuple
    fig = Figure(figsize=(3, 2))
    fig.subplots().plot(result.figure_data["curve"], label=result.figure_data["label"], lw=config.widths[0])
    return {"curve": fig}


def _present_two(result: Result, config: Config) -> dict[str, Figure]:
    figs = _present(result, config)
    fig = Figure(figsize=(3, 2))
    fig.subplots().bar([0], [result.metrics["end"]])
    return {**figs, "end": fig}


def _declare(present) -> Experiment:
    return Experiment(id="toy-redraw", title="Toy redraw", thesis_ref="-", config_cls=Config, compute=_compute,
                      present=present)


@pytest.fixture
def toy_redraw(registry):
    exp = register(_declare(_present))
    yield exp
    unregister("toy-redraw")


def test_redrawn_figures_are_the_figures_the_run_drew(toy_redraw, tmp_path):
    record = run_experiment("toy-redraw", output=tmp_path, progress=False)
    assert record.status == "ok" and (tmp_path / "toy-redraw" / FIGURE_DATA).is_file()
    png = tmp_path / "toy-redraw" / "curve.png"
    before = imread(png)
    png.unlink()
    assert redraw_figures(tmp_path) == {"toy-redraw.json": ["curve"]}
    np.testing.assert_array_equal(imread(png), before)


def test_a_new_present_is_drawn_and_listed_in_the_record(toy_redraw, tmp_path):
    run_experiment("toy-redraw", output=tmp_path, progress=False)
    unregister("toy-redraw")
    register(_declare(_present_two))
    assert main(["report", str(tmp_path), "--redraw", "--only", "toy-redraw"]) == 0
    record = run_experiment("toy-redraw", output=tmp_path, progress=False)  # up to date: read back, not recomputed
    assert sorted(record.figures) == ["curve", "end"] and (tmp_path / "toy-redraw" / "end.png").is_file()



def test_an_edited_record_is_not_redrawn_into_a_matching_digest(toy_redraw, tmp_path):
    import json

    from mmconcepts.engine import load_record

    run_experiment("toy-redraw", output=tmp_path, progress=False)
    path = tmp_path / "toy-redraw.json"
    record = json.loads(path.read_text())
    record["metrics"]["end"] = 2.0
    path.write_text(json.dumps(record))
    unregister("toy-redraw")
    register(_declare(_present_two))  # a redraw would rewrite the record (another figure)
    assert redraw_figures(tmp_path) == {}
    assert load_record(path).digest_ok is False and path.read_text() == json.dumps(record)

def test_records_without_kept_data_are_left_alone_and_damage_is_an_error(toy_redraw, tmp_path):
    run_experiment("toy-redraw", output=tmp_path, progress=False)
    kept = tmp_path / "toy-redraw" / FIGURE_DATA
    kept.write_bytes(b"not an archive")
    with pytest.raises(ExperimentError, match="damaged"):
        redraw_figures(tmp_path)
    kept.unlink()
    assert redraw_figures(tmp_path) == {}
    with pytest.raises(ExperimentError, match="no results folder"):
        redraw_figures(tmp_path / "nowhere")


def test_figure_data_the_codec_cannot_keep_is_not_kept(registry, tmp_path):
    def compute(config, ctx):
        return Result(metrics={"end": 1.0}, figure_data={"odd": {1, 2}})

    register(Experiment(id="toy-odd", title="Odd", thesis_ref="-", config_cls=Config, compute=compute,
                        present=lambda result, config: {"f": Figure()}))
    try:
        record = run_experiment("toy-odd", output=tmp_path, progress=False)
    finally:
        unregister("toy-odd")
    assert record.status == "ok" and record.figures and not (tmp_path / "toy-odd" / FIGURE_DATA).exists()


@pytest.mark.slow
def test_a_thesis_experiment_is_redrawn_to_the_pixel(tmp_path):
    exp = get("ch2-nmf-recovery")
    record = run_experiment(exp.id, preset="smoke", output=tmp_path, variant="synthetic", progress=False)
    pngs = {name: imread(tmp_path / path) for name, path in record.figures.items()}
    assert pngs
    for name in pngs:
        (tmp_path / record.figures[name]).unlink()
    assert redraw_figures(tmp_path)[f"{exp.id}.json"] == sorted(pngs)
    for name, pixels in pngs.items():
        np.testing.assert_array_equal(imread(tmp_path / record.figures[name]), pixels)
