"""ch5-incremental: incremental keyword learning with the cluster tree and TF-IDF voting (Fig 5.3, 5.4).

Thesis section 5.2.4. The recogniser of section 5.2.3 (80 ms MFCC windows sliding by a
third of their length, compared by DTW; the incremental hierarchical cluster tree with
the second backtracking search; leaves as acoustic events; TF-IDF votes, eq. 5.1) learns
from utterances tagged with their keyword, one at a time, and is tested on held-out
utterances after every training session.

- Single speaker (Fig. 5.3): one learner per speaker; the speaker's utterances are split
  into a training set (900 in the thesis) and a test set (100), stratified by keyword;
  accuracy on the test set after every session of 100 training utterances.
- Several speakers (Fig. 5.4): one learner; the training utterances of speaker 1, then
  of speaker 2, and so on; a fixed test set of 100 utterances per speaker; accuracy (all
  speakers and per speaker) after every session of 200 utterances.

The radius r_max of the leaves is set a priori from the windows of the first training
session (the median distance of a window to its nearest window in another utterance, see
:func:`~mmconcepts.experiments._ch5_common.choose_r_max`); the thesis gives no value.

On the Free Spoken Digit Dataset the task is the same with isolated words: each
recording is one digit word said alone, and its word is its tag (see the notes for why
composed utterances are not used here). Speakers are taken in sorted order of their ids,
whatever they are. Random streams: the train/test splits use the ``splits`` stream, each
learner's r_max sample and k-means the ``learner`` stream.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure
from threadpoolctl import threadpool_limits

from ..sound.features import MFCCConfig
from . import _ch5_common as common
from .base import Claim, Experiment, Result, RunContext, Table
from .config import PresetConfig
from .registry import register

__all__ = ["Config", "compute", "present", "run"]


@dataclass(frozen=True)
class Config(PresetConfig):
    """Protocol sizes (defaults: the thesis'); ``n_per_speaker`` selects the generated corpus."""

    n_per_speaker: int = 1000
    n_train: int = 900
    n_test: int = 100
    session: int = 100
    multi_session: int = 200
    n_mfcc: int = 13
    window_ms: float = 80.0
    metric: str = "dtw"
    backtrack: int = 4
    seed: int = 0

    QUICK = dict(n_per_speaker=250, n_train=200, n_test=50, session=50, multi_session=100)


def _split(y: np.ndarray, n_train: int, n_test: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Stratified test set of ``n_test`` and a shuffled training set of ``n_train`` (indices into y)."""
    from sklearn.model_selection import train_test_split

    n_test = min(n_test, len(y) // 2)
    idx = np.arange(len(y))
    strat = y if np.unique(y, return_counts=True)[1].min() >= 2 else None
    tr, te = train_test_split(idx, test_size=n_test, stratify=strat, random_state=int(rng.integers(2**31 - 1)))
    tr = rng.permutation(tr)[:n_train]
    return tr, np.sort(te)


def _learn(task: dict) -> dict:
    """Train one learner session by session; test after each session."""
    with threadpool_limits(1):
        windows, y, groups = task["windows"], task["y"], task["groups"]
        train, test, step = task["train"], task["test"], task["step"]
        voter = common.make_voter(task["voting"], [windows[i] for i in train[:step]], seed=task["seed"])
        seen, acc, per_group = [], [], []
        for start in range(0, len(train), step):
            batch = train[start : start + step]
            voter.partial_fit([windows[i] for i in batch], list(y[batch]))
            pred = np.asarray(voter.predict([windows[i] for i in test]))
            ok = pred == y[test]
            seen.append(start + len(batch))
            acc.append(float(ok.mean()))
            per_group.append({g: float(ok[groups[test] == g].mean()) for g in task["group_names"]})
    # the last session's hits, one 0/1 value per test utterance in the order of task["test"]
    return {"name": task["name"], "seen": seen, "accuracy": acc, "per_group": per_group, "final_hits": ok.astype(float),
            "n_leaves": int(voter.tree_.n_leaves_), "r_max": float(voter.tree.r_max)}


def compute(config: Config, ctx: RunContext) -> Result:
    """The learners' accuracy curves and final scores (no figures; ``figure_data``: the curves, the speakers and
    where each speaker's training utterances end, for :func:`present`)."""
    corpus = common.load_corpus(ctx, n_per_speaker=config.n_per_speaker)
    y_all = common.keyword_targets(corpus)
    spk_all = common.speaker_ids(corpus)
    speakers = sorted(set(spk_all))
    windows = common.corpus_windows(ctx, corpus, MFCCConfig(n_mfcc=config.n_mfcc), window_ms=config.window_ms)
    voting = common.voting_params(config.window_ms, metric=config.metric, backtrack=config.backtrack)
    st = common.streams(config.seed)
    rng = np.random.default_rng(st.splits)
    splits = {}
    for s in speakers:
        idx = np.flatnonzero(spk_all == s)
        tr, te = _split(y_all[idx], config.n_train, config.n_test, rng)
        splits[s] = (idx[tr], idx[te])
    tasks = []
    for j, s in enumerate(speakers):
        tr, te = splits[s]
        tasks.append({"name": s, "windows": windows, "y": y_all, "groups": spk_all, "group_names": [s],
                      "train": tr, "test": te, "step": config.session, "voting": voting,
                      "seed": common.sub_seed(st.learner, j)})
    multi_train = np.concatenate([splits[s][0] for s in speakers])
    multi_test = np.concatenate([splits[s][1] for s in speakers])
    tasks.append({"name": "__multi__", "windows": windows, "y": y_all, "groups": spk_all, "group_names": speakers,
                  "train": multi_train, "test": multi_test, "step": config.multi_session, "voting": voting,
                  "seed": common.sub_seed(st.learner, len(speakers))})
    out = ctx.parallel(_learn, tasks, desc="learners")
    single, multi = out[:-1], out[-1]
    y_test = y_all[multi_test]
    chance = float(np.unique(y_test, return_counts=True)[1].max() / len(y_test))

    metrics: dict[str, float] = {"chance.accuracy": chance}
    finals = [r["accuracy"][-1] for r in single]
    firsts = [r["accuracy"][0] for r in single]
    metrics["single_speaker.final_accuracy"] = float(np.mean(finals))
    metrics["single_speaker.first_session_accuracy"] = float(np.mean(firsts))
    # per test utterance (0/1) samples: the protocol draws one split and does not repeat, so the spread of a
    # final accuracy is that of a mean over the test utterances (a binomial-type t interval). A speaker's
    # samples are its test utterances in sorted order, for its own learner and for the several-speaker
    # learner alike (the same utterances: the two are paired); multi_speaker.final_accuracy's are all test
    # utterances, speaker after speaker.
    hit_samples: dict[str, list[float]] = {}
    units = {"single_speaker.final_accuracy": "speakers", "single_speaker.first_session_accuracy": "speakers",
             "multi_speaker.final_accuracy": "test utterances"}
    for j, (s, r) in enumerate(zip(speakers, single), 1):
        metrics[f"single_speaker.speaker_{j}.final_accuracy"] = r["accuracy"][-1]
        hit_samples[f"single_speaker.speaker_{j}.final_accuracy"] = r["final_hits"].tolist()
        mine = spk_all[multi_test] == s
        hit_samples[f"multi_speaker.speaker_{j}.final_accuracy"] = multi["final_hits"][mine].tolist()
        units[f"single_speaker.speaker_{j}.final_accuracy"] = units[f"multi_speaker.speaker_{j}.final_accuracy"] = \
            f"speaker {j}'s test utterances"
    metrics["multi_speaker.final_accuracy"] = multi["accuracy"][-1]
    hit_samples["multi_speaker.final_accuracy"] = multi["final_hits"].tolist()  # speaker after speaker
    # gain on speaker j's test utterances from learning speaker j's training utterances
    n_tr = [len(splits[s][0]) for s in speakers]
    ends = np.cumsum(n_tr)
    seen = np.asarray(multi["seen"])
    befores, afters = [], []
    for j, s in enumerate(speakers[1:], 1):
        before = [k for k in range(len(seen)) if seen[k] <= ends[j - 1]]
        after = [k for k in range(len(seen)) if seen[k] >= ends[j]]
        if before and after:
            befores.append(multi["per_group"][before[-1]][s])
            afters.append(multi["per_group"][after[0]][s])
    gains = [a - b for a, b in zip(afters, befores)]
    nan = float("nan")
    metrics["multi_speaker.new_speaker_before"] = float(np.mean(befores)) if befores else nan
    metrics["multi_speaker.new_speaker_after"] = float(np.mean(afters)) if afters else nan
    metrics["multi_speaker.new_speaker_gain"] = float(np.mean(gains)) if gains else nan
    for j, s in enumerate(speakers, 1):
        metrics[f"multi_speaker.speaker_{j}.final_accuracy"] = multi["per_group"][-1][s]

    # tables (the curves)
    t_single = Table("Fig. 5.3: accuracy after each training session, one learner per speaker",
                     ["training utterances"] + [f"speaker {j}" for j in range(1, len(single) + 1)],
                     [[n] + [r["accuracy"][k] for r in single] for k, n in enumerate(single[0]["seen"])])
    t_multi = Table("Fig. 5.4: one learner, speakers in sequence",
                    ["training utterances", "all"] + [f"speaker {j}" for j in range(1, len(speakers) + 1)],
                    [[n, multi["accuracy"][k]] + [multi["per_group"][k][s] for s in speakers]
                     for k, n in enumerate(multi["seen"])])
    samples = {"single_speaker.final_accuracy": finals, "single_speaker.first_session_accuracy": firsts, **hit_samples}
    if gains:
        samples.update({"multi_speaker.new_speaker_before": befores, "multi_speaker.new_speaker_after": afters,
                        "multi_speaker.new_speaker_gain": gains})
        units.update({name: "speakers after the first" for name in
                      ("multi_speaker.new_speaker_before", "multi_speaker.new_speaker_after",
                       "multi_speaker.new_speaker_gain")})
    leaves = ", ".join(f"speaker {j}: {r['n_leaves']} leaves (r_max {r['r_max']:.3g})" for j, r in enumerate(single, 1))
    return Result(
        metrics=metrics,
        samples=samples,
        sample_units=units,
        tables={"single_speaker": t_single, "multi_speaker": t_multi},
        figure_data={"single": [{"seen": r["seen"], "accuracy": r["accuracy"]} for r in single],
                     "multi": {key: multi[key] for key in ("seen", "accuracy", "per_group")},
                     "speakers": speakers, "ends": ends},
        notes=[common.data_source_note(ctx, corpus), common.KEYWORDS_READING,
               f"{len(speakers)} speakers (sorted ids: {', '.join(speakers)}); per speaker {len(splits[speakers[0]][0])} training and "
               f"{len(splits[speakers[0]][1])} test utterances; sessions of {config.session} (single) and "
               f"{config.multi_session} (several speakers) utterances; {config.window_ms:g} ms windows, "
               f"{config.metric.upper()}, restart search with b = {config.backtrack}.",
               f"Trees at the end: {leaves}; several speakers: {multi['n_leaves']} leaves.",
               "The thesis' figures give curves without numbers (its text gives none either), so no claim checks a "
               "magnitude; the claims are about their shape. Spread: single_speaker.final_accuracy and "
               "first_session_accuracy have one sample per speaker (one learner each, paired by speaker); the "
               "new-speaker numbers one per speaker after the first (accuracy on that speaker's test utterances just "
               "before and just after the session that ends its training utterances). The protocol draws one split "
               "and does not repeat, so the final accuracy of one speaker's learner, of the several-speaker learner "
               "on all test utterances and on each speaker's keep one 0/1 value per test utterance (hit or miss): "
               "their interval is the binomial-type t interval of a mean over test utterances, which leaves out "
               "the variation between splits and learners. A speaker's test utterances are the same for its own "
               "learner and for the several-speaker learner, in the same order (paired).",
               "Reading for FSDD: the thesis' task classifies utterances that hold exactly one keyword amid carrier "
               "words. FSDD has digits only, so in an utterance composed of several digits every word would be a "
               "keyword and the one-tag task would be ill-posed; the honest equivalent is the isolated word (one "
               "recording, one digit, its word as the tag). The task is therefore easier than the thesis' (no "
               "carrier words to ignore, ten short words); composed utterances are used by ch5-nmf-keywords, "
               "where the thesis' setting has one or several keywords per utterance."],
    )


def present(result: Result, config: Config) -> dict[str, Figure]:
    """Fig. 5.3 (one learner per speaker) and Fig. 5.4 (one learner, speakers in sequence)."""
    fd = result.figure_data
    single, multi, speakers, ends = fd["single"], fd["multi"], fd["speakers"], fd["ends"]
    chance = result.metrics["chance.accuracy"]
    fig3 = Figure(figsize=(6, 4))
    ax = fig3.subplots()
    for j, r in enumerate(single, 1):
        ax.plot(r["seen"], r["accuracy"], marker="o", label=f"speaker {j}")
    ax.axhline(chance, color="k", ls=":", label=f"chance ({chance:.2g}: one keyword at random)")
    ax.set_xlabel("training utterances")
    ax.set_ylabel("test accuracy (fraction of test utterances)")
    ax.set_ylim(0, 1)
    ax.set_title("Fig. 5.3: single-speaker incremental learning")
    ax.legend(fontsize=7)
    fig3.tight_layout()
    fig4 = Figure(figsize=(6, 4))
    ax = fig4.subplots()
    ax.plot(multi["seen"], multi["accuracy"], "k-o", label="all speakers")
    for j, s in enumerate(speakers, 1):
        ax.plot(multi["seen"], [p[s] for p in multi["per_group"]], marker=".", label=f"speaker {j}")
    for i, e in enumerate(ends[:-1]):
        ax.axvline(e, color="grey", lw=0.8, ls="--", label="the next speaker starts" if i == 0 else None)
    ax.axhline(chance, color="k", ls=":", label=f"chance ({chance:.2g}: one keyword at random)")
    ax.set_xlabel("training utterances (speakers in sequence)")
    ax.set_ylabel("test accuracy (fraction of test utterances)")
    ax.set_ylim(0, 1)
    ax.set_title("Fig. 5.4: several speakers")
    ax.legend(fontsize=7)
    fig4.tight_layout()
    return {"fig5_3": fig3, "fig5_4": fig4}


EXPERIMENT = register(Experiment(
    id="ch5-incremental",
    title="Incremental keyword learning with the cluster tree and TF-IDF voting",
    thesis_ref="Section 5.2.4, Fig. 5.3 and 5.4",
    config_cls=Config,
    compute=compute,
    present=present,
    reference={},
    claims=[
        Claim("Keywords are recognised far above chance after training on one speaker (Fig. 5.3).",
              "single_speaker.final_accuracy > 3 * chance.accuracy"),
        Claim("Accuracy improves as training utterances accumulate (Fig. 5.3).",
              "single_speaker.final_accuracy > single_speaker.first_session_accuracy"),
        Claim("The learner copes with several speakers: trained on all of them, it stays far above chance (Fig. 5.4).",
              "multi_speaker.final_accuracy > 3 * chance.accuracy"),
        Claim("Accuracy on a new speaker rises once that speaker's utterances are learnt (Fig. 5.4).",
              "multi_speaker.new_speaker_gain > 0"),
    ],
    datasets=("acorns", "fsdd", "audio"),
    description=__doc__.split("\n\n")[0],
))

#: ``compute`` and then ``present``: the result with its figures.
run = EXPERIMENT.run
