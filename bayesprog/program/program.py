"""Programs: load a YAML file, check it whole, ask it questions, ablate its terms."""

from __future__ import annotations

import copy
import dataclasses
import errno
import numbers
import os
from collections.abc import Iterable, Mapping, Sequence
from contextvars import ContextVar
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.errors import (
    ArgumentError,
    Diagnostic,
    ProgramCycleError,
    QuestionError,
    SpecError,
    did_you_mean,
    short_repr,
)
from bayesprog.forms import ParamValue, get_form
from bayesprog.inference.core import InferenceCache
from bayesprog.language.check import check_document, conditioning_problem, question_problem
from bayesprog.language.loader import Located, load_yaml
from bayesprog.language.plain import PlainDocument, read_plain
from bayesprog.model import InputDecl, Term
from bayesprog.support import cache, rich
from bayesprog.support.extras import LazyModule
from bayesprog.support.files import atomic_write
from bayesprog.vocabulary.expressions import (
    Expression,
    ExpressionError,
    Question,
    canonical,
    parse_expression,
)
from bayesprog.vocabulary.variables import Discrete, Variable

if TYPE_CHECKING:  # imported when a program is learned or drawn, not when bayesprog is
    import networkx as nx
    import pandas as pd

    from bayesprog.inference import MapResult, Posterior
    from bayesprog.inference.density import Density
    from bayesprog.inference.event import Probability
    from bayesprog.inference.mixed import Joint
    from bayesprog.language.document import Document
    from bayesprog.learning import Estimate
    from bayesprog.learning.csv_rows import BadRow
    from bayesprog.learning.evidence import Evidence
    from bayesprog.model.records import FitRecord


# the question machinery, imported at the first question: loading, checking and learning a
# program do not need it
quick = LazyModule("bayesprog.inference.quick")
dispatch = LazyModule("bayesprog.inference.dispatch")
answers = LazyModule("bayesprog.inference.answers")
densities = LazyModule("bayesprog.inference.density")


