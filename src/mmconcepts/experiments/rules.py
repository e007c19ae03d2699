"""A tiny, safe language for claim rules over metric names.

A claim of an experiment says something the thesis found ("NMF beats the SVM on the
full test set") and a rule that checks it from our numbers::

    nmf_frobenius.l_full > svm.l_full
    0.8 <= 16.nmf_kl.l_full < 1 and abs(bins_20.l_single - 0.5) < 0.1

The language is parsed here by hand (no :func:`eval`): Python has no safe expression
evaluator in the standard library, and metric names such as ``16.nmf_kl.l_full`` are not
Python identifiers anyway.

Grammar (Python precedence, lowest first)::

    rule       := or_expr
    or_expr    := and_expr ("or" and_expr)*
    and_expr   := not_expr ("and" not_expr)*
    not_expr   := "not" not_expr | comparison
    comparison := sum (("<" | "<=" | ">" | ">=" | "==" | "!=") sum)*   # chained, like Python
    sum        := product (("+" | "-") product)*
    product    := unary (("*" | "/") unary)*
    unary      := ("+" | "-") unary | atom
    atom       := NUMBER | METRIC | FUNC "(" sum ("," sum)* ")" | "(" or_expr ")"
    FUNC       := "abs" | "min" | "max"

A *word* is a maximal run of ``[A-Za-z0-9_.]``. A word that is a known metric name is a
metric; otherwise, if it reads as a decimal number (``3``, ``0.5``, ``.5``, ``1e-3``) it
is a number; otherwise it is an unknown metric and an error. The words ``and``, ``or``,
``not`` are operators, and ``abs``, ``min``, ``max`` are functions when a ``(`` follows.

Rules are typed: arithmetic and comparisons take numbers, ``and``/``or``/``not`` take
truth values, and a whole rule must be a truth value. Type errors are found when the rule
is parsed, before any number is looked at.

If a metric used by the rule is NaN (not measured), or a comparison meets a NaN computed
by the rule itself (``0 / 0``), the verdict is ``None``: *not evaluated*. Division by zero
follows IEEE arithmetic (``1 / 0`` is infinite).
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import ExperimentError

__all__ = ["Rule", "parse_rule", "evaluate_rule", "is_valid_metric_name", "RESERVED_WORDS"]

#: Words that cannot be metric names.
RESERVED_WORDS = frozenset({"and", "or", "not", "abs", "min", "max"})

_WORD_CHARS = re.compile(r"[A-Za-z0-9_.]+")
_NUMBER = re.compile(r"(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\Z")
_EXPONENT_START = re.compile(r"(?:\d+(?:\.\d*)?|\.\d+)[eE]\Z")
_EXPONENT_REST = re.compile(r"[+-]\d+")
_OPERATORS = ("<=", ">=", "==", "!=", "<", ">", "+", "-", "*", "/", "(", ")", ",")
_COMPARISONS = {"<", "<=", ">", ">=", "==", "!="}
_FUNCTIONS = {"abs": (1, 1), "min": (1, None), "max": (1, None)}


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


# --------------------------------------------------------------------------- tokens


@dataclass(frozen=True)
class _Token:
    kind: str  # "num", "metric", "op", "kw", "func", "end"
    value: Any
    pos: int


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
    return ExperimentError(
        f"claim rule {rule!r}: unknown metric {name!r} at position {pos}.{hint}{listing}"
    )


def _tokenize(rule: str, names: Collection[str] | None) -> list[_Token]:
    tokens: list[_Token] = []
    i, n = 0, len(rule)
    while i < n:
        ch = rule[i]
        if ch.isspace():
            i += 1
            continue
        m = _WORD_CHARS.match(rule, i)
        if m:
            word, start, i = m.group(), i, m.end()
            nxt = rule[i:].lstrip()[:1]
            if names is not None and word in names:
                tokens.append(_Token("metric", word, start))
            elif word in ("and", "or", "not"):
                tokens.append(_Token("kw", word, start))
            elif word in _FUNCTIONS and nxt == "(":
                tokens.append(_Token("func", word, start))
            elif _NUMBER.fullmatch(word):
                tokens.append(_Token("num", float(word), start))
            elif _EXPONENT_START.fullmatch(word) and _EXPONENT_REST.match(rule, i):
                # "1e-3": the word run stops at the sign of the exponent.
                rest = _EXPONENT_REST.match(rule, i)
                assert rest is not None
                i = rest.end()
                tokens.append(_Token("num", float(rule[start:i]), start))
            elif word in RESERVED_WORDS:
                raise _error(rule, f"{word!r} is a function and must be followed by '('", start)
            elif names is None:
                tokens.append(_Token("metric", word, start))
            else:
                raise _unknown_metric(rule, word, names, start)
            continue
        for op in _OPERATORS:
            if rule.startswith(op, i):
                tokens.append(_Token("op", op, i))
                i += len(op)
                break
        else:
            raise _error(rule, f"unexpected character {ch!r}", i)
    tokens.append(_Token("end", None, n))
    return tokens


# --------------------------------------------------------------------------- parser
#
# Nodes are tuples; node[0] is the kind:
#   ("num", float) ("metric", name) ("neg", x) ("bin", op, a, b) ("call", f, [args])
#   ("cmp", [ops], [operands]) ("and", [xs]) ("or", [xs]) ("not", x)
# Numeric kinds: num metric neg bin call; boolean kinds: cmp and or not.

_NUMERIC = {"num", "metric", "neg", "bin", "call"}


class _Parser:
    def __init__(self, rule: str, tokens: list[_Token]) -> None:
        self.rule = rule
        self.tokens = tokens
        self.i = 0

    @property
    def tok(self) -> _Token:
        return self.tokens[self.i]

    def _describe(self, tok: _Token) -> str:
        if tok.kind == "end":
            return "end of rule"
        if tok.kind == "num":
            return f"number {tok.value:g}"
        return repr(tok.value)

    def fail(self, message: str, tok: _Token | None = None) -> ExperimentError:
        tok = tok or self.tok
        return _error(self.rule, message, tok.pos)

    def accept(self, kind: str, value: Any = None) -> _Token | None:
        tok = self.tok
        if tok.kind == kind and (value is None or tok.value == value):
            self.i += 1
            return tok
        return None

    def expect(self, kind: str, value: Any, what: str) -> _Token:
        tok = self.accept(kind, value)
        if tok is None:
            raise self.fail(f"expected {what}, found {self._describe(self.tok)}")
        return tok

    def need(self, node: tuple, want: str, tok: _Token) -> tuple:
        is_num = node[0] in _NUMERIC
        if want == "num" and not is_num:
            raise self.fail("expected a number here, found a true/false expression", tok)
        if want == "bool" and is_num:
            raise self.fail("expected a true/false expression (a comparison) here, found a number", tok)
        return node

    def parse(self) -> tuple:
        if self.tok.kind == "end":
            raise _error(self.rule, "the rule is empty")
        node = self.or_expr()
        if self.tok.kind != "end":
            raise self.fail(f"unexpected {self._describe(self.tok)}")
        if node[0] in _NUMERIC:
            raise _error(
                self.rule,
                "a rule must be true or false (use a comparison such as 'a > b'), "
                "but this one computes a number",
            )
        return node

    def or_expr(self) -> tuple:
        tok = self.tok
        items = [self.and_expr()]
        while (op := self.accept("kw", "or")) is not None:
            items.append(self.and_expr())
            tok = op
        if len(items) == 1:
            return items[0]
        for item in items:
            self.need(item, "bool", tok)
        return ("or", items)

    def and_expr(self) -> tuple:
        tok = self.tok
        items = [self.not_expr()]
        while (op := self.accept("kw", "and")) is not None:
            items.append(self.not_expr())
            tok = op
        if len(items) == 1:
            return items[0]
        for item in items:
            self.need(item, "bool", tok)
        return ("and", items)

    def not_expr(self) -> tuple:
        op = self.accept("kw", "not")
        if op is not None:
            return ("not", self.need(self.not_expr(), "bool", op))
        return self.comparison()

    def comparison(self) -> tuple:
        first_tok = self.tok
        first = self.sum()
        ops: list[str] = []
        operands = [first]
        while self.tok.kind == "op" and self.tok.value in _COMPARISONS:
            op = self.tok
            self.i += 1
            ops.append(op.value)
            operand_tok = self.tok
            operands.append(self.need(self.sum(), "num", operand_tok))
        if not ops:
            return first
        self.need(first, "num", first_tok)
        return ("cmp", ops, operands)

    def sum(self) -> tuple:
        left_tok = self.tok
        node = self.product()
        while self.tok.kind == "op" and self.tok.value in ("+", "-"):
            op = self.tok
            self.i += 1
            right_tok = self.tok
            right = self.product()
            node = ("bin", op.value, self.need(node, "num", left_tok), self.need(right, "num", right_tok))
        return node

    def product(self) -> tuple:
        left_tok = self.tok
        node = self.unary()
        while self.tok.kind == "op" and self.tok.value in ("*", "/"):
            op = self.tok
            self.i += 1
            right_tok = self.tok
            right = self.unary()
            node = ("bin", op.value, self.need(node, "num", left_tok), self.need(right, "num", right_tok))
        return node

    def unary(self) -> tuple:
        if self.tok.kind == "op" and self.tok.value in ("+", "-"):
            op = self.tok
            self.i += 1
            operand_tok = self.tok
            operand = self.need(self.unary(), "num", operand_tok)
            return ("neg", operand) if op.value == "-" else operand
        return self.atom()

    def atom(self) -> tuple:
        tok = self.tok
        if tok.kind == "num":
            self.i += 1
            return ("num", tok.value)
        if tok.kind == "metric":
            self.i += 1
            return ("metric", tok.value)
        if tok.kind == "func":
            self.i += 1
            self.expect("op", "(", f"'(' after {tok.value}")
            args = []
            if self.tok.kind == "op" and self.tok.value == ")":
                raise self.fail(f"{tok.value}() needs at least one argument")
            while True:
                arg_tok = self.tok
                args.append(self.need(self.sum(), "num", arg_tok))
                if self.accept("op", ",") is None:
                    break
            self.expect("op", ")", f"',' or ')' in the call to {tok.value}")
            lo, hi = _FUNCTIONS[tok.value]
            if len(args) < lo or (hi is not None and len(args) > hi):
                expected = f"exactly {lo}" if lo == hi else f"at least {lo}"
                raise self.fail(f"{tok.value}() takes {expected} argument(s), got {len(args)}", tok)
            return ("call", tok.value, args)
        if tok.kind == "op" and tok.value == "(":
            self.i += 1
            node = self.or_expr()
            self.expect("op", ")", "')'")
            return node
        raise self.fail(f"expected a number, a metric name or '(', found {self._describe(tok)}")


# --------------------------------------------------------------------------- evaluation


def _div(a: float, b: float) -> float:
    if b != 0:
        return a / b
    if a == 0 or math.isnan(a) or math.isnan(b):
        return math.nan
    return math.copysign(math.inf, a) * math.copysign(1.0, b)


def _compare(op: str, a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        raise _Undefined
    if op == "<":
        return a < b
    if op == "<=":
        return a <= b
    if op == ">":
        return a > b
    if op == ">=":
        return a >= b
    if op == "==":
        return a == b
    return a != b


def _eval(node: tuple, metrics: Mapping[str, float]) -> Any:
    kind = node[0]
    if kind == "num":
        return node[1]
    if kind == "metric":
        return float(metrics[node[1]])
    if kind == "neg":
        return -_eval(node[1], metrics)
    if kind == "bin":
        a, b = _eval(node[2], metrics), _eval(node[3], metrics)
        op = node[1]
        if op == "+":
            return a + b
        if op == "-":
            return a - b
        if op == "*":
            return a * b
        return _div(a, b)
    if kind == "call":
        args = [_eval(arg, metrics) for arg in node[2]]
        if node[1] == "abs":
            return abs(args[0])
        if any(math.isnan(x) for x in args):
            return math.nan
        return min(args) if node[1] == "min" else max(args)
    if kind == "cmp":
        ops, operands = node[1], node[2]
        left = _eval(operands[0], metrics)
        for op, operand in zip(ops, operands[1:]):
            right = _eval(operand, metrics)
            if not _compare(op, left, right):
                return False
            left = right
        return True
    if kind == "and":
        return all(_eval(item, metrics) for item in node[1])
    if kind == "or":
        return any(_eval(item, metrics) for item in node[1])
    if kind == "not":
        return not _eval(node[1], metrics)
    raise AssertionError(f"unknown node {kind}")  # pragma: no cover


def _collect_metrics(node: tuple, out: set[str]) -> None:
    kind = node[0]
    if kind == "metric":
        out.add(node[1])
    elif kind == "neg" or kind == "not":
        _collect_metrics(node[1], out)
    elif kind == "bin":
        _collect_metrics(node[2], out)
        _collect_metrics(node[3], out)
    elif kind in ("call", "cmp"):
        for child in node[2]:
            _collect_metrics(child, out)
    elif kind in ("and", "or"):
        for child in node[1]:
            _collect_metrics(child, out)


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
    _tree: tuple

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
        for name in self.metrics:
            value = metrics[name]
            if value is None or math.isnan(float(value)):
                return None
        try:
            return bool(_eval(self._tree, metrics))
        except _Undefined:
            return None


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
    if names is not None and not isinstance(names, (set, frozenset, dict)):
        names = frozenset(names)
    tokens = _tokenize(rule, names)
    tree = _Parser(rule, tokens).parse()
    used: set[str] = set()
    _collect_metrics(tree, used)
    return Rule(text=rule, metrics=frozenset(used), _tree=tree)


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
