"""Which real data sets a run uses: the data plan (:class:`DataPlan`), made once per run from the data root
and the ``--data NAME=PATH`` arguments; the ``--data`` arguments checked; a set's signature (part of a
record's up-to-date key).

A run (:func:`~mmconcepts.engine.reproduce`, or :func:`~mmconcepts.engine.run_experiment` alone) resolves
the data root once (:func:`resolve_root`: the argument, else ``$MMCONCEPTS_DATA_ROOT``), looks under it once
for the sets its experiments declare (:func:`mmconcepts.datasets.find_datasets`: each set's layout is checked
by its registry entry, :data:`mmconcepts.datasets.DATASETS`), and keeps the answer as a :class:`DataPlan`:
for each experiment, a :class:`PlanEntry` with the real sets it runs on and its variants. Each run of an
experiment takes its entry; its record's ``variant`` and ``data`` are that entry's.
"""

from __future__ import annotations

import difflib
import logging
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import ExperimentError, ParameterError
from .experiment import Experiment
from .registry import all_experiments


__all__ = ["VARIANTS", "DataPlan", "PlanEntry", "make_data_plan", "resolve_root", "parse_data_args", "check_data",
           "check_root_holds_a_set", "data_signature"]

logger = logging.getLogger("mmconcepts.experiments")


#: The data variants of a run: on the real sets found, or on generated stand-ins.
VARIANTS = ("real", "synthetic")


_DATA_NAME = re.compile(r"[A-Za-z0-9_.-]+\Z")


def parse_data_args(items: Iterable[str] | None) -> dict[str, Path]:
    """Parse ``--data NAME=PATH`` arguments into ``{name: path}``.

    Raises
    ------
    ExperimentError
        On an item without ``=``, an empty or malformed name, an empty path, or a name
        given twice.
    """
    out: dict[str, Path] = {}
    for item in items or ():
        name, sep, path = str(item).partition("=")
        name = name.strip()
        if not sep or not name or not path:
            raise ExperimentError(f"--data expects NAME=PATH (e.g. choreo1=/data/choreo1); got {item!r}.")
        if not _DATA_NAME.fullmatch(name):
            raise ExperimentError(f"--data {item!r}: the name {name!r} must be a word ([A-Za-z0-9_.-]).")
        if name in out:
            raise ExperimentError(f"--data {name}=... is given twice ({out[name]} and {path}); give each data set once.")
        out[name] = Path(path).expanduser()
    return out


def check_data(
    data: Mapping[str, str | os.PathLike[str]] | None, experiments: Sequence[Experiment] | None = None
) -> dict[str, Path]:
    """Validate ``--data`` names and paths; return ``{name: absolute path}``.

    Parameters
    ----------
    data : mapping of str to path, optional
    experiments : sequence of Experiment, optional
        Experiments whose declared data-set names are accepted without consulting the
        registry; any other name must be declared by some registered experiment.

    Raises
    ------
    ExperimentError
        If no experiment declares a name, a path does not exist, or the path of a set of
        :data:`mmconcepts.datasets.DATASETS` does not hold its layout (each is named).
    """
    if not data:
        return {}
    if isinstance(data, (str, bytes)) or not isinstance(data, Mapping):
        raise ExperimentError(f"data must be a mapping of data-set names to paths; got {type(data).__name__}.")
    from ..datasets import DATASETS

    resolved = {str(name): Path(path).expanduser() for name, path in data.items()}
    declared = {n for exp in experiments or () for n in exp.datasets} | set(DATASETS)
    if any(name not in declared for name in resolved):
        registered = all_experiments()
        declared |= {n for exp in registered for n in exp.datasets}
    unknown = sorted(name for name in resolved if name not in declared)
    if unknown:
        known = ", ".join(sorted(declared)) or "none"
        raise ExperimentError(
            f"--data {unknown[0]}=...: no experiment uses a data set named {unknown[0]!r}. "
            f"Known data-set names: {known} (see `mmconcepts list`)."
        )
    for name, path in resolved.items():
        if not path.exists():
            raise ExperimentError(f"--data {name}={path}: the path {str(path)!r} does not exist; give the folder "
                                  f"holding {name!r} (see `mmconcepts data list`).")
        info = DATASETS.get(name)
        problem = None if info is None else info.check(path)
        if info is not None and problem is not None:
            raise ExperimentError(f"--data {name}={path}: the folder does not hold {name!r} in its layout ({problem}). "
                                  f"Expected: {info.layout}")
    return {name: path.resolve() for name, path in resolved.items()}