class Program:
    """A checked Bayesian program: variables, decomposition, questions; asked through the engine.

    >>> import bayesprog
    >>> p = bayesprog.loads('''
    ... bayesprog: 1
    ... variables:
    ...   Rain: {states: [rain, dry]}
    ...   Grass: {states: [wet, dry]}
    ... decomposition:
    ...   - {term: P(Rain), form: table, table: [0.2, 0.8]}
    ...   - term: P(Grass | Rain)
    ...     form: table
    ...     table: {rain: [0.9, 0.1], dry: [0.2, 0.8]}
    ... ''')
    >>> p.ask("P(Rain | Grass=wet)").probabilities.round(4).tolist()
    [0.5294, 0.4706]
    """

    def __init__(
        self,
        variables: dict[str, Variable],
        terms: list[Term],
        questions: dict[str, Question],
        inputs: dict[str, InputDecl],
        *,
        name: str | None = None,
        description: str = "",
        path: Path | None = None,
        ablated: tuple[str, ...] = (),
        learned: Sequence[FitRecord] = (),
        time: tuple[tuple[str, str], ...] | None = None,
    ):
        self.variables = variables
        self.terms = terms
        self.questions = questions
        self.inputs = inputs
        self.name = name or (path.stem if path else "program")
        self.description = description
        self.path = path
        self.ablated = ablated
        #: the fits that set the parameters (provenance and statistics), oldest first
        self.learned = list(learned)
        #: the (previous, state) pairs when the decomposition is one time step, else None
        self.time = time
        self.inference_cache = InferenceCache()
        self._parsed: dict[str, Question] = {}  # question texts asked before, parsed

    # structure -------------------------------------------------------------------------------------
    @cached_property
    def graph(self) -> nx.DiGraph:
        """The decomposition as a DAG: one node per variable, an edge from each parent."""
        import networkx as nx

        g = nx.DiGraph()
        for name, var in self.variables.items():
            g.add_node(name, variable=var)
        for t in self.terms:
            if not t.soft:
                for p in t.parents:
                    g.add_edge(p.name, t.child.name)
        return g

    def ancestors(self, name: str) -> set[str]:
        """The variables ``name`` depends on through the decomposition (its parents, theirs...)."""
        cache = self.__dict__.setdefault("_ancestors", {})
        if name not in cache:
            parents = self._parents
            found: set[str] = set()
            todo = [name]
            while todo:
                for p in parents.get(todo.pop(), ()):
                    if p not in found:
                        found.add(p)
                        todo.append(p)
            cache[name] = found
        return cache[name]

    @cached_property
    def _parents(self) -> dict[str, tuple[str, ...]]:
        out: dict[str, tuple[str, ...]] = {}
        for t in self.terms:
            if not t.soft:
                out[t.child.name] = out.get(t.child.name, ()) + tuple(p.name for p in t.parents)
        return out

    @cached_property
    def active_terms(self) -> list[Term]:
        """The terms with every ablated term replaced by a uniform."""
        if not self.ablated:
            return list(self.terms)
        uniform = get_form("uniform")
        out = []
        for t in self.terms:
            if not t.soft and str(t.expression) in self.ablated:
                t = Term(t.expression, t.child, t.parents, uniform, {}, t.position,  # type: ignore[arg-type]
                         description="ablated: uniform")
            out.append(t)
        return out

    @cached_property
    def conditioning(self) -> tuple[str, ...]:
        """The variables the decomposition gives no term (a control, a known input), in their
        order of declaration: the program is the conditional distribution of the others given
        them, ``P(X Y | U)``, and every question gives their values.

        >>> import bayesprog
        >>> p = bayesprog.loads('''
        ... bayesprog: 1
        ... variables: {X: {states: [x0, x1]}, U: {states: [u0, u1]}}
        ... decomposition:
        ...   - {term: "P(X | U)", form: table, table: {u0: [0.9, 0.1], u1: [0.2, 0.8]}}
        ... ''')
        >>> p.conditioning, p.ask("P(X | U=u1)").probabilities.tolist()
        (('U',), [0.2, 0.8])
        """
        defined = {t.child.name for t in self.terms if not t.soft}
        return tuple(name for name in self.variables if name not in defined)

    @property
    def is_discrete(self) -> bool:
        return all(v.is_discrete for v in self.variables.values())

    def term_of(self, variable: str) -> Term:
        """The decomposition term that defines ``variable``."""
        for t in self.terms:
            if not t.soft and t.child.name == variable:
                return t
        raise QuestionError(f"no variable {variable!r} in {self.name}")

    def term(self, text: str) -> Term:
        """The term written ``text`` (parents in any order)."""
        expr = parse_expression(text)
        for t in self.terms:
            if not t.soft and t.expression.key == expr.key:
                return t
        terms = [str(t.expression) for t in self.terms if not t.soft]
        defined = next((t for t in terms if parse_expression(t).left == expr.left), None)
        hint = (f": did you mean {defined!r}?" if defined is not None
                else did_you_mean(str(expr), terms))
        raise QuestionError(f"no term {expr} in {self.name}{hint} (terms: {', '.join(terms)})")

    def table(self, term: str) -> pd.DataFrame:
        """The probabilities of a discrete term as a pandas DataFrame: one row per
        configuration of its parents (their states as the index, a MultiIndex for several),
        one column per state of its variable. A term without parents is one row, indexed by
        the term. An ablated term gives its uniform.

        >>> import bayesprog
        >>> p = bayesprog.loads('''
        ... bayesprog: 1
        ... variables: {A: {states: [a0, a1]}, B: {states: [b0, b1]}}
        ... decomposition:
        ...   - {term: P(A), form: table, table: [0.3, 0.7]}
        ...   - {term: P(B | A), form: table, table: {a0: [0.9, 0.1], a1: [0.2, 0.8]}}
        ... ''')
        >>> t = p.table("P(B | A)")
        >>> t.loc["a1"].tolist(), t.columns.tolist(), t.index.name
        ([0.2, 0.8], ['b0', 'b1'], 'A')
        """
        import pandas as pd

        from bayesprog.inference.factors import is_static, plain_table

        key = self.term(term).expression.key
        found = next(t for t in self.active_terms if not t.soft and t.expression.key == key)
        child, parents = found.child, list(found.parents)
        real = [p.name for p in parents if not isinstance(p, Discrete)]
        if not isinstance(child, Discrete) or real or not is_static(found):
            why = (f"{child.name} is real" if not isinstance(child, Discrete) else
                   f"it depends on the real {', '.join(real)}" if real else
                   "it reads inputs or evidence values")
            raise QuestionError(f"{found.expression} is not a table of probabilities: {why} "
                                "(its parameters are in program.term(...).params)")
        made = plain_table(self, found)
        assert made is not None  # a static term
        axes, array, log_top = made  # a table written as probabilities: as written
        order = [axes.index(p.name) for p in parents] + [axes.index(child.name)]
        probabilities = np.transpose(array * np.exp(log_top) if log_top else array, order)
        # the states as values of their type, as answers give them: integers for a range
        columns = pd.Index(list(child.typed_states), name=child.name, tupleize_cols=False)
        if not parents:
            return pd.DataFrame(probabilities[None, :], index=[str(found.expression)],
                                columns=columns)
        levels = [pd.Index(list(p.typed_states), tupleize_cols=False) for p in parents
                  if isinstance(p, Discrete)]
        index: pd.Index = pd.MultiIndex.from_product(levels, names=[p.name for p in parents])
        if len(parents) == 1:
            index = index.get_level_values(0)
        return pd.DataFrame(probabilities.reshape(-1, child.card), index=index, columns=columns)

    # questions -------------------------------------------------------------------------------------
    def question(self, question: str | Question | Expression, kind: str | None = None) -> Question:
        """A question by name, by ``P(A | B)`` text, or as given."""
        if isinstance(question, Question):
            q = question
        elif isinstance(question, Expression):
            q = Question(question, "probability" if question.event else "posterior")
        elif question in self.questions:
            q = self.questions[question]
        elif question in self._parsed:
            q = self._parsed[question]
        else:
            try:
                expr = parse_expression(question)
            except ExpressionError as exc:
                names = ", ".join(self.questions) or "none"
                hint = ""
                if isinstance(question, str) and "(" not in question:  # a name misspelt
                    hint = (f": ask P({question}) for its distribution"
                            if question in self.variables else
                            did_you_mean(question, self.questions))
                raise QuestionError(f"{exc} (named questions of {self.name}: {names}){hint}"
                                    ) from None
            problem = question_problem(expr, self.variables)
            if problem:
                raise QuestionError(problem)
            q = Question(expr, "probability" if expr.event else "posterior")
            if len(self._parsed) < 1024:  # a question asked again is parsed once
                self._parsed[question] = q
        if kind is not None and kind != q.kind:
            if kind not in ("posterior", "map", "filter", "smooth", "sequence", "probability"):
                raise QuestionError(f"kind must be 'posterior', 'map', 'filter', 'smooth', "
                                    f"'sequence' or 'probability', got {kind!r}")
            if q.expression.event:
                raise QuestionError(f"{q.expression} asks the probability of an event, not a "
                                    f"{kind} question: ask P(searched | known) without values "
                                    "on the left for a distribution")
            q = Question(q.expression, kind, q.name, q.description)
        if self.conditioning:
            problem = conditioning_problem(q.expression, self.conditioning)
            if problem:
                raise QuestionError(problem)
        return q

    def ask(
        self,
        question: str | Question,
        evidence: Mapping[str, Any] | None = None,
        *,
        inputs: Mapping[str, Any] | None = None,
        soft: Mapping[str, Any] | None = None,
        kind: str | None = None,
        rng: Any = None,
        method: str | None = None,
        samples: int | None = None,
        bins: int | None = None,
        burn_in: int | None = None,
        thin: int | None = None,
        ablate: Mapping[str, Any] | None = None,
    ) -> Posterior | MapResult | Density | Joint | Probability:
        """Answer ``question`` for the evidence (arrays with leading batch dimensions allowed).

        Parameters
        ----------
        question : a question name, ``"P(A B | C=c, D)"`` text, or a :class:`Question`.
        evidence : values of the known variables: state names or indices (discrete), numbers
            (continuous), arrays ``batch + (card,)`` for fields. Leading dimensions broadcast
            together into the batch shape; N evidence sets are one call.
        inputs : runtime inputs (arrays with the declared trailing shape, batch dims in front).
        soft : likelihood vectors over a discrete variable's states (virtual evidence).
        kind : ``"posterior"`` or ``"map"``, overriding the question's kind.
        rng : for MAP ties and sampling: a seed, a ``numpy.random.Generator``, or one generator
            per batch row (then each row's choice is independent of the batching). ``None``
            means seed 0.
        method : ``None`` (the cheapest exact method; with unknown real variables that are
            not linear-Gaussian, ``"grid"``), ``"table"``, ``"contraction"`` or
            ``"gaussian"`` (exact), ``"lbp"`` (loopy belief propagation), ``"lw"``
            (likelihood weighting, with ``stderr`` and ``ess`` on the answer) or ``"grid"``
            (unknown real variables on bins, with an estimated ``error``).
        samples : draws per evidence row for ``method="lw"``, kept sweeps for ``"gibbs"``
            (default 10,000).
        burn_in, thin : for ``method="gibbs"``: the sweeps forgotten first (default 1,000), and
            one sweep kept in ``thin`` (default 1).
        bins : bins per unknown real variable for ``method="grid"`` (default 128; the answer
            is made with twice as many, and its error estimated from the difference).
        ablate : terms made uniform on some rows of the batch: ``{"P(B | A)": rows}``, where
            ``rows`` are booleans that broadcast with the batch (True: the term is uniform on
            that row, as in :meth:`ablate`; False: it is as written). Rows that differ in
            which terms they use are then one question, answered exactly by contraction (or
            by ``"lbp"``); on a row that ablates a term, its inputs are not read (any finite
            values stand in).

        Returns
        -------
        Posterior with ``probabilities[batch..., states...]``, MapResult for MAP questions,
        for a question on real variables a Density (``mean``, ``sd``, ``quantile``, ``map``,
        ``pdf``), and for one on discrete and real variables together a Joint (the discrete
        configurations' ``weights``, the real ones' density given each, its ``map()``).
        """
        # a question asked again with one state name per known variable (or none): its warm path
        warm = (type(question) is str and (evidence is None or type(evidence) is dict)
                and inputs is None and soft is None and ablate is None and rng is None
                and samples is None and bins is None and burn_in is None and thin is None
                and (kind is None or kind == "posterior")
                and (method is None or type(method) is str))
        if warm:
            kept = (question, kind, method, tuple(evidence) if evidence else ())
            kernel = self.inference_cache.quick.get(kept)  # (quick.answer, without a call)
            if kernel is not None:
                found = kernel(evidence or {})
                if found is not None:
                    return found
        q = self.question(question, kind)
        if soft and self.conditioning and isinstance(soft, Mapping):
            given = [name for name in soft if name in self.conditioning]
            if given:
                raise QuestionError(f"soft evidence on {', '.join(given)}: it has no term in "
                                    "the decomposition, so the question gives its value; "
                                    "expected soft evidence on a variable with a term")
        options: dict[str, Any] = {}
        if samples is not None:
            if isinstance(samples, bool) or not isinstance(samples, numbers.Integral) \
                    or samples < 1:
                raise ArgumentError(f"samples: expected an integer >= 1, found "
                                    f"{short_repr(samples)}")
            options["samples"] = int(samples)
        if bins is not None:
            if isinstance(bins, bool) or not isinstance(bins, numbers.Integral) or bins < 2:
                raise ArgumentError(f"bins: expected an integer >= 2, found {short_repr(bins)}")
            options["bins"] = int(bins)
        for key, value, least in (("burn_in", burn_in, 0), ("thin", thin, 1)):
            if value is not None:
                if isinstance(value, bool) or not isinstance(value, numbers.Integral) \
                        or value < least:
                    raise ArgumentError(f"{key}: expected an integer >= {least}, found "
                                        f"{short_repr(value)}")
                options[key] = int(value)
        if method is not None and not isinstance(method, str):
            raise ArgumentError(f"method: expected a method's name, found {short_repr(method)}")
        rows_ablated = self._rows_ablated(ablate) if ablate is not None else None
        if rows_ablated and (q.kind in ("filter", "smooth", "sequence") or len(
                {self.variables[v].is_discrete for v in q.expression.left}) > 1):
            raise QuestionError(f"ablate=: a term made uniform on some rows is answered for "
                                f"questions on discrete variables, not {q.expression} "
                                f"({q.kind}): ablate the term for every row (Program.ablate)")
        if q.kind == "probability":
            if rows_ablated:
                raise QuestionError(f"ablate=: the probability of {q.expression} is asked with "
                                    "each term as written or ablated for every row "
                                    "(Program.ablate)")
            from bayesprog.inference.event import probability

            return probability(self, q, evidence, inputs, soft, method, dict(options, rng=rng))
        if q.kind in ("filter", "smooth", "sequence"):
            from bayesprog.program.dynamic import over_time

            return over_time(self, q, evidence, inputs, soft, method, dict(options, rng=rng))
        if len({self.variables[v].is_discrete for v in q.expression.left}) > 1:
            from bayesprog.inference.mixed import mixed

            return mixed(self, q, evidence, inputs, soft, method, options)
        result = dispatch.ask(self, q, evidence, inputs, soft, rng, method, options,
                               rows_ablated)
        if warm:
            quick.learn(self, kept, q, evidence or {})
        return result

    def _rows_ablated(self, ablate: Any) -> dict[str, Any]:
        """``ask``'s ``ablate`` by each term's text (parents in any order, as :meth:`term`
        reads them); the terms this program already ablates are left out (uniform on every
        row)."""
        if not isinstance(ablate, Mapping) or not all(isinstance(n, str) for n in ablate):
            raise ArgumentError(f"ablate: expected a mapping of terms like 'P(B | A)' to the "
                                f"rows where each is uniform, found {short_repr(ablate)}")
        out: dict[str, Any] = {}
        for name, rows in ablate.items():
            text = str(self.term(name).expression)
            if text not in self.ablated:
                out[text] = rows
        return out

    def posterior(self, question: str | Question, evidence: Mapping[str, Any] | None = None,
                  **kw: Any) -> Posterior:
        """The posterior of discrete searched variables (:meth:`ask` of kind ``posterior``);
        a question on real variables is asked with :meth:`density`."""
        result = self.ask(question, evidence, kind="posterior", **kw)
        if not isinstance(result, answers.Posterior):
            raise QuestionError(_other_answer(result, "posterior"))
        return result

    def marginals(self, evidence: Mapping[str, Any] | None = None,
                  variables: str | list[str] | tuple[str, ...] | None = None, *,
                  inputs: Mapping[str, Any] | None = None,
                  soft: Mapping[str, Any] | None = None,
                  ablate: Mapping[str, Any] | None = None) -> dict[str, Posterior]:
        """The posterior of every discrete variable not observed (or of ``variables``) given
        ``evidence``, in one pass: a junction tree calibrated once, read for all of them
        (batched evidence as in :meth:`ask`; each answer carries the evidence's probability).
        Every unobserved variable the answers depend on must be discrete.

        >>> import bayesprog
        >>> p = bayesprog.loads('''
        ... bayesprog: 1
        ... variables: {Rain: {states: [rain, dry]}, Sprinkler: {states: [on, off]},
        ...             Grass: {states: [wet, dry]}}
        ... decomposition:
        ...   - {term: P(Rain), form: table, table: [0.2, 0.8]}
        ...   - {term: P(Sprinkler), form: table, table: [0.4, 0.6]}
        ...   - {term: 'P(Grass | Rain, Sprinkler)', form: table,
        ...      table: [[[0.99, 0.01], [0.8, 0.2]], [[0.9, 0.1], [0.0, 1.0]]]}
        ... ''')
        >>> found = p.marginals({"Grass": "wet"})
        >>> {name: answer.probabilities.round(4).tolist() for name, answer in found.items()}
        {'Rain': [0.3782, 0.6218], 'Sprinkler': [0.7927, 0.2073]}
        """
        from bayesprog.inference.junction import all_marginals

        return all_marginals(self, evidence, variables, inputs, soft, ablate)

    def density(self, question: str | Question, evidence: Mapping[str, Any] | None = None,
                **kw: Any) -> Density:
        """The posterior density of real searched variables (:meth:`ask` of kind
        ``posterior``): a :class:`~bayesprog.inference.density.Density` with ``mean``,
        ``sd``, ``quantile``, ``pdf`` and ``map``.

        >>> import bayesprog
        >>> p = bayesprog.loads('''
        ... bayesprog: 1
        ... variables: {X: {continuous: [-.inf, .inf]}, Y: {continuous: [-.inf, .inf]}}
        ... decomposition:
        ...   - {term: P(X), form: normal, mean: 0, sigma: 1}
        ...   - {term: P(Y | X), form: normal, mean: X, sigma: 1}
        ... ''')
        >>> d = p.density("P(X | Y)", {"Y": 2.0})
        >>> round(float(d.mean("X")), 12), round(float(d.sd("X")) ** 2, 12)
        (1.0, 0.5)
        """
        result = self.ask(question, evidence, kind="posterior", **kw)
        if not isinstance(result, densities.Density):
            raise QuestionError(_other_answer(result, "density"))
        return result

    def probability(self, question: str | Question,
                    evidence: Mapping[str, Any] | None = None, **kw: Any) -> Probability:
        """The probability of an event given known values, ``P(A=a, B=b | C=c)``: a number per
        row of evidence (a density where the event fixes a real variable). The event's values
        are written in the question or given in ``evidence`` (a batch of events at once);
        ``log_probability`` keeps the precision of very small ones.

        >>> import bayesprog
        >>> p = bayesprog.loads('''
        ... bayesprog: 1
        ... variables: {A: {states: [a0, a1]}, B: {states: [b0, b1]}}
        ... decomposition:
        ...   - {term: P(A), form: table, table: [0.3, 0.7]}
        ...   - {term: P(B | A), form: table, table: [[0.9, 0.1], [0.2, 0.8]]}
        ... ''')
        >>> round(float(p.probability("P(B=b0)")), 12)  # 0.3 * 0.9 + 0.7 * 0.2
        0.41
        >>> p.probability("P(A=a0 | B)", {"B": ["b0", "b1"]}).probability.round(6).tolist()
        [0.658537, 0.050847]
        """
        from bayesprog.inference.event import Probability

        result = self.ask(question, evidence, kind="probability", **kw)
        if not isinstance(result, Probability):
            raise QuestionError(f"{question}: not the probability of an event: ask it with "
                                f"program.ask(...) (here a {type(result).__name__})")
        return result

    def map(self, question: str | Question, evidence: Mapping[str, Any] | None = None,
            **kw: Any) -> MapResult:
        result = self.ask(question, evidence, kind="map", **kw)
        if not isinstance(result, answers.MapResult):  # real variables searched: a density's mode
            raise QuestionError(f"{question}: searches real variables, whose most probable "
                                f"values are not a table's MAP: ask it with "
                                f"program.ask(...) (here a {type(result).__name__}, whose "
                                f".map gives them) or program.density(...).map")
        return result

    def sample(self, n: int, evidence: Mapping[str, Any] | None = None, *,
               inputs: Mapping[str, Any] | None = None, rng: Any = None,
               method: str | None = None) -> Any:
        """``n`` joint draws of the program's variables, as a pandas DataFrame: one column per
        variable (state names, integers for a range; numbers for a continuous variable;
        fields are not drawn), in declaration order.

        ``method``: ``"forward"`` (ancestral sampling; the default without evidence),
        ``"lw"`` (likelihood weighting: the known variables fixed to their evidence, each draw
        with its normalised ``weight`` column; the default with evidence) or ``"rejection"``
        (forward draws kept where they match discrete evidence; unweighted). ``rng``: a seed
        or a ``numpy.random.Generator`` (default seed 0). A variable without a term
        (:attr:`conditioning`) is given in ``evidence``, not drawn: the draws are then those
        of the others given its value, forward (unweighted) when nothing else is known.

        >>> import bayesprog
        >>> p = bayesprog.loads('''
        ... bayesprog: 1
        ... variables: {A: {states: [a0, a1]}, X: {continuous: [-.inf, .inf]}}
        ... decomposition:
        ...   - {term: P(A), form: table, table: [0.3, 0.7]}
        ...   - {term: P(X | A), form: normal, mean: {a0: -1, a1: 1}, sigma: 0.5}
        ... ''')
        >>> draws = p.sample(1000, rng=0)
        >>> list(draws.columns)
        ['A', 'X']
        """
        from bayesprog.inference.sampling import sample_program

        if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 1:
            raise ArgumentError(f"n: expected a number of draws >= 1, found {short_repr(n)}")
        if method not in (None, "forward", "lw", "rejection"):
            raise QuestionError(f"method: expected 'forward', 'lw' or 'rejection', found "
                                f"{short_repr(method)}")
        return sample_program(self, int(n), evidence, inputs, rng, method)

    # ablation --------------------------------------------------------------------------------------
    def ablate(self, *terms: str | Iterable[str]) -> Program:
        """A new program in which each named term is replaced by a uniform.

        >>> import bayesprog
        >>> p = bayesprog.loads('''
        ... bayesprog: 1
        ... variables: {A: {states: [a0, a1]}, B: {states: [b0, b1]}}
        ... decomposition:
        ...   - {term: P(A), form: table, table: [0.3, 0.7]}
        ...   - {term: P(B | A), form: table, table: [[0.9, 0.1], [0.2, 0.8]]}
        ... ''')
        >>> p.ablate("P(B | A)").ask("P(A | B=b0)").probabilities.round(12).tolist()
        [0.3, 0.7]
        """
        names: list[str] = []
        for item in terms:
            group = [item] if isinstance(item, str) else item
            if isinstance(group, Iterable) and not isinstance(group, bytes):
                group = list(group)
            if not isinstance(group, list) or not all(isinstance(n, str) for n in group):
                raise ArgumentError(f"ablate: expected terms like 'P(B | A)' (strings, or "
                                    f"lists of them), found {short_repr(item)}")
            names.extend(group)
        resolved = [str(self.term(n).expression) for n in names]
        new = copy.copy(self)
        new.ablated = tuple(dict.fromkeys(self.ablated + tuple(resolved)))
        new.inference_cache = InferenceCache()
        new.__dict__.pop("active_terms", None)
        return new

    # identification --------------------------------------------------------------------------------
    def evidence(self, data: Any, *, score: str = "bdeu", equivalent_sample_size: float = 1.0,
                 columns: Mapping[str, str] | None = None) -> Evidence:
        """The log marginal likelihood of ``data`` under this program's decomposition: exact
        for discrete tables and complete data (the BDeu closed form with
        ``equivalent_sample_size``, or ``score="k2"``), the BIC approximation otherwise; the
        answer's ``method`` says which (see :func:`bayesprog.compare`).

        >>> import bayesprog
        >>> p = bayesprog.loads("bayesprog: 1\\nvariables: {A: {states: [a0, a1]}}\\n"
        ...                     "decomposition: [{term: P(A), form: table, table: [0.5, 0.5]}]")
        >>> round(p.evidence({"A": ["a0", "a0", "a1"]}, score="k2").log_evidence, 6)
        -2.484907
        """
        from bayesprog.learning.evidence import evidence

        return evidence(self, data, score=score, equivalent_sample_size=equivalent_sample_size,
                        columns=columns)

    def fit(self, data: Any, *, freeze: Iterable[str] = (), max_iter: int = 10_000,
            tol: float = 1e-8, columns: Mapping[str, str] | None = None,
            states_from_data: Sequence[str] = (), on_bad_lines: str = "error",
            other_columns: str = "refuse") -> Fit:
        """Learn the program's free parameters from ``data``: a CSV or Parquet file, a pandas
        DataFrame or a mapping of columns (or a CSV file being read on a thread meanwhile,
        :class:`~bayesprog.learning.plain_csv.ReadAhead`, as ``bayesprog learn`` reads it
        while the program loads); one column per variable, missing values allowed
        (``columns`` maps a column of another name to its variable: ``{"material": "M"}``).
        ``states_from_data`` names variables whose states are those found in their column
        (sorted, as written: a lab's own materials), the terms over them learned anew; the
        fitted file then declares them so.

        A bad row (more or fewer fields than the header, a line that is not UTF-8 text, a
        value that is not a number of a continuous column or outside its support, a state the
        program does not declare) is refused, the earliest in the file, with its line
        (``on_bad_lines="error"``, as pandas names it); ``"skip"`` sets every bad row aside
        and learns from the others, as from the file without them (``fit.set_aside`` names
        each row, its line and why; the record counts them); ``"warn"`` also warns
        (:class:`~bayesprog.learning.data.BadRowsWarning`). A missing value is not bad. A
        column that is no variable's is refused (``other_columns="refuse"``: a misspelt name),
        or read past (``"ignore"``: a log's cells and timings beside the variables).

        Terms marked ``learn: false`` in the file, and those named in ``freeze``, keep their
        values; the others are fitted by maximum likelihood (the posterior mean under the
        term's Dirichlet pseudo-counts), by EM where discrete values are missing or a variable
        has no column, and by EM for mixtures. EM stops once the log-likelihood per row is
        estimated within ``tol`` of its limit (Aitken's acceleration,
        :func:`~bayesprog.learning.fit.stopping`), or after ``max_iter`` iterations
        (``fit.converged`` False; ``fit.stopped`` says why it stopped). A program fitted before
        continues from its fit's statistics. Returns a :class:`Fit`; its ``program`` is the
        fitted program.

        >>> import bayesprog
        >>> p = bayesprog.loads('''
        ... bayesprog: 1
        ... variables: {M: {states: [wood, silk]}, E: {continuous: [-.inf, .inf]}}
        ... decomposition:
        ...   - {term: P(M), form: table, table: [0.5, 0.5]}
        ...   - {term: P(E | M), form: normal, mean: 0.0, sigma: 1.0}
        ... ''')
        >>> fit = p.fit({"M": ["wood", "wood", "silk", "silk"], "E": [0.4, 0.6, 0.1, 0.3]})
        >>> fit.program.term("P(E | M)").params["mean"].array.round(3).tolist()
        [0.5, 0.2]
        >>> fit = p.fit({"M": ["wood", "wood", "silk", "silk", "wool"],
        ...              "E": [0.4, 0.6, 0.1, 0.3, 0.2]}, on_bad_lines="skip")
        >>> fit.record.rows_set_aside, fit.set_aside[0].row
        (1, 5)
        >>> fit.set_aside[0].why
        "column 'M': unknown state 'wool' of M (did you mean 'wood'?): expected one of wood, silk"
        """
        import warnings

        from bayesprog.learning import fit_terms
        from bayesprog.learning.data import (
            BadRowError,
            BadRowsWarning,
            check_on_bad_lines,
            load_data,
            open_variable,
            set_aside_message,
        )

        if isinstance(freeze, str):
            freeze = [freeze]
        if not isinstance(freeze, Iterable) or not all(isinstance(t, str) for t in freeze):
            raise ArgumentError(f"freeze: expected terms like 'P(B | A)' (strings), found "
                                f"{short_repr(freeze)}")
        if isinstance(max_iter, bool) or not isinstance(max_iter, numbers.Integral):
            raise ArgumentError(f"max_iter: expected an integer >= 1, found {short_repr(max_iter)}")
        if isinstance(tol, bool) or not isinstance(tol, numbers.Real):
            raise ArgumentError(f"tol: expected a number >= 0, found {short_repr(tol)}")
        try:
            labels = [str(self.term(t).expression) for t in freeze]
        except ExpressionError as exc:
            raise QuestionError(f"freeze: {exc}") from None
        if columns is not None and (not isinstance(columns, Mapping) or not all(
                isinstance(k, str) and isinstance(v, str) for k, v in columns.items())):
            raise ArgumentError(f"columns: expected a mapping of column names to variable "
                                f"names, found {short_repr(columns)}")
        mode = check_on_bad_lines(on_bad_lines)
        if isinstance(states_from_data, str):
            states_from_data = [states_from_data]
        names = list(states_from_data)
        for name in names:
            open_variable(self.variables, name)
        try:
            if names:  # the data read once: their states, then their rows for the new program
                loaded = load_data(data, self.variables, columns, on_bad_lines=mode,
                                   states_from_data=names, other_columns=other_columns)
                program = self._with_states_from(loaded.states, labels)
                fit = program.fit(loaded, freeze=labels, max_iter=max_iter, tol=tol,
                                  columns=columns)
                fit.states = loaded.states
            else:
                estimate = fit_terms(self.variables, self.terms, self.learned, data,
                                     freeze=labels, max_iter=max_iter, tol=tol,
                                     columns=columns, on_bad_lines=mode,
                                     other_columns=other_columns)
                terms = [dataclasses.replace(t, params={**t.params, **estimate.params[t.label]})
                         if t.label in estimate.params else t for t in self.terms]
                fitted = Program(self.variables, terms, self.questions, self.inputs,
                                 name=self.name, description=self.description, path=self.path,
                                 ablated=self.ablated, learned=[*self.learned, estimate.record],
                                 time=self.time)
                fit = Fit(fitted, estimate, self.path)
        except BadRowError as exc:
            raise exc.fixed('on_bad_lines="skip" sets bad rows aside') from None
        if mode == "warn" and fit.set_aside:
            warnings.warn(set_aside_message(fit.record.data, fit.set_aside), BadRowsWarning,
                          stacklevel=2)
        return fit

    def _with_states_from(self, found: Mapping[str, list[str]], freeze: Sequence[str]
                          ) -> Program:
        """This program with each variable of ``found`` taking the states found in its column
        of the data (sorted, as written), and the terms over it starting from neutral values
        (uniform tables, means 0, spreads 1) that the fit then replaces. A term with a parameter
        of no neutral value (a mixture's means) starts from its written values when the data
        find the states as declared."""
        from bayesprog.forms.base import nonnegative, positive, real, simplex, unit_interval

        variables = dict(self.variables)
        for name, values in found.items():
            variables[name] = Discrete(name, tuple(values),
                                       description=self.variables[name].description)
        neutral = {nonnegative: 1.0, positive: 1.0, real: 0.0, unit_interval: 0.5}
        terms = []
        for t in self.terms:
            over = {t.child.name, *(p.name for p in t.parents)} & set(found)
            if not over:
                terms.append(t)
                continue
            if t.learn is None or str(t.expression) in freeze:
                raise ArgumentError(f"{t.label} keeps its values (learn: false or freeze) but "
                                    f"they are laid out by the states of {', '.join(over)}, "
                                    "which the data replace: learn it too")
            child = variables[t.child.name]
            if all(tuple(found[v]) == tuple(getattr(self.variables[v], "states", ()))
                   for v in over) and any(
                    p.name in t.params and not (p.constraint is simplex or (
                        p.constraint in neutral and p.event_ndim == 0))
                    for p in t.form.params):
                # laid out by the states the data find as declared, and with a parameter of no
                # neutral value (a mixture's means): it starts from its values as written
                terms.append(t)
                continue
            params: dict[str, Any] = {}
            for p in t.form.params:
                if p.name not in t.params:
                    continue
                if p.constraint is simplex and isinstance(child, Discrete):
                    params[p.name] = ParamValue((), np.full(child.card, 1.0 / child.card))
                elif p.constraint in neutral and p.event_ndim == 0:
                    params[p.name] = ParamValue((), np.asarray(neutral[p.constraint]))
                else:
                    raise ArgumentError(f"{t.label}: its parameter {p.name!r} has no neutral "
                                        "value to start from once the states change")
            terms.append(dataclasses.replace(
                t, child=child, parents=tuple(variables[p.name] for p in t.parents),
                params=params))
        # the statistics of earlier fits count other states: this fit starts afresh
        return Program(variables, terms, self.questions, self.inputs, name=self.name,
                       description=self.description, path=self.path, ablated=self.ablated,
                       learned=[], time=self.time)

    def _repr_html_(self) -> str | None:
        """In a notebook: the decomposition in Bayesian-programming notation and the graph."""
        return rich.html("program", self)

    def __repr__(self) -> str:
        extra = f", conditioning={list(self.conditioning)}" if self.conditioning else ""
        extra += f", ablated={list(self.ablated)}" if self.ablated else ""
        return (f"Program({self.name!r}, variables={list(self.variables)}, "
                f"terms={[str(t.expression) for t in self.terms if not t.soft]}{extra})")


