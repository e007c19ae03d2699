"""The HTML/Markdown report built from result records."""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser

import pytest

from mmconcepts.errors import ExperimentError
from mmconcepts.experiments import Claim, Result, register, reproduce, run_experiment
from mmconcepts.report import write_report


class _Collector(HTMLParser):
    """Collects text, <img> sources and checks tags are balanced."""

    VOID = {"meta", "img", "br", "hr", "link", "input"}

    def __init__(self):
        super().__init__()
        self.stack, self.text, self.imgs, self.errors = [], [], [], []

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.imgs.append(dict(attrs)["src"])
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack.pop() != tag:
            self.errors.append(tag)

    def handle_data(self, data):
        self.text.append(data)


def _parse(html_text):
    parser = _Collector()
    parser.feed(html_text)
    parser.close()
    return parser


@pytest.fixture
def results(toy, tmp_path):
    """A results folder with an ok, a failed and a skipped record, and a stray JSON file."""
    register(toy.FAIL)
    register(toy.SKIP)
    out = tmp_path / "results"
    reproduce(output=out, progress=False)
    (out / "settings.json").write_text(json.dumps({"not": "a record"}))
    (out / "broken.json").write_text("{ not json")
    return out


def test_report_shows_metrics_thesis_values_and_verdicts(results):
    html_path, md_path = write_report(results)
    assert html_path == results / "report.html" and md_path == results / "report.md"
    stored = json.loads((results / "toy-mean.json").read_text())
    mean = stored["metrics"]["mean"]
    ours = f"{mean:.4g}"
    html_text = html_path.read_text()
    md = md_path.read_text()

    # numbers table: metric | thesis | ours on each data, thesis blank when absent
    assert "| metric | thesis | generated data |" in md
    assert f"| mean | 0.5 | {ours} |" in md
    assert f"| std | 0.2887 | {stored['metrics']['std']:.4g} |" in md
    assert re.search(r"\| 1\.chunk_mean \| +\| [0-9.]+ \|", md)
    assert f'<td>mean</td><td class="num">0.5</td><td class="num">{ours}</td>' in html_text

    # claims with their kind, the thesis' source, the verdict per data and the test behind it
    assert "| claim | kind | thesis source | rule | generated data | test on generated data |" in md
    # (the toy keeps no per-fold samples: its verdicts say they were decided without a spread)
    assert re.search(r"\| The sample mean is close to one half\. \| thesis \| Section 0\.0 \(line 1\) \| [^|]+ \| "
                     r"holds \(no spread\) \| abs\(mean - 0\.5\) &lt; 0\.1: margin \+0\.0\d+ \(no spread\) \|", md)
    assert re.search(r"\| The sample mean exceeds one \(false on purpose\)\. \| ours \|   \| [^|]+ \| fails \(no spread\) \|",
                     md)
    # a magnitude: the thesis' number written once (the reference table) fills the text; no samples, no interval
    assert re.search(r"\| The sample mean against the thesis' 0\.5\. \| magnitude \| Table 0\.0 \(line 2\) \| mean \| "
                     r"inconclusive \| ours / thesis 1\.\d+ \|", md)
    assert "verdict-holds" in html_text and "verdict-fails" in html_text and "verdict-inconclusive" in html_text

    # summary lines: what ran (status), on which data, and the claims' verdicts counted apart by kind, each
    # experiment linked to its run's anchor
    assert "| experiment | title | data | ran | thesis | magnitude | ours | run time |" in md
    assert ("| [`toy-mean`](#exp-toy-mean-synthetic) | Toy: the mean of uniform numbers | generated data | ran "
            "| 1 holds | 1 inconclusive | 1 fails | ") in md
    assert re.search(r"\| \[`toy-fail`\]\(#exp-toy-fail-synthetic\) \| [^|]+ \| [^|]+ \| FAILED \|   \|   \|   \|", md)
    assert re.search(r"\| \[`toy-skip`\]\(#exp-toy-skip-synthetic\) \| [^|]+ \| [^|]+ \| skipped \|", md)
    assert ("On generated data: 1 run(s) ran (1 failed, 2 skipped); thesis statements: 1 holds; magnitudes "
            "(ours / thesis): 1 inconclusive; our checks: 1 fails.") in md
    assert "| thesis statements | generated data | 1 | 1 holds, 0 fails, 0 depends, 0 inconclusive, 0 not evaluated |" in md
    assert "chance alone would make about 1 x 0.025 = 0.0 of them hold" in md
    # the tables by kind: thesis statements with where they replicate, magnitudes, ours
    thesis = md.split("#### Thesis statements: which replicate")[1].split("####")[0]
    assert "| [`toy-mean`](#exp-toy-mean) | [The sample mean is close to one half.](#exp-toy-mean-claim-1) | " \
           "Section 0.0 (line 1) | holds (no spread) | holds |" in thesis
    assert "false on purpose" not in thesis and "false on purpose" in md.split("#### Our checks")[1]
    assert "broke on purpose" in md and "no real data here" in md

    # result table, config, run info, figures
    assert "Quantiles of the sample" in md and "| 0.25 |" in md
    assert "| n_chunks | 4 |" in md and "| sizes | [1, 2, 3] |" in md
    assert "![figure hist](toy-mean/hist.png)" in md
    parsed = _parse(html_text)
    assert parsed.errors == [] and parsed.stack == []
    assert parsed.imgs == ["toy-mean/hist.png"]
    assert (results / parsed.imgs[0]).is_file()
    assert "<style>" in html_text and "<link" not in html_text  # self-contained