def check_root_holds_a_set(root: Path, given: str | os.PathLike[str]) -> None:
    """Refuse a data root that is a folder but holds none of the known sets.

    Parameters
    ----------
    root : Path
        The resolved data root (an existing folder).
    given : str or path-like
        The data root as it was given, named in the message.

    Raises
    ------
    ExperimentError
        If no set of :data:`mmconcepts.datasets.DATASETS` is found in ``root`` with a sound
        layout. The message names the folders looked for, why each one present was refused,
        and the set ``root`` itself looks like, if any (a set's folder given for its parent).
    """
    from ..datasets import DATASETS, dataset_status

    rows = dataset_status(root)
    if any(row["found"] is not None for row in rows):
        return
    looked = ", ".join(" or ".join(f + "/" for f in info.folders) for info in DATASETS.values())
    refused = [f"{row['problem']}" for row in rows if row["problem"]]
    why = f" Refused: {'; '.join(refused)}." if refused else " None of these folders is in it."
    itself = [name for name, info in DATASETS.items() if info.check(root) is None]
    hint = (f" It looks like the set {itself[0]!r} itself: give the folder that holds it "
            f"({str(root.parent)!r}), or --data {itself[0]}={given}." if itself else "")
    raise ExperimentError(
        f"--data-root {str(given)!r}: the folder {str(root)!r} holds no known data set; looked for {looked}.{why}"
        f"{hint} Fix: give the folder holding the real sets (see `mmconcepts data list --data-root DIR`), or pass "
        "--allow-generated (DataPlan.build(..., allow_generated=True)) to run on generated data."
    )


def resolve_root(data_root: str | os.PathLike[str] | None = None) -> Path | None:
    """The data root of a run: ``data_root`` if given, else ``$MMCONCEPTS_DATA_ROOT``, else None.

    Called once per run, by :meth:`DataPlan.build`.

    Parameters
    ----------
    data_root : str or path-like, optional
        The folder given (``--data-root DIR``); see :func:`mmconcepts.datasets.data_root`.

    Returns
    -------
    Path or None
        The absolute data root; None when none is given. A root from the environment that
        is not a folder is returned as it is, with a warning (no real set is found in it).

    Raises
    ------
    ExperimentError
        If ``data_root`` is given and is not an existing folder (a mistyped path would
        otherwise run every experiment on generated data); the message names a folder
        beside it with a close name, if there is one.
    """
    from ..datasets import DATA_ROOT_ENV
    from ..datasets import data_root as _data_root

    root = _data_root(data_root)
    if root is None or root.is_dir():
        return root
    if data_root is None or str(data_root) == "":
        logger.warning("$%s=%s is not a folder: no real data set is used.", DATA_ROOT_ENV, root)
        return root
    what = "is not a folder" if root.exists() else "does not exist"
    try:
        siblings = [p.name for p in root.parent.iterdir() if p.is_dir()]
    except OSError:
        siblings = []
    close = difflib.get_close_matches(root.name, siblings, n=1)
    hint = f" Did you mean {str(root.parent / close[0])!r}?" if close else ""
    raise ExperimentError(f"--data-root {str(data_root)!r}: the data root {str(root)!r} {what}; give the folder "
                          f"holding the real sets by name (see `mmconcepts data list`).{hint}")


