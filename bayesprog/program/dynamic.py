"""Questions over a sequence of steps, for programs whose decomposition is one time step.

A program with ``time: {previous: {PREV: X}}`` describes one step: ``PREV`` is the state ``X``
one step earlier, its term the belief before the first step, and the other terms the
transition ``P(X | PREV ...)`` and what is observed at a step. Evidence for ``T`` steps is given
with time as the first axis (``{"Y": [y1, ..., yT]}``, batch axes after it).

* ``filter``: ``P(X_t | y_1..t)`` for every t, by the forward recursion: each step is one
  question of the step program, the belief of the step before given as soft evidence on
  ``PREV`` (whose own term is then uniform). Nothing of the history is kept but that belief.
* ``smooth``: ``P(X_t | y_1..T)``, by the forward and the backward recursion (the backward
  message of a step is a question of the step program on ``PREV`` with soft evidence on ``X``).
* ``sequence``: the most likely sequence ``argmax P(x_1..T | y_1..T)`` (Viterbi; the state
  before the first step summed out), from the step program's joint ``P(PREV X | y_t)``; the
  sequences that tie are counted and one of them is drawn by ``rng``, as a MAP question's tied
  assignments are (:mod:`bayesprog.inference.viterbi`). Its ``probability`` is
  ``P(x_1..T | y_1..T)`` of that sequence.

Every step's question is asked of the engine for all sequences of the batch at once.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import scipy

from bayesprog.errors import QuestionError, expect_mapping
from bayesprog.inference import MapResult, Posterior
from bayesprog.inference.density import Density
from bayesprog.inference.viterbi import most_likely_sequence
from bayesprog.limits import check_size, limit
from bayesprog.vocabulary.expressions import Expression, Question

KINDS = ("filter", "smooth", "sequence")


def _steps(evidence: dict[str, Any]) -> tuple[int, dict[str, list[Any]]]:
    """The number of steps and each step's evidence (time is the first axis)."""
    lengths = {}
    for name, value in evidence.items():
        arr = np.asarray(value, dtype=object)
        if arr.ndim < 1:
            raise QuestionError(f"evidence for {name}: expected one value per step (time as "
                                f"the first axis), found a single value {value!r}")
        lengths[name] = len(arr)
    if not lengths:
        raise QuestionError("a question over steps needs evidence with time as the first axis")
    if len(set(lengths.values())) > 1:
        found = ", ".join(f"{k}: {n}" for k, n in lengths.items())
        raise QuestionError(f"evidence over steps of different lengths ({found}): expected "
                            "one value per step for every variable")
    steps = next(iter(lengths.values()))
    if steps == 0:
        raise QuestionError("evidence over no steps: expected at least one step (time is the "
                            "first axis; a batch of sequences goes after it)")
    return steps, {name: [value[t] for t in range(steps)] for name, value in evidence.items()}