def test_report_escapes_html(results):
    html_text = write_report(results)[0].read_text()
    assert "A &lt;toy&gt; experiment &amp; nothing more." in html_text
    assert "<toy>" not in html_text
    assert "abs(mean - 0.5) &lt; 0.1" in html_text


def test_report_ignores_non_records_and_logs_it(results, caplog):
    with caplog.at_level("INFO", logger="mmconcepts"):
        _, md_path = write_report(results)
    assert "settings.json: not a result record" in caplog.text
    assert "broken.json: not a result record" in caplog.text
    md = md_path.read_text()
    assert "settings" not in md and "4 experiment(s)" in md
    # a file that is not even JSON may be a truncated record: listed, not silently dropped
    assert re.search(r"\| broken\.json \| not a valid result record: .+ \|", md)


def _damaged(results):
    """Records damaged by hand: truncated, a string metric, claims not a list, a list config, int notes."""
    good = json.loads((results / "toy-mean.json").read_text())
    (results / "cut.json").write_text(json.dumps(good)[:200])
    bad_metric = dict(good, experiment="toy-cut-metric", metrics=dict(good["metrics"], mean="high"))
    (results / "bad-metric.json").write_text(json.dumps(bad_metric))
    (results / "bad-claims.json").write_text(json.dumps(dict(good, experiment="toy-bad-claims", claims={"a": 1})))
    # read as a record, but the report cannot show it (it crashed the report once)
    (results / "list-config.json").write_text(json.dumps(dict(good, experiment="toy-list-config", config=[1])))
    (results / "int-notes.json").write_text(json.dumps(dict(good, experiment="toy-int-notes", notes=5)))
    return {"cut.json", "bad-metric.json", "bad-claims.json", "list-config.json", "int-notes.json"}


def test_damaged_records_are_listed_and_the_others_shown(results, caplog):
    damaged = _damaged(results)
    with caplog.at_level("WARNING", logger="mmconcepts"):
        html_path, md_path = write_report(results)
    md, html_text = md_path.read_text(), html_path.read_text()
    section = md.split("### Records left out")[1].split("## Summary")[0]
    listed = set(re.findall(r"^\| ([\w.-]+\.json) \|", section, re.M))
    assert listed == damaged | {"broken.json"}
    assert "4 experiment(s)" in md and "| [`toy-mean`](#exp-toy-mean-synthetic) |" in md  # the good ones are there
    assert "settings.json" not in section
    assert 'id="records-left-out"' in html_text and not _parse(html_text).errors
    for name in damaged:
        assert f"{name}: left out of the report" in caplog.text


