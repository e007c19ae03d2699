"""The independent random streams of one experiment run, all drawn from its seed in one way.

An experiment makes one :class:`Streams` from its seed (:func:`streams`) and asks it for
each draw by the stream's name and a key: ``st.rng("data", fold)`` (a generator),
``st.seed_for("learner", i)`` (an int seed, for a library's ``random_state``),
``st.seeds_for("reference", n)`` (one per fold or repetition), ``st.sub(r)`` (a whole set of
streams for repetition ``r``). Every draw is the :class:`numpy.random.SeedSequence` of the
seed with the spawn key ``(*sub-path, stream index, *key)``: it depends only on the seed, the
stream and the key, so adding a stream, a fold or a repetition never changes the others, and
no draw is an int turned back into a sequence.
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError

__all__ = ["STREAMS", "Streams", "streams"]

#: The streams' names, in the order of their spawn-key index (never reorder: it would change every draw).
STREAMS = ("data", "learner", "splits", "reference", "composition")

#: The spawn-key word that opens a sub-set of streams (:meth:`Streams.sub`); no stream has this index.
_SUB = 2**16

#: Int seeds are in ``[0, 2**31 - 1)``, so that any library takes them as ``random_state``.
_INT_SEEDS = 2**31 - 1


def _word(value: object, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or int(value) < 0:
        raise ParameterError(f"{what} must be a non-negative int; got {value!r}. "
                             "Key a draw by fold, repetition or item numbers.")
    return int(value)


@dataclass(frozen=True)
class Streams:
    """The independent random streams of one experiment run.

    ``data`` draws or composes the data, ``learner`` initialises the learners, ``splits``
    draws cross-validation folds and train/test parts, ``reference`` draws reference
    examples and random baselines, ``composition`` assembles derived test material (composed
    utterances, streams). The seed that drew the data never reaches a learner.

    Draw ``(name, *key)`` is ``numpy.random.SeedSequence(root, spawn_key=(*path, i, *key))``
    where ``i`` is the index of ``name`` in :data:`STREAMS` and ``root`` is :attr:`seed`
    (or the stream's own root, :meth:`rooted`). Without a key and a path this is
    ``SeedSequence(seed).spawn(5)[i]``.

    Parameters
    ----------
    seed : int
        The experiment's seed (``config.seed``).
    roots : tuple of (str, int), default=()
        Streams drawn from a seed of their own (e.g. a sensitivity check that changes the
        learners' initialisation and keeps the data); see :meth:`rooted`.
    path : tuple of int, default=()
        The spawn-key prefix of a sub-set of streams (see :meth:`sub`).

    Examples
    --------
    >>> st = streams(0)
    >>> st.seed_for("learner", 2) == st.seeds_for("learner", 3)[2]
    True
    >>> st.rng("data", 1).integers(10) == streams(0).rng("data", 1).integers(10)
    True
    """

    seed: int
    roots: tuple[tuple[str, int], ...] = ()
    path: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "seed", _word(self.seed, "The seed"))
        for name, root in self.roots:
            self._index(name)
            _word(root, f"The root seed of stream {name!r}")

    @staticmethod
    def _index(name: str) -> int:
        try:
            return STREAMS.index(name)
        except ValueError:
            raise ParameterError(f"The random stream must be one of {', '.join(STREAMS)}; got {name!r}.") from None

    def sequence(self, name: str, *key: int) -> np.random.SeedSequence:
        """The seed sequence of draw ``(name, *key)``.

        Parameters
        ----------
        name : {'data', 'learner', 'splits', 'reference', 'composition'}
        *key : int
            Non-negative ints naming the draw within the stream (fold, repetition, item).

        Returns
        -------
        numpy.random.SeedSequence
        """
        index = self._index(name)
        words = tuple(_word(k, "A stream key") for k in key)
        root = dict(self.roots).get(name, self.seed)
        return np.random.SeedSequence(root, spawn_key=(*self.path, index, *words))

    def rng(self, name: str, *key: int) -> np.random.Generator:
        """A generator for draw ``(name, *key)`` (:meth:`sequence`)."""
        return np.random.default_rng(self.sequence(name, *key))

    def seed_for(self, name: str, *key: int) -> int:
        """An int seed in ``[0, 2**31 - 1)`` for draw ``(name, *key)``, for a ``random_state``."""
        return int(self.sequence(name, *key).generate_state(1)[0] % _INT_SEEDS)

    def seeds_for(self, name: str, n: int, *key: int) -> list[int]:
        """``[seed_for(name, *key, i) for i in range(n)]``: one seed per fold or repetition."""
        return [self.seed_for(name, *key, i) for i in range(_word(n, "The number of seeds"))]

    def sub(self, *key: int) -> Streams:
        """All five streams again, for the part ``key`` of the run (a repetition, a world).

        Independent of this set's streams and of every other part's.
        """
        words = tuple(_word(k, "A sub-stream key") for k in key)
        return dataclasses.replace(self, path=(*self.path, _SUB, *words))

    def rooted(self, name: str, seed: int) -> Streams:
        """These streams with stream ``name`` drawn from ``seed`` instead (the others unchanged)."""
        self._index(name)
        roots = tuple((n, s) for n, s in self.roots if n != name) + ((name, _word(seed, "The root seed")),)
        return dataclasses.replace(self, roots=roots)


def streams(seed: int, *, learner_seed: int | None = None) -> Streams:
    """The independent random streams of an experiment run with seed ``seed``.

    Parameters
    ----------
    seed : int
        The experiment's seed (``config.seed``).
    learner_seed : int, optional
        Draw the ``learner`` stream from this seed instead (``config.learner_seed``: a check
        that changes the learners' initialisation alone, the data unchanged).

    Returns
    -------
    Streams
    """
    st = Streams(seed)
    return st if learner_seed is None else st.rooted("learner", learner_seed)
