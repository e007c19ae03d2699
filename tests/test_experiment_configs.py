"""The experiments' config presets (issue 13: one PresetConfig instead of 17 copies of quick/full).

``PRESETS`` is what every experiment's ``Config.quick()`` and ``Config.full()`` returned
before the presets were declared as data (captured with ``dataclasses.asdict`` at commit
435265f, before the change): every field, its order, value and type must stay the same,
since the config is part of each result record and of its key.
"""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil

import pytest

import mmconcepts.experiments as experiments
from mmconcepts.errors import ParameterError
from mmconcepts.experiments.config import PresetConfig

PRESETS = {
    "ch2_nmf_recovery.quick": dict(
        n_samples=300, n_features=60, n_components=5, noise=0.05, betas=(0.0, 0.5, 1.0, 1.5, 2.0, 2.5),
        pg_betas=(1.0, 2.0), max_iter=400, pg_max_iter=400, n_repeats=3, learner_seed=None, seed=0),
    "ch2_nmf_recovery.full": dict(
        n_samples=1000, n_features=200, n_components=10, noise=0.05, betas=(0.0, 0.5, 1.0, 1.5, 2.0, 2.5),
        pg_betas=(1.0, 2.0), max_iter=2000, pg_max_iter=1000, n_repeats=5, learner_seed=None, seed=0),
    "ch3_choreography.quick": dict(
        n_folds=10, n_components=150, max_iter=100, inner_cv=3, data='joint', method='vq', n_bins=16, delay=3,
        assignment='soft', n_records_partial=137, n_records_full=277, sensitivity=True, seed=0),
    "ch3_choreography.full": dict(
        n_folds=None, n_components=150, max_iter=200, inner_cv=5, data='joint', method='vq', n_bins=16, delay=3,
        assignment='soft', n_records_partial=137, n_records_full=277, sensitivity=True, seed=0),
    "ch3_combinations.quick": dict(
        n_folds=10, n_components=150, max_iter=100, inner_cv=3, data='joint', method='vq', n_bins=16, delay=3,
        assignment='soft', n_records_partial=137, n_records_full=277, sensitivity=True, seed=0),
    "ch3_combinations.full": dict(
        n_folds=None, n_components=150, max_iter=200, inner_cv=5, data='joint', method='vq', n_bins=16, delay=3,
        assignment='soft', n_records_partial=137, n_records_full=277, sensitivity=True, seed=0),
    "ch3_msr_action3d.quick": dict(
        n_folds_single=3, n_folds_mixed=5, n_components=150, max_iter=100, inner_cv=3, n_records=None, seed=0),
    "ch3_msr_action3d.full": dict(
        n_folds_single=10, n_folds_mixed=10, n_components=150, max_iter=200, inner_cv=5, n_records=None, seed=0),
    "ch3_representations.quick": dict(
        bins=(4, 9, 16), delays=(1, 3, 10), bins_delay=3, kde_bins=15, n_folds=3, n_components=150, max_iter=100,
        n_records=326, seed=0),
    "ch3_representations.full": dict(
        bins=(4, 9, 16, 25, 36, 49), delays=(1, 2, 3, 5, 8, 12, 20), bins_delay=3, kde_bins=15, n_folds=10,
        n_components=150, max_iter=200, n_records=326, seed=0),
    "ch3_threshold.quick": dict(
        n_folds=10, n_components=150, max_iter=100, inner_cv=3, data='joint', method='vq', n_bins=16, delay=3,
        assignment='soft', n_records_partial=137, n_records_full=277, sensitivity=True, seed=0),
    "ch3_threshold.full": dict(
        n_folds=None, n_components=150, max_iter=200, inner_cv=5, data='joint', method='vq', n_bins=16, delay=3,
        assignment='soft', n_records_partial=137, n_records_full=277, sensitivity=True, seed=0),
    "ch3_unseen.quick": dict(
        n_folds=10, n_components=150, max_iter=100, inner_cv=3, data='joint', method='vq', n_bins=16, delay=3,
        assignment='soft', n_records_partial=137, n_records_full=277, sensitivity=False, seed=0),
    "ch3_unseen.full": dict(
        n_folds=None, n_components=150, max_iter=200, inner_cv=5, data='joint', method='vq', n_bins=16, delay=3,
        assignment='soft', n_records_partial=137, n_records_full=277, sensitivity=True, seed=0),
    "ch4_factorial_irl.quick": dict(
        grid_size=10, success_prob=0.7, discount=0.9, n_primitives=5, n_tasks=30, n_demos=10, demo_length=10,
        n_test_tasks=30, n_example_features=15, beta=1.0, flat_max_iter=50, factorial_max_iter=200, inner_steps=5,
        demos_curve=(2, 10), tasks_curve=(10, 30), seed=0),
    "ch4_factorial_irl.full": dict(
        grid_size=10, success_prob=0.7, discount=0.9, n_primitives=5, n_tasks=100, n_demos=10, demo_length=10,
        n_test_tasks=100, n_example_features=15, beta=1.0, flat_max_iter=100, factorial_max_iter=200, inner_steps=5,
        demos_curve=(1, 2, 5, 10), tasks_curve=(10, 20, 50, 100), seed=0),
    "ch4_inverse_control.quick": dict(
        grid_size=5, n_primitives=6, n_train=200, n_test=50, n_steps=100, dt=0.01, lam=1.0, max_iter=60,
        supervised_max_iter=2000, d_solver='cg', sensor_noise=0.0001, dynamics='euler', n_repeats=3,
        sensitivity=True, learner_seed=None, seed=0),
    "ch4_inverse_control.full": dict(
        grid_size=5, n_primitives=6, n_train=200, n_test=100, n_steps=100, dt=0.01, lam=1.0, max_iter=200,
        supervised_max_iter=2000, d_solver='cg', sensor_noise=0.0001, dynamics='euler', n_repeats=5,
        sensitivity=True, learner_seed=None, seed=0),
    "ch5_incremental.quick": dict(
        n_per_speaker=250, n_train=200, n_test=50, session=50, multi_session=100, n_mfcc=13, window_ms=80.0,
        metric='dtw', backtrack=4, seed=0),
    "ch5_incremental.full": dict(
        n_per_speaker=1000, n_train=900, n_test=100, session=100, multi_session=200, n_mfcc=13, window_ms=80.0,
        metric='dtw', backtrack=4, seed=0),
    "ch5_nmf_keywords.quick": dict(
        n_per_speaker=250, speaker_index=0, n_folds=5, hac_mfcc=22, n_components=50, max_iter=50, voting_mfcc=13,
        window_ms=80.0, n_composed_per_fold=60, min_words=2, max_words=4, min_pause_s=0.1, max_pause_s=0.3,
        threshold_cv=3, seed=0),
    "ch5_nmf_keywords.full": dict(
        n_per_speaker=1000, speaker_index=0, n_folds=10, hac_mfcc=22, n_components=50, max_iter=50, voting_mfcc=13,
        window_ms=80.0, n_composed_per_fold=100, min_words=2, max_words=4, min_pause_s=0.1, max_pause_s=0.3,
        threshold_cv=5, seed=0),
    "ch5_tree.quick": dict(
        n_per_speaker=250, n_train_utterances=400, n_queries=400, n_blocks=10, n_mfcc=13, window_ms=80.0,
        metric='dtw', seed=0),
    "ch5_tree.full": dict(
        n_per_speaker=1000, n_train_utterances=3600, n_queries=2000, n_blocks=10, n_mfcc=13, window_ms=80.0,
        metric='dtw', seed=0),
    "ch6_concepts.quick": dict(
        n_per_speaker=250, n_motion=250, k=15, n_iter=50, n_bins=10, motion_bins=25, n_repeats=3, seed=0),
    "ch6_concepts.full": dict(
        n_per_speaker=1000, n_motion=1100, k=15, n_iter=50, n_bins=10, motion_bins=25, n_repeats=10, seed=0),
    "ch6_image_features.quick": dict(
        n_per_speaker=250, n_views=24, n_repeats=3, k=50, n_iter=50, seed=0),
    "ch6_image_features.full": dict(
        n_per_speaker=1000, n_views=41, n_repeats=10, k=50, n_iter=50, seed=0),
    "ch6_modalities.quick": dict(
        n_per_speaker=250, n_motion=250, n_views=24, n_repeats=3, k=50, k_sweep=(10, 50), n_iter=50, motion_bins=25,
        seed=0),
    "ch6_modalities.full": dict(
        n_per_speaker=1000, n_motion=1100, n_views=41, n_repeats=20, k=50, k_sweep=(5, 10, 20, 50, 100, 200),
        n_iter=50, motion_bins=25, seed=0),
    "ch6_motion_sound.quick": dict(
        n_per_speaker=250, n_motion=250, n_folds=5, k=50, n_iter=50, motion_bins=25, seed=0),
    "ch6_motion_sound.full": dict(
        n_per_speaker=1000, n_motion=1100, n_folds=10, k=50, n_iter=50, motion_bins=25, seed=0),
    "ch6_sliding.quick": dict(
        n_per_speaker=250, n_views=24, widths=(0.1, 0.3, 1.0), shift=0.5, frame_rate=4.0, fixed_width=0.3,
        probe_shift=0.05, k=50, n_iter=50, n_repeats=1, n_test_folds=5, seed=0),
    "ch6_sliding.full": dict(
        n_per_speaker=1000, n_views=41, widths=(0.05, 0.1, 0.2, 0.3, 0.5, 1.0), shift=0.5, frame_rate=4.0,
        fixed_width=0.3, probe_shift=0.05, k=50, n_iter=50, n_repeats=3, n_test_folds=5, seed=0),
}

