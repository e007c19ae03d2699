"""ch6-sliding: learning from sliding windows of a simulated video stream (Fig 6.8, 6.9).

Thesis section 6.6.2. Training utterances (speaker 1, one keyword each) are concatenated
in a random order into a sound stream; images are shown at a fixed frame rate, each frame
showing the object of the concept of the utterance playing at the frame's start (so frames
straddle sentence boundaries, as in the thesis). Sliding windows of width w with a shift
of a fraction of w are cut from the stream; each window is represented by the HAC of its
sound and by the average of the colour descriptors of the frames it intersects, weighted
by the duration of the intersection. One multimodal NMF (k = 50, 50 iterations) learns
from the windows of each width.

- Fig. 6.8 (success against window width): as in the thesis, full test utterances and
  single images are the test and reference examples (Sound -> Image and Image -> Sound,
  internal space, cosine, one reference image per concept).
- Fig. 6.9 (where the concept is recognised): windows (width ``probe_width``) slide through
  each test utterance; the similarity (1 - cosine dissimilarity of internal
  representations) between each window and a reference image of the utterance's concept
  is traced against time, with the keyword's position (word timings of the corpus)
  marked. ``localisation.peak_in_keyword`` is the fraction of test utterances whose most
  similar window overlaps the keyword; ``localisation.chance`` is the fraction expected if
  the peak fell on a window drawn at random.

The sound stream is built from the per-utterance MFCC sequences laid end to end (10 ms
frames), which equals the MFCC of the concatenated audio except for the two or three frames
whose analysis window straddles a boundary.

Real data (the default when present): FSDD spoken digits of one speaker and ETH-80 object
views. FSDD recordings are single words, so for Fig. 6.9 each test recording is flanked by
1-3 other test recordings of the same speaker (other words, other concepts), laid end to
end the same way (:func:`compose_test_utterances`, its own random stream); the target's
span is known exactly from the lengths.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure
from threadpoolctl import threadpool_limits

from ..errors import ConvergenceWarning, DataError
from ..multimodal import MultimodalNMF, crossmodal_distances, matching_success_rate, pairwise_divergence
from ..sound.features import MFCCConfig
from ..sound.hac import HAC
from . import _ch6_common as common
from .base import Claim, Experiment, Result, RunContext, Table
from .registry import register

__all__ = ["Config", "run", "stream_windows", "compose_test_utterances"]


@dataclass(frozen=True)
class Config:
    """Sizes; ``n_per_speaker`` and ``n_views`` select the generated data."""

    n_per_speaker: int = 1000
    n_views: int = 41
    widths: tuple[float, ...] = (0.05, 0.1, 0.2, 0.5, 1.0)
    shift: float = 0.5
    frame_rate: float = 4.0
    probe_width: float = 0.3
    probe_shift: float = 0.05
    k: int = 50
    n_iter: int = 50
    seed: int = 0

    @classmethod
    def quick(cls) -> "Config":
        return cls(n_per_speaker=250, n_views=24, widths=(0.1, 0.3, 1.0))

    @classmethod
    def full(cls) -> "Config":
        return cls()


def stream_windows(starts: np.ndarray, durations: np.ndarray, width: float, shift: float) -> np.ndarray:
    """(start, end) times of the sliding windows over a stream of segments laid end to end."""
    total = float(starts[-1] + durations[-1])
    if width <= 0 or shift <= 0:
        raise DataError(f"window width and shift must be > 0; got {width}, {shift}.")
    t0 = np.arange(0.0, max(total - width, 0.0) + 1e-9, shift)
    return np.stack([t0, t0 + width], axis=1)


def _overlap(a0, a1, b0, b1):
    return np.maximum(0.0, np.minimum(a1, b1) - np.maximum(a0, b0))


def _window_features(task: dict, width: float) -> tuple:
    """HAC and frame-weighted image features of every window of the training stream."""
    hop = task["hop"]
    stream = task["stream"]
    win = stream_windows(task["starts"], task["durations"], width, width * task["shift"])
    seqs = []
    for t0, t1 in win:
        a, b = int(t0 / hop), max(int(t0 / hop) + 1, int(t1 / hop))
        seqs.append(stream[a:b])
    # frames: frame f covers [f / fps, (f + 1) / fps)
    fps = task["frame_rate"]
    F = task["frame_features"]
    images = np.zeros((len(win), F.shape[1]))
    for i, (t0, t1) in enumerate(win):  # a window meets at most width * fps + 1 frames
        f = np.arange(int(t0 * fps), min(int(np.ceil(t1 * fps)), F.shape[0]))
        w = _overlap(t0, t1, f / fps, (f + 1) / fps) / width
        images[i] = w @ F[f]
    return seqs, images


def _width(task: dict) -> dict:
    width = task["width"]
    with threadpool_limits(1), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        hac = task["hac"]
        seqs, img = _window_features(task, width)
        keep = [i for i, s in enumerate(seqs) if len(s) > 0]
        S = hac.transform([seqs[i] for i in keep])
        model = MultimodalNMF(task["k"], max_iter=task["n_iter"], random_state=task["seed"]).fit(
            {"sound": S, "image": img[keep]})
        St, Ir = task["S_test"], task["I_ref"]
        out = {"n_windows": len(keep)}
        for key, (tm, rm, Xt, Xr, yt, yr) in {
            "s2i": ("sound", "image", St, Ir, task["y_test"], task["y_ref"]),
            "i2s": ("image", "sound", task["I_test"], task["S_ref"], task["y_ref_img"], task["y_test"]),
        }.items():
            D = crossmodal_distances(model, {tm: Xt}, {rm: Xr}, space="internal", metric="cosine")
            out[key] = matching_success_rate(D, yt, yr, random_state=task["reference_seed"])
        if task["probe"]:
            out["model"] = model
    return out


def compose_test_utterances(mfccs, y: np.ndarray, pool: np.ndarray, rng: np.random.Generator, hop: float,
                            n_flank: tuple[int, int] = (1, 3)) -> tuple[list, np.ndarray, np.ndarray, list]:
    """Longer test utterances: each recording of ``pool`` flanked by 1-3 others of other concepts.

    For corpora of isolated words (FSDD): the target recording is put at a random place
    among ``n`` other recordings of ``pool`` (same speaker, other words, so other
    concepts), their MFCC sequences laid end to end. The label is the target's concept and
    the keyword's span is known exactly from the lengths.

    Returns
    -------
    seqs : list of ndarray, the composed MFCC sequences
    labels : ndarray of int, the target's concept
    spans : ndarray of shape (n, 2), start and end (s) of the target
    texts : list of str, the words said (the target in capitals)
    """
    seqs, labels, spans, parts_of = [], [], [], []
    pool = np.asarray(pool)
    for i in pool:
        others = pool[y[pool] != y[i]]
        n = int(rng.integers(n_flank[0], n_flank[1] + 1))
        flank = rng.choice(others, size=min(n, others.size), replace=False)
        pos = int(rng.integers(0, flank.size + 1))
        parts = [int(j) for j in flank[:pos]] + [int(i)] + [int(j) for j in flank[pos:]]
        start = sum(len(mfccs[j]) for j in parts[:pos]) * hop
        seqs.append(np.concatenate([mfccs[j] for j in parts]))
        labels.append(int(y[i]))
        spans.append((start, start + len(mfccs[i]) * hop))
        parts_of.append((parts, pos))
    return seqs, np.asarray(labels), np.asarray(spans, dtype=float).reshape(-1, 2), parts_of


def _probe(model, hac, mfccs, y, spans, I_ref, y_ref, width: float, shift: float, hop: float) -> dict:
    """Similarity to the true concept's image along each test utterance (Fig. 6.9)."""
    h_img = model.transform({"image": I_ref})
    proto = np.stack([h_img[y_ref == c].mean(0) for c in range(int(y_ref.max()) + 1)])
    hits, chance, traces = [], [], []
    starts, windows = [], []
    for seq in mfccs:  # every window of every test utterance, transformed in one batch
        T = len(seq) * hop
        t0 = np.arange(0.0, max(T - width, 0.0) + 1e-9, shift)
        starts.append(t0)
        windows += [seq[int(a / hop): max(int(a / hop) + 1, int((a + width) / hop))] for a in t0]
    h_all = model.transform({"sound": hac.transform(windows)})
    bounds = np.cumsum([0] + [len(t0) for t0 in starts])
    for t0, c, span, a, b in zip(starts, y, spans, bounds[:-1], bounds[1:]):
        sim = 1.0 - pairwise_divergence(h_all[a:b], proto[c:c + 1], "cosine")[:, 0]
        traces.append((t0 + width / 2, sim, span))
        if np.isfinite(span).all():
            over = _overlap(t0, t0 + width, span[0], span[1]) > 0
            hits.append(bool(over[int(np.argmax(sim))]))
            chance.append(float(over.mean()))
    return {"peak_in_keyword": float(np.mean(hits)) if hits else float("nan"),
            "chance": float(np.mean(chance)) if chance else float("nan"), "traces": traces, "n": len(hits)}


