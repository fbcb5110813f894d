"""Gibbs sampling against pyAgrum's GibbsSampling (not a test).

bnlearn networks as pgmpy ships them (imported by ``bayesprog import``; pyAgrum's network built
from the imported tables), every leaf observed in its least likely state (evidence under which
likelihood weighting starves), the posterior of one root asked with ``method="gibbs"`` and by
pyAgrum's ``GibbsSampling`` with the same number of sweeps (pyAgrum: ``setMaxIter``, each
iteration drawing every unobserved variable in turn, its other stopping rules out of reach,
its burn-in the same). Each side is timed warm (its first answer
not counted), medians of ``--repeats``; the time per sweep, the ratio (pyAgrum's time over
ours: above 1, bayesprog is faster) and each answer's largest difference from the exact
posterior are printed and written to ``--out``.

    python benchmarks/gibbs.py [--networks asia child alarm insurance] [--sweeps 20000]
        [--repeats 5] [--out results/benchmarks/gibbs.json]
"""

from __future__ import annotations

import argparse
import gzip
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pgmpy
import pyagrum as gum

import bayesprog
from bayesprog.io import import_network

EXAMPLES = Path(pgmpy.__file__).parent / "utils" / "example_models"
BURN_IN = 1_000


def case(name: str, tmp: Path) -> tuple[bayesprog.Program, gum.BayesNet, str, dict[str, str]]:
    bif = tmp / f"{name}.bif"
    bif.write_bytes(gzip.decompress((EXAMPLES / f"{name}.bif.gz").read_bytes()))
    program = bayesprog.load(import_network(bif, tmp / f"{name}.yaml"))
    bn = agrum_network(program)
    children = {p.name for t in program.terms for p in t.parents}
    leaves = sorted(v for v in program.variables if v not in children)
    roots = sorted(t.child.name for t in program.terms if not t.parents)
    evidence = {v: program.variables[v].states[int(np.argmin(
        program.ask(f"P({v})").probabilities))] for v in leaves}
    target = next(r for r in roots if r not in evidence)
    return program, bn, target, evidence


def agrum_network(program: bayesprog.Program) -> gum.BayesNet:
    """pyAgrum's network of the imported program's tables (its BIF reader refuses some of
    bnlearn's state names, child's ``Asy/Patch``)."""
    bn = gum.BayesNet(program.name)
    for name, variable in program.variables.items():
        bn.add(gum.LabelizedVariable(name, name, [str(s) for s in variable.states]))
    for term in program.terms:
        for parent in term.parents:
            bn.addArc(parent.name, term.child.name)
    for term in program.terms:
        axes = [*(p.name for p in term.parents), term.child.name]  # the table's axes
        cpt = bn.cpt(term.child.name)
        order = [axes.index(v) for v in list(cpt.names)[::-1]]  # toarray's axes: reversed
        cpt.fillWith(np.transpose(term.params["table"].array, order).ravel().tolist())
    return bn


def measure(name: str, sweeps: int, repeats: int, tmp: Path) -> dict:
    program, bn, target, evidence = case(name, tmp)
    question = f"P({target} | {', '.join(evidence)})"
    exact = np.asarray(program.ask(question, evidence).probabilities)

    def ours() -> np.ndarray:
        answer = program.ask(question, evidence, method="gibbs", samples=sweeps,
                             burn_in=BURN_IN, rng=1)
        return np.asarray(answer.probabilities)

    def theirs() -> np.ndarray:
        engine = gum.GibbsSampling(bn)
        engine.setEvidence(evidence)
        engine.setBurnIn(BURN_IN)
        engine.setMaxIter(sweeps)
        engine.setNbrDrawnVar(bn.size() - len(evidence))  # an iteration is a sweep
        engine.setDrawnAtRandom(False)
        engine.setEpsilon(1e-300)  # its other stopping rules out of reach
        engine.setMinEpsilonRate(1e-300)
        engine.setMaxTime(1e9)
        engine.makeInference()
        states = [bn.variable(target).label(i) for i in range(bn.variable(target).domainSize())]
        posterior = np.asarray(engine.posterior(target).toarray())
        order = [states.index(s) for s in program.variables[target].states]
        return posterior[order]

    gum.initRandom(1)
    answers = {"bayesprog": ours(), "pyagrum": theirs()}  # warm: compiled, first-call costs
    times: dict[str, list[float]] = {k: [] for k in answers}
    for _ in range(repeats):  # interleaved: load drifts evenly over both
        for key, function in (("bayesprog", ours), ("pyagrum", theirs)):
            start = time.perf_counter()
            function()
            times[key].append(time.perf_counter() - start)
    medians = {k: statistics.median(v) for k, v in times.items()}
    return {"network": name, "question": question, "sweeps": sweeps,
            **{f"{k}_s": v for k, v in medians.items()},
            "ratio_pyagrum": medians["pyagrum"] / medians["bayesprog"],
            **{f"{k}_error": float(np.abs(a - exact).max()) for k, a in answers.items()},
            "times_s": times}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", nargs="+", default=["asia", "child", "alarm", "insurance"])
    parser.add_argument("--sweeps", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default="results/benchmarks/gibbs.json")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        rows = [measure(n, args.sweeps, args.repeats, Path(tmp)) for n in args.networks]
    print(f"{'network':<10} {'sweeps':>7} {'ours':>9} {'pyAgrum':>9} {'ag/ours':>8} "
          f"{'ours err':>9} {'ag err':>8}")
    for r in rows:
        print(f"{r['network']:<10} {r['sweeps']:>7} {1e3 * r['bayesprog_s']:>7.1f}ms "
              f"{1e3 * r['pyagrum_s']:>7.1f}ms {r['ratio_pyagrum']:>8.1f} "
              f"{r['bayesprog_error']:>9.4f} {r['pyagrum_error']:>8.4f}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"repeats": args.repeats, "burn_in": BURN_IN, "rows": rows},
                              indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