def test_report_checks_stored_verdicts_against_the_records_numbers(results, caplog):
    path = results / "toy-mean.json"
    record = json.loads(path.read_text())
    record["claims"][1]["verdict"] = "holds"  # tampered: the stored verdict disagrees with the numbers
    record["metrics"]["mean"] = None  # and a metric is now unknown (NaN)
    path.write_text(json.dumps(record))
    with caplog.at_level("WARNING", logger="mmconcepts.report"):
        md = write_report(results)[1].read_text()
    assert re.search(r"\| The sample mean exceeds one [^|]+ \| ours \|   \| [^|]+ \| not evaluated \(stored as holds; "
                     r"the record's numbers give not evaluated\) \|", md)
    assert re.search(r"\| The sample mean is close to one half\. \| thesis \| [^|]+ \| [^|]+ \| not evaluated ", md)
    assert "| mean | 0.5 | n/a |" in md
    assert "is stored as 'holds' but the record's numbers give 'not evaluated'" in caplog.text


def test_report_shows_the_stored_verdict_and_its_test(toy, tmp_path):
    """The report renders what the record stores: the verdict and the interval of each comparison's margin."""
    exp = toy.make_experiment(
        "toy-stored",
        lambda c, x: Result(metrics={"a": 0.8, "b": 0.6}, samples={"a": [0.8, 0.82, 0.78, 0.81, 0.79],
                                                                   "b": [0.6, 0.61, 0.59, 0.62, 0.58]}),
        claims=[Claim("a beats b", "a > b", kind="thesis", source="Table 1 (line 10)")],
    )
    run_experiment(exp, output=tmp_path, progress=False)
    stored = json.loads((tmp_path / "toy-stored.json").read_text())["claims"][0]
    lo, hi = stored["tests"][0]["interval"]
    md = write_report(tmp_path)[1].read_text()
    assert f"| a beats b | thesis | Table 1 (line 10) | a &gt; b | holds | a &gt; b: margin +0.2 [{lo:.4g}, {hi:.4g}] |" in md


def test_report_of_missing_folder_is_a_clear_error(tmp_path):
    with pytest.raises(ExperimentError, match="does not exist"):
        write_report(tmp_path / "nowhere")


def test_empty_folder_gives_an_empty_report(tmp_path):
    html_path, md_path = write_report(tmp_path)
    assert "No result records found." in md_path.read_text()
    assert "No result records found." in html_path.read_text()


def test_nan_claim_shown_as_not_evaluated(toy, tmp_path):
    exp = toy.make_experiment(
        "toy-nan",
        lambda c, x: Result(metrics={"acc": float("nan"), "base": 0.5}),
        claims=[Claim("acc beats base", "acc > base")],
        reference={"acc": 0.9},
    )
    run_experiment(exp, output=tmp_path, progress=False)
    md = write_report(tmp_path)[1].read_text()
    assert "| acc beats base | ours |   | acc &gt; base | not evaluated |" in md
    assert "| acc | 0.9 | n/a |" in md


def test_report_flags_records_of_older_code_and_verdicts_without_spread(toy, tmp_path):
    from mmconcepts.experiments import Claim, Result

    exp = toy.make_experiment(
        "toy-spread",
        lambda c, x: Result(metrics={"a": 0.8, "b": 0.6}, samples={"a": [0.8, 0.81, 0.79, 0.8, 0.8],
                                                                   "b": [0.6, 0.61, 0.59, 0.6, 0.6]}),
        claims=[Claim("a beats b", "a > b")],
    )
    run_experiment(exp, output=tmp_path, progress=False)
    md = write_report(tmp_path)[1].read_text()
    assert "| a beats b | ours |   | a &gt; b | holds |" in md  # decided over the folds: no suffix
    assert re.search(r"\| a \| 0\.8 \[0\.7\d*, 0\.8\d*\] \|", md)  # no thesis number: no thesis column
    assert "| metric | generated data |" in md and "| metric | thesis |" not in md
    assert "older code" not in md
    path = tmp_path / "toy-spread.json"
    record = json.loads(path.read_text())
    record["code"] = "0000000000000000"
    path.write_text(json.dumps(record))
    assert "ran (older code)" in write_report(tmp_path)[1].read_text()