def over_time(program: Any, question: Question, evidence: Mapping[str, Any] | None,
              inputs: Mapping[str, Any] | None, soft: Mapping[str, Any] | None,
              method: str | None, options: Mapping[str, Any]) -> Posterior | MapResult | Density:
    """The answer of a ``filter``, ``smooth`` or ``sequence`` question (see the module)."""
    if program.time is None:
        raise QuestionError(f"a {question.kind} question needs a program that repeats per step "
                            "(a time: section)")
    expr = question.expression
    states = [state for _, state in program.time]
    if not program.variables[states[0]].is_discrete:
        if soft:
            raise QuestionError("soft evidence is taken by questions over discrete states; a "
                                "Kalman filter observes real values")
        steps, per_step = _steps(expect_mapping(evidence, "evidence",
                                                "variable names to values"))
        if method == "pf":
            return _particles(program, question, per_step, steps, inputs, options)
        return _kalman(program, question, per_step, steps, inputs)
    if len(program.time) > 1:
        outside = [v for v in expr.left if v not in states]
        if outside or (question.kind == "sequence" and set(expr.left) != set(states)):
            wanted = (f"P({' '.join(states)} | ...)" if question.kind == "sequence"
                      else f"P({' or '.join(states)} | ...)")
            raise QuestionError(f"a {question.kind} question searches the state: expected "
                                f"{wanted}, found {expr}")
        steps, per_step = _steps_of(evidence, soft)
        soft_steps = _soft_steps(program, soft, steps)
        return _joint(program, question, per_step, steps, inputs, method, options, soft_steps)
    (previous, state), = program.time
    if expr.left != (state,):
        raise QuestionError(f"a {question.kind} question searches the state: expected "
                            f"P({state} | ...), found {expr}")
    steps, per_step = _steps_of(evidence, soft)
    soft_steps = _soft_steps(program, soft, steps)
    known = expr.right
    step = program.ablate(str(program.term_of(previous).expression))
    card = program.variables[state].card

    steps_by = _StepMethod()

    def ask(searched: tuple[str, ...], t: int, soft_on: dict[str, np.ndarray]) -> Posterior:
        q = Question(Expression(searched, known, dict(expr.values)))
        answer = step.ask(q, {k: v[t] for k, v in per_step.items()}, inputs=inputs,
                          soft={**soft_on, **{k: v[t] for k, v in soft_steps.items()}},
                          method=method, samples=options.get("samples"))
        assert isinstance(answer, Posterior)
        return steps_by.seen(answer, question.kind)

    first = _before(program, [previous]).probabilities  # the belief before the first step
    forward, log_evidence = [], []
    belief: np.ndarray = first
    for t in range(steps):
        answer = ask((state,), t, {previous: belief})
        belief = answer.probabilities
        forward.append(belief)
        # log P(y_t | y_<t): the step's evidence under a uniform PREV, times the card
        log_evidence.append(answer.log_evidence + np.log(card))
    batch = forward[0].shape[:-1]
    if question.kind == "filter":
        return steps_by.mark(_posterior(question, program, state, np.stack(forward),
                                        np.stack(log_evidence), "filter"))

    def smoothed() -> Posterior:
        backward = np.ones_like(forward[-1])
        marginals = [forward[-1]]
        for t in range(steps - 1, 0, -1):
            backward = ask((previous,), t, {state: backward}).probabilities
            joint = forward[t - 1] * backward
            marginals.append(joint / joint.sum(axis=-1, keepdims=True))
        return steps_by.mark(_posterior(question, program, state, np.stack(marginals[::-1]),
                                        np.stack(log_evidence), "smooth"))

    if question.kind == "smooth":
        return smoothed()
    # the most likely sequence: max-product over the step joints P(PREV X | y_t)
    with np.errstate(divide="ignore"):
        log_first = np.log(np.broadcast_to(first, batch + (card,)))
    logs = []
    for t in range(steps):
        answer = ask((previous, state), t, {})
        # P(PREV X | y_t) under a uniform PREV, times its evidence and the card:
        # log P(X | PREV) + log P(y_t | X)
        scale = (answer.log_evidence + np.log(card))[..., None, None]
        with np.errstate(divide="ignore"):
            logs.append(np.log(answer.probabilities) + scale)
    path, log_best, ties = most_likely_sequence(log_first, logs, options.get("rng"))
    indices = path[..., None]  # [T, batch, 1]
    marginals = smoothed()
    total = np.broadcast_to(np.sum(log_evidence, axis=0), batch)
    return _sequence(program, expr, (state,), indices, log_best, ties, total, marginals)


class _StepMethod:
    """The method that answered the steps' questions, kept for the answer over steps: an
    approximate one is named there (``steps_method``, with how it estimated the evidence)."""

    def __init__(self) -> None:
        self.method = ""
        self.evidence: str | None = None

    def seen(self, answer: Any, kind: str | None) -> Any:
        if kind == "sequence" and np.isnan(answer.log_evidence).any():
            raise QuestionError(f"method {answer.method!r} does not estimate the probability "
                                "of evidence, which the most likely sequence needs: leave out "
                                "the method (an exact one answers) or use lw")
        if not _exact(answer.method):
            self.method, self.evidence = answer.method, answer.evidence
        return answer

    def mark(self, answer: Posterior) -> Posterior:
        answer.steps_method = self.method
        answer.evidence = answer.evidence or self.evidence
        return answer


def _exact(method: str) -> bool:
    from bayesprog.inference.methods.base import method_named

    known = method_named(method)
    return known is None or known.exact


def _before(program: Any, previous: list[str], inputs: Mapping[str, Any] | None = None,
            method: str | None = None) -> Any:
    """The belief before the first step, ``P(previous)``. The terms of the states one step
    earlier depend on nothing else: it is asked of the engine without the variables that have
    no term, which every question of the program gives and which this one does not read."""
    from bayesprog.inference import dispatch

    question = Question(Expression(tuple(previous)))
    return dispatch.ask(program, question, None, inputs, None, None, method, {})


def _sequence(program: Any, expr: Expression, variables: tuple[str, ...], indices: np.ndarray,
              log_best: np.ndarray, ties: np.ndarray, total: np.ndarray,
              posterior: Posterior) -> MapResult:
    """The answer of a sequence question: the path's state indices ``[T, batch..., k]``, its
    log-probability with the evidence, the sequences that tie with it, the evidence's
    log-probability (``total``), the smoothed marginals."""
    with np.errstate(over="ignore", invalid="ignore"):
        probability = np.exp(log_best - total)
    return MapResult(
        question=f"{expr}   (the most likely sequence, {_steps_text(len(indices))})",
        variables=variables,
        names={v: program.variables[v].states for v in variables},
        indices=indices,
        probability=np.where(np.isfinite(total), probability, 0.0),
        ties=ties,
        zero_evidence=~np.isfinite(total),
        posterior=posterior,
        ablated=program.ablated,
        kind="sequence",
    )


def _steps_text(steps: int) -> str:
    return f"{steps} step" + ("" if steps == 1 else "s")


