"""The result record as a dataclass: exactly the JSON schema the runner writes, read back unchanged."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mmconcepts.errors import ExperimentError
from mmconcepts.experiments import RECORD_KEYS, SCHEMA_VERSION, ClaimRecord, ResultRecord, Table, load_record

RECORDS = Path(__file__).resolve().parents[1] / "data" / "records"
#: Records written by `mmconcepts reproduce --quick` at commit d273023 (schema 2, before claims had kinds).
SCHEMA_2 = ["ch2-nmf-recovery.json", "ch3-combinations.synthetic.json"]


def test_records_written_by_the_runner_round_trip_byte_for_byte(toy, tmp_path):
    from mmconcepts.experiments import run_experiment

    run_experiment("toy-mean", output=tmp_path, progress=False)
    path = tmp_path / "toy-mean.json"
    text = path.read_text(encoding="utf-8")
    record = ResultRecord.from_json(text)
    assert record.to_json() == text
    assert ResultRecord.from_dict(record.to_dict()).to_json() == text
    assert ResultRecord.from_dict(dict(record)).to_json() == text  # the mapping view reads back too
    assert list(json.loads(text)) == list(RECORD_KEYS) == list(record.to_dict())
    assert load_record(path).to_json() == text
    assert record.schema_version == SCHEMA_VERSION == 5
    assert record.digest_ok is True and json.loads(text)["digest"] == record.digest
    assert [c.kind for c in record.claims] == ["thesis", "ours", "magnitude"]


@pytest.mark.parametrize("name", SCHEMA_2)
def test_schema_2_records_read_with_unclassified_claims(name):
    text = (RECORDS / name).read_text(encoding="utf-8")
    old = json.loads(text)
    record = ResultRecord.from_json(text)
    assert record.schema_version == 2 and record.units == {} and record.split_groups == {}
    assert {c.kind for c in record.claims} == {"unclassified"}
    assert [c.verdict for c in record.claims] == [c["verdict"] for c in old["claims"]]
    assert [c.support for c in record.claims] == [c["support"] for c in old["claims"]]
    assert list(record.metrics) == list(old["metrics"])
    assert load_record(RECORDS / name) is not None
    # written back, it is a record of this schema's keys that reads back the same
    again = ResultRecord.from_json(record.to_json())
    assert again.to_json() == record.to_json()


#: Records of schema 3 (before the concept explorer): two smoke records of the golden set as that schema wrote them.
SCHEMA_3 = Path(__file__).resolve().parents[1] / "data" / "records" / "schema-3"


@pytest.mark.parametrize("name", ["ch6-concepts.json", "ch7-online.json"])
def test_schema_3_records_read_without_an_explorer(name):
    text = (SCHEMA_3 / name).read_text(encoding="utf-8")
    old = json.loads(text)
    assert old["schema_version"] == 3 and "explorer" not in old
    record = ResultRecord.from_json(text)
    assert record.schema_version == 3 and record.explorer == {} and record["explorer"] == {}
    assert record.metrics.keys() == old["metrics"].keys() and [c.verdict for c in record.claims] == \
        [c["verdict"] for c in old["claims"]]
    again = json.loads(record.to_json())  # written back: this schema's keys, the explorer empty
    assert list(again) == list(RECORD_KEYS) and again["explorer"] == {}


def test_an_explorer_entry_round_trips():
    entry = {"note": "n", "cards": [{"title": "atom 1", "note": "", "labels": [{"label": "seven", "share": 0.5}],
                                     "clips": [{"path": "x/explorer/card-1-clip-1.wav", "seconds": 0.5,
                                                "sample_rate": 8000, "caption": "c"}], "images": [], "motions": []}]}
    record = ResultRecord(experiment="x", status="ok", explorer=entry)
    assert list(record.to_dict()).index("explorer") == list(RECORD_KEYS).index("figures") + 1
    assert ResultRecord.from_json(record.to_json()).explorer == entry


def test_real_record_fields_are_typed():
    record = ResultRecord.from_json((RECORDS / "ch3-combinations.synthetic.json").read_text(encoding="utf-8"))
    assert record.experiment == "ch3-combinations" and record.status == "ok" and record.variant == "synthetic"
    assert record.schema_version == 2
    assert isinstance(record.tables["distribution"], Table)
    assert record.tables["distribution"].columns == ["occurrences", "examples", "combinations"]
    assert [type(c) for c in record.claims] == [ClaimRecord]
    assert record.claims[0].verdict in ("holds", "fails", "inconclusive", "not evaluated")
    assert record.metrics["n_examples"] == 277.0
    # the mapping view gives the JSON values (claims and tables as dicts), as the dict the runner used to return
    assert record["claims"][0]["rule"] == record.claims[0].rule
    assert record["tables"]["distribution"]["columns"] == ["occurrences", "examples", "combinations"]
    assert record.get("no such key") is None and "metrics" in record and len(record) == len(RECORD_KEYS)


def test_schema_1_record_without_the_newer_keys_loads_with_defaults():
    path = RECORDS / "ch3-combinations.schema1.json"
    old = json.loads(path.read_text(encoding="utf-8"))
    assert {"variant", "code", "samples", "intervals", "sample_units", "warnings"}.isdisjoint(old)
    record = load_record(path)
    assert record is not None and record.schema_version == 1
    assert record.variant == "synthetic" and record.code is None  # no data: generated data
    assert record.samples == record.intervals == record.sample_units == {} and record.warnings == []
    assert [c.verdict for c in record.claims] == ["holds"]  # from holds: True
    assert [c.support for c in record.claims] == [None] and record.claims[0].basis == ""
    assert record.metrics == old["metrics"]
    assert ResultRecord.from_dict(dict(old, data={"choreo1": "/d"})).variant == "real"
    assert ResultRecord.from_dict({**old, "claims": [{"text": "t", "rule": "a > 0", "holds": False},
                                                     {"text": "u", "rule": "a > 0"}]}).claims[1].verdict == \
        "not evaluated"


def test_known_answer_json():
    """A record built by hand is written as exactly this JSON (key order, null for NaN, indentation)."""
    record = ResultRecord(experiment="x-1", status="ok", title="T", preset="quick", config={"seed": 0}, seed=0,
                          metrics={"a": 0.5, "b": math.nan}, samples={"a": [0.25, None]},
                          claims=[ClaimRecord(text="a is positive", rule="a > 0", kind="ours", holds=True,
                                              verdict="holds", basis="reported numbers")],
                          tables={"t": Table("cap", ["k", "v"], [[1, None]])}, figures={"f": "x-1/f.png"},
                          elapsed_s=1.5)
    d = record.to_dict()
    assert list(d) == list(RECORD_KEYS)
    assert d["metrics"] == {"a": 0.5, "b": None}
    assert d["claims"] == [{"text": "a is positive", "rule": "a > 0", "kind": "ours", "source": "", "holds": True,
                            "verdict": "holds", "basis": "reported numbers", "tests": [], "scope": "", "ratio": None,
                            "ratio_interval": None, "settings": [], "detail": "", "support": None}]
    assert d["tables"] == {"t": {"title": "cap", "columns": ["k", "v"], "rows": [[1, None]], "note": ""}}
    text = record.to_json()
    assert text.startswith('{\n  "schema_version": 5,\n  "experiment": "x-1",\n  "title": "T",\n') and text.endswith("}\n")
    assert '"b": null' in text and "NaN" not in text
    back = ResultRecord.from_json(text)
    assert math.isnan(back.metrics["b"]) and back.metrics["a"] == 0.5
    assert math.isnan(back["metrics"]["b"])  # the mapping view keeps metrics as floats
    assert back.to_json() == text


@pytest.mark.parametrize("text, fragment", [
    ("not json", "not valid JSON"),
    ("[1, 2]", "not a result record"),
    ('{"experiment": "x", "status": "ok"}', "not a result record"),
    ('{"schema_version": 6, "experiment": "x", "status": "ok"}', "schema version 6"),
    ('{"schema_version": 4, "experiment": "x", "status": "ok", "explorer": [1]}', "explorer of a result record"),
    ('{"schema_version": true, "experiment": "x", "status": "ok"}', "schema version True"),
    ('{"schema_version": 2, "experiment": "x", "status": "ok", "metrics": [1]}', "metrics"),
    ('{"schema_version": 2, "experiment": "x", "status": "ok", "metrics": {"a": "high"}}', "malformed"),
    ('{"schema_version": 2, "experiment": "x", "status": "ok", "tables": {"t": {"rows": []}}}', "malformed"),
    ('{"schema_version": 2, "experiment": "x", "status": "ok", "claims": [{"text": "t"}]}', "claim"),
])
def test_not_a_record(text, fragment, tmp_path):
    with pytest.raises(ExperimentError, match=fragment):
        ResultRecord.from_json(text)
    (tmp_path / "r.json").write_text(text)
    assert load_record(tmp_path / "r.json") is None


# --------------------------------------------------------------------------- property: JSON round trip
_names = st.from_regex(r"[a-z][a-z0-9_.]{0,8}", fullmatch=True)
_floats = st.floats(allow_nan=True, allow_infinity=False, width=64)
_cells = st.one_of(st.none(), st.integers(-10**6, 10**6), st.floats(allow_nan=False, allow_infinity=False),
                   st.text(max_size=8))


@st.composite
def _records(draw):
    n_cols = draw(st.integers(1, 3))
    tables = {draw(_names): Table(draw(st.text(max_size=10)), [f"c{i}" for i in range(n_cols)],
                                  draw(st.lists(st.lists(_cells, min_size=n_cols, max_size=n_cols), max_size=3)),
                                  note=draw(st.text(max_size=10)))
              for _ in range(draw(st.integers(0, 2)))}
    claims = [ClaimRecord(text=draw(st.text(min_size=1, max_size=10)), rule="a > 0",
                          kind=draw(st.sampled_from(["thesis", "magnitude", "ours", "check"])),
                          source=draw(st.text(max_size=10)),
                          holds=draw(st.sampled_from([True, False, None])),
                          verdict=draw(st.sampled_from(["holds", "fails", "depends", "inconclusive", "not evaluated",
                                                        "matches", "below", "above"])),
                          tests=[{"comparison": "a > 0", "margin": draw(st.floats(-1, 1)),
                                  "interval": draw(st.one_of(st.none(), st.lists(st.floats(-1, 1), min_size=2,
                                                                                 max_size=2))),
                                  "decided": draw(st.sampled_from([True, False, None])), "n_units": 5, "df": 4.0,
                                  "note": ""}],
                          scope=draw(st.sampled_from(["", "within one fit"])),
                          ratio=draw(st.one_of(st.none(), st.floats(0, 2))),
                          support=draw(st.one_of(st.none(), st.floats(0, 1))), basis=draw(st.text(max_size=10)))
              for _ in range(draw(st.integers(0, 2)))]
    return ResultRecord(
        experiment=draw(st.from_regex(r"[a-z0-9]+(-[a-z0-9]+)*", fullmatch=True)),
        status=draw(st.sampled_from(["ok", "failed", "skipped"])),
        message=draw(st.one_of(st.none(), st.text(max_size=20))),
        preset=draw(st.sampled_from(["quick", "full", "custom"])),
        config={"seed": draw(st.integers(0, 10**9)), "sizes": draw(st.lists(st.integers(), max_size=3))},
        seed=draw(st.integers(0, 10**9)),
        variant=draw(st.sampled_from(["real", "synthetic"])),
        code=draw(st.one_of(st.none(), st.text(alphabet="0123456789abcdef", min_size=16, max_size=16))),
        data=draw(st.dictionaries(_names, st.text(max_size=10), max_size=2)),
        metrics=draw(st.dictionaries(_names, _floats, max_size=5)),
        intervals=draw(st.dictionaries(_names, st.lists(st.floats(allow_nan=False, allow_infinity=False),
                                                        min_size=2, max_size=2), max_size=2)),
        samples=draw(st.dictionaries(_names, st.lists(st.one_of(st.none(), st.floats(allow_nan=False,
                                                                                     allow_infinity=False)),
                                                      max_size=4), max_size=3)),
        sample_units=draw(st.dictionaries(_names, st.text(min_size=1, max_size=8), max_size=2)),
        units=draw(st.dictionaries(_names, st.fixed_dictionaries(
            {"kind": st.sampled_from(["independent", "resampled", "within-fit"]), "test_train_ratio": st.floats(0, 1),
             "description": st.text(max_size=8)}), max_size=2)),
        split_groups=draw(st.dictionaries(_names, st.fixed_dictionaries(
            {"by": st.text(max_size=8), "n_folds": st.integers(1, 10), "shared_sources": st.integers(0, 3)}),
            max_size=2)),
        reference=draw(st.dictionaries(_names, st.floats(allow_nan=False, allow_infinity=False), max_size=2)),
        claims=claims, tables=tables,
        figures=draw(st.dictionaries(_names, st.text(max_size=10), max_size=2)),
        notes=draw(st.lists(st.text(max_size=20), max_size=3)),
        extra={"k": draw(st.lists(st.one_of(st.none(), st.integers(), st.text(max_size=5)), max_size=3))},
        warnings=draw(st.lists(st.text(max_size=20), max_size=2)),
        elapsed_s=draw(st.floats(0, 1e5)),
        started_at="2026-01-01T00:00:00+00:00", python="3.11.7", platform="Linux",
    )


@settings(max_examples=150, deadline=None)
@given(_records())
def test_json_round_trip_property(record):
    text = record.to_json()
    back = ResultRecord.from_json(text)
    assert back.to_json() == text
    json.loads(text, parse_constant=lambda token: pytest.fail(f"non-strict JSON token {token}"))
    # metrics: NaN in memory, null in the JSON, NaN again when read; every other number unchanged
    stored = json.loads(text)["metrics"]
    for name, value in record.metrics.items():
        assert (stored[name] is None) == math.isnan(value)
        assert math.isnan(back.metrics[name]) if math.isnan(value) else back.metrics[name] == value
    assert back.tables.keys() == record.tables.keys()
    assert all(back.tables[n].rows == record.tables[n].rows for n in record.tables)
    assert [c.to_dict() for c in back.claims] == [c.to_dict() for c in record.claims]
    view = dict(back)  # the mapping view is the JSON dict, metrics aside
    assert {k: v for k, v in view.items() if k != "metrics"} == {k: v for k, v in json.loads(text).items()
                                                                 if k != "metrics"}


def test_a_metric_too_big_for_a_float_is_an_experiment_error():
    from mmconcepts.errors import ExperimentError
    from mmconcepts.engine.record import ResultRecord

    with pytest.raises(ExperimentError, match="OverflowError"):
        ResultRecord.from_dict({"schema_version": 2, "experiment": "x", "status": "ok", "metrics": {"a": 10**400}})


# --------------------------------------------------------------------------- the digest of the computed content


def _sha256_of_content(d):
    """The digest computed here from the JSON dict, independently of the package: SHA-256 of the canonical JSON
    (sorted keys, no spaces, ASCII) of every key but the digest and the clock."""
    import hashlib

    content = {k: v for k, v in d.items() if k not in ("digest", "elapsed_s", "started_at")}
    return hashlib.sha256(json.dumps(content, sort_keys=True, separators=(",", ":"), ensure_ascii=True,
                                     allow_nan=False).encode("ascii")).hexdigest()


def _hand_record(**kw):
    return ResultRecord(experiment="x-1", status="ok", preset="quick", config={"seed": 0}, seed=0,
                        metrics={"a": 0.5, "b": math.nan}, samples={"a": [0.25, 0.75]},
                        claims=[ClaimRecord(text="a is positive", rule="a > 0", kind="ours", holds=True,
                                            verdict="holds", basis="reported numbers")],
                        tables={"t": Table("cap", ["k", "v"], [[1, 2.5]])}, elapsed_s=1.5,
                        started_at="2026-01-01T00:00:00+00:00", **kw)


def test_the_digest_is_the_sha256_of_the_computed_content():
    record = _hand_record()
    d = json.loads(record.to_json())
    assert d["digest"] == record.digest == _sha256_of_content(d)
    assert list(d)[-1] == "digest"


@pytest.mark.parametrize("edit", [
    lambda r: r.metrics.update(a=0.6),
    lambda r: r.samples["a"].append(1.0),
    lambda r: setattr(r.claims[0], "verdict", "fails"),
    lambda r: setattr(r.claims[0], "text", "a is negative"),
    lambda r: r.tables["t"].rows[0].__setitem__(1, 3.5),
    lambda r: r.config.update(seed=1),
    lambda r: setattr(r, "status", "failed"),
    lambda r: r.intervals.update(a=[0.1, 0.9]),
])
def test_the_digest_changes_with_any_computed_number_verdict_or_claim(edit):
    record = _hand_record()
    before = record.digest
    edit(record)
    assert record.digest != before


def test_the_digest_leaves_out_the_clock():
    record = _hand_record()
    before = record.digest
    record.elapsed_s, record.started_at = 99.0, "2030-01-01T00:00:00+00:00"
    assert record.digest == before


@pytest.mark.parametrize("edit, ok", [
    (lambda d: None, True),
    (lambda d: d.update(elapsed_s=7.0, started_at="yesterday"), True),  # the clock is not digested
    (lambda d: d["metrics"].update(a=0.6), False),
    (lambda d: d["metrics"].update(b=math.inf), False),  # a metric not measured made infinite
    (lambda d: d["metrics"].update(b=math.nan), True),  # NaN is how null is read back: the same content
    (lambda d: d["claims"][0].update(verdict="fails"), False),
    (lambda d: d["claims"][0].pop("support"), False),  # a key removed, even one read back with its default
    (lambda d: d.update(extra_key=1), False),
    (lambda d: d.pop("digest"), False),  # schema 5 without a digest
    (lambda d: d.update(digest=None), False),
    (lambda d: d.update(digest=12), False),
    (lambda d: d.update(digest="0" * 64), False),
    (lambda d: d.update(schema_version=4) or d.pop("digest"), None),  # an older record: no digest to check
    (lambda d: d.update(schema_version=4), False),  # a digest that does not match, whatever the schema
])
def test_a_record_read_back_says_whether_its_digest_matches(edit, ok):
    d = json.loads(_hand_record().to_json())
    edit(d)
    assert ResultRecord.from_json(json.dumps(d)).digest_ok is ok


def test_a_record_made_in_memory_has_a_matching_digest():
    assert _hand_record().digest_ok is True
    assert ResultRecord.from_dict(dict(_hand_record())).digest_ok is True  # the mapping view carries the digest


def test_records_of_older_schemas_have_no_digest_to_check():
    for name in ["ch2-nmf-recovery.json", "ch3-combinations.schema1.json"]:
        assert load_record(RECORDS / name).digest_ok is None
