"""The syntax of claim rules: words, aliases, the whitelist of nodes and their types, evaluation of a node.

The language is described in :mod:`mmconcepts.engine.rules`; this module reads a rule's text
into a checked tree (:func:`rewrite_rule`, :func:`check_node`) and evaluates a node on metric values
(:func:`evaluate_node`).
"""

from __future__ import annotations

import ast
import bisect
import difflib
import math
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import cast

from ..errors import ExperimentError


__all__ = ["COMPARE", "RESERVED_WORDS", "Undefined", "check_node", "describe_syntax_error", "evaluate_node",
           "is_valid_metric_name", "rewrite_rule", "rule_error", "unknown_metric"]

#: Words that cannot be metric names.
RESERVED_WORDS = frozenset({"and", "or", "not", "abs", "min", "max"})

_WORD_CHARS = re.compile(r"[A-Za-z0-9_.]+")
_NUMBER = re.compile(r"(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\Z")
_EXPONENT_START = re.compile(r"(?:\d+(?:\.\d*)?|\.\d+)[eE]\Z")
_EXPONENT_REST = re.compile(r"[+-]\d+")
_SYMBOLS = re.compile(r"<=|>=|==|!=|[<>+\-*/(),]")
_FUNCTIONS = {"abs": (1, 1), "min": (1, None), "max": (1, None)}
_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
COMPARE = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!="}


def is_valid_metric_name(name: str) -> bool:
    """Return whether ``name`` can be used as a metric name in rules.

    A metric name is a non-empty run of letters, digits, ``_`` and ``.`` that is not a
    reserved word (``and or not abs min max``) and does not read as a number.
    """
    return (
        isinstance(name, str)
        and _WORD_CHARS.fullmatch(name) is not None
        and name not in RESERVED_WORDS
        and _NUMBER.fullmatch(name) is None
    )


class Undefined(Exception):
    """Internal: a comparison met a NaN, so the rule has no verdict."""


def rule_error(rule: str, message: str, pos: int | None = None) -> ExperimentError:
    where = "" if pos is None else f" at position {pos}"
    pointer = "" if pos is None else "\n    " + rule + "\n    " + " " * pos + "^"
    return ExperimentError(f"claim rule {rule!r}: {message}{where}.{pointer}")


def unknown_metric(rule: str, name: str, names: Collection[str], pos: int) -> ExperimentError:
    known = sorted(names)
    close = difflib.get_close_matches(name, known, n=3, cutoff=0.6)
    hint = f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    if not known:
        listing = " No metrics are known."
    elif len(known) <= 20:
        listing = " Known metrics: " + ", ".join(known) + "."
    else:
        listing = f" ({len(known)} metrics are known.)"
    return ExperimentError(f"claim rule {rule!r}: unknown metric {name!r} at position {pos}.{hint}{listing}")


# --------------------------------------------------------------------------- words -> Python text


@dataclass
class _Source:
    """The rule rewritten as Python text, with a map from its offsets back to the rule's."""

    rule: str
    text: str
    starts: list[int]  # offsets in text where a piece begins
    origins: list[int]  # the rule offset of each piece
    tokens: list[tuple[int, str]]  # (rule offset, token as written), in order
    metrics: dict[str, str]  # alias -> metric name

    def position(self, offset: int) -> int:
        """The rule offset of Python-text ``offset``."""
        i = max(bisect.bisect_right(self.starts, offset) - 1, 0)
        return min(self.origins[i] + max(offset - self.starts[i], 0), len(self.rule))

    def token_at(self, pos: int) -> str:
        """A description of the rule's token at ``pos`` (or the end of the rule)."""
        for start, tok in self.tokens:
            if start >= pos:
                return repr(tok)
        return "end of rule"


def rewrite_rule(rule: str, names: Collection[str] | None) -> _Source:
    parts: list[str] = []
    src = _Source(rule, "", [], [], [], {})
    metric_ids: dict[str, str] = {}
    length = 0

    def emit(text: str, origin: int) -> None:
        nonlocal length
        src.starts.append(length)
        src.origins.append(origin)
        parts.append(text)
        length += len(text)

    i, n = 0, len(rule)
    while i < n:
        ch = rule[i]
        if ch.isspace():
            emit(" ", i)
            i += 1
            continue
        m = _WORD_CHARS.match(rule, i)
        if m:
            word, start, i = m.group(), i, m.end()
            nxt = rule[i:].lstrip()[:1]
            if names is not None and word in names:
                kind = "metric"
            elif word in ("and", "or", "not") or (word in _FUNCTIONS and nxt == "("):
                kind = "word"
            elif _NUMBER.fullmatch(word):
                kind = "number"
            elif _EXPONENT_START.fullmatch(word) and _EXPONENT_REST.match(rule, i):
                # "1e-3": the word run stops at the sign of the exponent
                rest = _EXPONENT_REST.match(rule, i)
                assert rest is not None
                i = rest.end()
                word, kind = rule[start:i], "number"
            elif word in RESERVED_WORDS:
                raise rule_error(rule, f"{word!r} is a function and must be followed by '('", start)
            elif names is None:
                kind = "metric"
            else:
                raise unknown_metric(rule, word, names, start)
            src.tokens.append((start, word))
            if kind == "metric":
                alias = metric_ids.setdefault(word, f"_m{len(metric_ids)}")
                src.metrics[alias] = word
                emit(alias, start)
            elif kind == "number":
                emit(repr(float(word)), start)
            else:
                emit(word, start)
            continue
        m = _SYMBOLS.match(rule, i)
        if m is None:
            raise rule_error(rule, f"unexpected character {ch!r}", i)
        src.tokens.append((i, m.group()))
        emit(m.group(), i)
        i = m.end()
    src.text = "".join(parts)
    return src


