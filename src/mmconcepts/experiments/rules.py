"""A tiny, safe language for claim rules over metric names.

A claim of an experiment says something the thesis found ("NMF beats the SVM on the
full test set") and a rule that checks it from our numbers::

    nmf_frobenius.l_full > svm.l_full
    0.8 <= 16.nmf_kl.l_full < 1 and abs(bins_20.l_single - 0.5) < 0.1

A rule is a Python expression over metric names, evaluated without :func:`eval`: the
metric names (``16.nmf_kl.l_full`` is no Python identifier) are replaced by aliases,
the text is parsed by :func:`ast.parse`, and only a whitelist of nodes is accepted and
walked here:

- numbers and metric names;
- ``+ - * /`` and unary ``+ -``;
- comparisons ``< <= > >= == !=``, chained as in Python (``0 < a < 1``);
- ``and``, ``or``, ``not``;
- the functions ``abs`` (one argument), ``min`` and ``max`` (one or more).

Precedence is Python's. A *word* is a maximal run of ``[A-Za-z0-9_.]``. A word that is a
known metric name is a metric; otherwise, if it reads as a decimal number (``3``, ``0.5``,
``.5``, ``1e-3``) it is a number; otherwise it is an unknown metric and an error. The
words ``and``, ``or``, ``not`` are operators, and ``abs``, ``min``, ``max`` are functions
when a ``(`` follows.

Rules are typed: arithmetic and comparisons take numbers, ``and``/``or``/``not`` take
truth values, and a whole rule must be a truth value. Type errors are found when the rule
is parsed, before any number is looked at.

If a metric used by the rule is NaN (not measured), or a comparison meets a NaN computed
by the rule itself (``0 / 0``), the verdict is ``None``: *not evaluated*. Division by zero
follows IEEE arithmetic (``1 / 0`` is infinite).
"""

from __future__ import annotations

import ast
import bisect
import difflib
import math
import re
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import cast

from ..errors import ExperimentError

__all__ = ["Rule", "Comparison", "parse_rule", "evaluate_rule", "is_valid_metric_name", "RESERVED_WORDS",
           "FAIR_AGREEMENT", "fair_bar", "above_chance_rule"]

#: Words that cannot be metric names.
RESERVED_WORDS = frozenset({"and", "or", "not", "abs", "min", "max"})

_WORD_CHARS = re.compile(r"[A-Za-z0-9_.]+")
_NUMBER = re.compile(r"(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\Z")
_EXPONENT_START = re.compile(r"(?:\d+(?:\.\d*)?|\.\d+)[eE]\Z")
_EXPONENT_REST = re.compile(r"[+-]\d+")
_SYMBOLS = re.compile(r"<=|>=|==|!=|[<>+\-*/(),]")
_FUNCTIONS = {"abs": (1, 1), "min": (1, None), "max": (1, None)}
_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
_COMPARE = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!="}


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


class _Undefined(Exception):
    """Internal: a comparison met a NaN, so the rule has no verdict."""


def _error(rule: str, message: str, pos: int | None = None) -> ExperimentError:
    where = "" if pos is None else f" at position {pos}"
    pointer = "" if pos is None else "\n    " + rule + "\n    " + " " * pos + "^"
    return ExperimentError(f"claim rule {rule!r}: {message}{where}.{pointer}")


def _unknown_metric(rule: str, name: str, names: Collection[str], pos: int) -> ExperimentError:
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


def _rewrite(rule: str, names: Collection[str] | None) -> _Source:
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
                raise _error(rule, f"{word!r} is a function and must be followed by '('", start)
            elif names is None:
                kind = "metric"
            else:
                raise _unknown_metric(rule, word, names, start)
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
            raise _error(rule, f"unexpected character {ch!r}", i)
        src.tokens.append((i, m.group()))
        emit(m.group(), i)
        i = m.end()
    src.text = "".join(parts)
    return src


# --------------------------------------------------------------------------- checking the tree


