"""What a question needs of its program: the requisite terms, found by the Bayes-ball algorithm.

``P(searched | evidence)`` depends on the term of a variable only when a parameter of that term
is not d-separated from the searched variables by the evidence (Shachter, "Bayes-Ball: The
Rational Pastime", UAI 1998). The others are left out before a question is planned: barren
variables (no observed descendant), evidence that the observed variables screen off from the
searched ones, and the ancestors behind that evidence. A searched variable independent of the
evidence is answered from its own ancestors only.

Soft evidence on a variable (given with a question, or written in the program) is a virtual
observed child of that variable. A program with an unnormalised term (a potential) keeps every
ancestor of what the question touches: its terms are not conditional distributions, and
d-separation does not say what they change.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from bayesprog.inference.protocol import ProgramLike


@dataclass
class Family:
    """The program's graph as the questions walk it: each variable's parents and children
    (terms of the decomposition), the variables with soft evidence written in the program,
    and whether every term is a conditional distribution."""

    parents: dict[str, list[str]] = field(default_factory=dict)
    children: dict[str, list[str]] = field(default_factory=dict)
    soft: set[str] = field(default_factory=set)
    #: variables whose term is unnormalised (a potential) or soft evidence
    unnormalised: set[str] = field(default_factory=set)
    #: the real (continuous) variables
    continuous: set[str] = field(default_factory=set)

    def ancestors(self, names: Iterable[str]) -> set[str]:
        """``names`` and all their ancestors."""
        found = set(names)
        todo = list(found)
        while todo:
            for parent in self.parents.get(todo.pop(), ()):
                if parent not in found:
                    found.add(parent)
                    todo.append(parent)
        return found


def family(program: ProgramLike) -> Family:
    """The program's :class:`Family` (made once per program)."""
    cache = program.inference_cache
    if cache.family is None:
        found = Family()
        for t in program.active_terms:
            name = t.child.name
            if t.soft:
                found.soft.add(name)
                found.unnormalised.add(name)
                continue
            if not t.form.is_normalized(t.child):
                found.unnormalised.add(name)
            if not t.child.is_discrete:
                found.continuous.add(name)
            found.parents[name] = [p.name for p in t.parents]
            for p in t.parents:
                found.children.setdefault(p.name, []).append(name)
        cache.family = found
    return cache.family


def requisite(program: ProgramLike, searched: Iterable[str], observed: Iterable[str],
              soft: Iterable[str] = ()) -> set[str] | None:
    """The variables whose terms ``P(searched | observed)`` needs (soft evidence on ``soft``),
    or None when the program's terms are not all conditional distributions (then a question
    keeps the ancestors of what it touches)."""
    graph = family(program)
    if graph.unnormalised - graph.soft:
        return None
    parents, children = graph.parents, graph.children
    virtual = graph.soft | set(soft)  # variables with an observed virtual child
    known = set(observed)
    top: set[str] = set()
    bottom: set[str] = set()
    # (variable, whether the ball comes from a child): searched variables start as if from one
    schedule = [(name, True) for name in searched]
    while schedule:
        name, from_child = schedule.pop()
        if name in known:
            # an observed variable passes a ball from a parent up to its own parents; one
            # from a child stops here
            if not from_child and name not in top:
                top.add(name)
                schedule.extend((p, True) for p in parents.get(name, ()))
            continue
        if from_child and name not in top:
            top.add(name)
            schedule.extend((p, True) for p in parents.get(name, ()))
        if name not in bottom:
            bottom.add(name)
            schedule.extend((c, False) for c in children.get(name, ()))
            if name in virtual:  # the virtual child is observed: the ball comes back up
                schedule.append((name, True))
    return top