def run(config: Config, ctx: RunContext) -> Result:
    from ..vision import ImageFeatures

    st = common.streams(config.seed)
    speech = common.load_speech(ctx, n_per_speaker=config.n_per_speaker, seed=st.data)
    keywords, y, mfcc, sub = speech["keywords"], speech["y"], speech["mfcc"], speech["corpus"]
    hop = MFCCConfig(n_mfcc=22).hop_ms / 1000
    spans = speech["spans"]
    ims = common.load_images(ctx, len(keywords), config.n_views)
    objects = sorted(set(ims.labels))
    if len(objects) < len(keywords):
        raise DataError(f"{len(keywords)} keywords but only {len(objects)} objects.")
    drng, frng = np.random.default_rng(st.data), np.random.default_rng(st.splits)
    learner = common.child_seeds(st.learner, 3)  # HAC, colour codebook, NMF
    obj = drng.permutation(objects)[: len(keywords)].tolist()
    image_concept = common.image_concepts(ims.labels, obj)
    part_y = common.concept_parts(y, (0.6, 0.2, 0.2), frng)
    tr, te = np.flatnonzero(part_y == 0), np.flatnonzero(part_y == 1)
    # images: each concept's views split between the stream (training) and the references
    part_i = common.concept_parts(image_concept, (0.6, 0.4), frng)
    img_train = [np.flatnonzero((image_concept == c) & (part_i == 0)) for c in range(len(keywords))]
    img_ref = [np.flatnonzero((image_concept == c) & (part_i == 1)) for c in range(len(keywords))]
    c_loc, _ = common.image_locals(ctx, ims)
    with threadpool_limits(1), warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        hac = HAC(random_state=learner[0]).fit([mfcc[i] for i in tr])
        feats = ImageFeatures(("color",), random_state=learner[1])
        feats.fit_locals([c_loc[i] for i in np.concatenate(img_train)], None)
        colour = feats.transform_locals(c_loc, None)["color"]
        colour = colour.toarray() if hasattr(colour, "toarray") else np.asarray(colour)
        order = drng.permutation(tr)
        durations = np.array([len(mfcc[i]) * hop for i in order])
        starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        stream = np.concatenate([mfcc[i] for i in order])
        n_frames = int(np.ceil((starts[-1] + durations[-1]) * config.frame_rate))
        frame_t = np.arange(n_frames) / config.frame_rate
        playing = np.clip(np.searchsorted(starts, frame_t, side="right") - 1, 0, len(order) - 1)
        frame_img = np.array([drng.choice(img_train[y[order[u]]]) for u in playing])
        S_all = hac.transform(mfcc)
    ref_imgs = np.concatenate(img_ref)
    y_ref_img = np.concatenate([np.full(len(v), c) for c, v in enumerate(img_ref)])
    base = {"hac": hac, "hop": hop, "stream": stream, "starts": starts, "durations": durations,
            "shift": config.shift, "frame_rate": config.frame_rate, "frame_features": colour[frame_img],
            "k": config.k, "n_iter": config.n_iter, "seed": learner[2],
            "reference_seed": st.reference,
            "S_test": S_all[te], "y_test": y[te], "S_ref": S_all[te], "I_ref": colour[ref_imgs], "y_ref": y_ref_img,
            "I_test": colour[ref_imgs], "y_ref_img": y_ref_img}
    widths = list(config.widths)
    probe_at = int(np.argmin(np.abs(np.asarray(widths) - config.probe_width)))
    tasks = [dict(base, width=w, probe=(j == probe_at)) for j, w in enumerate(widths)]
    outs = ctx.parallel(_width, tasks, desc="window widths")
    metrics: dict[str, float] = {"chance": 1.0 / len(keywords)}
    for w, o in zip(widths, outs):
        tag = f"width_{w:g}".replace(".", "_")
        metrics[f"{tag}.s2i"] = o["s2i"]
        metrics[f"{tag}.i2s"] = o["i2s"]
        metrics[f"{tag}.n_windows"] = float(o["n_windows"])
    metrics["best.s2i"] = max(o["s2i"] for o in outs)
    # Fig. 6.9: test utterances with the keyword inside a longer utterance
    composed = not np.isfinite(spans[te]).all(axis=1).any()
    if composed:  # isolated words (FSDD): a target recording flanked by 1-3 other test recordings
        seqs, y_probe, spans_probe, parts = compose_test_utterances(
            mfcc, y, te, np.random.default_rng(st.composition), hop)
        texts = [" ".join(keywords[y[j]].upper() if k == pos else keywords[y[j]] for k, j in enumerate(p))
                 for p, pos in parts]
    else:
        seqs, y_probe, spans_probe = [mfcc[i] for i in te], y[te], spans[te]
        texts = [sub.transcriptions[i] for i in te]
    probe = _probe(outs[probe_at]["model"], hac, seqs, y_probe, spans_probe, colour[ref_imgs], y_ref_img,
                   widths[probe_at], config.probe_shift, hop)
    metrics["localisation.peak_in_keyword"] = probe["peak_in_keyword"]
    metrics["localisation.chance"] = probe["chance"]
    metrics["localisation.n_utterances"] = float(probe["n"])

    fig8 = Figure(figsize=(6, 4))
    ax = fig8.subplots()
    ax.plot(widths, [o["s2i"] for o in outs], "o-", label="S -> I")
    ax.plot(widths, [o["i2s"] for o in outs], "s-", label="I -> S")
    ax.axhline(metrics["chance"], color="k", ls=":", label="chance")
    ax.set_xscale("log")
    ax.set_xlabel("window width (s)")
    ax.set_ylabel("success rate (full utterances vs single images)")
    ax.set_ylim(0, 1)
    ax.set_title("Fig. 6.8: learning from sliding windows")
    ax.legend(fontsize=7)
    fig8.tight_layout()
    fig9 = Figure(figsize=(8, 6))
    axes = fig9.subplots(3, 2).ravel()
    shown = [int(np.flatnonzero(y_probe == c)[0]) for c in np.unique(y_probe)][:6]  # six different concepts
    for ax, i in zip(axes, shown):
        (t, sim, span), text = probe["traces"][i], texts[i]
        ax.plot(t, sim, "-")
        if np.isfinite(span).all():
            ax.axvspan(span[0], span[1], color="orange", alpha=0.3)
        ax.set_title(text, fontsize=7)
        ax.set_ylim(0, 1)
        ax.tick_params(labelsize=6)
    fig9.suptitle(f"Fig. 6.9: similarity to the concept's image along test utterances (keyword shaded, "
                  f"{widths[probe_at]:g} s windows)", fontsize=8)
    fig9.tight_layout()
    rows = [[w, o["n_windows"], o["s2i"], o["i2s"]] for w, o in zip(widths, outs)]
    return Result(
        metrics=metrics,
        tables={"fig6_8": Table("Fig. 6.8: success against window width", ["width (s)", "training windows", "S -> I",
                                                                            "I -> S"], rows)},
        figures={"fig6_8": fig8, "fig6_9": fig9},
        notes=[common.image_note(ctx, ims) + " " + common.speech_note(ctx, speech),
               f"Speaker {speech['speaker']}: a stream of {len(tr)} training utterances ({starts[-1] + durations[-1]:.0f} s), "
               f"{config.frame_rate:g} image frames per second; windows shifted by {config.shift:g} of their width; "
               f"{len(te)} test utterances and {len(ref_imgs)} reference images; k = {config.k}.",
               ("Fig. 6.9 test utterances (isolated words): each test recording flanked by 1-3 other test recordings "
                "of the same speaker (other words, so other concepts) at a random place, their MFCC sequences laid "
                "end to end (independent random stream); the target's span is known from the lengths. "
                if composed else "Fig. 6.9 test utterances: the test sentences, keyword spans from the word timings. ")
               + f"Localisation: {probe['n']} test utterances with keyword timings; the most similar "
               f"{widths[probe_at]:g} s window overlaps the keyword in {probe['peak_in_keyword']:.2f} of them "
               f"(chance {probe['chance']:.2f})."],
    )


register(Experiment(
    id="ch6-sliding",
    title="Learning from sliding windows of a simulated video stream",
    thesis_ref="Section 6.6.2, Fig. 6.8 and 6.9",
    config_cls=Config,
    run=run,
    reference={},
    claims=[
        Claim("The learner copes with the ambiguity of sliding windows: learnt from windows, it still matches full "
              "utterances with images above chance.", "best.s2i > 2 * chance"),
        Claim("Recognition is localised around the keyword: the window most similar to the concept's image "
              "overlaps the keyword more often than a random window would.",
              "localisation.peak_in_keyword > localisation.chance + 0.1"),
    ],
    datasets=("fsdd", "eth80", "acorns", "audio", "images"),
    description=__doc__.split("\n\n")[0],
))