def _check(node: ast.AST, src: _Source) -> str:
    """Check ``node`` against the whitelist; return its type, ``"num"`` or ``"bool"``."""

    def pos(n: ast.AST) -> int:
        return src.position(getattr(n, "col_offset", 0))

    def need(n: ast.AST, want: str) -> None:
        got = _check(n, src)
        if got != want:
            if want == "num":
                raise _error(src.rule, "expected a number here, found a true/false expression", pos(n))
            raise _error(src.rule, "expected a true/false expression (a comparison) here, found a number", pos(n))

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
    if isinstance(node, ast.Compare) and all(type(op) in _COMPARE for op in node.ops):
        for operand in [node.left, *node.comparators]:
            need(operand, "num")
        return "bool"
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS \
            and not node.keywords and not any(isinstance(a, ast.Starred) for a in node.args):
        name = node.func.id
        lo, hi = _FUNCTIONS[name]
        if not node.args:
            raise _error(src.rule, f"{name}() needs at least one argument", pos(node))
        if len(node.args) < lo or (hi is not None and len(node.args) > hi):
            expected = f"exactly {lo}" if lo == hi else f"at least {lo}"
            raise _error(src.rule, f"{name}() takes {expected} argument(s), got {len(node.args)}", pos(node))
        for arg in node.args:
            need(arg, "num")
        return "num"
    # point at what is not allowed: the operator of 'a ** b', the comma of 'a, b', else the node
    first = node.left if isinstance(node, ast.BinOp) else node.elts[0] if isinstance(node, ast.Tuple) and node.elts else None
    p = src.position(first.end_col_offset) if first is not None and first.end_col_offset is not None else pos(node)
    while p < len(src.rule) and src.rule[p].isspace():
        p += 1
    raise _error(src.rule, f"unexpected {src.token_at(p)}", p)


def _describe_syntax_error(exc: SyntaxError, src: _Source) -> ExperimentError:
    if "never closed" in str(exc.msg):
        return _error(src.rule, "expected ')', found end of rule", len(src.rule))
    p = src.position(exc.offset - 1) if exc.offset else len(src.rule)  # Python gives 0 at the end of input
    if p >= len(src.rule.rstrip()):
        return _error(src.rule, "unexpected end of rule", len(src.rule))
    return _error(src.rule, f"unexpected {src.token_at(p)}", p)


# --------------------------------------------------------------------------- evaluation


def _div(a: float, b: float) -> float:
    if b != 0:
        return a / b
    if a == 0 or math.isnan(a) or math.isnan(b):
        return math.nan
    return math.copysign(math.inf, a) * math.copysign(1.0, b)