def test_claims_by_data_lists_each_claim_once_with_its_verdict_per_data_disagreements_first(toy, tmp_path):
    from mmconcepts.report._model import claims_by_data, collect

    def make(variant_metrics):
        def run(config, ctx):
            m = variant_metrics["real" if ctx.data else "synthetic"]
            return Result(metrics=m, samples={k: [v - 0.01, v, v + 0.01, v - 0.005, v + 0.005] for k, v in m.items()})
        return run

    exp = toy.make_experiment(
        "toy-bydata",
        make({"real": {"a": 0.2, "b": 0.6}, "synthetic": {"a": 0.8, "b": 0.6}}),
        claims=[Claim("b is positive", "b > 0"), Claim("a beats b", "a > b", kind="thesis", source="Table 1 (line 1)")],
        datasets=("toyset",),
    )
    data = tmp_path / "data" / "toyset"
    data.mkdir(parents=True)
    out = tmp_path / "out"
    run_experiment(exp, output=out, progress=False, data={"toyset": data}, variant="real")
    run_experiment(exp, output=out, progress=False, data={"toyset": data}, variant="synthetic")
    columns, rows = claims_by_data(collect(out))
    assert columns == ["experiment", "claim", "kind", "thesis source", "real data", "generated data", "agreement"]
    # the claim that differs comes first, though it was declared second
    assert rows == [["toy-bydata", "a beats b", "thesis", "Table 1 (line 1)", "fails", "holds", "differ"],
                    ["toy-bydata", "b is positive", "ours", "", "holds", "holds", "same"]]
    # one kind at a time: thesis statements say where they replicate
    assert claims_by_data(collect(out), "thesis")[1] == [
        ["toy-bydata", "a beats b", "thesis", "Table 1 (line 1)", "fails", "holds", "generated data only"]]
    assert claims_by_data(collect(out), "thesis")[0][-1] == "replicates on"
    md = write_report(out)[1].read_text()
    # each claim links to its row in the experiment's section (and the experiment to its section)
    assert ("| [`toy-bydata`](#exp-toy-bydata) | [a beats b](#exp-toy-bydata-claim-2) | Table 1 (line 1) | fails | "
            "holds | generated data only |" in md)
    assert '| <a id="exp-toy-bydata-claim-2"></a> | a beats b | thesis | Table 1 (line 1) | a &gt; b | fails | holds |' in md
    html = (out / "report.html").read_text()
    assert _parse(html).errors == [] and "Every claim on each data" in html


def test_markdown_shows_hand_edited_fields_verbatim(results):
    """report.md let raw HTML through (the status field, backticks in an id)."""
    good = json.loads((results / "toy-mean.json").read_text())
    edited = dict(good, experiment="toy``x<i>", status="<script>alert(1)</script>", data={"a`b": "/p<a>th"})
    (results / "edited.json").write_text(json.dumps(edited))
    md = write_report(results)[1].read_text()
    assert "<script>" not in md and "<i>" not in md.replace("```toy``x<i>```", "")
    assert "status: **&lt;script&gt;alert(1)&lt;/script&gt; (edited after it was written" in md
    # code spans whose fence is longer than any backtick run inside (CommonMark), so the text stays verbatim
    assert "```toy``x<i>``` · thesis:" in md
    assert "- data set ``a`b``: `/p<a>th`" in md


class _Anchors(HTMLParser):
    """Collects element ids, in-page links and the <details> of a page."""

    def __init__(self):
        super().__init__()
        self.ids, self.links, self.details, self.nav_links = [], [], [], []
        self._in_nav = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.append(a["id"])
        if tag == "nav":
            self._in_nav = True
        if tag == "a" and (a.get("href") or "").startswith("#"):
            self.links.append(a["href"][1:])
            if self._in_nav:
                self.nav_links.append(a["href"][1:])
        if tag == "details":
            self.details.append(a)

    def handle_endtag(self, tag):
        if tag == "nav":
            self._in_nav = False


def _anchors(html_text):
    parser = _Anchors()
    parser.feed(html_text)
    parser.close()
    return parser