# --------------------------------------------------------------------------- checking the tree


def check_node(node: ast.AST, src: _Source) -> str:
    """Check ``node`` against the whitelist; return its type, ``"num"`` or ``"bool"``."""

    def pos(n: ast.AST) -> int:
        return src.position(getattr(n, "col_offset", 0))

    def need(n: ast.AST, want: str) -> None:
        got = check_node(n, src)
        if got != want:
            if want == "num":
                raise rule_error(src.rule, "expected a number here, found a true/false expression", pos(n))
            raise rule_error(src.rule, "expected a true/false expression (a comparison) here, found a number", pos(n))

    if isinstance(node, ast.Constant) and type(node.value) is float:
        return "num"
    if isinstance(node, ast.Name) and node.id in src.metrics:
        return "num"
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
        need(node.operand, "num")
        return "num"
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        need(node.operand, "bool")
        return "bool"
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        need(node.left, "num")
        need(node.right, "num")
        return "num"
    if isinstance(node, ast.BoolOp):
        for value in node.values:
            need(value, "bool")
        return "bool"
    if isinstance(node, ast.Compare) and all(type(op) in COMPARE for op in node.ops):
        for operand in [node.left, *node.comparators]:
            need(operand, "num")
        return "bool"
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS \
            and not node.keywords and not any(isinstance(a, ast.Starred) for a in node.args):
        name = node.func.id
        lo, hi = _FUNCTIONS[name]
        if not node.args:
            raise rule_error(src.rule, f"{name}() needs at least one argument", pos(node))
        if len(node.args) < lo or (hi is not None and len(node.args) > hi):
            expected = f"exactly {lo}" if lo == hi else f"at least {lo}"
            raise rule_error(src.rule, f"{name}() takes {expected} argument(s), got {len(node.args)}", pos(node))
        for arg in node.args:
            need(arg, "num")
        return "num"
    # point at what is not allowed: the operator of 'a ** b', the comma of 'a, b', else the node
    first = node.left if isinstance(node, ast.BinOp) else node.elts[0] if isinstance(node, ast.Tuple) and node.elts else None
    p = src.position(first.end_col_offset) if first is not None and first.end_col_offset is not None else pos(node)
    while p < len(src.rule) and src.rule[p].isspace():
        p += 1
    raise rule_error(src.rule, f"unexpected {src.token_at(p)}", p)


def describe_syntax_error(exc: SyntaxError, src: _Source) -> ExperimentError:
    if "never closed" in str(exc.msg):
        return rule_error(src.rule, "expected ')', found end of rule", len(src.rule))
    p = src.position(exc.offset - 1) if exc.offset else len(src.rule)  # Python gives 0 at the end of input
    if p >= len(src.rule.rstrip()):
        return rule_error(src.rule, "unexpected end of rule", len(src.rule))
    return rule_error(src.rule, f"unexpected {src.token_at(p)}", p)


# --------------------------------------------------------------------------- evaluation


def _div(a: float, b: float) -> float:
    if b != 0:
        return a / b
    if a == 0 or math.isnan(a) or math.isnan(b):
        return math.nan
    return math.copysign(math.inf, a) * math.copysign(1.0, b)


def _compare(op: type[ast.cmpop], a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        raise Undefined
    return {ast.Lt: a < b, ast.LtE: a <= b, ast.Gt: a > b, ast.GtE: a >= b, ast.Eq: a == b, ast.NotEq: a != b}[op]


def evaluate_node(node: ast.AST, values: Mapping[str, float]):
    if isinstance(node, ast.Constant):
        return float(cast(float, node.value))  # check_node admits float constants only
    if isinstance(node, ast.Name):
        return values[node.id]
    if isinstance(node, ast.UnaryOp):
        x = evaluate_node(node.operand, values)
        return -x if isinstance(node.op, ast.USub) else (not x if isinstance(node.op, ast.Not) else x)
    if isinstance(node, ast.BinOp):
        a, b = evaluate_node(node.left, values), evaluate_node(node.right, values)
        op = type(node.op)
        return a + b if op is ast.Add else a - b if op is ast.Sub else a * b if op is ast.Mult else _div(a, b)
    if isinstance(node, ast.BoolOp):
        if isinstance(node.op, ast.And):
            return all(evaluate_node(v, values) for v in node.values)
        return any(evaluate_node(v, values) for v in node.values)
    if isinstance(node, ast.Compare):
        left = evaluate_node(node.left, values)
        for cmp, right_node in zip(node.ops, node.comparators):
            right = evaluate_node(right_node, values)
            if not _compare(type(cmp), left, right):
                return False
            left = right
        return True
    if isinstance(node, ast.Call):
        args = [evaluate_node(a, values) for a in node.args]
        func = cast(ast.Name, node.func)  # check_node admits calls of abs, min and max by name only
        if func.id == "abs":
            return abs(args[0])
        if any(math.isnan(x) for x in args):
            return math.nan
        return min(args) if func.id == "min" else max(args)
    raise AssertionError(f"unchecked node {type(node).__name__}")  # pragma: no cover