@dataclass
class Fit:
    """The result of :meth:`Program.fit`: the fitted program, its log-likelihood and the record
    (data file hash, rows used, method) that :meth:`save` writes into the fitted file."""

    program: Program
    estimate: Estimate
    source: Path | None
    #: the variables whose states the data set (their new states), written into the file
    states: dict[str, list[str]] = dataclasses.field(default_factory=dict)

    @property
    def log_likelihood(self) -> float:
        return self.estimate.log_likelihood

    @property
    def record(self) -> FitRecord:
        return self.estimate.record

    @property
    def converged(self) -> bool:
        return self.estimate.converged

    @property
    def iterations(self) -> int:
        """The EM iterations made (1: one pass over complete rows)."""
        return self.estimate.iterations

    @property
    def stopped(self) -> str:
        """Why the fit stopped: converged (the log-likelihood per row within ``tol`` of its
        limit, or no longer changing), or the ``max_iter`` iterations allowed were made, with
        the last change and how far the limit is estimated to be."""
        return self.estimate.stopped

    @property
    def set_aside(self) -> list[BadRow]:
        """The bad rows of the data set aside (``on_bad_lines``): each one's line (in a CSV
        file), why, and row."""
        return self.estimate.set_aside

    def text(self, source: str | Path | None = None, *, rounded: bool = False) -> str:
        """The fitted program file: ``source`` (by default the file the program was loaded
        from) with the learned values in place, comments and layout kept, and the fit's record
        appended under ``learned:``. The values are written as fitted (15 significant digits),
        so that the file loads as :attr:`program`; ``rounded`` writes them to the precision their rows support
        instead (the significant digits of :func:`~bayesprog.learning.write.supported_digits`,
        a mean to a twentieth of its standard error), the digits in the record."""
        path = Path(source) if source is not None else self.source
        if path is None:
            raise QuestionError("this program was not loaded from a file: give the program "
                                "file to write the fitted values into (source=...)")
        text = self.fitted_text(path.read_text(encoding="utf-8"), rounded=rounded)
        # the fitted file must load as a program; where it would not, the lines said are the
        # fitted text's, not the input's
        loads(text, f"{path} (as fitted)", path.parent)
        return text

    def fitted_text(self, text: str, *, rounded: bool = False) -> str:
        """``text`` (the program file's text) with the learned values in place and the fit's
        record appended, as :meth:`text` writes it, but not loaded again to check it (for a
        caller that loads what it writes)."""
        from bayesprog.forms.base import simplex as simplex_constraint
        from bayesprog.learning import render_fitted
        from bayesprog.learning.write import supported_digits

        simplex = {t.label: [p.name for p in t.form.params if p.constraint is simplex_constraint]
                   for t in self.program.terms}
        locations = {t.label: t.form.location_scale for t in self.program.terms
                     if t.form.location_scale is not None}
        record = self.record
        if rounded:
            rows = record.rows_supporting or record.rows_used
            record = record.replace(digits=supported_digits(rows))
        return render_fitted(text, self.estimate.params, self.program.variables, record,
                             simplex, locations, self.states)

    def save(self, path: str | Path, source: str | Path | None = None, *,
             rounded: bool = False) -> Path:
        """Write the fitted program file (:meth:`text`) to ``path`` at once (never
        half-written)."""
        path = Path(path)
        atomic_write(path, self.text(source, rounded=rounded).encode("utf-8"), parents=False)
        return path