@dataclass(frozen=True)
class PlanEntry:
    """Which data one experiment runs on in a run: its entry of the :class:`DataPlan`.

    Parameters
    ----------
    experiment : str
        The experiment's id.
    sets : dict of str to Path
        The real sets found for it (``{name: absolute path}``, in the order it declares them):
        those under the data root, overridden by ``--data NAME=PATH``. Empty: it runs on
        generated data.
    variants : tuple of str
        The variants it runs on, its default run first: ``("real", "synthetic")`` when a set
        was found and it also runs on generated data, ``("real",)`` when it runs on real data
        only, ``("synthetic",)`` when no set was found (an experiment that runs on real data
        only is then recorded as skipped).
    """

    experiment: str
    sets: dict[str, Path]
    variants: tuple[str, ...]

    def chosen(self, variant: str) -> str:
        """The variant a run asked for ``variant`` (``"auto"``: the default one, ``variants[0]``) goes on."""
        return self.variants[0] if variant == "auto" else variant

    def data(self, variant: str) -> dict[str, Path]:
        """The real sets a run on ``variant`` gets (all of :attr:`sets` on ``"real"``, none on ``"synthetic"``)."""
        return dict(self.sets) if variant == "real" else {}

    def secondary(self, variant: str) -> bool:
        """Whether a run on ``variant`` is the run on generated data of an experiment that has real data."""
        return variant == "synthetic" and bool(self.sets)


@dataclass(frozen=True)
class DataPlan:
    """Which real data sets each experiment of a run uses, resolved once for the whole run.

    Made by :meth:`build`; :func:`~mmconcepts.engine.reproduce` makes one and gives it to each
    of its runs (also on driver processes: it pickles), :func:`~mmconcepts.engine.run_experiment`
    called alone makes its own.

    Parameters
    ----------
    root : Path or None
        The data root (:func:`resolve_root`); None when none was given.
    given : dict of str to Path
        The sets given by path (``--data NAME=PATH``), checked (:func:`check_data`).
    entries : dict of str to PlanEntry
        Each experiment's entry, by id.
    """

    root: Path | None
    given: dict[str, Path]
    entries: dict[str, PlanEntry]

    @classmethod
    def build(cls, experiments: Sequence[Experiment], data: Mapping[str, str | os.PathLike[str]] | None = None,
              data_root: str | os.PathLike[str] | None = None, *, allow_generated: bool = False) -> DataPlan:
        """Resolve the data root and ``data`` once into the plan of ``experiments``.

        The root is looked at once for every set the experiments declare (each set's layout
        checked by its entry of :data:`mmconcepts.datasets.DATASETS`); a set given in ``data``
        replaces the root's.

        Parameters
        ----------
        experiments : sequence of Experiment
        data : mapping of str to path, optional
            Real sets by name (``--data NAME=PATH``); checked by :func:`check_data`.
        data_root : str or path-like, optional
            The data root (default ``$MMCONCEPTS_DATA_ROOT``, else none): :func:`resolve_root`.
        allow_generated : bool, default=False
            Accept a ``data_root`` given that holds no known set (every experiment then runs on
            generated data). A root from the environment is never refused.

        Raises
        ------
        ExperimentError
            On a ``data`` name no experiment declares, a path that does not exist or (for a
            known set) does not hold the set's layout; a ``data_root`` that is not an existing
            folder, or that holds no known set (:func:`check_root_holds_a_set`) unless
            ``allow_generated``.
        """
        from ..datasets import DATASETS, find_datasets

        given = check_data(data, experiments)
        root = resolve_root(data_root)
        names = list(dict.fromkeys(n for exp in experiments for n in exp.datasets if n in DATASETS))
        found = find_datasets(root, names=names) if root is not None and root.is_dir() and names else {}
        if data_root is not None and str(data_root) != "" and root is not None and not found and not allow_generated:
            check_root_holds_a_set(root, data_root)  # a root given that holds no known set (a root from $ is not)
        located = {**{n: Path(p).resolve() for n, p in found.items()}, **given}
        entries = {}
        for exp in experiments:
            sets = {n: located[n] for n in exp.datasets if n in located}
            variants = ("synthetic",) if not sets else ("real", "synthetic") if exp.synthetic else ("real",)
            entries[exp.id] = PlanEntry(exp.id, sets, variants)
        plan = cls(root, given, entries)
        logger.debug("data plan: root %s; %s", root, "; ".join(
            f"{e.experiment}: {'+'.join(e.variants)} {sorted(e.sets)}" for e in entries.values()))
        return plan

    def missing(self, exp: Experiment) -> str:
        """Why no real set of ``exp`` is in the plan: the sets it needs and where they were looked for.

        Returns
        -------
        str
            One sentence for an error message, naming the sets ``exp`` declares (any one is enough),
            the data root (or that there is none) and why each folder present under it was refused.
        """
        from ..datasets import DATA_ROOT_ENV, dataset_status

        if not exp.datasets:
            return f"{exp.id} declares no real data set: it runs on generated data only."
        needs = " or ".join(repr(n) for n in exp.datasets)
        if self.root is None:
            where = f"no data root was given (--data-root DIR, or ${DATA_ROOT_ENV})"
        elif not self.root.is_dir():
            where = f"the data root {str(self.root)!r} is not a folder"
        else:
            refused = [row["problem"] for row in dataset_status(self.root)
                       if row["name"] in exp.datasets and row["problem"]]
            where = f"none is in the data root {str(self.root)!r}" + (f" ({'; '.join(refused)})" if refused else "")
        return (f"{exp.id} runs on real data of {needs}, and {where}. Give the set with --data NAME=PATH or a data "
                "root holding it (see `mmconcepts data list`).")

    def entry(self, exp: Experiment | str) -> PlanEntry:
        """The entry of ``exp`` (an experiment or its id).

        Raises
        ------
        ExperimentError
            If the plan was made without that experiment.
        """
        exp_id = exp.id if isinstance(exp, Experiment) else str(exp)
        try:
            return self.entries[exp_id]
        except KeyError:
            raise ExperimentError(f"the data plan has no entry for {exp_id!r} (it covers "
                                  f"{', '.join(self.entries) or 'no experiment'}); make it with "
                                  "DataPlan.build(experiments, ...) over the experiments it runs.") from None