def _posterior(question: Question, program: Any, state: str, probabilities: np.ndarray,
               log_evidence: np.ndarray, kind: str) -> Posterior:
    shape = probabilities.shape[:-1]
    return Posterior(
        question=f"{question.expression}   ({'filtered' if kind == 'filter' else 'smoothed'}, "
                 f"{_steps_text(shape[0])})",
        variables=(state,),
        names={state: program.variables[state].states},
        values={state: program.variables[state].typed_states},
        probabilities=probabilities,
        log_evidence=np.broadcast_to(log_evidence, shape).copy(),
        batch_shape=shape,
        ablated=program.ablated,
        method=kind,
    )


def _steps_of(evidence: Mapping[str, Any] | None,
              soft: Mapping[str, Any] | None) -> tuple[int, dict[str, list[Any]]]:
    """The number of steps and each step's evidence; with soft evidence alone, its steps."""
    given = expect_mapping(evidence, "evidence", "variable names to values")
    if not given and soft:
        first = np.asarray(next(iter(soft.values())), dtype=float)
        if first.ndim < 2 or len(first) == 0:
            raise QuestionError("soft evidence over steps: expected one likelihood vector per "
                                f"step (time first), found shape {list(first.shape)}")
        return len(first), {}
    return _steps(given)


def _soft_steps(program: Any, soft: Mapping[str, Any] | None,
                steps: int) -> dict[str, list[np.ndarray]]:
    """Soft evidence over steps: per variable, one likelihood vector per step (time as the
    first axis, as the evidence), on what a step observes, not on its states."""
    if not soft:
        return {}
    kept = {name for pair in program.time for name in pair}
    out = {}
    for name, value in expect_mapping(soft, "soft", "variable names to likelihoods").items():
        if name in kept:
            raise QuestionError(f"soft evidence on {name}: the states over time are what the "
                                "recursion computes; give soft evidence on what a step "
                                "observes")
        array = np.asarray(value, dtype=float)
        if array.ndim < 2 or len(array) != steps:
            raise QuestionError(f"soft evidence on {name} over {steps} steps: expected one "
                                f"likelihood vector per step (time first), found shape "
                                f"{list(array.shape)}")
        out[name] = [array[t] for t in range(steps)]
    return out


def _joint(program: Any, question: Question, per_step: dict[str, list[Any]], steps: int,
           inputs: Mapping[str, Any] | None, method: str | None,
           options: Mapping[str, Any],
           soft_steps: dict[str, list[np.ndarray]] | None = None) -> Posterior | MapResult:
    """A question over steps of a program with several state variables: the recursions over
    their joint state. Each step's ``log P(x_t, y_t | x_t-1)`` for every joint state before
    (a batch of that many rows) is one question of the step program with the states one step
    earlier given and their terms uniform; the forward, backward and Viterbi recursions then
    run in log space on those matrices."""
    pairs = program.time
    previous = [p for p, _ in pairs]
    states = [s for _, s in pairs]
    cards = [program.variables[s].card for s in states]
    size = int(np.prod(cards))
    expr = question.expression
    step = program.ablate(*[str(program.term_of(p).expression) for p in previous])
    steps_by = _StepMethod()
    index = np.unravel_index(np.arange(size), cards)  # each joint state's indices
    first = _before(program, previous).probabilities.reshape(-1)
    batch: tuple[int, ...] | None = None
    logs = []
    for t in range(steps):
        known = {k: np.asarray(v[t], dtype=object) for k, v in per_step.items()}
        if batch is None:
            batch = np.broadcast_shapes(*(a.shape for a in known.values())) if known else ()
        # joint states before x the sequences of the batch
        shape = (size, *batch)
        given = {p: np.broadcast_to(np.asarray(i).reshape((size,) + (1,) * len(batch)), shape)
                 for p, i in zip(previous, index, strict=True)}
        given.update({k: np.broadcast_to(a, shape) for k, a in known.items()})
        q = Question(Expression(tuple(states), tuple(previous) + tuple(expr.right),
                                dict(expr.values)))
        likelihoods = {k: np.broadcast_to(v[t], shape + v[t].shape[-1:])
                       for k, v in (soft_steps or {}).items()}
        answer = steps_by.seen(step.ask(q, given, inputs=inputs, method=method,
                                        soft=likelihoods or None,
                                        samples=options.get("samples")), question.kind)
        with np.errstate(divide="ignore"):
            # log P(x, y_t | x_before) = log P(x | x_before, y_t) + log P(x_before, y_t) + log S
            logm = (np.log(answer.probabilities.reshape(shape + (size,)))
                    + (answer.log_evidence + np.log(size))[..., None])
        logs.append(np.moveaxis(logm, 0, -2))  # batch..., before, after
    assert batch is not None
    with np.errstate(divide="ignore"):
        log_first = np.broadcast_to(np.log(first), batch + (size,))
    forward, log_evidence = [], []
    alpha = log_first
    for t in range(steps):
        joint = scipy.special.logsumexp(alpha[..., :, None] + logs[t], axis=-2)
        total = scipy.special.logsumexp(joint, axis=-1)
        log_evidence.append(total)
        with np.errstate(invalid="ignore"):
            alpha = joint - total[..., None]
        forward.append(alpha)
    searched = list(expr.left)
    if question.kind in ("filter", "smooth"):
        if question.kind == "filter":
            marginals = forward
        else:
            beta = np.zeros(batch + (size,))
            marginals = [forward[-1]]
            for t in range(steps - 1, 0, -1):
                beta = scipy.special.logsumexp(logs[t] + beta[..., None, :], axis=-1)
                both = forward[t - 1] + beta
                marginals.append(both - scipy.special.logsumexp(both, axis=-1, keepdims=True))
            marginals = marginals[::-1]
        probabilities = np.exp(np.stack(marginals)).reshape((steps, *batch, *cards))
        keep = [states.index(v) for v in searched]
        drop = tuple(1 + len(batch) + i for i in range(len(states)) if i not in keep)
        probabilities = probabilities.sum(axis=drop)
        # the searched variables in the question's order
        order = sorted(keep)
        probabilities = np.moveaxis(
            probabilities, [1 + len(batch) + order.index(i) for i in keep],
            [1 + len(batch) + j for j in range(len(keep))])
        shape = probabilities.shape[:1 + len(batch)]
        kind = question.kind
        return steps_by.mark(Posterior(
            question=f"{expr}   ({'filtered' if kind == 'filter' else 'smoothed'}, "
                     f"{_steps_text(steps)})",
            variables=tuple(searched),
            names={v: program.variables[v].states for v in searched},
            values={v: program.variables[v].typed_states for v in searched},
            probabilities=probabilities,
            log_evidence=np.broadcast_to(np.stack(log_evidence), shape).copy(),
            batch_shape=shape,
            ablated=program.ablated,
            method=kind,
        ))
    # the most likely joint sequence
    joint_path, log_best, ties = most_likely_sequence(log_first, logs, options.get("rng"))
    per_variable = np.stack(np.unravel_index(joint_path, cards), axis=-1)  # [T, batch..., k]
    order = [states.index(v) for v in searched]
    indices = per_variable[..., order]
    total = np.broadcast_to(np.sum(np.stack(log_evidence), axis=0), batch)
    smooth = _joint(program, Question(Expression(expr.left, expr.right, dict(expr.values)),
                                      kind="smooth"), per_step, steps, inputs, method, options,
                    soft_steps)
    assert isinstance(smooth, Posterior)
    return _sequence(program, expr, tuple(searched), indices, log_best, ties, total, smooth)