def _other_answer(result: Any, asked: str) -> str:
    """Why :meth:`Program.posterior` or :meth:`Program.density` cannot give ``result``, and
    which method does."""
    question = getattr(result, "question", "the question")
    if isinstance(result, densities.Density):
        return (f"{question} searches real variables ({', '.join(result.variables)}): its "
                "posterior is a density; ask it with program.density(...) (mean, sd, "
                "quantile, pdf, map) or program.ask(...)")
    if isinstance(result, answers.Posterior):
        return (f"{question} searches discrete variables ({', '.join(result.variables)}): "
                "its posterior is a table; ask it with program.posterior(...)")
    return (f"{question} searches discrete and real variables together: ask it with "
            f"program.ask(...) (a Joint: the discrete configurations' weights, the real "
            f"variables' density given each), not program.{asked}(...)")


def _document(located: Located) -> tuple[Document | PlainDocument | None, list[Diagnostic]]:
    if not isinstance(located.data, dict):
        return None, [located.diagnostic((), "expected a program: a mapping with bayesprog, "
                                         f"variables, decomposition; found {type(located.data).__name__}")]
    _names_as_written(located)
    plain = read_plain(located.data)
    if plain is not None:  # the common shape, read without building pydantic's validators
        return plain, []
    from bayesprog.language.document import Document, validate_located

    return validate_located(located, Document)


