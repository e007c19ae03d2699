"""Benchmark: the full protocol (``mmconcepts reproduce --full``), experiment by experiment: wall, CPU and memory.

Runs ``mmconcepts reproduce --full --workers N --only ID --output OUTPUT`` (with ``--data-root DIR`` when given:
each experiment on the real sets found there and on generated data) for each experiment in turn, each in a
child process measured as ``/usr/bin/time`` measures it (``os.wait4``): the wall time, the CPU time (user +
system) of the child and of the worker processes it waited for, and the peak resident memory of the largest of
them. The wall time of each run (real data, generated data) is the one its result record states when the child
ends (kept with the measurement: a later run that rewrites the records does not change the table).

Each child's measurement is appended to ``OUTPUT/timings.jsonl`` as it ends (its warnings and errors to
``OUTPUT/timings.log``), and an experiment measured there without error is not run again: run the same command
again to go on after an interruption. The experiment that was interrupted then starts again (chapter 3's fold
caches, kept in the cache folder, spare the folds it had finished, so its measurement is then below a whole
run's). The table printed at the end (Markdown) is made from that file and from the records.

Run:  .venv/bin/python benchmarks/full_protocol.py --output results-full [--data-root DIR] [--workers 2]
      [--experiments ch3-choreography ch3-unseen ...] [--preset full] [--table-only]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path


def _experiments() -> list[str]:
    from mmconcepts.engine import all_experiments, load_experiments

    load_experiments()
    return [e.id for e in all_experiments()]


def measure(exp_id: str, args: argparse.Namespace) -> dict:
    """Run one experiment's reproduction in a child process; its wall, CPU and peak memory."""
    cmd = [sys.executable, "-m", "mmconcepts", "-q", "reproduce", f"--{args.preset}", "--workers", str(args.workers),
           "--only", exp_id, "--output", str(args.output)]
    env = dict(os.environ)
    if args.data_root:
        cmd += ["--data-root", str(args.data_root)]
    else:  # generated data only, whatever the environment names
        env.pop("MMCONCEPTS_DATA_ROOT", None)
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    with open(args.output / "timings.log", "a") as log:  # the children's warnings and errors
        log.write(f"== {exp_id} {started}\n")
        log.flush()
        child = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=log)
        _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    return {"experiment": exp_id, "started_at": started, "wall_s": round(time.perf_counter() - t0, 3),
            "cpu_s": round(usage.ru_utime + usage.ru_stime, 3), "peak_rss_kb": int(usage.ru_maxrss),
            "returncode": child.returncode, "workers": args.workers, "preset": args.preset,
            "data_root": bool(args.data_root), "records": _records(args.output, exp_id)}


def _records(output: Path, exp_id: str) -> dict[str, float | None]:
    """The wall time each of the experiment's records states, by data ("real", "synthetic")."""
    from mmconcepts.engine.outputs import record_path

    out: dict[str, float | None] = {}
    for path in (record_path(output, exp_id), record_path(output, exp_id, secondary=True)):
        try:
            record = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(record, dict) and record.get("experiment") == exp_id and record.get("status") == "ok":
            out[str(record.get("variant"))] = record.get("elapsed_s")
    return out


def _duration(seconds: float | None) -> str:
    from mmconcepts.report._model import format_duration  # the report's own form of a run time

    return "-" if seconds is None else format_duration(seconds)


def _measured(output: Path) -> list[dict]:
    path = output / "timings.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def table(output: Path) -> str:
    """The Markdown table of the last measurement of each experiment in ``output/timings.jsonl``."""
    last: dict[str, dict] = {}
    for entry in _measured(output):
        last[entry["experiment"]] = entry
    rows = ["| experiment | real data (record) | generated data (record) | wall (process) | CPU | peak memory |",
            "|---|---|---|---|---|---|"]
    totals = {"real": 0.0, "synthetic": 0.0, "wall": 0.0, "cpu": 0.0}
    peak = 0
    for exp_id, entry in last.items():
        walls = entry["records"] if "records" in entry else _records(output, exp_id)
        note = "" if entry["returncode"] == 0 else f" (exit {entry['returncode']})"
        rows.append(f"| {exp_id}{note} | {_duration(walls.get('real'))} | {_duration(walls.get('synthetic'))} | "
                    f"{_duration(entry['wall_s'])} | {_duration(entry['cpu_s'])} | "
                    f"{entry['peak_rss_kb'] / 1e6:.2f} GB |")
        totals["real"] += walls.get("real") or 0.0
        totals["synthetic"] += walls.get("synthetic") or 0.0
        totals["wall"] += entry["wall_s"]
        totals["cpu"] += entry["cpu_s"]
        peak = max(peak, entry["peak_rss_kb"])
    rows.append(f"| **all** | {_duration(totals['real'])} | {_duration(totals['synthetic'])} | "
                f"{_duration(totals['wall'])} | {_duration(totals['cpu'])} | {peak / 1e6:.2f} GB |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--output", type=Path, required=True, help="results folder (kept: rerun to resume)")
    parser.add_argument("--data-root", type=Path, default=None, help="the real data sets (default: generated only)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--preset", choices=("full", "quick", "smoke"), default="full")
    parser.add_argument("--experiments", nargs="+", default=None, help="default: every registered experiment")
    parser.add_argument("--table-only", action="store_true", help="print the table of the runs made so far")
    args = parser.parse_args()
    args.output.mkdir(parents=True, exist_ok=True)
    if not args.table_only:
        done = {e["experiment"] for e in _measured(args.output) if e["returncode"] == 0 and e["preset"] == args.preset}
        for exp_id in [e for e in args.experiments or _experiments() if e not in done]:
            entry = measure(exp_id, args)
            with open(args.output / "timings.jsonl", "a") as f:
                f.write(json.dumps(entry) + "\n")
            print(f"{exp_id}: {_duration(entry['wall_s'])} wall, {_duration(entry['cpu_s'])} CPU, "
                  f"{entry['peak_rss_kb'] / 1e6:.2f} GB, exit {entry['returncode']}", file=sys.stderr, flush=True)
    print(table(args.output))


if __name__ == "__main__":
    main()
