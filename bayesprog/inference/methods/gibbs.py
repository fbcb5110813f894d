"""Approximate, by Gibbs sampling: a Markov chain over the question's unknown discrete variables,
each variable drawn in turn from its distribution given all the others (the product of the
factors it is in, sliced by the evidence and by the others' current states), every evidence row
at once. The chain starts from the likeliest of a few likelihood-weighted draws, forgets its
start for ``burn_in`` sweeps, then keeps one sweep in ``thin`` until ``samples`` are kept. Unlike
likelihood weighting, whose draws ignore the evidence below them, the chain goes where the
evidence puts the probability, so unlikely evidence does not starve it. The error of each
probability is estimated from batch means (the kept sweeps cut into 20 consecutive batches), as
is an effective sample size. Only asked for by name (``method="gibbs"``): the evidence's
probability is not estimated (``log_evidence`` is NaN, and the answer says so), and a chain
cannot leave states that deterministic terms wall off. The sweeps run compiled
(:mod:`bayesprog.inference.methods._gibbs_kernel`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from bayesprog.inference.answers import Posterior
from bayesprog.inference.factors import question_factors
from bayesprog.inference.methods.base import PER_FACTOR, Cost, Method, answer, register_method
from bayesprog.inference.plan import QuestionPlan
from bayesprog.inference.sampling import draw, generators

#: kept sweeps, sweeps forgotten first, and one sweep kept in ``THIN``, unless asked otherwise
DEFAULT_SAMPLES, DEFAULT_BURN_IN, DEFAULT_THIN = 10_000, 1_000, 1
#: the kept sweeps are cut into this many consecutive batches for the error estimate
BATCHES = 20
#: likelihood-weighted draws the chain's start is chosen from
STARTS = 64
#: uniform draws made at once, per row: sweeps in a block
BLOCK = 256


@register_method
class GibbsSampling(Method):
    name = "gibbs"
    title = "Gibbs sampling"
    exact = False
    uncertainty = "stderr"

    def describe(self, answer: Any) -> str:
        return f"{self.title}: +- one standard error, from batch means"

    def why_not(self, plan: QuestionPlan) -> str | None:
        if plan.latent:
            return (f"{', '.join(plan.latent)} unknown and real: Gibbs sampling draws discrete "
                    "variables (method='lw' draws real ones)")
        return None

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        if self.why_not(plan) is not None:
            return None
        sweeps = _sweeps(plan.options)
        cards = [plan.card(t.child.name) for t in plan.terms if t.child.is_discrete] or [1]
        work = float(plan.bound.size) * sweeps * sum(cards) * 20
        return Cost(operations=work, memory=float(plan.bound.size) * max(cards) * 8,
                    fixed=PER_FACTOR * len(plan.terms))

    def posterior(self, plan: QuestionPlan) -> Posterior:
        program, bound, searched = plan.program, plan.bound, plan.searched
        rows = bound.size
        samples = int(plan.options.get("samples") or DEFAULT_SAMPLES)
        burn_in = int(plan.options.get("burn_in", DEFAULT_BURN_IN))
        thin = int(plan.options.get("thin", DEFAULT_THIN))
        factors = [f for f in question_factors(program, plan.terms, bound) if f.axes]
        unknown = sorted({a for f in factors for a in f.axes} | set(searched))
        position = {v: i for i, v in enumerate(unknown)}
        cards = [plan.card(v) for v in unknown]
        gens = generators(plan.options.get("rng"), rows)
        state, possible = _start(program, plan, bound, unknown, gens)
        from bayesprog.inference.methods._gibbs_kernel import flatten, sweep

        flat = flatten(factors, position, len(unknown))
        searched_cards = tuple(plan.card(v) for v in searched)
        searched_at = np.asarray([position[v] for v in searched], np.int64)
        keep = np.zeros((samples, rows), dtype=np.int64)
        kept = 0
        total = burn_in + samples * thin
        done = 0
        while done < total:  # the rows' draws a block at a time, from each row's generator
            block = min(BLOCK, total - done)
            uniforms = np.stack([g.random((block, len(unknown))) for g in gens], axis=1)
            kept = sweep(state, np.asarray(cards, np.int64), uniforms.reshape(block, rows, -1),
                         *flat, done, burn_in, thin, kept, keep, searched_at,
                         np.asarray(searched_cards, np.int64))
            done += block
        size = int(np.prod(searched_cards))
        probs = _frequencies(keep, size)
        per_batch = np.stack([_frequencies(part, size)
                              for part in np.array_split(keep, BATCHES)])
        stderr = per_batch.std(axis=0, ddof=1) / np.sqrt(BATCHES)
        with np.errstate(divide="ignore", invalid="ignore"):
            ess_cells = np.where((probs > 0) & (probs < 1) & (stderr > 0),
                                 probs * (1 - probs) / stderr**2, np.inf)
        ess = np.minimum(ess_cells.min(axis=1), samples).astype(float)
        probs = np.where(possible[:, None], probs, 0.0)
        log_z = np.where(possible, np.nan, -np.inf)
        return answer(plan, probs, log_z, method=self.name, stderr=stderr, ess=ess,
                      uncertainty=self.uncertainty,
                      evidence="not estimated by Gibbs sampling")


def _sweeps(options: dict[str, Any]) -> int:
    return int(options.get("burn_in", DEFAULT_BURN_IN)) + int(
        options.get("samples") or DEFAULT_SAMPLES) * int(options.get("thin", DEFAULT_THIN))


def _start(program: Any, plan: QuestionPlan, bound: Any, unknown: list[str],
           gens: list[np.random.Generator]) -> tuple[np.ndarray, np.ndarray]:
    """Each row's starting state: the likeliest of a few likelihood-weighted draws (a state of
    positive probability with the evidence), and whether the row has one at all."""
    draws = draw(program, plan.terms, bound, STARTS, gens)
    best = np.argmax(draws.log_weights, axis=1)
    possible = np.isfinite(np.max(draws.log_weights, axis=1))
    rows = np.arange(bound.size)
    state = np.zeros((bound.size, len(unknown)), dtype=np.intp)
    for j, v in enumerate(unknown):
        if v in draws.values:
            state[:, j] = np.asarray(draws.values[v])[rows, best]
    return state, possible


def _frequencies(cells: np.ndarray, size: int) -> np.ndarray:
    """``[rows, size]``: how often each cell was kept, per row."""
    rows = cells.shape[1]
    offsets = np.arange(rows) * size
    counts = np.bincount((cells + offsets).ravel(), minlength=rows * size).reshape(rows, size)
    return counts / max(len(cells), 1)