def _names_as_written(located: Located) -> None:
    """A number written as a state is the state's name as written (``1.50``, not ``1.5``)."""
    variables = located.data.get("variables")
    if not isinstance(variables, dict):
        return
    for name, spec in variables.items():
        states = spec.get("states") if isinstance(spec, dict) else None
        if isinstance(states, list):
            for i, state in enumerate(states):
                text = located.texts.get(("variables", name, "states", i))
                if text is not None and not isinstance(state, str):
                    states[i] = text


def loads(text: str | bytes, file: str = "<string>", base_dir: Path | None = None,
          variables: Mapping[str, Any] | None = None,
          terms: Mapping[str, Mapping[str, Any]] | None = None) -> Program:
    """Load a program from YAML text. Raises :class:`SpecError` listing every problem.

    ``variables`` replaces the declarations of some of the file's variables before the program
    is checked, as if the file said so (for instance a grid's shape, set by the workspace a
    program is used in); every check then runs on the result, so a term that no longer fits is
    reported at its place in the file. A program a term names (``form: program``) has the
    variables it shares with that term replaced alike. ``terms`` likewise sets parameters of
    some terms of the decomposition, named as in the file (``{"P(I | O)": {"a": 2.0, "b":
    3.0}}``: the keys given replace the entry's, the others stay).

    >>> text = ("{bayesprog: 1, variables: {O: {grid: {shape: [2, 3], cell: 1.0}}}, "
    ...         "decomposition: [{term: P(O), form: uniform}]}")
    >>> p = loads(text, variables={"O": {"grid": {"shape": [4, 4], "cell": 0.5}}})
    >>> p.variables["O"].card
    16
    """
    if isinstance(text, (bytes, bytearray)):  # a file's bytes: UTF-8, as files are read
        try:
            text = bytes(text).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ArgumentError(f"loads: expected the text of a program, found bytes that are "
                                f"not UTF-8 ({exc.reason} at byte {exc.start})") from None
    if not isinstance(text, str):
        raise ArgumentError(f"loads: expected the text of a program (a string, or UTF-8 "
                            f"bytes), found {type(text).__name__} {short_repr(text)}")
    if variables is not None and not isinstance(variables, Mapping):
        raise ArgumentError(f"variables: expected a mapping of variable names to "
                            f"declarations, found {short_repr(variables)}")
    if terms is not None and not (isinstance(terms, Mapping) and all(
            isinstance(k, str) and isinstance(v, Mapping) for k, v in terms.items())):
        raise ArgumentError(f"terms: expected a mapping of terms ('P(A | B)') to mappings of "
                            f"parameters, found {short_repr(terms)}")
    located, problems = load_yaml(text, file)
    if problems and located.data is None:
        raise SpecError(problems)
    if variables:
        # a sub-program that does not declare a variable shared with its term is told so by the
        # term's own check (the same states), not as a replacement of a missing variable
        shared, token = _SHARED.get(), _SHARED.set(frozenset())
        try:
            problems += _replace_variables(located, variables, skip_missing=shared)
        finally:
            _SHARED.reset(token)
    if terms:
        problems += _replace_terms(located, terms)
    doc, schema_problems = _document(located)
    problems += schema_problems
    if doc is None:
        raise SpecError(problems)

    def load_named(file: Path, shared: tuple[str, ...] = ()) -> Program:
        named = _NAMED.get()
        if named is not None:
            named.append(file)
        # a program named by a term: the variables it shares with the term (its child and
        # parents) are replaced there as they are here, so they keep the same states
        given = {name: variables[name] for name in shared if variables and name in variables}
        token = _SHARED.set(frozenset(given))
        try:
            return load(file, variables=given or None)
        finally:
            _SHARED.reset(token)

    checked = check_document(located, doc, base_dir or Path.cwd(), load_named)
    problems += checked.problems
    if problems:
        raise SpecError(problems)
    questions = {
        name: Question(expr, kind, name, desc) for name, (expr, kind, desc) in checked.questions.items()
    }
    program = Program(
        checked.variables,
        checked.terms,
        questions,
        checked.inputs,
        name=doc.name,
        description=doc.description,
        path=Path(file) if file != "<string>" else None,
        learned=doc.learned,
        time=checked.time,
    )
    if checked.ablate:
        program = program.ablate([str(e) for e in checked.ablate])
    return program