def make_data_plan(experiments: Sequence[Experiment], data: Mapping[str, str | os.PathLike[str]] | None = None,
                   data_root: str | os.PathLike[str] | None = None, data_plan: DataPlan | None = None) -> DataPlan:
    """The data plan of a run: ``data_plan`` when given (checked to cover ``experiments``), else one made from
    ``data`` and ``data_root`` (:meth:`DataPlan.build`).

    Parameters
    ----------
    experiments : sequence of Experiment
        The experiments of the run.
    data : mapping of str to path, optional
        Real sets by name (``--data NAME=PATH``).
    data_root : str or path-like, optional
        The data root (default ``$MMCONCEPTS_DATA_ROOT``).
    data_plan : DataPlan, optional
        A plan made beforehand from ``data`` and ``data_root`` (then neither is given).

    Returns
    -------
    DataPlan

    Raises
    ------
    ParameterError
        If ``data_plan`` is not a :class:`DataPlan`, or is given with ``data`` or ``data_root``
        (it was made from them: give one or the other).
    ExperimentError
        As :meth:`DataPlan.build`; or if ``data_plan`` has no entry for one of ``experiments``.
    """
    if data_plan is None:
        return DataPlan.build(experiments, data, data_root)
    if not isinstance(data_plan, DataPlan):
        raise ParameterError(f"data_plan must be a DataPlan (DataPlan.build(experiments, data, data_root)); "
                             f"got {type(data_plan).__name__}.")
    if data or (data_root is not None and str(data_root) != ""):
        raise ParameterError("give data and data_root, or a data_plan made from them, not both.")
    for exp in experiments:
        data_plan.entry(exp)
    return data_plan


def data_signature(path: str | os.PathLike[str]) -> str:
    """A cheap signature of a data set's contents: number of files, total bytes, newest change.

    Part of a result's up-to-date key, so that adding, repairing or re-fetching recordings
    recomputes the result even though the set's folder is the same.
    """
    path = Path(path)
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    n = size = newest = 0
    for f in files:
        try:
            st = f.stat()
        except OSError:
            continue
        n, size, newest = n + 1, size + st.st_size, max(newest, st.st_mtime_ns)
    return f"{n} files, {size} bytes, newest {newest}"
