"""The smallest complete experiment: saved as ``src/mmconcepts/experiments/ch2/coin.py``, it is found,
run by ``mmconcepts run ch2-coin``, recorded, judged and reported like the thesis' own."""

from dataclasses import dataclass

import numpy as np

from mmconcepts.engine import Claim, Experiment, PresetConfig, Result, RunContext, SampleUnit, register, streams


@dataclass(frozen=True)
class Config(PresetConfig):
    n_flips: int = 1000  # the defaults are the full protocol
    n_repeats: int = 10
    seed: int = 0

    QUICK = {"n_flips": 200, "n_repeats": 5}  # what the quick preset changes


def compute(config: Config, ctx: RunContext) -> Result:
    st = streams(config.seed)  # draw r of the data stream: st.rng("data", r)
    heads = [float((st.rng("data", r).random(config.n_flips) < 0.5).mean()) for r in range(config.n_repeats)]
    return Result(metrics={"heads": float(np.mean(heads))}, samples={"heads": heads},
                  sample_units={"heads": "repeat"}, units={"repeat": SampleUnit.seeds()})


EXPERIMENT = register(Experiment(
    id="ch2-coin", title="A fair coin", thesis_ref="Section 2.1", config_cls=Config, compute=compute,
    claims=[Claim("A fair coin shows heads more often than one time in three.", "heads > 0.33")],
))
