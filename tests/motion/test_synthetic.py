"""The synthetic choreography generator: files load back, determinism, data set structure."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest

from mmconcepts.errors import ParameterError
from mmconcepts.motion import (
    CHOREO1_LIMBS,
    CHOREO1_SMALL_GESTURES,
    JOINT_ANGLE_NAMES,
    joint_angles,
    load_choreo1,
    load_choreo2,
    orientation_angles,
)
from mmconcepts.motion.synthetic import (
    choreo1_label_sets,
    make_choreo1,
    make_choreo2,
    simulate_choreography,
    write_choreo1,
    write_choreo2,
)

J = {n: i for i, n in enumerate(JOINT_ANGLE_NAMES)}


def test_written_files_load_back_identical(tmp_path):
    path = write_choreo1(tmp_path, "mixed_full", random_state=4, n_records=5)
    ds = load_choreo1(path)
    labels = ds.labels
    again = write_choreo1(tmp_path / "again", "mixed_full", random_state=4, n_records=5)
    ds2 = load_choreo1(again)
    assert len(ds) == 5 and labels == ds2.labels
    for a, b in zip(ds, ds2):
        np.testing.assert_array_equal(a.positions, b.positions)  # same seed, same arrays
        assert a.positions.shape[1:] == (24, 3)
    # and the arrays in the NPZ are exactly those simulated
    from mmconcepts.motion.synthetic import DancerParams, _dancer_body, _record_rng
    rec = simulate_choreography(ds[0].labels, random_state=_record_rng(4, "mixed_full", 0),
                                body=_dancer_body(4, DancerParams()))
    np.testing.assert_array_equal(rec.positions, ds[0].positions)


def test_different_seeds_differ(tmp_path):
    a = load_choreo1(write_choreo1(tmp_path / "a", "primitive", random_state=1, n_records=3))
    b = load_choreo1(write_choreo1(tmp_path / "b", "primitive", random_state=2, n_records=3))
    assert not all(x.positions.shape == y.positions.shape and np.allclose(x.positions, y.positions)
                   for x, y in zip(a, b))


def test_choreo2_files(tmp_path):
    path = write_choreo2(tmp_path, random_state=0, n_records=6)
    ds = load_choreo2(path)
    assert len(ds) == 6 and all(len(r.labels) == 1 and 0 <= r.labels[0] < 10 for r in ds)
    r = ds[0]
    assert r.positions.shape[1:] == (15, 3) and r.orientations.shape[1:] == (15, 4)
    np.testing.assert_allclose(np.linalg.norm(r.orientations, axis=2), 1.0, atol=1e-5)
    ang = orientation_angles(r)
    assert ang.shape == (r.n_frames, 27) and np.isfinite(ang).all()


def test_gestures_move_the_right_limb():
    # gesture 5 (right arm raised from horizontal to vertical): the right shoulder
    # elevation spans ~90 -> ~170 deg while the left arm stays low
    a = np.degrees(joint_angles(simulate_choreography((5,), random_state=0, duration=6.0)))
    r, l = a[:, J["right_shoulder_elev"]], a[:, J["left_shoulder_elev"]]
    assert np.percentile(r, 5) < 110 and np.percentile(r, 95) > 140
    assert np.percentile(l, 95) < 40
    # walking (24): both knees bend, arms don't rise
    a = np.degrees(joint_angles(simulate_choreography((24,), random_state=0, duration=6.0)))
    assert np.percentile(a[:, J["left_knee_flex"]], 95) > 30 and np.percentile(a[:, J["right_knee_flex"]], 95) > 30
    # idle limbs still move a little (sway + noise) but not like a gesture
    idle = a[:, J["right_elbow_flex"]]
    assert 0.3 < idle.std() < 10


def test_incompatible_gestures_rejected():
    with pytest.raises(ParameterError):
        simulate_choreography((1, 2))  # two right-arm gestures
    with pytest.raises(ParameterError):
        simulate_choreography((19, 1))  # both arms + right arm


def test_label_sets_structure():
    prim = choreo1_label_sets("primitive", random_state=0)
    assert len(prim) == 326 and set(Counter(prim).values()) <= {6, 7} and len(set(prim)) == 47
    small = choreo1_label_sets("mixed_partial", random_state=0)
    assert len(small) == 137 and {g for s in small for g in s} == set(CHOREO1_SMALL_GESTURES)
    full = choreo1_label_sets("mixed_full", random_state=0)
    assert len(full) == 277 and len({g for s in full for g in s}) == 47
    c = Counter(full)
    assert abs(sum(v for v in c.values() if v == 1) / 277 - 0.6) < 0.01
    for s in small + full:
        limbs = sorted(CHOREO1_LIMBS[g] for g in s)
        assert limbs in (["both_arms", "legs"], ["left_arm", "legs", "right_arm"])


def test_cache_not_regenerated(tmp_path):
    ds = make_choreo1("mixed_partial", data_home=tmp_path, random_state=0, n_records=4)
    folder = tmp_path / "choreo1-synthetic" / "seed0" / "mixed_partial-n4"
    npz = folder / "mixed_partial.npz"
    stamp = npz.stat().st_mtime_ns
    ds2 = make_choreo1("mixed_partial", data_home=tmp_path, random_state=0, n_records=4)
    assert npz.stat().st_mtime_ns == stamp
    np.testing.assert_array_equal(ds[3].positions, ds2[3].positions)
    # an incomplete cache (its manifest missing) is rebuilt
    (folder / "manifest.json").unlink()
    ds3 = make_choreo1("mixed_partial", data_home=tmp_path, random_state=0, n_records=4)
    assert npz.stat().st_mtime_ns != stamp
    np.testing.assert_array_equal(ds[3].positions, ds3[3].positions)
    # another version of the generator is rebuilt too
    manifest = json.loads((folder / "manifest.json").read_text())
    (folder / "manifest.json").write_text(json.dumps({**manifest, "code": "mmconcepts.motion.synthetic/v0"}))
    stamp = npz.stat().st_mtime_ns
    make_choreo1("mixed_partial", data_home=tmp_path, random_state=0, n_records=4)
    assert npz.stat().st_mtime_ns != stamp
    assert sorted(p.name for p in tmp_path.iterdir()) == [".locks", "choreo1-synthetic"]
    with pytest.raises(ParameterError):
        make_choreo1("mixed_partial", data_home=tmp_path, random_state=np.random.default_rng(0))


def test_make_choreo2_small(tmp_path):
    ds = make_choreo2(data_home=tmp_path, random_state=0, n_records=10)
    assert sorted(r.labels[0] for r in ds) == list(range(10))


@pytest.mark.slow
def test_full_mixed_set_generation_and_features(tmp_path):
    import time

    from mmconcepts.motion import MotionHistograms

    ds = make_choreo1("mixed_full", data_home=tmp_path, random_state=0)
    assert len(ds) == 277
    t = time.perf_counter()
    H = MotionHistograms().fit_transform([joint_angles(r) for r in ds])
    assert time.perf_counter() - t < 10.0
    assert H.shape == (277, 16 * 16)


_BARRIER = None  # set before the worker processes are forked: both calls start together


def _generate_in_child(args):
    import os

    from mmconcepts.motion import synthetic

    which, home = args
    _BARRIER.wait(timeout=60)  # fails (BrokenBarrierError) unless two processes got here at once
    if which == "choreo1":
        ds = synthetic.make_choreo1("mixed_partial", data_home=home, random_state=0, n_records=4)
    else:
        ds = synthetic.make_choreo2(data_home=home, random_state=0, n_records=10)
    return [r.positions.sum() for r in ds], os.getpid()


@pytest.mark.parametrize("which", ["choreo1", "choreo2"])
def test_concurrent_processes_generate_the_set_once(tmp_path, monkeypatch, which):
    """Two processes sharing a cache folder (``reproduce --concurrent``) asking at once for a set not yet there:
    one writes it, the other waits and loads the same records (no clash in the folder being built)."""
    import multiprocessing
    import os
    import time
    from concurrent.futures import ProcessPoolExecutor

    from mmconcepts.motion import synthetic

    log = tmp_path / "log"
    log.mkdir()
    name = "write_choreo1" if which == "choreo1" else "write_choreo2"
    real = getattr(synthetic, name)

    def logged(*args, **kwargs):  # inherited by the forked workers
        (log / f"{os.getpid()}-{time.monotonic_ns()}").touch()
        time.sleep(0.5)
        return real(*args, **kwargs)

    monkeypatch.setattr(synthetic, name, logged)
    ctx = multiprocessing.get_context("fork")
    monkeypatch.setitem(globals(), "_BARRIER", ctx.Barrier(2))  # inherited by the forked workers
    with ProcessPoolExecutor(2, mp_context=ctx) as pool:
        (a, pa), (b, pb) = pool.map(_generate_in_child, [(which, str(tmp_path / "home"))] * 2)
    assert len(list(log.iterdir())) == 1
    assert a == b and pa != pb
