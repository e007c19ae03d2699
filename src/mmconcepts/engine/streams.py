"""The independent random streams of one experiment run, spawned from its seed."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["Streams", "streams", "child_seeds"]


class Streams(NamedTuple):
    """Seeds (ints) of the independent random streams of one experiment run.

    ``data`` draws or composes the data, ``learner`` initialises the learners, ``splits``
    draws cross-validation folds and train/test parts, ``reference`` draws reference
    examples and random baselines, ``composition`` assembles derived test material (composed
    utterances, streams). The seed that drew the data never reaches a learner.
    """

    data: int
    learner: int
    splits: int
    reference: int
    composition: int = 0


def child_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent seeds spawned from ``seed`` (one per fold or repetition)."""
    return [int(k.generate_state(1, dtype=np.uint32)[0]) for k in np.random.SeedSequence(int(seed)).spawn(n)]


def streams(seed: int) -> Streams:
    """Spawn the independent streams of an experiment from its seed.

    ``numpy.random.SeedSequence(seed).spawn(5)``, each child turned into an int seed in
    ``[0, 2**31 - 1)`` (so that it can be passed as any library's ``random_state``). A
    child depends only on ``seed`` and its index, so adding a stream never changes the
    others.

    Parameters
    ----------
    seed : int
        The experiment's seed (``config.seed``).

    Returns
    -------
    Streams
    """
    kids = np.random.SeedSequence(int(seed)).spawn(len(Streams._fields))
    return Streams(*(int(k.generate_state(1)[0] % (2**31 - 1)) for k in kids))