def test_html_navigation_every_link_resolves_and_every_part_has_an_anchor(results):
    html_text = write_report(results)[0].read_text()
    page = _anchors(html_text)
    assert len(page.ids) == len(set(page.ids)), "duplicate ids"
    assert set(page.links) <= set(page.ids), set(page.links) - set(page.ids)
    # the contents: the summary, the left-out records, the claims and every experiment, with each run
    assert {"summary", "records-left-out", "claims", "exp-toy-mean", "exp-toy-fail", "exp-toy-skip", "exp-toy-data",
            "exp-toy-mean-synthetic"} <= set(page.nav_links)
    assert 'class="toc"' in html_text and "position: sticky" in html_text
    # one collapsible section per experiment, open by default, each with a link back to the summary
    experiments = [d for d in page.details if d.get("class") == "experiment"]
    assert len(experiments) == 4 and all("open" in d for d in experiments)
    for exp_id in ("toy-mean", "toy-fail", "toy-skip", "toy-data"):
        section = html_text.split(f'id="exp-{exp_id}"', 1)[1].split("</section>\n</div></details></section>", 1)[0]
        assert 'href="#summary"' in section
    # anchors per claim, table and figure; the summary's claims link to their rows
    assert {"exp-toy-mean-claim-1", "exp-toy-mean-claim-2", "exp-toy-mean-synthetic-table-quantiles",
            "exp-toy-mean-synthetic-fig-hist"} <= set(page.ids)
    assert 'href="#exp-toy-mean-claim-1">The sample mean is close to one half.</a>' in html_text
    # printing shows every section: the script opens them before printing
    assert 'addEventListener("beforeprint"' in html_text


def test_markdown_navigation_every_link_has_its_anchor(results):
    md = write_report(results)[1].read_text()
    anchors = re.findall(r'<a id="([^"]+)"></a>', md)
    links = re.findall(r"\]\(#([^)]+)\)", md)
    assert len(anchors) == len(set(anchors)) and links and set(links) <= set(anchors), set(links) - set(anchors)
    assert "## Contents" in md and "- [`toy-mean`](#exp-toy-mean): Toy: the mean of uniform numbers" in md
    assert md.count("[↑ back to the summary](#summary)") >= 4
    assert '<a id="exp-toy-mean-synthetic-table-quantiles"></a>\n#### Table: Quantiles of the sample' in md
    assert '<a id="exp-toy-mean-synthetic-fig-hist"></a>\n![figure hist](toy-mean/hist.png)' in md


def test_anchors_stay_unique_when_ids_collide(results):
    """Two records of one experiment and data, and ids that slug alike: every anchor still unique and resolved."""
    good = json.loads((results / "toy-mean.json").read_text())
    (results / "copy.json").write_text(json.dumps(good))
    (results / "other.json").write_text(json.dumps(dict(good, experiment="toy mean")))  # slugs as toy-mean
    html_path, md_path = write_report(results)
    page = _anchors(html_path.read_text())
    assert len(page.ids) == len(set(page.ids)) and set(page.links) <= set(page.ids)
    assert {"exp-toy-mean", "exp-toy-mean-2", "exp-toy-mean-2-synthetic-2"} <= set(page.ids)
    md = md_path.read_text()
    anchors = re.findall(r'<a id="([^"]+)"></a>', md)
    assert len(anchors) == len(set(anchors)) and set(re.findall(r"\]\(#([^)]+)\)", md)) <= set(anchors)


def test_missing_figure_is_named_not_an_image_that_cannot_load(results):
    (results / "toy-mean" / "hist.png").unlink()
    html_text, md = (p.read_text() for p in write_report(results))
    assert "<img" not in html_text and "figure file missing: <code>toy-mean/hist.png</code>" in html_text
    assert "*Figure `hist`: file missing (`toy-mean/hist.png`)*" in md


# --------------------------------------------------------------------------- the concept explorer

@pytest.fixture
def concepts(toy, tmp_path):
    """A results folder with the toy concept explorer's record (two cards: clips, thumbnails, a motion each)."""
    register(toy.CONCEPTS)
    out = tmp_path / "results"
    run_experiment("toy-concepts", output=out, progress=False)
    return out


