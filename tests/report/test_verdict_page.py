"""The documentation's verdict pages: generated from records (`mmconcepts verdicts`), and every claim they list is a
claim of the code, with the same text and kind."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from mmconcepts.cli import main
from mmconcepts.engine.digest import content_digest
from mmconcepts.errors import ExperimentError
from mmconcepts.experiments import all_experiments, reproduce
from mmconcepts.report.verdict_page import GENERATED_MARK, TALLIES_END, TALLIES_START, verdict_page

DOCS = Path(__file__).resolve().parents[2] / "docs"


def _rows(text: str) -> list[dict[str, str]]:
    """The rows of every table with the columns experiment | claim | kind of a Markdown page, as dicts."""
    rows: list[dict[str, str]] = []
    header: list[str] | None = None
    for line in text.splitlines():
        if not line.startswith("|"):
            header = None
            continue
        cells = [c.strip().replace("\\|", "|").replace("&lt;", "<").replace("&gt;", ">")
                 for c in re.split(r"(?<!\\)\|", line)[1:-1]]
        if header is None:
            header = cells
        elif set(line) <= set("|-: "):
            continue
        elif header[:3] == ["experiment", "claim", "kind"]:
            rows.append(dict(zip(header, cells)))
    return rows


def test_the_page_lists_every_claim_by_kind_with_its_verdict(toy, tmp_path):
    reproduce(output=tmp_path, ids=["toy-mean"], progress=False)
    page = verdict_page(tmp_path, command="mmconcepts reproduce --only toy-mean", commit="abc1234")
    assert page.startswith("# Verdicts") and GENERATED_MARK in page
    assert "preset **quick**, seed(s) 0, code of commit **abc1234**" in page
    assert "by `mmconcepts reproduce --only toy-mean`" in page
    rows = _rows(page)
    assert [(r["experiment"], r["claim"], r["kind"]) for r in rows] == [
        ("toy-mean", "The sample mean is close to one half.", "thesis"),
        ("toy-mean", "The sample mean against the thesis' 0.5.", "magnitude"),
        ("toy-mean", "The sample mean exceeds one (false on purpose).", "ours"),
    ]
    stored = {c["text"]: c for c in json.loads((tmp_path / "toy-mean.json").read_text())["claims"]}
    for row in rows:
        assert row["generated data"].split(" (")[0].split(":")[0] == stored[row["claim"]]["verdict"]
    assert "| thesis statements | generated data | 1 | 1 holds, 0 fails, 0 depends, 0 inconclusive, 0 not evaluated |" \
        in page
    assert str(tmp_path) not in page  # no path of the machine that made it


def test_the_page_refuses_records_of_other_code_or_mixed_runs(toy, tmp_path):
    reproduce(output=tmp_path, ids=["toy-mean"], progress=False)
    path = tmp_path / "toy-mean.json"
    record = json.loads(path.read_text())
    record["code"] = "0000000000000000"
    path.write_text(json.dumps(record))
    with pytest.raises(ExperimentError, match="do not match their digest"):  # an edited record is never a page
        verdict_page(tmp_path)
    record["digest"] = content_digest(record)  # as the other code would have written it
    path.write_text(json.dumps(record))
    with pytest.raises(ExperimentError, match="other code"):
        verdict_page(tmp_path)
    assert "not the code of this page's commit" in verdict_page(tmp_path, allow_stale=True)
    other = dict(record, experiment="toy-other", preset="full")
    other["digest"] = content_digest(other)
    (tmp_path / "toy-other.json").write_text(json.dumps(other))
    with pytest.raises(ExperimentError, match="mix presets"):
        verdict_page(tmp_path, allow_stale=True)
    with pytest.raises(ExperimentError, match="does not exist"):
        verdict_page(tmp_path / "nowhere")


def test_the_page_states_each_runs_recorded_time_and_their_totals(toy, tmp_path):
    reproduce(output=tmp_path, ids=["toy-mean"], progress=False)
    record = json.loads((tmp_path / "toy-mean.json").read_text())
    times = {"toy-mean": (90.0, "2026-01-02T10:00:00Z"), "toy-other": (45.0, "2026-01-02T10:01:00+00:00"),
             "toy-third": (None, "2026-01-02T09:00:00Z")}
    for name, (seconds, start) in times.items():
        other = dict(record, experiment=name)
        if name != "toy-mean":  # a record of another experiment, as its run would have written it
            other["digest"] = content_digest(other)
        # the run time is outside the digest: the record is still the one the run wrote
        (tmp_path / f"{name}.json").write_text(json.dumps(dict(other, elapsed_s=seconds, started_at=start)))
    section = verdict_page(tmp_path, commit="abc1234").split("## Run time", 1)[1]
    assert "| toy-mean | 1 min 30 s |" in section and "| toy-other | 45.0 s |" in section
    assert "| toy-third | not recorded |" in section
    assert "| all runs | 2 min 15 s |" in section
    # from 10:00:00 to 10:01:45 (the run without a time has no end, and is left out)
    assert "All runs: 2 min 15 s; from the first run's start to the last run's end: 1 min 45 s" in section


def test_the_command_writes_the_page_and_the_readmes_tallies(toy, tmp_path, capsys):
    reproduce(output=tmp_path / "r", ids=["toy-mean"], progress=False)
    readme = tmp_path / "README.md"
    readme.write_text(f"# R\n\nbefore\n\n{TALLIES_START}\nSTALE-BLOCK\n{TALLIES_END}\n\nafter\n")
    assert main(["verdicts", str(tmp_path / "r"), "--write", str(tmp_path / "v.md"), "--commit", "abc1234",
                 "--tallies", str(readme)]) == 0
    page = (tmp_path / "v.md").read_text()
    assert GENERATED_MARK in page
    text = readme.read_text()
    assert text.startswith("# R\n\nbefore\n\n") and text.endswith(f"{TALLIES_END}\n\nafter\n") and "STALE-BLOCK" not in text
    block = text.split(TALLIES_START)[1].split(TALLIES_END)[0]
    assert "code of commit **abc1234**" in block
    assert "| thesis statements | generated data | 1 | 1 holds, 0 fails, 0 depends, 0 inconclusive, 0 not evaluated |" \
        in block
    assert main(["verdicts", str(tmp_path / "r"), "--tallies", str(readme)]) == 2  # needs --write
    assert main(["verdicts", str(tmp_path / "nowhere")]) == 1  # an error, said in one line


def _generated_pages(kind: str = "verdicts") -> list[Path]:
    """The docs' pages written by ``mmconcepts verdicts`` (``kind="verdicts"``) or by its ``--compare`` form."""
    pages = [p for p in sorted(DOCS.rglob("*.md")) if GENERATED_MARK in p.read_text(encoding="utf-8")]
    compared = [p for p in pages if "mmconcepts verdicts --compare" in p.read_text(encoding="utf-8")]
    return compared if kind == "compare" else [p for p in pages if p not in compared]