def _kalman(program: Any, question: Question, per_step: dict[str, list[Any]], steps: int,
            inputs: Mapping[str, Any] | None) -> Density:
    """A question over steps of a program whose states are real: the Kalman filter (``filter``)
    and the Rauch-Tung-Striebel smoother (``smooth``), exact for a linear-Gaussian step.

    The step's model is read from the program itself, by Gaussian algebra: the states and
    observations of a step given the states before, ``(x_t, y_t) | x_t-1 ~ N(c + G x_t-1, S)``
    (asked with ``x_t-1`` at 0 and at each unit vector), and the belief before the first step
    ``N(m_0, P_0)``. Each step conditions the joint Gaussian of ``(x_t-1, x_t, y_t)`` on
    ``y_t``; the smoother runs back through the joints of ``(x_t-1, x_t)`` the filter kept, so
    an observation may also depend on the state before."""
    expr = question.expression
    if question.kind == "sequence":
        raise QuestionError("a sequence question searches discrete states: for real states the "
                            "most likely sequence of a linear-Gaussian program is the smoothed "
                            "means (ask a smooth question)")
    previous = [p for p, _ in program.time]
    states = [s for _, s in program.time]
    # a control (a variable without a term, given at every step) is not observed: the step's
    # model is read at its value of each step
    controls = [name for name in expr.right if name in program.conditioning]
    observed = [name for name in expr.right if name not in program.conditioning]
    for name in observed:
        if program.variables[name].is_discrete:
            raise QuestionError(f"a Kalman filter observes real variables: {name} is discrete "
                                "(ask a particle filter, method='pf')")
    d, m = len(states), len(observed)

    def gaussian(asked: Callable[[], Any]) -> Density:
        try:
            answer = asked()
        except QuestionError as exc:
            raise QuestionError(f"a Kalman filter needs a linear-Gaussian step (normal terms, "
                                f"means affine in their parents; else ask a particle filter, "
                                f"method='pf'): {exc}") from None
        assert isinstance(answer, Density) and answer.means is not None
        if answer.means.shape[1] != 1:
            raise QuestionError("a filter over real states needs one Gaussian per step: a "
                                "discrete variable of the step mixes several")
        return answer

    start = gaussian(lambda: _before(program, previous, inputs, "gaussian"))
    assert start.means is not None and start.covariances is not None
    m0 = start.means[0, 0]
    p0 = start.covariances[0, 0]
    step = program.ablate(*[str(program.term_of(p).expression) for p in previous])
    # the states before at 0, at each unit vector, and at a few more points that check that
    # the step is linear in them (a formula such as sin(X_before) is not)
    probes = np.random.default_rng(0).normal(scale=3.0, size=(3, d))
    rows = np.vstack([np.zeros(d), np.eye(d), probes])
    # with controls, one model per step and sequence: [steps, batch..., rows] probes
    values = {name: np.asarray(per_step[name]) for name in controls}
    lead = np.broadcast_shapes(*(v.shape for v in values.values())) if controls else ()
    given = {p: np.broadcast_to(rows[:, i], lead + (len(rows),))
             for i, p in enumerate(previous)}
    given.update({name: np.broadcast_to(v[..., None], lead + (len(rows),))
                  for name, v in values.items()})
    model = gaussian(lambda: step.ask(
        f"P({' '.join(states + observed)} | {', '.join(previous + controls)})", given,
        inputs=inputs, method="gaussian"))
    k = d + m
    means = model.means[:, 0].reshape(lead + (len(rows), k))  # type: ignore[index]
    covariances = model.covariances[:, 0].reshape(lead + (len(rows), k, k))  # type: ignore[index]
    c = means[..., 0, :]
    g = np.swapaxes(means[..., 1:d + 1, :] - c[..., None, :], -1, -2)  # ... (d + m) x d
    noise = covariances[..., 0, :, :]
    scale = 1.0 + np.abs(means).max()
    linear = c[..., None, :] + np.einsum("pj,...ij->...pi", probes, g)
    if (np.abs(means[..., d + 1:, :] - linear).max() > 1e-9 * scale
            or np.abs(covariances - noise[..., None, :, :]).max()
            > 1e-9 * (1 + np.abs(noise).max())):
        raise QuestionError("a Kalman filter needs a linear-Gaussian step: the means of "
                            f"{', '.join(states + observed)} are not affine in "
                            f"{', '.join(previous)} (a non-linear formula): ask a particle "
                            "filter, method='pf' (--method pf)")
    y_all = (np.stack([np.asarray(per_step[name], dtype=float) for name in observed], axis=-1)
             if observed else np.zeros((steps, 0)))
    batch = np.broadcast_shapes(y_all.shape[1:-1], lead[1:])
    extra = (1,) * (len(batch) - (y_all.ndim - 2))  # the batch axes the commands add
    y_all = np.broadcast_to(y_all.reshape((steps, *extra) + y_all.shape[1:]), (steps, *batch, m))
    mean = np.broadcast_to(m0, batch + (d,)).copy()
    cov = np.broadcast_to(p0, batch + (d, d)).copy()
    filtered, joints, log_evidence = [], [], []
    y_index = np.arange(2 * d, 2 * d + m)
    for t in range(steps):
        c_t, g_t, noise_t = (c[t], g[t], noise[t]) if controls else (c, g, noise)
        # the joint of (x_t-1, x_t, y_t) given y_1..t-1
        mu = np.concatenate([mean, c_t + np.einsum("...ij,...j->...i", g_t, mean)], axis=-1)
        cross = np.einsum("...ij,...kj->...ik", cov, g_t)  # cov(x_t-1, (x_t, y_t))
        lower = np.einsum("...ij,...jk,...lk->...il", g_t, cov, g_t) + noise_t
        sigma = _blocks(cov, cross, lower)
        keep = np.arange(2 * d)
        s_yy = sigma[..., y_index[:, None], y_index]
        s_ky = sigma[..., keep[:, None], y_index]
        gain = np.linalg.solve(s_yy, np.swapaxes(s_ky, -1, -2))  # m x 2d per batch
        gain = np.swapaxes(gain, -1, -2)
        innovation = y_all[t] - mu[..., y_index]
        joint_mean = mu[..., keep] + np.einsum("...ij,...j->...i", gain, innovation)
        joint_cov = sigma[..., keep[:, None], keep] - np.einsum("...ij,...kj->...ik", gain, s_ky)
        _, logdet = np.linalg.slogdet(s_yy)
        quad = np.einsum("...i,...i->...", innovation,
                         np.linalg.solve(s_yy, innovation[..., None])[..., 0])
        log_evidence.append(-0.5 * (quad + logdet + m * np.log(2 * np.pi)))
        joints.append((joint_mean, joint_cov))
        mean = joint_mean[..., d:]
        cov = joint_cov[..., d:, d:]
        filtered.append((mean, cov))
    if question.kind == "smooth":
        smooth_mean, smooth_cov = filtered[-1]
        out = [(smooth_mean, smooth_cov)]
        for t in range(steps - 1, 0, -1):
            joint_mean, joint_cov = joints[t]  # (x_t-1, x_t) given y_1..t
            before_mean, after_mean = joint_mean[..., :d], joint_mean[..., d:]
            before_cov = joint_cov[..., :d, :d]
            cross = joint_cov[..., :d, d:]
            after_cov = joint_cov[..., d:, d:]
            j = np.swapaxes(np.linalg.solve(after_cov, np.swapaxes(cross, -1, -2)), -1, -2)
            smooth_mean = before_mean + np.einsum("...ij,...j->...i", j,
                                                  smooth_mean - after_mean)
            smooth_cov = before_cov + np.einsum("...ij,...jk,...lk->...il", j,
                                                smooth_cov - after_cov, j)
            out.append((smooth_mean, smooth_cov))
        chosen = out[::-1]
    else:
        chosen = filtered
    order = [states.index(v) for v in expr.left]
    means_t = np.stack([mu for mu, _ in chosen])[..., order]  # T, batch..., k
    covs_t = np.stack([sg for _, sg in chosen])[..., order, :][..., :, order]
    shape = (steps,) + batch
    rows_n = int(np.prod(shape))
    kind = question.kind
    return Density(
        f"{expr}   ({'filtered' if kind == 'filter' else 'smoothed'}, {_steps_text(steps)})",
        tuple(expr.left), shape, np.stack(log_evidence).reshape(shape), ablated=program.ablated,
        method="kalman" if kind == "filter" else "kalman-rts",
        weights=np.ones((rows_n, 1)), means=means_t.reshape(rows_n, 1, len(order)),
        covariances=covs_t.reshape(rows_n, 1, len(order), len(order)))