def test_the_explorer_plays_every_clip_and_shows_every_image_and_motion(concepts):
    record = json.loads((concepts / "toy-concepts.json").read_text())
    files = {kind: [m["path"] for card in record["explorer"]["cards"] for m in card[kind]]
             for kind in ("clips", "images", "motions")}
    html_text, md = (p.read_text() for p in write_report(concepts))
    page = _parse(html_text)
    assert page.errors == []
    audio = re.findall(r'<audio controls preload="metadata" src="([^"]+)"></audio>', html_text)
    assert audio == files["clips"] and len(audio) == 4
    assert page.imgs == files["images"][:2] + files["motions"][:1] + files["images"][2:] + files["motions"][1:]
    assert all(path.endswith(".svg") for path in files["motions"])
    # one card per concept, with its aligned labels and their shares, and anchors
    assert html_text.count('<article class="card"') == 2
    assert 'aligned with <span class="label">tone <b>75 %</b></span>, <span class="label">noise <b>25 %</b></span>' \
        in html_text
    assert {"exp-toy-concepts-synthetic-explorer", "exp-toy-concepts-synthetic-card-1",
            "exp-toy-concepts-synthetic-card-2"} <= set(_anchors(html_text).ids)
    assert "Toy concepts: tones, ramps and a wave." in html_text and "220 Hz · 0.50 s" in html_text
    # the Markdown report: a compact list of links
    assert '<a id="exp-toy-concepts-synthetic-explorer"></a>\n#### Concept explorer' in md
    card = next(line for line in md.splitlines() if "**atom 0**" in line)
    assert card.startswith('- <a id="exp-toy-concepts-synthetic-card-1"></a>**atom 0**: aligned with tone (75 %), '
                           "noise (25 %) · clips: [1](toy-concepts/explorer/card-1-clip-1.wav) [2](")
    assert "motion: [1](toy-concepts/explorer/card-1-motion-1.svg)" in card


def test_explorer_files_missing_are_named_not_elements_that_cannot_load(concepts):
    (concepts / "toy-concepts" / "explorer" / "card-1-clip-2.wav").unlink()
    (concepts / "toy-concepts" / "explorer" / "card-2-image-1.png").unlink()
    (concepts / "toy-concepts" / "explorer" / "card-1-motion-1.svg").unlink()
    html_text, md = (p.read_text() for p in write_report(concepts))
    assert html_text.count("<audio") == 3 and "card-1-clip-2.wav\"" not in html_text
    assert "audio file missing: <code>toy-concepts/explorer/card-1-clip-2.wav</code>" in html_text
    assert "image file missing: <code>toy-concepts/explorer/card-2-image-1.png</code>" in html_text
    assert "motion file missing: <code>toy-concepts/explorer/card-1-motion-1.svg</code>" in html_text
    assert all(not src.endswith(("card-2-image-1.png", "card-1-motion-1.svg")) for src in _parse(html_text).imgs)
    assert "2 (missing: `toy-concepts/explorer/card-1-clip-2.wav`)" in md


def test_explorer_entries_from_a_hand_edited_record_are_shown_safely(concepts):
    path = concepts / "toy-concepts.json"
    record = json.loads(path.read_text())
    cards = record["explorer"]["cards"]
    cards[0]["title"] = "<script>alert(1)</script>"
    cards[0]["clips"][0]["path"] = "/etc/passwd"  # absolute: not a file of the results folder
    cards[0]["clips"][1]["path"] = "../outside.wav"
    cards[1]["labels"] = [{"label": "x", "share": "much"}, "not a label"]
    cards.append("not a card")
    path.write_text(json.dumps(record))
    html_text = write_report(concepts)[0].read_text()
    assert "<script>alert(1)</script>" not in html_text and "&lt;script&gt;alert(1)&lt;/script&gt;" in html_text
    assert "/etc/passwd" not in html_text and "outside.wav" not in html_text
    assert html_text.count("<audio") == 2 and html_text.count('<article class="card"') == 2
    assert '<span class="label">x</span>' in html_text


def test_a_record_of_schema_3_has_no_explorer_section(results):
    record = json.loads((results / "toy-mean.json").read_text())
    record["schema_version"] = 3
    del record["explorer"]
    (results / "toy-mean.json").write_text(json.dumps(record))
    html_text, md = (p.read_text() for p in write_report(results))
    assert "Concept explorer" not in html_text and "Concept explorer" not in md and "exp-toy-mean" in html_text


# --------------------------------------------------------------------------- the figures the report shows

