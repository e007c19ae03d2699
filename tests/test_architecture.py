"""The import rules of the experiments package: the engine imports no chapter, and a chapter imports no other
chapter (its shared protocols live in the library or in the engine). Imports are read from the source (``ast``)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "mmconcepts" / "experiments"
CHAPTER = re.compile(r"^_?ch(\d)")

#: Chapter-to-chapter imports not yet moved out (module -> imported module). Chapters 6 and 7 build their data on
#: chapter 5's speech protocol and chapter 7 on chapter 6's pairs; the list may only shrink.
NOT_YET_MOVED = {
    ("_ch6_common", "_ch5_common"),
    ("ch7_compositional", "_ch5_common"),
    ("ch7_online", "_ch6_common"),
}


def _imported_modules(path: Path) -> set[str]:
    """The modules of the experiments package that ``path`` imports (top level or inside functions)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level == 1:
                out.update([module.split(".")[0]] if module else [a.name for a in node.names])
            elif module.startswith("mmconcepts.experiments."):
                out.add(module.split(".")[2])
            elif module == "mmconcepts.experiments":
                out.update(a.name for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name.split(".")[2] for a in node.names if a.name.startswith("mmconcepts.experiments."))
    return out


def _chapter(module: str) -> str | None:
    match = CHAPTER.match(module)
    return match.group(1) if match else None


def _imports() -> dict[str, set[str]]:
    return {p.stem: _imported_modules(p) for p in sorted(PACKAGE.glob("*.py"))}


def test_the_reader_sees_every_kind_of_import(tmp_path):
    source = tmp_path / "m.py"
    source.write_text("from . import _ch5_common as c\nfrom .base import x\nfrom mmconcepts.experiments.ch6_concepts "
                      "import y\nimport mmconcepts.experiments.ch3_unseen\ndef f():\n    from ._ch3_common import z\n")
    assert _imported_modules(source) == {"_ch5_common", "base", "ch6_concepts", "ch3_unseen", "_ch3_common"}


def test_the_engine_imports_no_chapter():
    found = {(m, i) for m, imported in _imports().items() if _chapter(m) is None for i in imported if _chapter(i)}
    assert not found, f"engine modules importing chapter modules: {sorted(found)}"


def test_no_chapter_imports_another():
    found = {(m, i) for m, imported in _imports().items() if _chapter(m)
             for i in imported if _chapter(i) and _chapter(i) != _chapter(m)}
    problems = _list_changes(found, NOT_YET_MOVED, "imports between chapters (move the shared code to the library or "
                                                  "the engine)")
    assert not problems, "\n".join(problems)


def _list_changes(found: set, allowed: set, what: str) -> list[str]:
    """How ``found`` differs from the list ``allowed``: new entries, and listed ones that are gone (so the list
    stays exact and can only shrink)."""
    return ([f"new {what}: {sorted(found - allowed)}"] if found - allowed else []) + \
        ([f"these are gone, remove them from the list: {sorted(allowed - found)}"] if allowed - found else [])


SOURCE = PACKAGE.parent

#: Private names still imported from another module (importer, module, name); the list may only shrink. The
#: unchecked MDP/IRL solvers (mdp -> irl -> factorial) are most of the rest.
PRIVATE_NOT_YET_MOVED = {
    ("motion/synthetic.py", "data", "_write_json"),
    ("sound/tree.py", "dtw", "_dtw_to_rows"),
    ("tasks/factorial.py", "irl", "_HINTS"),
    ("tasks/factorial.py", "irl", "_gradirl_objective"),
    ("tasks/factorial.py", "irl", "_stats"),
    ("tasks/irl.py", "mdp", "_boltzmann_policy"),
    ("tasks/irl.py", "mdp", "_greedy_policy"),
    ("tasks/irl.py", "mdp", "_policy_iteration"),
    ("tasks/irl.py", "mdp", "_soft_value_iteration"),
    ("tasks/irl.py", "mdp", "_value_iteration"),
}


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
