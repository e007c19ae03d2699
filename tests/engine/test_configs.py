"""The experiments' config presets (one PresetConfig instead of a copy of quick/full per experiment).

The presets' values are not pinned here (no tests that only pin presets):
when the presets moved into PresetConfig (commit 8d03b04) every experiment's quick and
full config was compared with the one returned before (``dataclasses.asdict`` repr: fields,
order, values and types) and found identical. These tests check the mechanism.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import pkgutil
import re

from pathlib import Path

import pytest

import mmconcepts.experiments as experiments
from mmconcepts.errors import ParameterError
from mmconcepts.engine.config import PresetConfig

#: Every experiment module of the chapters (each has a Config), found as the registry finds them.
MODULES = sorted(m.name.removeprefix("mmconcepts.experiments.")
                 for m in pkgutil.walk_packages(experiments.__path__, prefix="mmconcepts.experiments.")
                 if re.fullmatch(r"mmconcepts\.experiments\.ch\d\.\w+", m.name) and not m.name.endswith(".protocol"))


@pytest.mark.parametrize("name", MODULES)
def test_every_config_declares_its_presets_as_changes_from_its_defaults(name):
    config_cls = importlib.import_module(f"mmconcepts.experiments.{name}").Config
    assert issubclass(config_cls, PresetConfig) and config_cls.__dataclass_params__.frozen
    defaults = dataclasses.asdict(config_cls())
    for preset in ("quick", "full"):
        config = getattr(config_cls, preset)()
        assert type(config) is config_cls and config == config_cls.preset(preset)
        declared = dict(getattr(config_cls, preset.upper()))
        # the preset is the defaults with exactly the declared values in place
        assert dataclasses.asdict(config) == {**defaults, **declared}
    assert config_cls.quick() != config_cls.full()  # a quick preset that is the full one would be no preset


def test_presets_are_class_data_not_fields():
    from mmconcepts.experiments.ch3.choreography import Config as Choreography
    from mmconcepts.experiments.ch3.unseen import Config as Unseen

    assert {"QUICK", "FULL"}.isdisjoint(f.name for f in dataclasses.fields(Unseen))
    assert "QUICK" not in dataclasses.asdict(Unseen.quick())
    # a subclass extends its base's presets: ch3-unseen's quick preset is ch3-choreography's without the sensitivity
    assert Unseen.quick() == Unseen(**dataclasses.asdict(dataclasses.replace(Choreography.quick(), n_folds=5)))
    assert Unseen.full() == Unseen(**dataclasses.asdict(Choreography.full()))


def test_a_preset_naming_no_field_or_no_preset_is_an_error():
    @dataclasses.dataclass(frozen=True)
    class Config(PresetConfig):
        n: int = 3
        seed: int = 0

        QUICK = {"n": 1, "n_typo": 2}

    assert Config.full() == Config()
    with pytest.raises(ParameterError, match=r"Config.QUICK sets \['n_typo'\], which are not fields"):
        Config.quick()
    with pytest.raises(ParameterError, match="preset must be one of quick, full, smoke; got 'fast'"):
        Config.preset("fast")


def test_the_smoke_preset_is_the_quick_one_changed_by_smoke():
    from mmconcepts.engine import Experiment, all_experiments

    exps = all_experiments()
    assert exps and [e.id for e in exps if not e.has_smoke] == []  # one declared smoke preset per experiment
    for exp in exps:
        cls = exp.config_cls
        assert dataclasses.asdict(cls.smoke()) == {**dataclasses.asdict(cls()), **cls.QUICK, **cls.SMOKE}, exp.id
        assert cls.smoke() != cls.quick(), exp.id
        assert exp.make_config("smoke", seed=4).seed == 4

    @dataclasses.dataclass(frozen=True)
    class Plain(PresetConfig):  # no SMOKE: no smoke preset
        n: int = 3
        seed: int = 0

        QUICK = {"n": 1}

    plain = Experiment(id="plain", title="Plain", thesis_ref="none", config_cls=Plain, run=lambda config, ctx: None)
    assert not plain.has_smoke
    with pytest.raises(ParameterError, match="no smoke preset"):
        plain.make_config("smoke")


def test_a_smoke_config_is_recorded_under_the_smoke_preset():
    from mmconcepts.engine import get
    from mmconcepts.engine.runner import config_and_preset

    exp = get("ch2-nmf-recovery")
    assert config_and_preset(exp, None, exp.config_cls.smoke(), None)[1] == "smoke"
    assert config_and_preset(exp, "smoke", None, 3)[1] == "smoke"
    assert config_and_preset(exp, None, dataclasses.replace(exp.config_cls.smoke(), n_repeats=3), None)[1] == "custom"
    golden = Path(__file__).resolve().parents[1] / "golden"
    assert {json.loads(p.read_text())["preset"] for p in golden.glob("*.json")} == {"smoke"}