def test_the_docs_have_a_generated_verdict_page_and_the_readme_its_tallies():
    assert DOCS / "verdicts.md" in _generated_pages()
    page = (DOCS / "verdicts.md").read_text(encoding="utf-8")
    readme = (DOCS.parent / "README.md").read_text(encoding="utf-8")
    block = readme.split(TALLIES_START)[1].split(TALLIES_END)[0]
    tallies = page.split("## Tallies", 1)[1].split("\n## ", 1)[0].strip("\n")
    assert tallies and tallies in block, "README's tallies are not those of docs/verdicts.md: run mmconcepts verdicts"


@pytest.mark.parametrize("page", _generated_pages(), ids=lambda p: p.name)
def test_every_claim_in_the_docs_is_a_claim_of_the_code(page):
    claims = {(exp.id, c.text): c.kind for exp in all_experiments() for c in exp.claims}
    rows = _rows(page.read_text(encoding="utf-8"))
    assert rows, f"{page.name} lists no claim"
    for row in rows:
        key = (row["experiment"], row["claim"])
        assert key in claims, f"{page.name}: {key} is not a claim of the code (stale page: regenerate it)"
        assert claims[key] == row["kind"], f"{page.name}: {key} is of kind {claims[key]}, not {row['kind']}"
    text = page.read_text(encoding="utf-8")
    assert re.search(r"preset \*\*(quick|full)\*\*", text) and re.search(r"code of commit \*\*[0-9a-f]{7,}", text)


def test_two_runs_compared_metric_by_metric(toy, tmp_path):
    from mmconcepts.report.verdict_page import comparison_page

    from mmconcepts.experiments import run_experiment

    run_experiment("toy-mean", output=tmp_path / "old", progress=False)
    run_experiment("toy-mean", output=tmp_path / "new", progress=False, seed=1)
    old = json.loads((tmp_path / "old" / "toy-mean.json").read_text())["metrics"]
    new = json.loads((tmp_path / "new" / "toy-mean.json").read_text())["metrics"]
    assert old["mean"] != new["mean"]
    page = comparison_page(tmp_path / "old", tmp_path / "new", ids=["toy-mean"], metrics=["mean", "*.chunk_mean"],
                           title="T", old_commit="aaaaaaa", new_commit="bbbbbbb", write=tmp_path / "c.md")
    assert (tmp_path / "c.md").read_text() == page and GENERATED_MARK in page
    assert "*before*: commit **aaaaaaa**" in page and "*after*: commit **bbbbbbb**" in page
    assert f"| mean | {old['mean']:.4g} | {new['mean']:.4g} |" in page
    assert f"| 1.chunk_mean | {old['1.chunk_mean']:.4g} | {new['1.chunk_mean']:.4g} |" in page
    assert "| std |" not in page  # not asked for
    with pytest.raises(ExperimentError, match="no experiment"):
        comparison_page(tmp_path / "old", tmp_path / "new", ids=["toy-mean"], metrics=["nothing*"], title="T")


@pytest.mark.parametrize("page", _generated_pages("compare"), ids=lambda p: p.name)
def test_every_compared_experiment_in_the_docs_is_one_of_the_code(page):
    ids = {exp.id for exp in all_experiments()}
    text = page.read_text(encoding="utf-8")
    sections = re.findall(r"^## (\S+) \((?:real|generated) data\)$", text, flags=re.M)
    assert sections, f"{page.name} compares no experiment"
    assert set(sections) <= ids, f"{page.name}: {sorted(set(sections) - ids)} are not experiments of the code"
    assert re.search(r"\*before\*: commit \*\*[0-9a-f]{7,}", text) and re.search(r"\*after\*: commit \*\*[0-9a-f]{7,}", text)


def test_where_a_thesis_statement_replicates():
    from mmconcepts.report.verdict_page import NOT_RUN, _replicates_on

    labels = ["real data", "generated data"]
    assert _replicates_on(["holds", "holds (within one fit)"], labels) == "both"
    assert _replicates_on(["fails", "holds"], labels) == "generated data only"
    assert _replicates_on(["holds", "depends (holds only under a; fails under b)"], labels) == "real data only"
    assert _replicates_on(["inconclusive", "fails"], labels) == "neither"
    assert _replicates_on([NOT_RUN, "holds (within one fit)"], labels) == "generated data (the only data)"
    assert _replicates_on([NOT_RUN, "fails"], labels) == "neither"