def _blocks(top_left: np.ndarray, top_right: np.ndarray, bottom_right: np.ndarray) -> np.ndarray:
    """``[[A, B], [B^T, C]]`` for batches of blocks."""
    upper = np.concatenate([top_left, top_right], axis=-1)
    lower = np.concatenate([np.swapaxes(top_right, -1, -2), bottom_right], axis=-1)
    return np.concatenate([upper, lower], axis=-2)


#: particles per sequence of a particle filter when the question does not say
PARTICLES = 2_000


def _particles(program: Any, question: Question, per_step: dict[str, list[Any]], steps: int,
               inputs: Mapping[str, Any] | None, options: Mapping[str, Any]) -> Density:
    """A filter or smooth question over real states answered by particles.

    The filter is the bootstrap filter: particles drawn from the belief before the first step;
    at each step each particle moves by the step's own terms (drawn as likelihood weighting
    draws, the states before given), is weighted by the likelihood of what the step observes,
    and the particles are resampled (systematic resampling) after their weighted summary is
    kept. Seeded by ``rng`` (step ``t``, sequence ``b`` and particle ``i`` use their own
    streams), whatever the batch.

    The smoother is forward filtering, backward smoothing (FFBSm, Doucet, Godsill and Andrieu
    2000): each step's weighted particles of the filter reweighted, from the last step back,
    by the step program's density of the pair of states (the transition and what the next
    step observes, :func:`_pair_log_density`),
    ``w_t|T(i) = w_t(i) sum_j w_t+1|T(j) psi(x_t^i, x_t+1^j) / sum_k w_t(k) psi(x_t^k, x_t+1^j)``,
    the marginal smoother (each step's marginal, not drawn paths): ``n^2`` densities a step,
    computed a block of pairs at a time (:func:`_smoothed_weights`), so that its memory grows
    as ``n``: every step's particles and weights are kept, never the ``n x n`` densities. No
    randomness beyond the filter's, so the same seed gives the same answer, bit for bit,
    whatever the batch, the blocks and the limits. A filter or smoother past the entries limit
    is refused before anything is drawn, with its estimate (:func:`_check_particles`).

    The answer gives each step's weighted mean and covariance of the particles (its density
    and quantiles are those of the Gaussian with these moments), the effective sample size of
    the weights (``ess``: before resampling for the filter, of the smoothing weights for the
    smoother) and ``log_evidence[t]``, the estimate of ``log p(y_t | y_1..t-1)``."""
    from bayesprog.inference.answers import seed_of
    from bayesprog.inference.binding import bind
    from bayesprog.inference.sampling import draw

    expr = question.expression
    if question.kind not in ("filter", "smooth"):
        raise QuestionError(f"particles answer filter and smooth questions, found a "
                            f"{question.kind} question (the most likely sequence is asked of "
                            "discrete states)")
    previous = [p for p, _ in program.time]
    states = [s for _, s in program.time]
    n = int(options.get("samples") or PARTICLES)
    seed = seed_of(options.get("rng", 0) or 0)
    observed = list(expr.right)
    known = {name: np.asarray(per_step[name], dtype=object) for name in observed}
    batch = np.broadcast_shapes(*(a.shape[1:] for a in known.values())) if known else ()
    sequences = int(np.prod(batch))
    _check_particles(n, sequences, steps, len(states), question.kind == "smooth")
    # the controls (variables without a term) given at the first step: the states one step
    # earlier do not depend on them, but the program is drawn given them
    controls = [name for name in observed if name in program.conditioning]

    def first_step(b: int) -> dict[str, Any]:
        return {name: np.broadcast_to(known[name][0], batch).reshape(-1)[b]
                for name in controls}

    particles = np.stack([
        np.stack([first[p].to_numpy(dtype=float) for p in previous], axis=-1)
        for first in (program.sample(n, first_step(b), rng=np.random.default_rng([seed, 0, b]))
                      for b in range(sequences))])  # [sequences, n, states]
    step = program.ablate(*[str(program.term_of(p).expression) for p in previous])
    terms = list(step.active_terms)
    means, covs, ess, log_evidence = [], [], [], []
    kept: list[tuple[np.ndarray, np.ndarray]] = []  # each step's particles and weights
    q = Question(Expression(tuple(states), tuple(previous) + tuple(observed),
                            dict(expr.values)))
    for t in range(steps):
        evidence: dict[str, Any] = {p: particles[..., i] for i, p in enumerate(previous)}
        for name in observed:
            value = np.broadcast_to(known[name][t], batch).reshape(sequences, 1)
            evidence[name] = np.broadcast_to(value, (sequences, n))
        bound = bind(step, q, evidence, inputs, None)
        gens = [np.random.default_rng([seed, t + 1, b, i]) for b in range(sequences)
                for i in range(n)]
        drawn = draw(step, terms, bound, 1, gens)
        moved = np.stack([np.asarray(drawn.values[s], float).reshape(sequences, n)
                          for s in states], axis=-1)
        log_w = drawn.log_weights.reshape(sequences, n)
        top = np.max(log_w, axis=1, keepdims=True)
        if not np.all(np.isfinite(top)):
            raise QuestionError(f"step {t + 1}: every particle has likelihood zero (the "
                                "observations are impossible under the program, or too few "
                                "particles: samples=...)")
        w = np.exp(log_w - top)
        total = w.sum(axis=1, keepdims=True)
        w = w / total
        log_evidence.append((top[:, 0] + np.log(total[:, 0] / n)).reshape(batch))
        ess.append((1.0 / (w**2).sum(axis=1)).reshape(batch))
        if question.kind == "smooth":
            kept.append((moved, w))
        else:
            means.append(_weighted_mean(w, moved))
            covs.append(_weighted_covariance(w, moved, means[-1]))
        # systematic resampling, one stream per sequence
        u = np.array([np.random.default_rng([seed, t + 1, b, n]).random()
                      for b in range(sequences)])
        points = (u[:, None] + np.arange(n)) / n
        picks = np.stack([np.minimum(np.searchsorted(np.cumsum(w[b]), points[b]), n - 1)
                          for b in range(sequences)])
        particles = np.take_along_axis(moved, picks[..., None], axis=1)
    if question.kind == "smooth":
        ess = []
        smoothed = _smoothed_weights(step, kept, previous, states, observed, known, batch,
                                     inputs)
        for (moved, _), w in zip(kept, smoothed, strict=True):
            means.append(_weighted_mean(w, moved))
            covs.append(_weighted_covariance(w, moved, means[-1]))
            ess.append((1.0 / (w**2).sum(axis=1)).reshape(batch))
    order = [states.index(v) for v in expr.left]
    shape = (steps,) + batch
    rows = int(np.prod(shape))
    mean_t = np.stack(means)[..., order].reshape(rows, 1, len(order))
    cov_t = np.stack(covs)[..., order, :][..., :, order].reshape(rows, 1, len(order),
                                                                     len(order))
    smooth = question.kind == "smooth"
    return Density(
        f"{expr}   ({'smoothed' if smooth else 'filtered'}, {_steps_text(steps)})",
        tuple(expr.left), shape, np.stack(log_evidence).reshape(shape),
        ablated=program.ablated, method="pf-smooth" if smooth else "pf",
        weights=np.ones((rows, 1)), means=mean_t, covariances=cov_t,
        ess=np.stack(ess).reshape(shape))


