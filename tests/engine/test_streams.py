"""The run's random streams: one way to draw, keyed by stream and key, independent draws."""

import ast
import pathlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from mmconcepts.engine import STREAMS, Streams, streams
from mmconcepts.errors import ParameterError

KEYS = hst.lists(hst.integers(0, 50), max_size=3).map(tuple)
NAMES = hst.sampled_from(STREAMS)


def _state(seq: np.random.SeedSequence) -> tuple:
    return tuple(seq.generate_state(4).tolist())


def test_a_draw_is_the_seed_sequence_of_the_seed_with_the_stream_and_key_as_spawn_key():
    # the known answer: numpy's own spawn tree of the seed
    st = streams(123)
    kids = np.random.SeedSequence(123).spawn(len(STREAMS))
    for i, name in enumerate(STREAMS):
        assert _state(st.sequence(name)) == _state(kids[i])
        assert st.seed_for(name) == int(kids[i].generate_state(1)[0] % (2**31 - 1))
        grand = np.random.SeedSequence(123).spawn(len(STREAMS))[i].spawn(3)[2]
        assert _state(st.sequence(name, 2)) == _state(grand)  # key i: the i-th child of the stream
        a = st.rng(name, 2).integers(2**62, size=3)
        np.testing.assert_array_equal(a, np.random.default_rng(grand).integers(2**62, size=3))


@settings(max_examples=200, deadline=None)
@given(seed=hst.integers(0, 2**40), a=hst.tuples(NAMES, KEYS), b=hst.tuples(NAMES, KEYS),
       sub_a=KEYS, sub_b=KEYS)
def test_distinct_draws_are_distinct_and_equal_draws_equal(seed, a, b, sub_a, sub_b):
    st = streams(seed)
    x = (st.sub(*sub_a) if sub_a else st).sequence(a[0], *a[1])
    y = (st.sub(*sub_b) if sub_b else st).sequence(b[0], *b[1])
    same = (a == b) and (sub_a == sub_b)
    assert (_state(x) == _state(y)) == same


@pytest.mark.parametrize("part, name, key, other_name, other_key", [
    ((0,), "data", (), "data", (0,)),  # a part's draw is not the stream's draw with the part as key
    ((1,), "data", (2,), "learner", (0, 2)),
    ((0,), "learner", (), "data", (1,)),
])
def test_a_part_never_meets_a_keyed_draw(part, name, key, other_name, other_key):
    st = streams(0)
    assert _state(st.sub(*part).sequence(name, *key)) != _state(st.sequence(other_name, *other_key))


@settings(max_examples=100, deadline=None)
@given(seed=hst.integers(0, 2**31), n=hst.integers(1, 20), key=KEYS, name=NAMES)
def test_seeds_for_is_seed_for_per_index_and_a_prefix_does_not_depend_on_n(seed, n, key, name):
    st = streams(seed)
    seeds = st.seeds_for(name, n, *key)
    assert seeds == [st.seed_for(name, *key, i) for i in range(n)]
    assert st.seeds_for(name, n + 3, *key)[:n] == seeds
    assert all(0 <= s < 2**31 - 1 for s in seeds)


def test_rooted_changes_one_stream_alone():
    st, other = streams(5), streams(5, learner_seed=9)
    assert other == st.rooted("learner", 9)
    for name in STREAMS:
        same = _state(st.sequence(name, 1, 2)) == _state(other.sequence(name, 1, 2))
        assert same == (name != "learner"), name
    # the rooted stream is the stream of the other seed
    assert _state(other.sequence("learner", 3)) == _state(streams(9).sequence("learner", 3))
    assert _state(other.sub(1).sequence("learner")) == _state(streams(9).sub(1).sequence("learner"))
    # the data seed alone changes the data, not the rooted learner
    third = streams(6, learner_seed=9)
    assert _state(third.sequence("learner", 0)) == _state(other.sequence("learner", 0))
    assert _state(third.sequence("data", 0)) != _state(other.sequence("data", 0))


def test_streams_pickle_and_compare_by_value():
    import pickle

    st = streams(3).rooted("learner", 4).sub(2)
    back = pickle.loads(pickle.dumps(st))
    assert back == st and back.seed_for("learner", 1) == st.seed_for("learner", 1)


@pytest.mark.parametrize("call", [
    lambda: streams(-1),
    lambda: streams(1.5),
    lambda: streams(True),
    lambda: streams(0).rng("noise"),
    lambda: streams(0).seed_for("data", -1),
    lambda: streams(0).seed_for("data", 1.0),
    lambda: streams(0).seeds_for("data", -2),
    lambda: streams(0).sub("a"),
    lambda: streams(0).rooted("nothing", 3),
    lambda: Streams(0, roots=(("data", -3),)),
])
def test_bad_arguments_say_what_was_expected(call):
    with pytest.raises(ParameterError, match="must be"):
        call()


def test_no_experiment_derives_seeds_by_hand():
    # every experiment draws through Streams: no SeedSequence, spawn or modulo of a seed in the chapters
    root = pathlib.Path(__import__("mmconcepts.experiments", fromlist=["x"]).__file__).parent
    offenders = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            func = node.func if isinstance(node, ast.Call) else None
            if isinstance(func, ast.Attribute) and func.attr in ("SeedSequence", "spawn", "generate_state"):
                offenders.append(f"{path.relative_to(root)}:{node.lineno} {func.attr}")
            if isinstance(node, ast.Name) and node.id in ("child_seeds", "sub_seed"):
                offenders.append(f"{path.relative_to(root)}:{node.lineno} {node.id}")
    assert offenders == []