def _compare(op: type[ast.cmpop], a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        raise _Undefined
    return {ast.Lt: a < b, ast.LtE: a <= b, ast.Gt: a > b, ast.GtE: a >= b, ast.Eq: a == b, ast.NotEq: a != b}[op]


def _eval(node: ast.AST, values: Mapping[str, float]):
    if isinstance(node, ast.Constant):
        return float(cast(float, node.value))  # _check admits float constants only
    if isinstance(node, ast.Name):
        return values[node.id]
    if isinstance(node, ast.UnaryOp):
        x = _eval(node.operand, values)
        return -x if isinstance(node.op, ast.USub) else (not x if isinstance(node.op, ast.Not) else x)
    if isinstance(node, ast.BinOp):
        a, b = _eval(node.left, values), _eval(node.right, values)
        op = type(node.op)
        return a + b if op is ast.Add else a - b if op is ast.Sub else a * b if op is ast.Mult else _div(a, b)
    if isinstance(node, ast.BoolOp):
        if isinstance(node.op, ast.And):
            return all(_eval(v, values) for v in node.values)
        return any(_eval(v, values) for v in node.values)
    if isinstance(node, ast.Compare):
        left = _eval(node.left, values)
        for cmp, right_node in zip(node.ops, node.comparators):
            right = _eval(right_node, values)
            if not _compare(type(cmp), left, right):
                return False
            left = right
        return True
    if isinstance(node, ast.Call):
        args = [_eval(a, values) for a in node.args]
        func = cast(ast.Name, node.func)  # _check admits calls of abs, min and max by name only
        if func.id == "abs":
            return abs(args[0])
        if any(math.isnan(x) for x in args):
            return math.nan
        return min(args) if func.id == "min" else max(args)
    raise AssertionError(f"unchecked node {type(node).__name__}")  # pragma: no cover


_ALIAS = re.compile(r"\b_m\d+\b")


@dataclass(frozen=True)
class Comparison:
    """One comparison of a rule, ``left op right`` (a chained ``a < b < c`` is two).

    A rule is a combination (``and``, ``or``, ``not``) of comparisons; a verdict beyond the
    noise is decided comparison by comparison, on each one's *margin*: how far it is from
    flipping, positive when it holds (``left - right`` for ``>`` and ``>=``, ``right -
    left`` for ``<`` and ``<=``; ``left - right`` for ``==`` and ``!=``).

    Attributes
    ----------
    text : str
        The comparison as it reads in the rule (metric names, numbers as floats).
    op : str
        One of ``< <= > >= == !=``.
    metrics : frozenset of str
        The metric names it reads.
    """

    text: str
    op: str
    metrics: frozenset[str]
    _left: ast.AST
    _right: ast.AST
    _aliases: tuple[tuple[str, str], ...]

    def margin(self, metrics: Mapping[str, float]) -> float:
        """The margin (see the class docstring) on ``metrics``; NaN when a metric it reads is NaN."""
        values = {alias: float(metrics[name]) for alias, name in self._aliases if name in self.metrics}
        try:
            left, right = float(_eval(self._left, values)), float(_eval(self._right, values))
        except _Undefined:  # a NaN met inside (min of NaN, ...)
            return math.nan
        return right - left if self.op in ("<", "<=") else left - right

    def holds_at(self, margin: float) -> bool:
        """Whether the comparison holds when its margin is ``margin``."""
        if self.op in ("==",):
            return margin == 0
        if self.op == "!=":
            return margin != 0
        return margin > 0 or (margin == 0 and self.op in ("<=", ">="))


def _compare_nodes(node: ast.AST) -> list[ast.Compare]:
    """The comparison nodes under ``node``, in the order they are written (they never nest)."""
    return sorted((n for n in ast.walk(node) if isinstance(n, ast.Compare)), key=lambda n: (n.lineno, n.col_offset))


def _comparisons(node: ast.AST, aliases: tuple[tuple[str, str], ...]) -> list[Comparison]:
    names = dict(aliases)
    out: list[Comparison] = []
    for sub in _compare_nodes(node):
        left = sub.left
        for cmp, right in zip(sub.ops, sub.comparators):
            used = frozenset(names[n.id] for part in (left, right) for n in ast.walk(part)
                             if isinstance(n, ast.Name) and n.id in names)
            op = _COMPARE[type(cmp)]
            text = f"{ast.unparse(left)} {op} {ast.unparse(right)}"
            text = _ALIAS.sub(lambda m: names[m.group()], text)
            out.append(Comparison(text, op, used, left, right, aliases))
            left = right
    return out


def _kleene(node: ast.AST, decide: Mapping[int, bool | None], order: list[ast.Compare]) -> bool | None:
    """Three-valued value of ``node`` from the decisions of its comparisons (Kleene's logic)."""
    if isinstance(node, ast.Compare):
        base = sum(len(c.ops) for c in order[: order.index(node)])
        parts = [decide[base + i] for i in range(len(node.ops))]
        return False if False in parts else (True if all(p is True for p in parts) else None)
    if isinstance(node, ast.BoolOp):
        parts = [_kleene(v, decide, order) for v in node.values]
        if isinstance(node.op, ast.And):
            return False if False in parts else (True if all(p is True for p in parts) else None)
        return True if True in parts else (False if all(p is False for p in parts) else None)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        inner = _kleene(node.operand, decide, order)
        return None if inner is None else not inner
    raise AssertionError(f"a truth value from {type(node).__name__}")  # pragma: no cover - _check admits no other


@dataclass(frozen=True)
class Rule:
    """A parsed claim rule.

    Attributes
    ----------
    text : str
        The rule as written.
    metrics : frozenset of str
        The metric names the rule reads.
    """

    text: str
    metrics: frozenset[str]
    _tree: ast.Expression
    _aliases: tuple[tuple[str, str], ...]  # (alias, metric name)

    def evaluate(self, metrics: Mapping[str, float]) -> bool | None:
        """Evaluate the rule on ``metrics``.

        Parameters
        ----------
        metrics : mapping of str to float
            Must hold every name in :attr:`metrics`.

        Returns
        -------
        bool or None
            The verdict, or None ("not evaluated") when a metric used is NaN or missing
            its value (None), or a comparison meets a NaN computed by the rule.
        """
        missing = sorted(name for name in self.metrics if name not in metrics)
        if missing:
            raise _unknown_metric(self.text, missing[0], list(metrics), self.text.find(missing[0]))
        values: dict[str, float] = {}
        for alias, name in self._aliases:
            value = metrics[name]
            if value is None or math.isnan(float(value)):
                return None
            values[alias] = float(value)
        try:
            return bool(_eval(self._tree.body, values))
        except _Undefined:
            return None

    def comparisons(self) -> list[Comparison]:
        """The rule's comparisons, in the order they are written (a chain gives one per operator)."""
        return _comparisons(self._tree.body, self._aliases)

    def combine(self, decisions: Sequence[bool | None]) -> bool | None:
        """The rule's truth from a three-valued decision per comparison (Kleene's logic).

        Parameters
        ----------
        decisions : sequence of bool or None
            One per comparison, in the order of :meth:`comparisons`: True (holds), False
            (fails) or None (undecided).

        Returns
        -------
        bool or None
            ``and`` is False when a part is False, True when every part is True, else None;
            ``or`` is True when a part is True, False when every part is False, else None;
            ``not`` swaps True and False.
        """
        order = _compare_nodes(self._tree.body)
        if len(decisions) != sum(len(c.ops) for c in order):
            raise ExperimentError(f"claim rule {self.text!r}: {len(decisions)} decisions given for "
                                  f"{sum(len(c.ops) for c in order)} comparisons.")
        return _kleene(self._tree.body, dict(enumerate(decisions)), order)


def parse_rule(rule: str, names: Collection[str] | None = None) -> Rule:
    """Parse a claim rule.

    Parameters
    ----------
    rule : str
        The rule text, e.g. ``"0 < nmf.l_full - svm.l_full < 0.2 and 16.kl > 0.5"``.
    names : collection of str, optional
        The known metric names. A word of the rule that is one of them is a metric; a
        word that is not and does not read as a number is an error listing close
        matches. When None (checking the syntax before any metric exists), every word
        that does not read as a number is taken as a metric name.

    Returns
    -------
    Rule

    Raises
    ------
    ExperimentError
        On a syntax error, a type error (``abs(a > b)``, ``a + b`` as a whole rule) or an
        unknown metric name; the message shows the position.
    """
    if not isinstance(rule, str):
        raise ExperimentError(f"a claim rule must be a string; got {type(rule).__name__}.")
    if not rule.strip():
        raise _error(rule, "the rule is empty")
    if names is not None and not isinstance(names, (set, frozenset, dict)):
        names = frozenset(names)
    src = _rewrite(rule, names)
    try:
        tree = ast.parse(src.text.strip(), mode="eval")
    except SyntaxError as exc:
        lead = len(src.text) - len(src.text.lstrip())
        if exc.offset:
            exc.offset += lead
        raise _describe_syntax_error(exc, src) from None
    # strip() moved the offsets: walk with the leading blank accounted for
    lead = len(src.text) - len(src.text.lstrip())
    if lead:
        for node in ast.walk(tree):
            if hasattr(node, "col_offset"):
                node.col_offset += lead
    if _check(tree.body, src) != "bool":
        raise _error(rule, "a rule must be true or false (use a comparison such as 'a > b'), but this one computes a number")
    return Rule(text=rule, metrics=frozenset(src.metrics.values()), _tree=tree,
                _aliases=tuple(src.metrics.items()))


def evaluate_rule(rule: str, metrics: Mapping[str, float]) -> bool | None:
    """Parse ``rule`` against the names of ``metrics`` and evaluate it.

    Parameters
    ----------
    rule : str
        The rule text (see the module docstring for the language).
    metrics : mapping of str to float
        Metric values; NaN (or None) means "not measured".

    Returns
    -------
    bool or None
        True if the claim holds, False if it does not, None if it cannot be evaluated
        because a metric it uses is NaN.

    Raises
    ------
    ExperimentError
        If the rule does not parse or names an unknown metric.

    Examples
    --------
    >>> evaluate_rule("0 < 16.nmf.acc - svm.acc < 0.2", {"16.nmf.acc": 0.9, "svm.acc": 0.8})
    True
    >>> evaluate_rule("a > 1", {"a": float("nan")}) is None
    True
    """
    return parse_rule(rule, metrics.keys()).evaluate(metrics)


# --------------------------------------------------------------------------- bars above chance

#: The chance-corrected score a claim "above chance" asks for: ``(p - p0) / (ceiling - p0)`` above 0.2, the form of
#: Cohen's kappa, whose values up to 0.2 are "slight" agreement on the scale of Landis and Koch (1977). A useless
#: learner (``p = p0``) scores 0 on it, so a bar set this way cannot be passed at chance, however small ``p0``.
FAIR_AGREEMENT = 0.2


def fair_bar(chance: float, ceiling: float = 1.0) -> float:
    """The bar of a claim "above chance": ``chance + FAIR_AGREEMENT * (ceiling - chance)``.

    Examples
    --------
    >>> round(fair_bar(0.1), 3)   # 10 candidates: a random ranking succeeds 1 time in 10
    0.28
    """
    return float(chance) + FAIR_AGREEMENT * (float(ceiling) - float(chance))


def above_chance_rule(metric: str, chance: str, ceiling: str | None = None, *, below: bool = False) -> str:
    """The rule ``metric > chance + FAIR_AGREEMENT * (ceiling - chance)`` over metric names (ceiling 1 if None).

    ``chance`` is the metric (or number) a useless learner scores (a random ranking, an input-blind labelling, a
    shuffled control), computed by the experiment on the same folds; the rule asks for a chance-corrected score above
    :data:`FAIR_AGREEMENT`. With ``below``, the rule that ``metric`` stays under the bar (``<``), for a control.

    Examples
    --------
    >>> above_chance_rule("s2m.retrieval", "chance.retrieval")
    's2m.retrieval > chance.retrieval + 0.2 * (1 - chance.retrieval)'
    """
    top = "1" if ceiling is None else ceiling
    return f"{metric} {'<' if below else '>'} {chance} + {FAIR_AGREEMENT} * ({top} - {chance})"