def _weighted_mean(w: np.ndarray, particles: np.ndarray) -> np.ndarray:
    """``[sequences, d]``: the mean of each sequence's particles ``[sequences, n, d]``."""
    return np.einsum("bn,bnd->bd", w, particles)


def _weighted_covariance(w: np.ndarray, particles: np.ndarray, mean: np.ndarray) -> np.ndarray:
    dev = particles - mean[:, None, :]
    return np.einsum("bn,bnd,bne->bde", w, dev, dev)


#: pairs of particles whose densities one block of the smoother's backward pass holds (512 KB of
#: float64; fewer under a low BAYESPROG_MAX_ENTRIES, never less than one particle's row): the
#: pass needs memory in n, not n^2, and the block's size does not change its answer
PAIRS_PER_BLOCK = 1 << 16
#: float64 entries a block holds per pair: the densities, the kernel's row and what one call of
#: the engine allocates for it (the pairs' states, each term's log-factor)
BLOCK_ENTRIES_PER_PAIR = 16
#: float64 entries one particle's random stream takes (a numpy Generator, about 1 KB)
STREAM_ENTRIES = 128


def _check_particles(n: int, sequences: int, steps: int, dims: int, smooth: bool) -> None:
    """Refuse a particle filter or smoother past the entries limit, before anything is drawn:
    each particle's stream, states and weights at a step and, for the smoother, every step's
    particles, weights and smoothing weights (kept for the backward pass), and the backward
    pass's block (which shrinks to fit the limit, to one row of ``n`` pairs at least)."""
    per_particle = STREAM_ENTRIES + 4 * dims + 4
    if smooth:
        per_particle += steps * (dims + 2)
    entries = float(n) * sequences * per_particle
    if smooth:
        entries += float(BLOCK_ENTRIES_PER_PAIR) * n
    check_size(entries, f"a particle {'smoother' if smooth else 'filter'} of {n:,} particles "
               f"x {sequences:,} sequence{'s' if sequences > 1 else ''} x {steps:,} step"
               f"{'s' if steps > 1 else ''}",
               hint="; or ask fewer particles (samples=... in Python, --samples on the "
                    "command line), or fewer sequences or steps at once")