def _figure_problems(fig) -> list[str]:
    """What a reader would miss: unlabelled data axes, images without a colour bar, unlabelled reference lines,
    labelled curves without a legend."""
    import numpy as np

    problems = []
    colorbar_axes = {id(a) for a in fig.axes if hasattr(a, "_colorbar")}
    has_colorbar = bool(colorbar_axes)
    fig_legend = bool(fig.legends)
    for ax in fig.axes:
        if id(ax) in colorbar_axes or not ax.get_visible():
            continue
        name = ax.get_title() or "an axes"
        if ax.images:
            if not has_colorbar:
                problems.append(f"{name}: an image without a colour bar")
            continue
        if not (ax.get_ylabel() or any(ax is a or ax.get_shared_y_axes().joined(ax, a) for a in fig.axes
                                        if a.get_ylabel())):
            problems.append(f"{name}: no y label")
        if not ax.get_xlabel() and not any(ax.get_shared_x_axes().joined(ax, a) for a in fig.axes if a.get_xlabel()):
            problems.append(f"{name}: no x label")
        for line in ax.lines:  # a horizontal line across the axes is a reference (chance, control): name it
            x = np.asarray(line.get_xdata(), dtype=float)
            y = np.asarray(line.get_ydata(), dtype=float)
            if x.size == 2 and y.size == 2 and y[0] == y[1] and x.tolist() == [0.0, 1.0] and line.get_label().startswith("_"):
                problems.append(f"{name}: an unlabelled horizontal line at {y[0]:.3g}")
        labelled = [a for a in ax.get_children() if getattr(a, "get_label", lambda: "_")() and
                    not str(a.get_label()).startswith("_") and a not in (ax.xaxis, ax.yaxis)]
        if labelled and ax.get_legend() is None and not fig_legend:
            problems.append(f"{name}: labelled curves but no legend")
    return problems


def _factorial_irl_result():
    import numpy as np

    from mmconcepts.engine.spec import Result
    from mmconcepts.experiments.ch4.factorial_irl import Config

    cfg = Config(grid_size=3, n_primitives=2, n_tasks=4, n_demos=2, demos_curve=(1, 2), tasks_curve=(2, 4))
    S, A, rng = 9, 4, np.random.default_rng(0)
    learners = ("flat", "factorial", "flat_pca", "flat_gt", "maxent", "flat_examples")

    def scores(n):
        return {name: {"deviation": rng.random(n).tolist(), "normalised": (rng.random(n) * 0.5).tolist()}
                for name in learners}

    points = {(m, N): {"train": scores(N), "transfer": scores(3)} for m, N in [(1, 4), (2, 4), (2, 2)]}
    metrics = {f"{split}.{name}.deviation": 0.5 for split in ("train", "transfer") for name in learners}
    demo = np.array([[0, 1], [1, 1], [4, 0]])
    default = {"D_true": rng.standard_normal((2, S * A)), "D_fact": rng.standard_normal((2, S * A)),
               "test_rewards": rng.standard_normal((4, S, A)), "test_demos": [demo] * 4,
               "flat_test": rng.standard_normal((4, S, A)), "fact_test": rng.standard_normal((4, S, A))}
    return Result(metrics=metrics, figure_data={"points": points, "default": default}), cfg


def test_figures_of_chapter_4_have_colour_bars_labels_and_legends():
    """Fig. 4.4 had no colour bar (and overlapping titles); every figure of ch4-factorial-irl is now readable."""
    from mmconcepts.experiments.ch4.factorial_irl import present

    figures = present(*_factorial_irl_result())
    for name, fig in figures.items():
        assert _figure_problems(fig) == [], name
    fig44 = figures["fig4_4_dictionaries"]
    assert fig44.get_layout_engine() is not None  # constrained: titles cannot overlap the row above
    bars = [a for a in fig44.axes if hasattr(a, "_colorbar")]
    assert len(bars) == 2 and all(b.get_ylabel() for b in bars)  # one labelled colour bar per row
    curves = figures["fig4_5_train_curves"].axes[0]
    assert any(c.__class__.__name__ == "ErrorbarContainer" for c in curves.containers)  # uncertainty drawn
    assert any("chance" in t.get_text() for t in curves.get_legend().get_texts())


