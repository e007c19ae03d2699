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
import math
import re
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

from ..errors import ExperimentError
from .rule_syntax import (
    COMPARE,
    RESERVED_WORDS,
    Undefined,
    check_node,
    describe_syntax_error,
    evaluate_node,
    is_valid_metric_name,
    rewrite_rule,
    rule_error,
    unknown_metric,
)

__all__ = ["Rule", "Comparison", "parse_rule", "evaluate_rule", "is_valid_metric_name", "RESERVED_WORDS",
           "FAIR_AGREEMENT", "fair_bar", "above_chance_rule"]

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
            left, right = float(evaluate_node(self._left, values)), float(evaluate_node(self._right, values))
        except Undefined:  # a NaN met inside (min of NaN, ...)
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
            op = COMPARE[type(cmp)]
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
    raise AssertionError(f"a truth value from {type(node).__name__}")  # pragma: no cover - check_node admits no other


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
            raise unknown_metric(self.text, missing[0], list(metrics), self.text.find(missing[0]))
        values: dict[str, float] = {}
        for alias, name in self._aliases:
            value = metrics[name]
            if value is None or math.isnan(float(value)):
                return None
            values[alias] = float(value)
        try:
            return bool(evaluate_node(self._tree.body, values))
        except Undefined:
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
        raise rule_error(rule, "the rule is empty")
    if names is not None and not isinstance(names, (set, frozenset, dict)):
        names = frozenset(names)
    src = rewrite_rule(rule, names)
    try:
        tree = ast.parse(src.text.strip(), mode="eval")
    except SyntaxError as exc:
        lead = len(src.text) - len(src.text.lstrip())
        if exc.offset:
            exc.offset += lead
        raise describe_syntax_error(exc, src) from None
    # strip() moved the offsets: walk with the leading blank accounted for
    lead = len(src.text) - len(src.text.lstrip())
    if lead:
        for node in ast.walk(tree):
            if hasattr(node, "col_offset"):
                node.col_offset += lead
    if check_node(tree.body, src) != "bool":
        raise rule_error(rule, "a rule must be true or false (use a comparison such as 'a > b'), but this one computes a number")
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
