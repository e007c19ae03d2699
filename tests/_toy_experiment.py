"""Toy experiments for the framework tests (not part of the library).

``toy-mean`` is a complete experiment: the mean of seeded uniform numbers, with quick and
full presets, a table, a figure, a digit-led metric name, a reference value and two
claims, one that holds and one that does not. ``toy-data`` reads a number from a file
given with ``--data toyfile=PATH``. ``FAIL``, ``SKIP`` and ``make_experiment`` are for
tests to register themselves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure

from mmconcepts.experiments import Claim, Experiment, ExperimentSkipped, Result, RunContext, Table, register

#: Seeds of the configs ``run_toy`` was called with, to tell a rerun from a skip.
CALLS: list[int] = []


@dataclass(frozen=True)
class ToyConfig:
    n: int = 1000
    n_chunks: int = 4
    sizes: tuple[int, ...] = (1, 2, 3)
    seed: int = 0

    @classmethod
    def quick(cls) -> "ToyConfig":
        return cls(n=400)

    @classmethod
    def full(cls) -> "ToyConfig":
        return cls(n=4000, n_chunks=8)


def run_toy(config: ToyConfig, ctx: RunContext) -> Result:
    CALLS.append(config.seed)
    x = np.random.default_rng(config.seed).random(config.n)
    chunk_means = ctx.parallel(np.mean, np.array_split(x, config.n_chunks), desc="chunks")
    fig = Figure(figsize=(3, 2))
    ax = fig.subplots()
    ax.hist(x, bins=20)
    ax.set_title("values")
    quantiles = Table(
        title="Quantiles of the sample",
        columns=["q", "value"],
        rows=[[q, float(np.quantile(x, q))] for q in (0.25, 0.5, 0.75)],
        note="Uniform on [0, 1): expect q.",
    )
    return Result(
        metrics={
            "mean": float(x.mean()),
            "std": float(x.std()),
            "1.chunk_mean": float(chunk_means[0]),
            "n": config.n,
        },
        tables={"quantiles": quantiles},
        figures={"hist": fig},
        notes=["A <toy> experiment & nothing more."],
        extra={"chunk_means": np.asarray(chunk_means), "sizes": config.sizes},
    )


TOY = register(
    Experiment(
        id="toy-mean",
        title="Toy: the mean of uniform numbers",
        thesis_ref="Section 0.0 (test fixture)",
        config_cls=ToyConfig,
        run=run_toy,
        reference={"mean": 0.5, "std": 0.2887},
        claims=[
            Claim("The sample mean is close to one half.", "abs(mean - 0.5) < 0.1", kind="thesis",
                  source="Section 0.0 (line 1)"),
            Claim("The sample mean exceeds one (false on purpose).", "mean > 1"),
            Claim("The sample mean against the thesis' {thesis:mean}.", "mean", kind="magnitude",
                  source="Table 0.0 (line 2)"),
        ],
        description="A toy experiment for the tests.",
    )
)


@dataclass(frozen=True)
class SmallConfig:
    seed: int = 0

    @classmethod
    def quick(cls) -> "SmallConfig":
        return cls()

    @classmethod
    def full(cls) -> "SmallConfig":
        return cls()


def make_experiment(exp_id: str, run, *, claims=(), datasets=(), reference=None) -> Experiment:
    """A minimal experiment around ``run`` (not registered)."""
    return Experiment(
        id=exp_id,
        title=f"Toy {exp_id}",
        thesis_ref="none",
        config_cls=SmallConfig,
        run=run,
        reference=reference or {},
        claims=claims,
        datasets=datasets,
    )


def _read_data(config: SmallConfig, ctx: RunContext) -> Result:
    path = ctx.require_data("toyfile")
    return Result(metrics={"value": float(path.read_text())})


DATA = register(make_experiment("toy-data", _read_data, datasets=("toyfile",)))


def _fail(config, ctx):
    raise RuntimeError("the toy experiment broke on purpose")


def _skip(config, ctx):
    raise ExperimentSkipped("no real data here")


FAIL = make_experiment("toy-fail", _fail, claims=[Claim("Never evaluated.", "x > 0")])
SKIP = make_experiment("toy-skip", _skip)


#: The clips of ``toy-concepts`` (seconds) and their sample rate: what the tests expect back from the files.
CLIP_SECONDS = (0.5, 0.8, 1.25)
CLIP_RATE = 8000


def _concepts(config, ctx):
    """Two concept cards made of tones, gradients, a waving stick figure and curves (no learning)."""
    from mmconcepts.engine import AudioClip, ConceptCard, Explorer, MotionClip, Thumbnail

    t = [np.arange(int(s * CLIP_RATE)) / CLIP_RATE for s in CLIP_SECONDS]
    clips = tuple(AudioClip(0.5 * np.sin(2 * np.pi * f * x), CLIP_RATE, f"{f} Hz") for f, x in zip((220, 330, 440), t))
    ramp = np.linspace(0.0, 1.0, 60)
    images = (Thumbnail.from_image(np.tile(ramp, (40, 1)), "grey ramp"),
              Thumbnail.from_image(np.dstack([np.tile(ramp, (40, 1))] * 3)[::-1], "colour ramp"))
    frames = np.linspace(0, 2 * np.pi, 20)
    body = np.array([[0.0, 2.0], [0.0, 1.0], [0.0, 0.0], [0.5, 1.5]])  # head, hips, feet, hand (waving)
    positions = np.repeat(body[None], len(frames), axis=0)
    positions[:, 3, 1] += 0.4 * np.sin(frames)
    stick = MotionClip(positions=positions, bones=((0, 1), (1, 2), (0, 3)), frame_rate=10.0, caption="waving")
    curves = MotionClip(curves=np.stack([np.sin(frames), np.cos(frames)], axis=1), frame_rate=10.0, caption="angles")
    cards = (ConceptCard("atom 0", (("tone", 0.75), ("noise", 0.25)), clips, images, (stick,), note="a toy card"),
             ConceptCard("atom 1", (("ramp", 1.0),), clips[:1], images[:1], (curves,)))
    return Result(metrics={"n_cards": 2.0}, explorer=Explorer(cards, "Toy concepts: tones, ramps and a wave."))


CONCEPTS = make_experiment("toy-concepts", _concepts)