def _smoothed_weights(step: Any, kept: list[tuple[np.ndarray, np.ndarray]],
                      previous: list[str], states: list[str], observed: list[str],
                      known: dict[str, np.ndarray], batch: tuple[int, ...],
                      inputs: Mapping[str, Any] | None) -> list[np.ndarray]:
    """The smoothing weights ``[sequences, n]`` of each step's filter particles (FFBSm, see
    :func:`_particles`), from the last step back.

    ``w_t|T(i) = sum_j w_t+1|T(j) K_t(j, i)``, where ``K_t(j, i) = w_t(i) psi(x_t^i, x_t+1^j)
    / sum_k w_t(k) psi(x_t^k, x_t+1^j)`` is the backward kernel: each particle after's row is
    computed, normalised and added in, then dropped. The rows go by blocks of at most
    :data:`PAIRS_PER_BLOCK` pairs, each row's sum over all ``n`` particles before at once, and
    the rows are added in their order, one by one: the answer is the same, bit for bit,
    whatever the block's size."""
    steps = len(kept)
    sequences, n = kept[0][1].shape
    rows = max(1, min(PAIRS_PER_BLOCK, limit("entries") // BLOCK_ENTRIES_PER_PAIR) // n)
    smooth = kept[-1][1]
    out = [smooth]
    for t in range(steps - 2, -1, -1):
        before, w_before = kept[t]
        after = kept[t + 1][0]
        with np.errstate(divide="ignore"):
            log_w = np.log(w_before)
        new = np.zeros((sequences, n))
        for b in range(sequences):
            values = {name: np.broadcast_to(known[name][t + 1], batch).reshape(-1)[b]
                      for name in observed}
            for start in range(0, n, rows):
                stop = min(n, start + rows)
                kernel = _backward_kernel(log_w[b], _pair_log_density(
                    step, before[b], after[b, start:stop], previous, states, values, inputs))
                for weight, row in zip(smooth[b, start:stop], kernel, strict=True):
                    new[b] += weight * row
        new /= new.sum(axis=1, keepdims=True)
        smooth = new
        out.append(new)
    return out[::-1]


def _backward_kernel(log_w: np.ndarray, log_psi: np.ndarray) -> np.ndarray:
    """``[m, n]``: for each particle after (a row of ``log_psi``, ``[m, n]``, the pair's
    log-density at each particle before), the probability of each particle before, ``w(i)
    psi(i, j)`` normalised over ``i``. A row where no particle before leads is zeros. Computed
    in place of ``log_psi``."""
    kernel = log_psi
    kernel += log_w[None, :]
    top = np.max(kernel, axis=1, keepdims=True)
    top[~np.isfinite(top)] = 0.0
    kernel -= top
    np.exp(kernel, out=kernel)
    total = kernel.sum(axis=1, keepdims=True)
    total[total == 0] = 1.0
    kernel /= total
    return kernel


def _pair_log_density(step: Any, before: np.ndarray, after: np.ndarray, previous: list[str],
                      states: list[str], observed: dict[str, Any],
                      inputs: Mapping[str, Any] | None) -> np.ndarray:
    """``[m, n]``: the log-density of the step program (the states before's own term
    uniform) at each pair of a state after ``after`` ``[m, d]`` (a row) and a state before
    ``before`` ``[n, d]`` (a column), with what the step after observes: the transition's
    density times the likelihood of the observations (which may read the states before), the
    step's other unknown variables summed or integrated out by the engine, in one call."""
    from bayesprog.inference.binding import bind
    from bayesprog.inference.dispatch import compute_posterior

    n, m = len(before), len(after)
    question = Question(Expression((), (*previous, *states, *observed)))
    evidence: dict[str, Any] = {p: np.tile(before[:, i], m) for i, p in enumerate(previous)}
    evidence.update({s: np.repeat(after[:, i], n) for i, s in enumerate(states)})
    evidence.update(observed)
    bound = bind(step, question, evidence, inputs, None)
    try:
        answer = compute_posterior(step, question, bound, None, {})
    except QuestionError as exc:
        raise QuestionError(f"a particle smoother needs the step's density at a pair of "
                            f"states before and after: {exc}") from None
    return np.asarray(answer.log_evidence, float).reshape(m, n)
