"""The checks of a program that repeats per time step (its ``time:`` section): each state one
step earlier paired with its state, of one kind and the same states, the transition depending
on the step before; questions over steps (filter, smooth, sequence) searching the states."""

from __future__ import annotations

from bayesprog.language.check.base import Checker
from bayesprog.model import Term
from bayesprog.vocabulary.expressions import Expression


class TimeCheck(Checker):
    """The ``time:`` section, and the questions over steps."""

    def check_time(self, terms: list[Term], questions: dict[str, tuple[Expression, str, str]]
                   ) -> tuple[tuple[str, str], ...] | None:
        """The time section: each PREVIOUS and its STATE discrete with the same states, PREVIOUS
        without parents in a step; questions over steps search state variables (a sequence
        question all of them)."""
        spec = self.doc.time
        over_time = [(name, q) for name, q in questions.items()
                     if q[1] in ("filter", "smooth", "sequence")]
        if spec is None:
            for name, (_, kind, _) in over_time:
                self.error(("questions", name), f"question {name!r}: a {kind} question needs "
                           "a program that repeats per step (a time: section)", at_key=True)
            return None
        pairs = []
        failed = False
        previous_names = set(spec.previous)
        for previous, state in spec.previous.items():
            where = ("time", "previous", previous)
            problems = []
            for name in (previous, state):
                var = self.variables.get(name)
                if var is None:
                    problems.append(f"expected a declared variable, found nothing named {name!r}")
                elif name in self.untermed:
                    problems.append(f"{name} has no term in the decomposition: expected one, "
                                    + ("the belief before the first step" if name == previous
                                       else "the transition"))
            if state in previous_names:
                problems.append(f"{state} is a state one step earlier itself: expected a state "
                                "of this step")
            if not problems:
                a, b = self.variables[previous], self.variables[state]
                if a.is_discrete != b.is_discrete:
                    problems.append(f"{previous} and {state} must be of one kind, found one "
                                    "discrete and one real")
                elif a.is_discrete and a.states != b.states:  # type: ignore[union-attr]
                    problems.append(f"{previous} and {state} must have the same states, found "
                                    f"{a.describe_states()} and {b.describe_states()}")  # type: ignore[union-attr]
                elif not a.is_discrete and (a.low, a.high) != (b.low, b.high):  # type: ignore[union-attr]
                    problems.append(f"{previous} and {state} must have the same support, found "
                                    f"[{a.low}, {a.high}] and [{b.low}, {b.high}]")  # type: ignore[union-attr]
                own = next((t for t in terms if not t.soft and t.child.name == previous), None)
                if own is not None and any(p.name not in previous_names for p in own.parents):
                    problems.append(f"{previous}, the state one step earlier, has no parents "
                                    f"in a step but the other states one step earlier; found "
                                    f"{own.label}")
            for problem in problems:
                self.error(where, f"time: {problem}", at_key=True)
            failed = failed or bool(problems)
            pairs.append((previous, state))
        if failed:
            return None
        states = [state for _, state in pairs]
        kinds = {self.variables[s].is_discrete for s in states}
        if len(kinds) > 1:
            self.error(("time", "previous"), "time: the states over time are all discrete or "
                       "all real (a filter over a discrete and a real state together is out of "
                       "reach)", at_key=True)
            return None
        if len(set(states)) != len(states):
            self.error(("time", "previous"), "time: each state variable once, found "
                       f"{', '.join(states)}", at_key=True)
            return None
        built = {t.child.name for t in terms if not t.soft}
        for previous, state in pairs:
            ancestors = self._ancestors(terms, state)
            if state in built and not ancestors & previous_names:
                self.error(("time", "previous", previous), f"time: the term of {state} should "
                           "depend on the states one step earlier (the transition)", at_key=True)
                return None
        for name, (expr, kind, _) in over_time:
            outside = [v for v in expr.left if v not in states]
            if outside or (kind == "sequence" and len(states) > 1
                           and set(expr.left) != set(states)):
                wanted = (f"P({' '.join(states)} | ...)" if kind == "sequence"
                          else f"P({' or '.join(states)} | ...)")
                self.error(("questions", name), f"question {name!r}: a {kind} question "
                           f"searches the state: expected {wanted}, found {expr}", at_key=True)
        return tuple(pairs)

    @staticmethod
    def _ancestors(terms: list[Term], name: str) -> set[str]:
        """The variables ``name``'s term depends on, directly or through others of the step."""
        parents = {t.child.name: [p.name for p in t.parents] for t in terms if not t.soft}
        seen: set[str] = set()
        todo = list(parents.get(name, []))
        while todo:
            current = todo.pop()
            if current not in seen:
                seen.add(current)
                todo += parents.get(current, [])
        return seen
