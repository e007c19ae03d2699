"""The import rules of the package, read from the source (``ast``), and the engine's size limits.

The layers, from the bottom up: the library (``nmf``, ``motion``, ``sound``, ``vision``, ``tasks``,
``multimodal``, ``datasets``), the engine (``mmconcepts.engine``) and beside it the figures of the
library (``mmconcepts.plot``), the thesis' chapters (``mmconcepts.experiments.ch2`` ... ``ch7``), then
the report and the command line. A layer imports only the layers below it; only the report and the
command line import the figures; a chapter imports no other chapter; no engine module imports another
in a circle; no private name crosses a module. See docs/architecture.rst.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

SOURCE = Path(__file__).resolve().parents[2] / "src" / "mmconcepts"
LIBRARY = ("nmf", "motion", "sound", "vision", "tasks", "multimodal", "datasets")
CHAPTER = re.compile(r"mmconcepts\.experiments\.(ch\d)(\.|$)")

#: The longest an engine module may be (lines), and the body of run_experiment (lines, its docstring excluded).
ENGINE_MODULE_LINES = 400
RUN_EXPERIMENT_BODY_LINES = 60


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SOURCE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported_modules(path: Path, module: str) -> set[str]:
    """The absolute names of the modules ``path`` (the module ``module``) imports, at top level or in functions.

    ``from P import x`` counts as importing ``P`` and ``P.x`` (``x`` may be a submodule)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            out.add(target)
            out.update(f"{target}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {m for m in out if m == "mmconcepts" or m.startswith("mmconcepts.")}


def _graph() -> dict[str, set[str]]:
    return {_module_name(p): _imported_modules(p, _module_name(p)) for p in sorted(SOURCE.rglob("*.py"))}


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def _chapter(module: str) -> str | None:
    match = CHAPTER.match(module)
    return match.group(1) if match else None


def _list_changes(found: set, allowed: set, what: str) -> list[str]:
    """How ``found`` differs from the list ``allowed``: new entries, and listed ones that are gone (so the list
    stays exact and can only shrink)."""
    return ([f"new {what}: {sorted(found - allowed)}"] if found - allowed else []) + \
        ([f"these are gone, remove them from the list: {sorted(allowed - found)}"] if allowed - found else [])


def test_the_reader_sees_every_kind_of_import(tmp_path):
    pkg = tmp_path / "mmconcepts" / "experiments" / "ch6"
    pkg.mkdir(parents=True)
    source = pkg / "m.py"
    source.write_text("from . import protocol as c\nfrom ...engine.spec import x\nfrom ..ch5 import protocol\n"
                      "import mmconcepts.experiments.ch3.unseen\ndef f():\n    from ...nmf import NMF\n")
    found = _imported_modules(source, "mmconcepts.experiments.ch6.m")
    assert {"mmconcepts.experiments.ch6.protocol", "mmconcepts.engine.spec", "mmconcepts.experiments.ch5.protocol",
            "mmconcepts.experiments.ch3.unseen", "mmconcepts.nmf"} <= found
    assert {_chapter(m) for m in found} == {None, "ch3", "ch5", "ch6"}


def test_the_engine_imports_no_chapter_and_nothing_above_it():
    found = {(m, i) for m, imported in _graph().items() if _in(m, "mmconcepts.engine") for i in imported
             if any(_in(i, f"mmconcepts.{up}") for up in ("experiments", "report", "cli"))}
    assert not found, f"engine modules importing the layers above: {sorted(found)}"


def test_the_library_imports_neither_the_engine_nor_the_chapters():
    found = {(m, i) for m, imported in _graph().items() if any(_in(m, f"mmconcepts.{lib}") for lib in LIBRARY)
             for i in imported if _in(i, "mmconcepts.engine") or _in(i, "mmconcepts.experiments")}
    assert not found, f"library modules importing the engine or the chapters: {sorted(found)}"


def test_the_figures_import_only_the_library():
    found = {(m, i) for m, imported in _graph().items() if _in(m, "mmconcepts.plot") for i in imported
             if any(_in(i, f"mmconcepts.{up}") for up in ("engine", "experiments", "report", "cli"))}
    assert not found, f"mmconcepts.plot importing more than the library: {sorted(found)}"


def test_only_the_report_and_the_command_line_import_the_figures():
    found = {(m, i) for m, imported in _graph().items()
             if not any(_in(m, f"mmconcepts.{up}") for up in ("plot", "report", "cli"))
             for i in imported if _in(i, "mmconcepts.plot")}
    assert not found, f"modules below the report importing mmconcepts.plot: {sorted(found)}"


def test_no_chapter_imports_another():
    found = {(m, i) for m, imported in _graph().items() if _chapter(m)
             for i in imported if _chapter(i) and _chapter(i) != _chapter(m)}
    assert not found, f"imports between chapters (move the shared code to the library or experiments.protocols): " \
                      f"{sorted(found)}"


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of ``graph`` (Tarjan's strongly connected components of more than one module)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_cycles_are_found():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_circle():
    """No module of the package imports itself through others (imports inside functions count too; a package's
    ``__init__`` that only hands on its modules' names is left out, as importing ``P.x`` runs it first)."""
    graph = _graph()
    packages = {m for m in graph if (SOURCE.parent / m.replace(".", "/") / "__init__.py").exists()}
    modules = {m: {i for i in imported if i in graph and i not in packages and i != m}
               for m, imported in graph.items() if m not in packages}
    assert _cycles(modules) == []


@pytest.mark.parametrize("path", sorted((SOURCE / "engine").glob("*.py")), ids=lambda p: p.name)
def test_engine_modules_are_short(path):
    n = len(path.read_text(encoding="utf-8").splitlines())
    assert n <= ENGINE_MODULE_LINES, f"{path.name} has {n} lines; split it (at most {ENGINE_MODULE_LINES})"


def test_run_experiment_is_short():
    tree = ast.parse((SOURCE / "engine" / "runner.py").read_text(encoding="utf-8"))
    func = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "run_experiment")
    body_start = func.body[1].lineno if ast.get_docstring(func) else func.body[0].lineno
    n = func.end_lineno - body_start + 1
    assert n < RUN_EXPERIMENT_BODY_LINES, f"run_experiment's body has {n} lines"


def test_every_chapter_module_is_found_by_scanning():
    from mmconcepts.engine.registry import EXPERIMENT_PACKAGES, experiment_modules

    found = set(experiment_modules(EXPERIMENT_PACKAGES))
    on_disk = {_module_name(p) for p in (SOURCE / "experiments").rglob("*.py")}
    assert on_disk == found


#: Private names imported from another module (importer, module, name): none; the test keeps it so.
PRIVATE_NOT_YET_MOVED: set[tuple[str, str, str]] = set()


def _private_imports() -> set[tuple[str, str, str]]:
    """(importing file, imported module, name) for every ``from module import _name`` of the package."""
    out = set()
    for path in sorted(SOURCE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and (node.level or node.module.startswith("mmconcepts")):
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        out.add((path.relative_to(SOURCE).as_posix(), node.module.rsplit(".", 1)[-1], alias.name))
    return out


def test_no_new_private_name_crosses_a_module():
    problems = _list_changes(_private_imports(), PRIVATE_NOT_YET_MOVED,
                             "private names imported from another module (make them public in a private module)")
    assert not problems, "\n".join(problems)


def test_the_smallest_experiment_of_the_guide_runs(registry, tmp_path):
    """docs/architecture.rst shows docs/examples/smallest_experiment.py: it registers, runs, and its claim is decided."""
    import runpy

    from mmconcepts.engine import get, run_experiment

    runpy.run_path(str(SOURCE.parents[1] / "docs" / "examples" / "smallest_experiment.py"), run_name="coin")
    assert get("ch2-coin").title == "A fair coin"
    record = run_experiment("ch2-coin", output=tmp_path, progress=False)
    assert record.status == "ok", record.message
    assert 0.4 < record.metrics["heads"] < 0.6
    assert [c.verdict for c in record.claims] == ["holds"]
    assert record.intervals["heads"][0] < record.metrics["heads"] < record.intervals["heads"][1]


def test_the_guide_counts_the_names_its_smallest_experiment_uses():
    example = SOURCE.parents[1] / "docs" / "examples" / "smallest_experiment.py"
    names = [a.name for node in ast.parse(example.read_text(encoding="utf-8")).body
             if isinstance(node, ast.ImportFrom) and node.module == "mmconcepts.engine" for a in node.names]
    words = {6: "six", 7: "seven", 8: "eight", 9: "nine", 10: "ten"}
    guide = (SOURCE.parents[1] / "docs" / "architecture.rst").read_text(encoding="utf-8")
    assert f"uses {words[len(names)]} names of the engine" in guide, names
