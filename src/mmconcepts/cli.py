"""The ``mmconcepts`` command line: list, run and reproduce the thesis' experiments.

Examples
--------
::

    mmconcepts list
    mmconcepts run ch2-nmf-recovery                # quick preset, results in ./results
    mmconcepts run ch2-nmf-recovery --full --seed 3 --workers 8
    mmconcepts reproduce --data-root ~/mmdata --output results-full --full
    mmconcepts data list --data-root ~/mmdata
    mmconcepts data fetch fsdd --data-root ~/mmdata
    mmconcepts report results

Exit codes: 0 on success, 1 if an experiment failed (or another error occurred), 2 on a
usage error (bad option, unknown experiment id, a ``--data`` path that does not exist or does
not hold its set, a ``--data-root`` that does not exist or holds no known set without
``--allow-generated``, ``--variant real`` when no real set of the experiment is found).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import sys
import textwrap
from collections.abc import Iterator, Mapping, Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

from . import __version__
from ._paths import DEFAULT_RESULTS_DIR
from ._progress import QUIET_ENV

# mmconcepts.errors (and through it scikit-learn) and the experiments are imported inside
# the commands, so that `mmconcepts --help` answers at once.

__all__ = ["main", "build_parser"]

logger = logging.getLogger("mmconcepts")


class _UsageError(Exception):
    """An error in what the user asked for (exit code 2)."""


# --------------------------------------------------------------------------- parser


def _common_flags() -> argparse.ArgumentParser:
    # -v/-q accepted both before and after the subcommand; SUPPRESS keeps a value given
    # before the subcommand from being reset by the subparser's default.
    parent = argparse.ArgumentParser(add_help=False)
    group = parent.add_argument_group("output")
    group.add_argument(
        "-v", "--verbose", action="count", default=argparse.SUPPRESS,
        help="more log output (-vv for debug); show tracebacks of errors",
    )
    group.add_argument(
        "-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
        help="only warnings and errors: no progress bars, no notice of compiling numerical kernels",
    )
    return parent


def _workers(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an int >= 1 or -1 (one per CPU); got {text!r}") from None
    if value < 1 and value != -1:
        raise argparse.ArgumentTypeError(f"expected an int >= 1 or -1 (one per CPU); got {value}")
    return value


def _scheduler(text: str) -> str:
    from .errors import ParameterError
    from .engine.cluster import parse_scheduler

    try:
        parse_scheduler(text)
    except ParameterError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an int >= 1; got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an int >= 1; got {value}")
    return value


_BYTE_UNITS = {"": 1, "b": 1, "k": 10**3, "kb": 10**3, "m": 10**6, "mb": 10**6, "g": 10**9, "gb": 10**9,
               "t": 10**12, "tb": 10**12, "kib": 2**10, "mib": 2**20, "gib": 2**30, "tib": 2**40}


def _byte_size(text: str) -> int:
    """An argparse type: a number of bytes, with an optional unit (kB, MB, GB, TB or KiB, MiB, GiB, TiB)."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([a-zA-Z]*)\s*", text)
    unit = match.group(2).lower() if match else ""
    if match is None or unit not in _BYTE_UNITS:
        raise argparse.ArgumentTypeError(f"expected a size such as 500MB, 30GB or 2GiB; got {text!r}")
    value = int(Fraction(match.group(1)) * _BYTE_UNITS[unit])  # exact: no float rounding or overflow
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a size of at least 1 byte; got {text!r}")
    return value


def _data_root_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--data-root", metavar="DIR", type=_folder, default=None,
        help="folder holding the real data sets by name (default: $MMCONCEPTS_DATA_ROOT; "
             "without either, experiments run on generated data; a DIR that is not a folder is an error)",
    )