def test_figures_of_chapter_6_name_their_chance_line():
    """Fig. 6.5-6.6 drew an unlabelled chance line; Table 6.2's bars now carry their spread over folds."""
    import numpy as np

    from mmconcepts.engine.spec import Result
    from mmconcepts.experiments.ch6.modalities import Config, _key, _setups, present
    from mmconcepts.experiments.ch6.motion_sound import DIRECTIONS, METRICS, _figure, _spaces

    cfg = Config(n_repeats=3, k_sweep=(5, 10))
    reps = [{_key(*s): 0.5 + 0.1 * r for s in _setups()} for r in range(3)]
    metrics = {"chance": 0.1, **{f"k_{k}.{w}": 0.5 for k in (5, 10) for w in ("two", "three")},
               **{f"k_{k}.{w}_std": 0.05 for k in (5, 10) for w in ("two", "three")}}
    for name, fig in present(Result(metrics=metrics, figure_data={"repetitions": reps}), cfg).items():
        assert _figure_problems(fig) == [], name
        texts = [t.get_text() for leg in [*fig.legends, *(a.get_legend() for a in fig.axes)] if leg
                 for t in leg.get_texts()]
        assert any(t.startswith("chance (0.1") for t in texts), (name, texts)
    m = {f"{d}.{s}.{k}": 0.4 for d in DIRECTIONS for s in _spaces(d) for k in METRICS}
    m.update({f"{k}_std": 0.05 for k in list(m)}, chance=0.1, **{f"shuffled.{d}.internal.cosine": 0.12 for d in DIRECTIONS})
    fig = _figure(m, "", "Table 6.2", 5)
    assert _figure_problems(fig) == []
    assert len(fig.axes[0].containers) == 2 * len(METRICS) or np.any([len(c) for c in fig.axes[0].containers])
    assert any(c.__class__.__name__ == "BarContainer" and c.errorbar is not None for c in fig.axes[0].containers)


def test_figure_check_catches_what_it_is_for():
    """The checker itself: an image without a colour bar, an unlabelled chance line, no axis labels."""
    from matplotlib.figure import Figure

    fig = Figure()
    ax1, ax2 = fig.subplots(1, 2)
    ax1.imshow([[0, 1], [1, 0]])
    ax2.plot([0, 1], [0, 1], label="curve")
    ax2.axhline(0.1, ls=":")
    problems = _figure_problems(fig)
    assert any("colour bar" in p for p in problems)
    assert any("unlabelled horizontal line" in p for p in problems)
    assert any("no y label" in p for p in problems) and any("no legend" in p for p in problems)


def test_a_spread_is_shown_beside_its_value_and_not_as_a_row(toy, tmp_path):
    exp = toy.make_experiment(
        "toy-sd",
        lambda c, x: Result(metrics={"acc": 0.8, "acc_std": 0.05, "lone_std": 0.3, "base": 0.5}),
        reference={"acc": 0.9},
    )
    run_experiment(exp, output=tmp_path, progress=False)
    md = write_report(tmp_path)[1].read_text()
    html = (tmp_path / "report.html").read_text()
    assert "| metric | thesis | generated data |" in md  # the thesis has a number here
    assert "| acc | 0.9 | 0.8, sd 0.05 |" in md
    assert "| acc_std |" not in md  # no row of its own
    assert "| lone_std |   | 0.3 |" in md  # a _std metric without its base stays a row
    assert "0.8, sd 0.05" in html and ">acc_std<" not in html


def test_report_marks_a_record_whose_digest_does_not_match(toy, tmp_path):
    run_experiment("toy-mean", output=tmp_path, progress=False)
    html_path, md_path = write_report(tmp_path)
    assert "edited after it was written" not in md_path.read_text()
    path = tmp_path / "toy-mean.json"
    record = json.loads(path.read_text())
    record["claims"][1]["verdict"] = "holds"  # edited into a verdict
    path.write_text(json.dumps(record))
    html_path, md_path = write_report(tmp_path)
    md, html_text = md_path.read_text(), html_path.read_text()
    assert "status: **ran (edited after it was written: it does not match its digest)**" in md
    assert "ran (edited after it was written: it does not match its digest)" in " ".join(_parse(html_text).text)
    record["schema_version"], _ = 4, record.pop("digest")  # made to look older: no digest to check
    path.write_text(json.dumps(record))
    assert "status: **ran (unverified: no digest)**" in write_report(tmp_path)[1].read_text()