MODULES = sorted(m.name for m in pkgutil.iter_modules(experiments.__path__) if m.name.startswith("ch"))


def test_every_experiment_module_is_pinned():
    assert MODULES and sorted({k.rsplit(".", 1)[0] for k in PRESETS}) == MODULES


@pytest.mark.parametrize("key", sorted(PRESETS))
def test_presets_are_unchanged(key):
    name, preset = key.rsplit(".", 1)
    config_cls = importlib.import_module(f"mmconcepts.experiments.{name}").Config
    config = getattr(config_cls, preset)()
    assert type(config) is config_cls and isinstance(config, PresetConfig)
    # repr tells 80 from 80.0 and a tuple from a list; the order of the fields is kept too
    assert repr(dataclasses.asdict(config)) == repr(PRESETS[key])
    assert config == config_cls(**PRESETS[key]) and config == config_cls.preset(preset)
    assert config_cls.__dataclass_params__.frozen


def test_presets_are_class_data_not_fields():
    from mmconcepts.experiments.ch3_choreography import Config as Choreography
    from mmconcepts.experiments.ch3_unseen import Config as Unseen

    assert {"QUICK", "FULL"}.isdisjoint(f.name for f in dataclasses.fields(Unseen))
    assert "QUICK" not in dataclasses.asdict(Unseen.quick())
    # a subclass extends its base's presets: ch3-unseen's quick preset is ch3-choreography's without the sensitivity
    assert Unseen.quick() == Unseen(**dataclasses.asdict(dataclasses.replace(Choreography.quick(), sensitivity=False)))
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
    with pytest.raises(ParameterError, match="preset must be one of quick, full; got 'fast'"):
        Config.preset("fast")