#: the variables a program being loaded for a term shares with it (replaced where declared)
_SHARED: ContextVar[frozenset[str]] = ContextVar("bayesprog_shared", default=frozenset())


def _replace_variables(located: Located, variables: Mapping[str, Any],
                       skip_missing: frozenset[str] = frozenset()) -> list[Diagnostic]:
    declared = located.data.get("variables") if isinstance(located.data, dict) else None
    if not isinstance(declared, dict):
        return []  # the schema check reports the missing or malformed variables
    problems = []
    for name, spec in variables.items():
        if name not in declared and name in skip_missing:
            continue
        if name not in declared:
            problems.append(located.diagnostic(("variables",), f"no variable {name!r} to "
                                               f"replace: expected one of {', '.join(declared)}",
                                               at_key=True))
        else:
            declared[name] = copy.deepcopy(dict(spec))
    return problems


def load(path: str | Path, variables: Mapping[str, Any] | None = None,
         terms: Mapping[str, Mapping[str, Any]] | None = None) -> Program:
    """Load and check the program file at ``path`` (``variables``, ``terms``: see
    :func:`loads`). Where no file of that name exists, a bundled program of that name is
    loaded, as the command line does (``load("student")``: ``bayesprog examples`` lists them);
    a file always wins.

    >>> load("student").name
    'student'
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ArgumentError(f"load: expected a path (a string or pathlib.Path), found "
                            f"{type(path).__name__} {short_repr(path)}")
    path = _existing_or_bundled(Path(path))
    # programs name others (sub-programs, soft evidence): one that comes back to a file still
    # being loaded is a cycle, reported where it is named instead of recursing without end
    chain = _LOADING.get()
    key = path.resolve()
    if key in chain:
        raise ProgramCycleError([*chain[chain.index(key):], key])
    token = _LOADING.set((*chain, key))
    try:
        data = path.read_bytes()
        # a file loaded before, byte for byte, is read back checked (see bayesprog.support.cache)
        kept = cache.key(path, data) if variables is None and terms is None else None
        if kept is not None:
            program = cache.get(kept)
            if isinstance(program, Program):
                program.path = path
                return program
        text = data.decode("utf-8")
        named: list[Path] = []
        named_token = _NAMED.set(named)
        try:
            program = loads(text, str(path), path.parent, variables, terms)
        finally:
            _NAMED.reset(named_token)
        if kept is not None and not named:  # a file that names others may change with them
            cache.put(kept, program)
        return program
    finally:
        _LOADING.reset(token)


def _existing_or_bundled(path: Path) -> Path:
    """``path`` when it exists; else the bundled program of that name; else a
    ``FileNotFoundError`` that says neither is there."""
    if path.exists():
        return path
    from bayesprog.support.bundled import find

    found = find(str(path), "program")
    if found is not None:
        return found
    if path.is_absolute():  # a file named by another (a sub-program), never a bundled name
        raise FileNotFoundError(errno.ENOENT, "no such file", str(path))
    raise FileNotFoundError(errno.ENOENT, "no such file, and no bundled program of that name "
                            "(bayesprog examples lists them)", str(path))


def _replace_terms(located: Located, terms: Mapping[str, Mapping[str, Any]]
                   ) -> list[Diagnostic]:
    entries = located.data.get("decomposition") if isinstance(located.data, dict) else None
    if not isinstance(entries, list):
        return []  # the schema check reports the missing or malformed decomposition
    by_term = {canonical(e.get("term")): e for e in entries if isinstance(e, dict)}
    problems = []
    for name, params in terms.items():
        key = canonical(name)
        entry = by_term.get(key) if key is not None else None
        if entry is None:
            known = ", ".join(str(e.get("term")) for e in entries if isinstance(e, dict))
            problems.append(located.diagnostic(("decomposition",), f"no term {name!r} to set "
                                               f"parameters of: expected one of {known}",
                                               at_key=True))
        else:
            entry.update(copy.deepcopy(dict(params)))
    return problems


#: the files a program being loaded names (see :func:`load`: such a program is not cached)
_NAMED: ContextVar[list[Path] | None] = ContextVar("bayesprog_named", default=None)
#: The program files being loaded, outermost first (see :func:`load`).
_LOADING: ContextVar[tuple[Path, ...]] = ContextVar("bayesprog_loading", default=())
