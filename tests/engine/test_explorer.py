"""The concept explorer of a run: its cards checked, its files written beside the figures and read back."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from mmconcepts.engine import AudioClip, ConceptCard, Explorer, MotionClip, Thumbnail
from mmconcepts.engine.explorer import MAX_CARDS, MAX_CLIP_SECONDS, MAX_MEDIA, MAX_MOTION_FRAMES, MAX_THUMBNAIL
from mmconcepts.engine.media import EXPLORER_DIR, explorer_files, png_bytes, svg_text, write_explorer
from mmconcepts.errors import ExperimentError

SVG = "{http://www.w3.org/2000/svg}"


def test_wav_round_trip_within_16_bit_quantisation(rng, tmp_path):
    sf = pytest.importorskip("soundfile")
    x = rng.uniform(-0.95, 0.95, 4000)
    entry = write_explorer(Explorer((ConceptCard("atom 0", clips=(AudioClip(x, 8000, "noise"),)),)), tmp_path / "e")
    clip = entry["cards"][0]["clips"][0]
    assert clip == {"path": f"e/{EXPLORER_DIR}/card-1-clip-1.wav", "seconds": 0.5, "sample_rate": 8000,
                    "caption": "noise"}
    back, sr = sf.read(tmp_path / clip["path"])
    info = sf.info(tmp_path / clip["path"])
    assert (sr, info.channels, info.subtype, back.shape) == (8000, 1, "PCM_16", x.shape)
    assert np.abs(back - x).max() <= 0.5 / 32768 + 1e-12  # rounded to the nearest of 2**16 levels
    assert np.abs(back - x).max() > 0  # and quantised


def test_clipped_samples_and_the_ends_of_the_range(tmp_path):
    sf = pytest.importorskip("soundfile")
    x = np.array([-2.0, -1.0, 0.0, 1.0, 3.0])
    entry = write_explorer(Explorer((ConceptCard("a", clips=(AudioClip(x, 8000),)),)), tmp_path / "e")
    back, _ = sf.read(tmp_path / entry["cards"][0]["clips"][0]["path"], dtype="int16")
    assert back.tolist() == [-32768, -32768, 0, 32767, 32767]


def test_png_and_svg_files(tmp_path):
    from PIL import Image

    pixels = (np.arange(12 * 20 * 3) % 251).astype(np.uint8).reshape(12, 20, 3)
    stick = MotionClip(positions=np.array([[[0, 0], [0, 1], [1, 1]]] * 5, dtype=float) + np.arange(5)[:, None, None],
                       bones=((0, 1), (1, 2)), frame_rate=10.0)
    card = ConceptCard("atom 3", (("seven", 0.8), ("two", 0.2)), images=(Thumbnail(pixels, "view"),), motions=(stick,))
    entry = write_explorer(Explorer((card,), "note"), tmp_path / "x")
    assert entry["note"] == "note" and entry["cards"][0]["labels"] == [{"label": "seven", "share": 0.8},
                                                                       {"label": "two", "share": 0.2}]
    image = entry["cards"][0]["images"][0]
    assert (image["width"], image["height"]) == (20, 12)
    assert np.array_equal(np.asarray(Image.open(tmp_path / image["path"])), pixels)
    motion = entry["cards"][0]["motions"][0]
    assert (motion["frames"], motion["seconds"]) == (5, 0.5)
    root = ET.parse(tmp_path / motion["path"]).getroot()
    animate = root.find(f"{SVG}path/{SVG}animate")
    assert animate is not None and animate.get("dur") == "0.5s" and animate.get("attributeName") == "d"
    frames = animate.get("values").split(";")
    assert len(frames) == 5 and all(f.count("M") == 2 for f in frames)  # two bones a frame
    assert len(set(frames)) == 5  # the figure moves (one box for all frames)
    assert sorted(explorer_files(entry)) == sorted([image["path"], motion["path"]])


def test_a_stick_figure_is_drawn_upright_and_in_proportion():
    """y points up in the positions, down in SVG: the head (highest) is drawn at the top; one scale for both axes."""
    positions = np.array([[[0.0, 2.0], [0.0, 0.0], [1.0, 0.0]]] * 2)  # head, feet, a foot 1 to the side
    d = ET.fromstring(svg_text(MotionClip(positions=positions, bones=((0, 1), (1, 2))))).find(f"{SVG}path").get("d")
    hx, hy, fx, fy, fx2, fy2, gx, gy = map(int, re.findall(r"-?\d+", d))
    assert (fx, fy) == (fx2, fy2) and hx == fx and fy == gy
    assert hy < fy  # the head above the feet
    assert fy - hy == pytest.approx(2 * (gx - fx), abs=1)  # height 2, width 1: the same scale


def test_curves_move_a_cursor_over_the_curves():
    curves = np.stack([np.linspace(0, 1, 8), np.linspace(1, 0, 8)], axis=1)
    root = ET.fromstring(svg_text(MotionClip(curves=curves, frame_rate=4.0)))
    assert len(root.findall(f"{SVG}polyline")) == 2
    assert all(len(p.get("points").split()) == 8 for p in root.findall(f"{SVG}polyline"))
    cursor = root.find(f"{SVG}line")
    assert [a.get("dur") for a in cursor.findall(f"{SVG}animate")] == ["2s", "2s"]


def test_thumbnail_from_image_shrinks_and_keeps_the_aspect(rng):
    t = Thumbnail.from_image(rng.random((300, 150, 3)), "tall")
    assert t.pixels.dtype == np.uint8 and t.pixels.shape == (MAX_THUMBNAIL, MAX_THUMBNAIL // 2, 3)
    small = Thumbnail.from_image(np.full((10, 20), 0.5))
    assert small.pixels.shape == (10, 20) and int(small.pixels[0, 0]) == 128  # kept as it is
    assert Thumbnail.from_image(rng.random((300, 300)), size=64).pixels.shape == (64, 64)


@pytest.mark.parametrize("make, fragment", [
    (lambda: AudioClip(np.zeros(int(MAX_CLIP_SECONDS * 8000) + 1), 8000), f"at most {MAX_CLIP_SECONDS:g} s"),
    (lambda: AudioClip(np.array([0.0, np.nan]), 8000), "finite"),
    (lambda: AudioClip(np.zeros(10), 44.1), "sample_rate"),
    (lambda: Thumbnail(np.zeros((MAX_THUMBNAIL + 1, 4), np.uint8)), f"at most {MAX_THUMBNAIL} pixels"),
    (lambda: Thumbnail(np.zeros((4, 4))), "uint8"),
    (lambda: MotionClip(curves=np.zeros((MAX_MOTION_FRAMES + 1, 2))), f"at most {MAX_MOTION_FRAMES} frames"),
    (lambda: MotionClip(positions=np.zeros((3, 2, 2)), bones=((0, 2),)), "pairs of joint indices"),
    (lambda: MotionClip(positions=np.zeros((3, 2, 2)), bones=((0, 1),), curves=np.zeros((3, 1))), "one of them"),
    (lambda: ConceptCard("a", clips=(AudioClip(np.zeros(8), 8000),) * (MAX_MEDIA + 1)), f"at most {MAX_MEDIA}"),
    (lambda: ConceptCard("a", (("x", 1.5),)), "shares in [0, 1]"),
    (lambda: Explorer((ConceptCard("a"),) * (MAX_CARDS + 1)), f"at most {MAX_CARDS} ConceptCard"),
])
def test_bounds_and_types_are_checked(make, fragment):
    with pytest.raises(ExperimentError, match=r"expected .*Fix:") as info:
        make()
    assert fragment in str(info.value)


def _register(toy, run):
    """``toy-concepts`` registered with ``run`` as its computation."""
    from mmconcepts.engine import all_experiments, register, unregister

    if "toy-concepts" in {e.id for e in all_experiments()}:
        unregister("toy-concepts")
    return register(toy.make_experiment("toy-concepts", run))


def test_a_run_writes_its_explorer_and_its_record_lists_it(toy, tmp_path):
    from mmconcepts.engine import load_record, run_experiment

    calls = []
    _register(toy, lambda config, ctx: calls.append(1) or toy._concepts(config, ctx))
    record = run_experiment("toy-concepts", output=tmp_path, progress=False)
    assert record.status == "ok", record.message
    cards = record.explorer["cards"]
    assert [c["title"] for c in cards] == ["atom 0", "atom 1"] and record.explorer["note"].startswith("Toy concepts")
    assert [c["seconds"] for c in cards[0]["clips"]] == list(toy.CLIP_SECONDS)
    files = explorer_files(record.explorer)
    assert len(files) == 3 + 2 + 1 + 1 + 1 + 1 and all((tmp_path / f).is_file() for f in files)
    assert {p.name for p in (tmp_path / "toy-concepts" / EXPLORER_DIR).iterdir()} == {f.split("/")[-1] for f in files}
    on_disk = json.loads((tmp_path / "toy-concepts.json").read_text())
    assert on_disk["schema_version"] == 5 and on_disk["explorer"] == record.explorer
    assert load_record(tmp_path / "toy-concepts.json").explorer == record.explorer
    # up to date while its files are there; a missing file makes it run again
    run_experiment("toy-concepts", output=tmp_path, progress=False)
    assert len(calls) == 1
    (tmp_path / files[-1]).unlink()
    run_experiment("toy-concepts", output=tmp_path, progress=False)
    assert len(calls) == 2 and (tmp_path / files[-1]).is_file()


def test_stale_explorer_files_go_when_a_run_has_none(toy, tmp_path):
    from mmconcepts.engine import Result, run_experiment

    _register(toy, toy._concepts)
    run_experiment("toy-concepts", output=tmp_path, progress=False)
    folder = tmp_path / "toy-concepts" / EXPLORER_DIR
    assert folder.is_dir()
    _register(toy, lambda config, ctx: Result(metrics={"n_cards": 0.0}))
    record = run_experiment("toy-concepts", output=tmp_path, progress=False, force=True)
    assert record.explorer == {} and not folder.exists() and not folder.parent.exists()


def test_a_failed_run_keeps_no_explorer(toy, tmp_path):
    from mmconcepts.engine import run_experiment

    _register(toy, toy._concepts)
    run_experiment("toy-concepts", output=tmp_path, progress=False)

    def broken(config, ctx):
        raise RuntimeError("broke after the cards")

    _register(toy, broken)
    record = run_experiment("toy-concepts", output=tmp_path, progress=False, force=True, raise_errors=False)
    assert record.status == "failed" and record.explorer == {}
    assert not (tmp_path / "toy-concepts" / EXPLORER_DIR).exists()


def test_result_explorer_must_be_an_explorer():
    from mmconcepts.engine import Result

    with pytest.raises(ExperimentError, match="Result.explorer must be an Explorer"):
        Result(explorer=[ConceptCard("a")]).validate()  # type: ignore[arg-type]


def test_figures_redrawn_leave_the_explorer_in_place(toy, tmp_path):
    """A redraw that rewrites the record's figures removes the stale PNGs, never the explorer's files."""
    from matplotlib.figure import Figure

    from mmconcepts.engine import Experiment, redraw_figures, register, run_experiment, unregister

    def present(result, config, names=("a",)):
        return {name: Figure(figsize=(1, 1)) for name in names}

    def declare(present):
        return Experiment(id="toy-cards-redraw", title="t", thesis_ref="-", config_cls=toy.SmallConfig,
                          compute=toy._concepts, present=present)

    register(declare(present))
    record = run_experiment("toy-cards-redraw", output=tmp_path, progress=False)
    files = explorer_files(record.explorer)
    unregister("toy-cards-redraw")
    register(declare(lambda result, config: present(result, config, ("b",))))
    assert redraw_figures(tmp_path) == {"toy-cards-redraw.json": ["b"]}
    assert not (tmp_path / "toy-cards-redraw" / "a.png").exists()  # the stale figure went
    assert files and all((tmp_path / f).is_file() for f in files)