def _folder(text: str) -> Path:
    """An argparse type: a non-empty folder name (``Path("")`` would silently mean the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty folder name; give a folder, e.g. results")
    return Path(text)


def _run_options(parser: argparse.ArgumentParser) -> None:
    preset = parser.add_mutually_exclusive_group()
    preset.add_argument(
        "--quick", dest="preset", action="store_const", const="quick",
        help="small config that runs in seconds to minutes (default)",
    )
    preset.add_argument(
        "--full", dest="preset", action="store_const", const="full",
        help="the thesis-sized config (can take hours)",
    )
    preset.add_argument(
        "--smoke", dest="preset", action="store_const", const="smoke",
        help="the quick config made as small as it runs, for the experiments that declare one: seconds, to check "
             "that everything runs and that the records stay the same (the numbers mean nothing)",
    )
    parser.set_defaults(preset="quick")
    parser.add_argument(
        "--output", "-o", metavar="DIR", type=_folder, default=DEFAULT_RESULTS_DIR,
        help="results folder (default: %(default)s)",
    )
    _data_root_option(parser)
    parser.add_argument(
        "--data", metavar="NAME=PATH", action="append", default=[],
        help="a real data set for the experiments that use NAME, overriding the data root's "
             "(repeatable; see `mmconcepts data list` for the names)",
    )
    parser.add_argument(
        "--allow-generated", action="store_true",
        help="accept a --data-root that holds no known data set and run on generated data (without it, such a "
             "root is an error: a wrong folder would otherwise silently give results on generated data)",
    )
    parser.add_argument(
        "--workers", "-j", metavar="N", type=_workers, default=1,
        help="parallel worker processes (default: %(default)s; -1 for one per CPU)",
    )
    parser.add_argument(
        "--scheduler", metavar="ADDRESS", type=_scheduler, default=None,
        help="run the experiments' repetitions, folds and sweep points on a Dask cluster instead of "
             "--workers: 'local:N' starts N worker processes on this machine, 'tcp://HOST:PORT' uses a "
             "running dask.distributed scheduler whose workers see the same data root and cache folder "
             "(the dask extra; same numbers as a local run)",
    )
    parser.add_argument(
        "--force", action="store_true",
        help="recompute even when an up-to-date result exists",
    )


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of the ``mmconcepts`` command."""
    common = _common_flags()
    parser = argparse.ArgumentParser(
        prog="mmconcepts",
        description=textwrap.fill(
            "Reproduce the experiments of O. Mangin's thesis 'The emergence of multimodal "
            "concepts' (2014). Each experiment reproduces one table or figure, writes a JSON "
            "record and PNG figures, and checks the thesis' claims on its own numbers.",
            width=80,
        ),
        epilog=textwrap.dedent(
            """\
            examples:
              mmconcepts list
              mmconcepts run ch2-nmf-recovery
              mmconcepts run ch2-nmf-recovery --full --seed 3 --workers 8
              mmconcepts run ch6-modalities --full --scheduler local:8
              mmconcepts reproduce --full --scheduler tcp://head-node:8786 --concurrent 4
              mmconcepts reproduce --full --data choreo1=~/data/choreo1
              mmconcepts report results
              mmconcepts verdicts results --write docs/verdicts.md --tallies README.md

            exit codes: 0 success, 1 an experiment failed, 2 usage error"""
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    parser.add_argument("--version", action="version", version=f"mmconcepts {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser(
        "list", parents=[common], help="list the experiments",
        description="List every experiment: id, title, where the thesis reports it, and the "
                    "real data sets it accepts with --data.",
    )
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser(
        "run", parents=[common], help="run one experiment",
        description="Run one experiment, write DIR/ID.json and DIR/ID/*.png, and print its "
                    "metrics beside the thesis' and the verdict on each claim. A result that "
                    "is up to date (same config, seed, version and data) is not recomputed.",
    )
    p.add_argument("id", metavar="ID", help="experiment id (see `mmconcepts list`)")
    p.add_argument("--seed", type=int, metavar="N", default=None, help="replace the preset's random seed")
    p.add_argument(
        "--variant", choices=("auto", "real", "synthetic"), default="auto",
        help="data to run on: the real sets found (real), generated stand-ins (synthetic), or "
             "real when found, else generated (auto, the default)",
    )
    _run_options(p)
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser(
        "reproduce", parents=[common], help="run every experiment and write the report",
        description="Run every experiment (or those given with --only) on the real data sets "
                    "found under the data root and on generated data, keep going when one fails, "
                    "then write DIR/report.html and DIR/report.md with the real and generated "
                    "results side by side. Up-to-date results are not recomputed. Experiments "
                    "that only exist on absent real data are skipped.",
    )
    _run_options(p)
    p.add_argument(
        "--no-synthetic", dest="synthetic", action="store_false",
        help="do not also run the experiments that have real data on generated data",
    )
    p.add_argument("--only", metavar="ID", nargs="+", default=None, help="run only these experiments")
    p.add_argument(
        "--concurrent", metavar="N", type=_positive, default=1,
        help="run up to N experiments at the same time, on N processes that each run one experiment after "
             "another (sharing the --scheduler cluster, else each with --workers worker processes; "
             "default: %(default)s)",
    )
    p.set_defaults(func=_cmd_reproduce)

    p = sub.add_parser(
        "report", parents=[common], help="write the HTML/Markdown report of a results folder",
        description="Read the JSON result records of DIR and write DIR/report.html and DIR/report.md. With "
                    "--redraw, first draw every figure again from what its run kept beside it (no recomputing; "
                    "records of runs that kept nothing are left as they are).",
    )
    p.add_argument("dir", metavar="DIR", type=_folder, nargs="?", default=DEFAULT_RESULTS_DIR,
                   help="results folder (default: %(default)s)")
    p.add_argument("--redraw", action="store_true",
                   help="draw the figures again with the installed code's present(), from the kept figure data")
    p.add_argument("--only", metavar="ID", nargs="+", default=None, help="with --redraw: only these experiments")
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser(
        "verdicts", parents=[common], help="write the documentation's verdict page from a results folder",
        description="Read the JSON result records of DIR (one run of `mmconcepts reproduce`, real and generated "
                    "data) and print, or write to FILE, a Markdown page of every claim's verdict by kind of claim "
                    "(thesis statements and where they replicate, magnitudes, our checks, sanity checks) and of "
                    "each run's recorded wall time, stating the commit, code fingerprint, preset and seeds the "
                    "records came from. The records must come from the installed code.",
    )
    p.add_argument("dir", metavar="DIR", type=_folder, nargs="?", default=DEFAULT_RESULTS_DIR,
                   help="results folder (default: %(default)s)")
    p.add_argument("--write", metavar="FILE", default=None, help="write the page to FILE (default: print it)")
    p.add_argument("--title", default="Verdicts: which of the thesis' statements replicate", help="the page's title")
    p.add_argument("--made-by", metavar="COMMAND", default="",
                   help="the command that made the records, named on the page")
    p.add_argument("--commit", default=None,
                   help="the commit of the code that made the records (default: git's HEAD of the installed package)")
    p.add_argument("--allow-stale", action="store_true",
                   help="accept records of other code than the installed one (the page says so)")
    p.add_argument("--compare", metavar="OLD_DIR", default=None,
                   help="instead of the verdict page, set DIR's metrics beside those of an earlier run's folder "
                        "OLD_DIR (with --only and --metrics)")
    p.add_argument("--only", metavar="ID", nargs="+", default=None, help="the experiments to compare (--compare)")
    p.add_argument("--metrics", metavar="PATTERN", nargs="+", default=["*"],
                   help="the metric names to compare, as shell patterns (--compare; default: all)")
    p.add_argument("--old-commit", default=None, help="the commit of the code that made OLD_DIR (--compare)")
    p.add_argument("--tallies", metavar="PAGE", default=None,
                   help="also copy the page's tallies into PAGE (the README) between its <!-- tallies:start --> and "
                        "<!-- tallies:end --> markers (with --write)")
    p.set_defaults(func=_cmd_verdicts)

    p = sub.add_parser(
        "compare", parents=[common], help="check that two runs give the same numbers and verdicts",
        description="Compare the JSON result records of two results folders (two runs of the same experiments, "
                    "e.g. before and after a change of the code that should not change the results): every "
                    "metric, interval, sample, split and claim verdict. Wall-clock metrics (names matching "
                    "*time*, *seconds*, *ms_per_query*) are left out. Prints each difference; the exit status is "
                    "0 when the runs agree and 1 when they differ.",
    )
    p.add_argument("old", metavar="OLD_DIR", type=_folder, help="the results folder of the first run")
    p.add_argument("new", metavar="NEW_DIR", type=_folder, help="the results folder of the second run")
    p.add_argument("--only", metavar="ID", nargs="+", default=None, help="compare only these experiments")
    p.add_argument("--rtol", type=float, default=0.0,
                   help="relative tolerance of numbers (default: 0, equal to the bit)")
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser(
        "data", parents=[common], help="list or fetch the real data sets",
        description="The real data sets the experiments use, by name, under a data root "
                    "(--data-root DIR, else $MMCONCEPTS_DATA_ROOT).",
    )
    data_sub = p.add_subparsers(dest="data_command", metavar="ACTION", required=True)
    q = data_sub.add_parser(
        "list", parents=[common], help="every known set: where it was found, how many recordings, how to obtain it",
        description="Show every known data set, where it was found under the data root (or not), "
                    "how many recordings it holds, its licence and how to obtain it.",
    )
    _data_root_option(q)
    q.set_defaults(func=_cmd_data_list)
    q = data_sub.add_parser(
        "fetch", parents=[common], help="download, verify and unpack a set into the data root",
        description="Download a data set that has a stable public download, check its SHA-256, "
                    "and unpack it into DATA_ROOT/NAME.",
    )
    q.add_argument("name", metavar="NAME", help="data set name (see `mmconcepts data list`)")
    _data_root_option(q)
    q.add_argument("--url", default=None, help="download from this address instead of the set's own")
    q.add_argument("--sha256", default=None, help="expected SHA-256 of the download (with --url)")
    q.add_argument("--max-size", metavar="SIZE", type=_byte_size, default=None,
                   help="refuse an archive that unpacks to more than SIZE, e.g. 500MB, 30GB, 2GiB (default: the "
                        "set's own bound, else 10GB)")
    q.add_argument("--max-files", metavar="N", type=_positive, default=None,
                   help="refuse an archive of more than N files and folders (default: the set's own bound, else "
                        "100000)")
    q.set_defaults(func=_cmd_data_fetch)

    p = sub.add_parser(
        "cache", parents=[common], help="list or clear the cache of generated data and features",
        description="The folder of generated data sets and cached computations: $MMCONCEPTS_DATA, else "
                    "$XDG_CACHE_HOME/mmconcepts, else ~/.cache/mmconcepts (or --cache-dir DIR). Everything "
                    "in it can be recomputed.",
    )
    cache_sub = p.add_subparsers(dest="cache_command", metavar="ACTION", required=True)
    q = cache_sub.add_parser(
        "list", parents=[common], help="what the cache holds: one line per item, files, size, newest file",
        description="Show the cache folder and, for each item in it, its files, size and newest file.",
    )
    q.add_argument("--cache-dir", metavar="DIR", type=_folder, default=None, help="the cache folder to use")
    q.set_defaults(func=_cmd_cache_list)
    q = cache_sub.add_parser(
        "clear", parents=[common], help="delete cached files (all, some items, or the old ones)",
        description="Delete the files of the cache folder, or of the items NAME given (see `cache list`); "
                    "with --older-than, only the files last modified longer ago than AGE.",
    )
    q.add_argument("names", metavar="NAME", nargs="*", help="only these items of the cache folder")
    q.add_argument("--older-than", metavar="AGE", default=None,
                   help="only files older than AGE: numbers with units s, m, h, d, w (e.g. 12h, 7d, 1d12h)")
    q.add_argument("--cache-dir", metavar="DIR", type=_folder, default=None, help="the cache folder to use")
    q.set_defaults(func=_cmd_cache_clear)
    return parser


# --------------------------------------------------------------------------- output


def _setup_logging(verbose: int, quiet: bool) -> None:
    root = logging.getLogger("mmconcepts")
    for handler in list(root.handlers):
        if getattr(handler, "_mmconcepts_cli", False):
            root.removeHandler(handler)
    handler = logging.StreamHandler(sys.stderr)
    # a marker attribute on a stdlib handler (found and removed by the next call): typeshed's Handler has no such field
    handler._mmconcepts_cli = True  # type: ignore[attr-defined]
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s" if verbose else "%(message)s"))
    root.addHandler(handler)
    if quiet:
        root.setLevel(logging.WARNING)
    elif verbose >= 2:
        root.setLevel(logging.DEBUG)
    else:
        root.setLevel(logging.INFO)


@contextlib.contextmanager
def _quiet_processes(quiet: bool) -> Iterator[None]:
    """Under ``-q``, :data:`~mmconcepts._progress.QUIET_ENV` set for the command, in this process and in
    those it starts (worker processes inherit it), then put back as it was."""
    if not quiet:
        yield
        return
    before = os.environ.get(QUIET_ENV)
    os.environ[QUIET_ENV] = "1"
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(QUIET_ENV, None)
        else:
            os.environ[QUIET_ENV] = before


def _columns(rows: list[list[str]], indent: str = "  ", width: int | None = None) -> str:
    """``rows`` as aligned columns; with ``width``, the widest columns but the first are narrowed (down to
    :data:`_MIN_COLUMN` characters) and their cells wrapped at spaces (cut where a word is longer) so that no
    line is longer than ``width``, when it can be."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    if width is not None:
        room = width - len(indent) - 2 * (len(widths) - 1)
        while sum(widths) > room:
            i = max(range(1, len(widths)), key=lambda k: widths[k], default=0)
            if i == 0 or widths[i] <= _MIN_COLUMN:
                break
            widths[i] -= 1
    lines = []
    for r in rows:
        cells = [textwrap.wrap(c, w, break_on_hyphens=False) or [""] for c, w in zip(r, widths)]
        for k in range(max(len(c) for c in cells)):
            parts = [(c[k] if k < len(c) else "").ljust(w) for c, w in zip(cells, widths)]
            lines.append((indent + "  ".join(parts)).rstrip())
    return "\n".join(lines)


#: The narrowest a column of :func:`_columns` is made to fit the terminal.
_MIN_COLUMN = 8


def _terminal_width() -> int:
    """Columns of the terminal (``$COLUMNS`` first); 100 when the output is not a terminal."""
    import shutil

    return shutil.get_terminal_size((100, 24)).columns


def _claims_summary(claims: list[dict[str, Any]]) -> str:
    from .engine.verdicts import format_tally, tally_claims

    return format_tally(tally_claims(claims))


def _print_record(record: Mapping[str, Any], json_path: Path) -> None:
    from .report._model import format_number as _fmt

    status = record["status"]
    print(f"{record['experiment']}: {record['title']} [{record.get('thesis_ref', '')}]")
    print(f"  status: {status}   data: {record.get('variant', '?')}   preset: {record['preset']}   "
          f"seed: {record['seed']}   time: {record.get('elapsed_s', 0):.1f} s")
    for name, path in (record.get("data") or {}).items():
        print(f"  data {name}: {path}")
    print(f"  result: {json_path}")
    if status != "ok":
        print(f"  {status}: {record.get('message')}")
        return
    metrics, reference = record.get("metrics") or {}, record.get("reference") or {}
    intervals = record.get("intervals") or {}
    names = list(metrics) + [n for n in reference if n not in metrics]
    if names:
        def interval(n: str) -> str:
            lo_hi = intervals.get(n)
            return f"[{_fmt(lo_hi[0])}, {_fmt(lo_hi[1])}]" if lo_hi else ""

        rows = [["metric", "ours", "95 % interval", "thesis"]]
        rows += [[n, _fmt(metrics.get(n)), interval(n), _fmt(reference.get(n))] for n in names]
        print(_columns(rows))
    claims = record.get("claims") or []
    if claims:
        print(f"  claims: {_claims_summary(claims)}")
        for c in claims:
            scope = f", {c['scope']}" if c.get("scope") else ""
            print(f"    [{c.get('kind') or 'unclassified'}: {c.get('verdict') or 'not evaluated'}{scope}] {c['text']}  "
                  f"({c['rule']})")


# --------------------------------------------------------------------------- commands


def _data(args: argparse.Namespace) -> dict[str, Path]:
    from .errors import MMConceptsError
    from .engine import parse_data_args

    try:
        return parse_data_args(args.data)
    except MMConceptsError as exc:
        raise _UsageError(str(exc)) from exc


def _cmd_list(args: argparse.Namespace) -> int:
    from .engine import all_experiments

    experiments = all_experiments()
    if not experiments:
        print("no experiments registered")
        return 0
    rows = [["id", "title", "thesis", "data"]]
    rows += [[e.id, e.title, e.thesis_ref, ", ".join(e.datasets) or "-"] for e in experiments]
    print(_columns(rows, indent="", width=_terminal_width()))  # long cells wrapped within their column
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from .errors import MMConceptsError
    from .engine import DataPlan, get, load_experiments, run_experiment
    from .engine.workers import allocate_from_heap

    allocate_from_heap()  # the experiments' arrays from the heap: fewer page faults, the same numbers
    from .engine.outputs import record_path

    data = _data(args)
    load_experiments()  # an experiment module that does not import is not a usage error
    try:
        exp = get(args.id)
        exp.make_config(args.preset, seed=args.seed)
        # --data and --data-root checked, resolved once
        plan = DataPlan.build([exp], data, args.data_root, allow_generated=args.allow_generated)
    except MMConceptsError as exc:
        raise _UsageError(str(exc)) from exc
    entry = plan.entry(exp)
    if args.variant == "real" and not entry.sets:
        raise _UsageError(f"--variant real: {plan.missing(exp)}")
    if args.variant == "synthetic" and not exp.synthetic:
        raise _UsageError(f"--variant synthetic: {exp.id} runs only on real data ({', '.join(exp.datasets)}); "
                          "run it without --variant, or with --variant real.")
    record = run_experiment(
        exp, preset=args.preset, seed=args.seed, output=args.output, data_plan=plan, variant=args.variant,
        workers=args.workers, scheduler=args.scheduler, force=args.force, progress=not args.quiet, raise_errors=False,
    )
    secondary = entry.secondary(record.variant)
    _print_record(record, record_path(args.output, exp.id, secondary=secondary))
    if record["status"] == "failed" and args.verbose and record.get("traceback"):
        print(record["traceback"], file=sys.stderr, end="")
    return 1 if record["status"] == "failed" else 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from .errors import MMConceptsError
    from .engine import DataPlan, all_experiments, get, load_experiments, reproduce
    from .engine.workers import allocate_from_heap

    allocate_from_heap()  # the experiments' arrays from the heap: fewer page faults, the same numbers

    data = _data(args)
    load_experiments()
    try:
        for exp_id in args.only or ():
            get(exp_id)
        # --data and --data-root checked, resolved once
        plan = DataPlan.build(all_experiments(), data, args.data_root, allow_generated=args.allow_generated)
    except MMConceptsError as exc:
        raise _UsageError(str(exc)) from exc
    records = reproduce(
        preset=args.preset, output=args.output, data_plan=plan, synthetic=args.synthetic,
        workers=args.workers, scheduler=args.scheduler, concurrent=args.concurrent, force=args.force, ids=args.only,
        progress=not args.quiet,
    )
    html_path, md_path = _write_report(args.output)
    rows = [["experiment", "data", "ran", "claims"]]
    for r in records:
        message = ((r.get("message") or "").splitlines() or [""])[0]
        claims = _claims_summary(r.get("claims") or []) if r["status"] == "ok" else message
        rows.append([r["experiment"], r.get("variant", ""), r["status"], claims])
    print(_columns(rows, indent=""))
    print(f"report: {html_path}")
    print(f"        {md_path}")
    failed = [r["experiment"] for r in records if r["status"] == "failed"]
    if failed and args.verbose:
        for r in records:
            if r["status"] == "failed" and r.get("traceback"):
                print(f"--- {r['experiment']}", file=sys.stderr)
                print(r["traceback"], file=sys.stderr, end="")
    return 1 if failed else 0


def _cmd_data_list(args: argparse.Namespace) -> int:
    from .datasets import data_root, dataset_status

    root = data_root(args.data_root)
    print(f"data root: {root if root is not None else '(none: pass --data-root DIR or set MMCONCEPTS_DATA_ROOT)'}")
    rows = [["name", "found", "recordings", "licence", "how to obtain"]]
    for st in dataset_status(root):
        found = str(st["found"]) if st.get("found") else ("wrong layout: " + st["problem"] if st.get("problem") else "-")
        n = "" if st.get("n") is None else str(st["n"])
        rows.append([st["name"], found, n, st.get("licence") or "", st.get("obtain") or ""])
    print(_columns(rows, indent=""))
    return 0


def _cmd_data_fetch(args: argparse.Namespace) -> int:
    from .datasets import DATASETS, data_root, fetch_dataset

    if args.name not in DATASETS:
        raise _UsageError(f"unknown data set {args.name!r}; known: {', '.join(sorted(DATASETS))}.")
    root = data_root(args.data_root)
    if root is None:
        raise _UsageError("no data root: pass --data-root DIR or set MMCONCEPTS_DATA_ROOT.")
    import pooch

    pooch.get_logger().setLevel(logging.WARNING if args.quiet else logging.INFO)  # it logs each download at INFO
    path = fetch_dataset(args.name, root, url=args.url, sha256=args.sha256, progressbar=not args.quiet,
                         max_unpacked_bytes=args.max_size, max_files=args.max_files)
    print(f"{args.name}: {path}")
    return 0


def _size(n_bytes: int) -> str:
    value = float(n_bytes)
    for unit in ("B", "kB", "MB"):
        if value < 1000:
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1000
    return f"{value:.1f} GB"


def _cmd_cache_list(args: argparse.Namespace) -> int:
    import datetime

    from ._paths import data_home
    from .cache import cache_entries

    home = data_home(args.cache_dir, create=False)
    entries = cache_entries(home)
    print(f"cache: {home}{'' if home.is_dir() else ' (does not exist)'}")
    if entries:
        rows = [["item", "files", "size", "newest file (UTC)"]]
        for e in entries:
            newest = "" if e.newest is None else datetime.datetime.fromtimestamp(
                e.newest, datetime.timezone.utc).strftime("%Y-%m-%d %H:%M")
            rows.append([e.name, str(e.n_files), _size(e.n_bytes), newest])
        rows.append(["total", str(sum(e.n_files for e in entries)), _size(sum(e.n_bytes for e in entries)), ""])
        print(_columns(rows, indent=""))
    return 0


def _cmd_cache_clear(args: argparse.Namespace) -> int:
    from ._paths import data_home
    from .cache import clear_cache, parse_age

    from .errors import ParameterError

    home = data_home(args.cache_dir, create=False)
    try:  # a bad AGE or NAME is a usage error (exit code 2)
        older = None if args.older_than is None else parse_age(args.older_than)
        n_files, n_bytes = clear_cache(home, older_than=older, names=args.names or None)
    except ParameterError as exc:
        raise _UsageError(str(exc)) from exc
    print(f"removed {n_files} files ({_size(n_bytes)}) from {home}")
    return 0


def _write_report(folder: Path) -> tuple[Path, Path]:
    """``write_report(folder)`` under the folder's report lock.

    Runs writing to one folder at once (``reproduce`` on a cluster, one job per experiment)
    each write their records and then the report: with the lock, the last to read the
    records is the last to write the report, so the report lists every record written
    before it started (without it, a run that read the folder earlier could replace the
    report with one that misses the other run's experiments).
    """
    from ._io import check_output_dir, folder_lock
    from .errors import ParameterError
    from .report import write_report

    folder = Path(folder)
    if not folder.is_dir():
        return write_report(folder)  # which says the folder does not exist
    check_output_dir(folder)  # a folder that cannot be written: a ParameterError naming it
    try:
        with folder_lock(folder, ".report.lock"):
            return write_report(folder)
    except OSError as exc:
        raise ParameterError(
            f"cannot write the report in {folder} ({exc.strerror or exc}). Pass a results folder you can write to."
        ) from exc


def _cmd_report(args: argparse.Namespace) -> int:
    if args.only and not args.redraw:
        raise _UsageError("--only selects the experiments to redraw: give --redraw too.")
    if args.redraw:
        from .engine import load_experiments, redraw_figures

        load_experiments()
        drawn = redraw_figures(args.dir, ids=args.only)
        n = sum(len(v) for v in drawn.values())
        print(f"redrew {n} figure(s) of {len(drawn)} record(s)")
    html_path, md_path = _write_report(args.dir)
    print(f"report: {html_path}")
    print(f"        {md_path}")
    return 0


def _cmd_verdicts(args: argparse.Namespace) -> int:
    from .report.verdict_page import update_tallies, verdict_page, write_verdict_page

    options = dict(title=args.title, command=args.made_by, commit=args.commit, allow_stale=args.allow_stale)
    if args.compare:
        if not args.only:
            raise _UsageError("--compare needs the experiments to compare: --only ID [ID ...].")
        from .report.verdict_page import comparison_page

        text = comparison_page(args.compare, args.dir, ids=args.only, metrics=args.metrics, title=args.title,
                               old_commit=args.old_commit, new_commit=args.commit, write=args.write)
        print(f"wrote {args.write}" if args.write else text, end="\n" if args.write else "")
        return 0
    if args.tallies and not args.write:
        raise _UsageError("--tallies copies the tallies of the page written with --write: give --write FILE too.")
    if args.write:
        print(f"wrote {write_verdict_page(args.dir, args.write, **options)}")
        if args.tallies:
            print(f"wrote the tallies into {update_tallies(args.tallies, args.write)}")
    else:
        print(verdict_page(args.dir, **options), end="")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from .engine.compare import compare_records, format_differences

    if not (args.rtol >= 0.0):
        raise _UsageError(f"--rtol must be a number >= 0; got {args.rtol}.")
    diffs = compare_records(args.old, args.new, ids=args.only, rtol=args.rtol)
    print(format_differences(diffs))
    return 1 if diffs else 0


# --------------------------------------------------------------------------- main


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``mmconcepts`` command line.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit code: 0 success, 1 an experiment failed or an error occurred, 2 usage error.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version or a usage error
        return int(exc.code) if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    from .errors import MMConceptsError

    args.verbose = getattr(args, "verbose", 0)
    args.quiet = getattr(args, "quiet", False)
    _setup_logging(args.verbose, args.quiet)
    try:
        with _quiet_processes(args.quiet):
            return args.func(args)
    except _UsageError as exc:
        if args.verbose:
            logger.error("usage error", exc_info=exc.__cause__ or exc)
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except MMConceptsError as exc:
        if args.verbose:
            logger.exception("error")
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into a command that stopped reading (| head)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
