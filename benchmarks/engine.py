"""Engine speed against pgmpy VariableElimination and pyAgrum LazyPropagation (not a test).

For each bnlearn network, one posterior question P(target | 4 observed variables) with evidence
sets drawn by forward sampling (seeded), measured in one run against each peer's fastest
documented mode: pyAgrum's LazyPropagation with the target declared and the evidence changed in
place; pgmpy's VariableElimination with the faster of its default order and a MinFill order
chosen once. The JSON result says the mode of every row and holds every ratio.

* cold: the first query after building each model, from flushed CPU caches (its engine made,
  and for pyAgrum its junction tree built, within the time; bayesprog answers a layout's
  first question by elimination and plans it at the second); beside it, the same right after
  building the model, whatever that left in the caches;
* warm single: one evidence set per call, the evidence changed at every call;
* batches of 1, 100 and 10,000 evidence sets: bayesprog answers a batch in one call, pgmpy and
  pyAgrum loop over it (their per-query rate is measured on a sample of the batch and
  extrapolated; the table says so);
* peak memory of bayesprog's 10,000-set batch (tracemalloc, numpy allocations included).

bayesprog is measured twice: as it runs (a discrete question whose joint table over the observed
and searched variables is small is compiled into that table once, then each evidence set is a
lookup), and with those tables switched off (``contraction`` rows: every call contracts the
factors), which is what larger questions and continuous evidence get.

Every figure is the median of several repeats; ratios are bayesprog's rate over the others'.

Approximate methods on n x n grids of binary variables (each with its up and left neighbours
as parents; exact inference grows as 2^n): loopy belief propagation beside pyAgrum's, likelihood
weighting beside pyAgrum's importance sampling with as many draws, and the exact answer where
pyAgrum's junction tree finds it.

    python benchmarks/engine.py [--networks asia alarm] [--repeats 5] [--grids 12 20]
        [--out results/engine.json]
"""

from __future__ import annotations

import argparse
import contextlib
import gzip
import json
import signal
import statistics
import sys
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import pgmpy
    import pyagrum as gum
    from pgmpy.inference import VariableElimination

import bayesprog
from bayesprog.inference.methods import table as table_method
from bayesprog.io import dump_document, network_to_document, read_network

EXAMPLES = Path(pgmpy.__file__).parent / "utils" / "example_models"
TABLE_LIMIT = table_method.TABLE_LIMIT
#: written over before a cold query: larger than the machine's last-level cache
_SWEEP = np.zeros(2**23)  # 64 MiB


def flush_caches() -> None:
    """Evict what the CPU caches hold (by writing 64 MiB), so that a cold query starts from
    the same state whichever library asks it."""
    np.add(_SWEEP, 1.0, out=_SWEEP)


NETWORKS = ["asia", "alarm", "child", "insurance", "water", "hailfinder", "hepar2", "win95pts",
            "pigs", "munin1"]
BATCHES = [1, 100, 10_000]


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def call_time(fn, repeats: int, least: float = 2e-3) -> float:
    """Seconds per call of ``fn``: the median of ``repeats`` loops of as many calls as take
    ``least`` seconds (a call of tens of microseconds timed alone is as much the timer and
    what ran before it as the call)."""
    fn()
    calls = 1
    while True:
        t = time.perf_counter()
        for _ in range(calls):
            fn()
        if time.perf_counter() - t >= least:
            break
        calls *= 2
    return median_time(lambda: [fn() for _ in range(calls)], repeats) / calls


def forward_sample(model, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """n joint samples (state indices per variable), vectorised ancestral sampling."""
    import networkx as nx

    graph = nx.DiGraph(list(model.edges()))
    graph.add_nodes_from(model.nodes())
    cpds = {c.variable: c for c in model.get_cpds()}
    out: dict[str, np.ndarray] = {}
    for var in nx.topological_sort(graph):
        cpd = cpds[var]
        values = np.asarray(cpd.values, dtype=float)
        rows = values[(slice(None),) + tuple(out[p] for p in cpd.variables[1:])]
        rows = rows.reshape(values.shape[0], n) if cpd.variables[1:] else np.repeat(
            values[:, None], n, axis=1)
        cum = np.cumsum(rows / rows.sum(0), axis=0)
        out[var] = np.minimum((rng.random(n)[None] > cum).sum(0), values.shape[0] - 1)
    return out


def agrum_net(model) -> gum.BayesNet:
    bn = gum.BayesNet()
    cpds = {c.variable: c for c in model.get_cpds()}
    for var, cpd in cpds.items():
        bn.add(gum.LabelizedVariable(var, var, [str(x) for x in cpd.state_names[var]]))
    for var, cpd in cpds.items():
        for parent in cpd.variables[1:]:
            bn.addArc(parent, var)
    for var, cpd in cpds.items():
        values = np.asarray(cpd.values, dtype=float)
        parents = cpd.variables[1:]
        for index in np.ndindex(*values.shape[1:]):
            where = {p: str(cpd.state_names[p][i]) for p, i in zip(parents, index, strict=True)}
            bn.cpt(var)[where] = values[(slice(None),) + index].tolist()
    return bn


def load_network(name: str, tmp: Path):
    """The bnlearn network ``name`` (pgmpy's model, its tables normalised), written as a
    program file, and the benchmark's question on it: a seeded target and four observed
    variables; returns (model, path, target, observed, the generator that chose them)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bif = tmp / f"{name}.bif"
        bif.write_text(gzip.open(EXAMPLES / f"{name}.bif.gz", "rt").read())
        model = read_network(bif)
    for cpd in model.get_cpds():
        cpd.normalize(inplace=True)
    path = tmp / f"{name}.yaml"
    path.write_text(dump_document(network_to_document(model, name)))
    rng = np.random.default_rng(sum(map(ord, name)))
    names = sorted(model.nodes())
    chosen = rng.choice(len(names), size=5, replace=False)
    return model, path, names[chosen[0]], [names[i] for i in chosen[1:]], rng


#: seconds a peer's mode may take on one network before it is given up (see pgmpy_rate)
PEER_BUDGET = 120


@contextlib.contextmanager
def time_budget(seconds: float):
    """Raise TimeoutError in the block once ``seconds`` have passed (checked between Python
    bytecodes: a long numpy call ends first)."""
    def expire(signum, frame):
        raise TimeoutError(f"over {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def bench_network(name: str, repeats: int, tmp: Path, tables: bool = True) -> dict:
    table_method.TABLE_LIMIT = TABLE_LIMIT if tables else 0
    model, path, target, observed, rng = load_network(name, tmp)
    names = sorted(model.nodes())
    samples = forward_sample(model, max(BATCHES), rng)
    cpds = {c.variable: c for c in model.get_cpds()}

    def state(var: str, i: int) -> str:
        return str(cpds[var].state_names[var][i])

    def evidence(i: int) -> dict[str, str]:
        return {v: state(v, int(samples[v][i])) for v in observed}

    question = f"P({target} | {', '.join(observed)})"
    row: dict = {"network": name if tables else f"{name} (contraction)", "nodes": len(names),
                 "question": question, "tables": tables}

    # cold: the first query after building each model (bayesprog's program, pyAgrum's
    # BayesNet, both from the same tables; pgmpy's model, whose reader takes seconds, once),
    # timed from flushed caches: a first query meets the caches as the work before it left
    # them, and a sub-millisecond time depends on that more than on the query (pyAgrum on
    # asia: 0.04 ms right after an earlier query, 0.25 ms from flushed caches). Beside it,
    # "built": right after building the model, whatever that left in the caches.
    def cold_ours(flush: bool) -> float:
        program = bayesprog.load(path)
        if flush:
            flush_caches()
        t = time.perf_counter()
        program.ask(question, evidence(0))
        return time.perf_counter() - t

    def cold_pgmpy(flush: bool) -> float:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if flush:
                flush_caches()
            t = time.perf_counter()
            ve = VariableElimination(model)
            ve.query([target], evidence=evidence(0), show_progress=False)
        return time.perf_counter() - t

    def cold_agrum(flush: bool) -> float:
        # pyAgrum's fastest documented mode: the engine made, the target declared, then one
        # propagation (its junction tree is built there, for that target and evidence)
        bn = agrum_net(model)
        if flush:
            flush_caches()
        t = time.perf_counter()
        lazy = gum.LazyPropagation(bn)
        lazy.addTarget(target)
        lazy.setEvidence(evidence(0))
        lazy.makeInference()
        lazy.posterior(target)
        return time.perf_counter() - t

    cold_repeats = max(repeats, 9)
    for key, flush in (("cold_ms", True), ("cold_built_ms", False)):
        row[key] = {"bayesprog": 1e3 * statistics.median(cold_ours(flush)
                                                         for _ in range(cold_repeats))}
        try:
            with time_budget(PEER_BUDGET):
                row[key]["pgmpy"] = 1e3 * statistics.median(cold_pgmpy(flush)
                                                             for _ in range(cold_repeats))
        except (MemoryError, TimeoutError):  # an order of pgmpy's greedy heuristic too large
            row[key]["pgmpy"] = float("nan")
        row[key]["pyagrum"] = 1e3 * statistics.median(cold_agrum(flush)
                                                      for _ in range(cold_repeats))
    bn = agrum_net(model)

    # warm single queries, the evidence changing at every query
    program = bayesprog.load(path)
    program.ask(question, evidence(0))
    singles = [evidence(i) for i in range(200)]
    ve = VariableElimination(model)
    lazy = gum.LazyPropagation(bn)
    lazy.addTarget(target)
    first = singles[0]
    for v, value in first.items():  # evidence set once, then changed in place
        lazy.addEvidence(v, value)
    rest = [n for n in names if n != target and n not in observed]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from pgmpy.inference.EliminationOrder import MinFill

        order = MinFill(model).get_elimination_order(nodes=rest, show_progress=False)

    def loop_ours(sets):
        for e in sets:
            program.ask(question, e)

    def loop_pgmpy(sets, fixed=False):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for e in sets:
                ve.query([target], evidence=e, show_progress=False,
                         **({"elimination_order": order} if fixed else {}))

    def loop_agrum(sets):
        for e in sets:
            for v, value in e.items():
                lazy.chgEvidence(v, value)
            lazy.makeInference()
            lazy.posterior(target)

    sample_pgmpy = singles[:20]

    def pgmpy_rate(fixed: bool) -> float:
        # pgmpy's greedy order breaks ties in set order, which changes with Python's string
        # hashing from one process to the next: on munin1 some orders need more memory than
        # the machine has (the address-space cap set in main turns that into MemoryError) or
        # minutes per query (a mode over PEER_BUDGET seconds counts as rate 0)
        try:
            with time_budget(PEER_BUDGET):
                return len(sample_pgmpy) / median_time(
                    lambda: loop_pgmpy(sample_pgmpy, fixed), repeats)
        except (MemoryError, TimeoutError):
            return 0.0

    pgmpy_modes = {"greedy order per query (default)": pgmpy_rate(False),
                   "MinFill order chosen once": pgmpy_rate(True)}
    pgmpy_mode = max(pgmpy_modes, key=pgmpy_modes.__getitem__)
    row["modes"] = {
        "bayesprog": "tables where small, else contraction" if tables else "contraction",
        "pgmpy": f"VariableElimination, {pgmpy_mode} (the faster of: {', '.join(pgmpy_modes)})",
        "pyagrum": "LazyPropagation, target declared, evidence changed in place (chgEvidence)",
    }
    row["single_qps"] = {
        "bayesprog": len(singles) / median_time(lambda: loop_ours(singles), repeats),
        "pgmpy": pgmpy_modes[pgmpy_mode],
        "pyagrum": len(singles) / median_time(lambda: loop_agrum(singles), repeats),
    }
    # batches: one call for bayesprog; pgmpy and pyAgrum loop (rates from the single loops)
    row["batch_qps"] = {}
    for n in BATCHES:
        batch = {v: samples[v][:n] for v in observed}
        program.ask(question, batch)
        row["batch_qps"][str(n)] = {
            "bayesprog": n / median_time(lambda b=batch: program.ask(question, b), repeats),
            "pgmpy": row["single_qps"]["pgmpy"],
            "pyagrum": row["single_qps"]["pyagrum"],
        }
    row["ratios"] = {
        "cold_time_over_pyagrum": row["cold_ms"]["bayesprog"] / row["cold_ms"]["pyagrum"],
        "cold_time_over_pgmpy": row["cold_ms"]["bayesprog"] / row["cold_ms"]["pgmpy"],
        "cold_built_time_over_pyagrum": row["cold_built_ms"]["bayesprog"]
        / row["cold_built_ms"]["pyagrum"],
        "single_rate_over_pyagrum": row["single_qps"]["bayesprog"] / row["single_qps"]["pyagrum"],
        "single_rate_over_pgmpy": row["single_qps"]["bayesprog"] / row["single_qps"]["pgmpy"],
        **{f"batch_{n}_rate_over_pyagrum": row["batch_qps"][str(n)]["bayesprog"]
           / row["batch_qps"][str(n)]["pyagrum"] for n in BATCHES},
    }
    batch = {v: samples[v][: max(BATCHES)] for v in observed}
    tracemalloc.start()
    program.ask(question, batch)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    row["batch_peak_mib"] = peak / 2**20
    return row


#: questions per network and per relation of the target to its evidence (none, part or all
#: of it d-separated from the target)
QUESTIONS = 4
RELATIONS = ("none", "part", "all")


def relation(graph, target: str, observed: list[str]) -> str:
    """How many of the observed variables are d-separated from the target given the others
    (networkx's d-separation, independent of bayesprog's Bayes-ball)."""
    separated = sum(nx_d_separated(graph, target, v, [o for o in observed if o != v])
                    for v in observed)
    return "none" if not separated else "all" if separated == len(observed) else "part"


def nx_d_separated(graph, a: str, b: str, given: list[str]) -> bool:
    import networkx as nx

    return nx.is_d_separator(graph, {a}, {b}, set(given))


def bench_questions(name: str, repeats: int, tmp: Path, per: int = QUESTIONS) -> dict:
    """Warm single queries on questions drawn for the network (a seeded target and 1, 2 or 4
    observed variables, ``per`` of each relation of the target to its evidence where the
    network has them), 100 evidence sets each by forward sampling: bayesprog by default and
    with ``method="contraction"`` named, pyAgrum's LazyPropagation with the target declared
    and the evidence changed in place; every answer compared with pyAgrum's."""
    import networkx as nx

    table_method.TABLE_LIMIT = TABLE_LIMIT
    model, path, _, _, _ = load_network(name, tmp)
    bn = agrum_net(model)
    graph = nx.DiGraph(list(model.edges()))
    graph.add_nodes_from(model.nodes())
    names = sorted(model.nodes())
    cpds = {c.variable: c for c in model.get_cpds()}
    rng = np.random.default_rng(sum(map(ord, name)) + 1)
    samples = forward_sample(model, 100, rng)
    chosen: dict[str, list[tuple[str, list[str]]]] = {r: [] for r in RELATIONS}
    for _ in range(2000):  # draws until each relation has ``per`` questions (or none is left)
        if all(len(found) >= per for found in chosen.values()):
            break
        k = int(rng.choice([1, 2, 4]))
        picked = rng.choice(len(names), size=k + 1, replace=False)
        target, observed = names[picked[0]], [names[i] for i in picked[1:]]
        found = chosen[relation(graph, target, observed)]
        if len(found) < per and all({target, *observed} != {t, *o} for t, o in found):
            found.append((target, observed))
    rows = []
    for kind, questions in chosen.items():
        for target, observed in questions:
            sets = [{v: str(cpds[v].state_names[v][int(samples[v][i])]) for v in observed}
                    for i in range(100)]
            question = f"P({target} | {', '.join(observed)})"
            lazy = gum.LazyPropagation(bn)
            lazy.addTarget(target)
            for v, value in sets[0].items():
                lazy.addEvidence(v, value)

            def agrum(sets=sets, lazy=lazy, target=target):
                for e in sets:
                    for v, value in e.items():
                        lazy.chgEvidence(v, value)
                    lazy.makeInference()
                    lazy.posterior(target)

            row = {"network": name, "question": question, "relation": kind,
                   "us_per_query": {"pyagrum": 1e6 * call_time(agrum, repeats) / len(sets)}}
            difference = 0.0
            for mode, method in (("bayesprog", None), ("bayesprog contraction", "contraction")):
                program = bayesprog.load(path)

                def ours(sets=sets, program=program, question=question, method=method):
                    for e in sets:
                        program.ask(question, e, method=method)

                row["us_per_query"][mode] = 1e6 * call_time(ours, repeats) / len(sets)
                for e in sets[:20]:
                    answer = program.ask(question, e, method=method)
                    for v, value in e.items():
                        lazy.chgEvidence(v, value)
                    lazy.makeInference()
                    post = lazy.posterior(target)
                    labels = [post.variable(0).label(i)
                              for i in range(post.variable(0).domainSize())]
                    theirs = [post[labels.index(s)] for s in answer.states[target]]
                    difference = max(difference,
                                      float(np.abs(answer.probabilities - theirs).max()))
                row[f"method {mode}"] = answer.method
            times = row["us_per_query"]
            row["ratios"] = {"rate_over_pyagrum": times["pyagrum"] / times["bayesprog"],
                             "contraction_rate_over_pyagrum": times["pyagrum"]
                             / times["bayesprog contraction"]}
            row["max_difference_pyagrum"] = difference
            rows.append(row)
    return {"network": name, "questions": rows,
            "least_rate_over_pyagrum": min(r["ratios"]["rate_over_pyagrum"] for r in rows),
            "least_contraction_rate_over_pyagrum": min(
                r["ratios"]["contraction_rate_over_pyagrum"] for r in rows),
            "max_difference_pyagrum": max(r["max_difference_pyagrum"] for r in rows)}


def questions_table(found: list[dict]) -> str:
    head = (f"{'network':<12} {'questions':>9}  {'none/part/all':>13}  "
            f"{'least x agrum':>13} {'(contraction)':>13}  {'ours us/q':>18}  "
            f"{'agrum us/q':>18}  {'max |diff|':>10}")
    lines = [head, "-" * len(head)]
    for net in found:
        rows = net["questions"]
        kinds = "/".join(str(sum(r["relation"] == k for r in rows)) for k in RELATIONS)
        ours = [r["us_per_query"]["bayesprog"] for r in rows]
        theirs = [r["us_per_query"]["pyagrum"] for r in rows]
        lines.append(
            f"{net['network']:<12} {len(rows):>9}  {kinds:>13}  "
            f"{net['least_rate_over_pyagrum']:>13.2f} "
            f"{net['least_contraction_rate_over_pyagrum']:>13.2f}  "
            f"{min(ours):>8.1f} - {max(ours):>7.1f}  {min(theirs):>8.1f} - {max(theirs):>7.1f}  "
            f"{net['max_difference_pyagrum']:>10.1e}")
    lines.append("Warm single queries on drawn questions (1, 2 or 4 observed variables; none, "
                 "part or all of them d-separated from the target), 100 evidence sets each; "
                 "least x agrum: the smallest ratio of our rate to pyAgrum's over the "
                 "network's questions, by default and with the contraction named.")
    return "\n".join(lines)


def table(rows: list[dict]) -> str:
    head = (f"{'network':<24} {'nodes':>5}  {'cold ms (ours/pgmpy/agrum)':>28} "
            f"{'x agrum':>8} {'built x':>8}  "
            f"{'warm q/s ours':>13} {'x pgmpy':>8} {'x agrum':>8}  "
            + "  ".join(f"{'batch ' + str(n) + ' q/s':>16} {'x agrum':>8}" for n in BATCHES)
            + f"  {'peak MiB':>8}")
    lines = [head, "-" * len(head)]
    for r in rows:
        c, s = r["cold_ms"], r["single_qps"]
        line = (f"{r['network']:<24} {r['nodes']:>5}  "
                f"{c['bayesprog']:>8.2f} /{c['pgmpy']:>8.2f} /{c['pyagrum']:>8.2f} "
                f"{r['ratios']['cold_time_over_pyagrum']:>8.2f} "
                f"{r['ratios']['cold_built_time_over_pyagrum']:>8.2f}  "
                f"{s['bayesprog']:>13.0f} {s['bayesprog'] / s['pgmpy']:>8.1f} "
                f"{s['bayesprog'] / s['pyagrum']:>8.2f}  ")
        for n in BATCHES:
            b = r["batch_qps"][str(n)]
            line += f"{b['bayesprog']:>16.0f} {b['bayesprog'] / b['pyagrum']:>8.1f}  "
        line += f"{r['batch_peak_mib']:>8.1f}"
        lines.append(line)
    lines.append("cold: from flushed caches (x agrum: our time over pyAgrum's); built x: the "
                 "same ratio right after building each model, caches as that left them.")
    lines.append("pgmpy and pyAgrum answer batches by a loop: their batch rates are their warm "
                 "single-query rates (pgmpy measured on 20 queries, pyAgrum on 200).")
    if rows:
        lines.append("Modes: pyAgrum " + rows[0]["modes"]["pyagrum"] + "; pgmpy "
                     "VariableElimination, the faster per network of its default greedy order "
                     "and a MinFill order chosen once (in the JSON, per row).")
    return "\n".join(lines)


GRIDS = [12, 16, 20]


def grid_network(n: int, tmp: Path) -> tuple[gum.BayesNet, Path]:
    """An n x n grid of binary variables, each with its up and left neighbours as parents
    (random tables, seeded), written as BIF by pyAgrum and imported by bayesprog."""
    gum.initRandom(n)
    bn = gum.BayesNet(f"grid{n}")
    for i in range(n):
        for j in range(n):
            bn.add(gum.LabelizedVariable(f"X{i}_{j}", "", 2))
    for i in range(n):
        for j in range(n):
            if i:
                bn.addArc(f"X{i - 1}_{j}", f"X{i}_{j}")
            if j:
                bn.addArc(f"X{i}_{j - 1}", f"X{i}_{j}")
    bn.generateCPTs()
    bif = tmp / f"grid{n}.bif"
    gum.saveBN(bn, str(bif))
    from bayesprog.io import import_network

    return bn, import_network(str(bif), str(tmp / f"grid{n}.yaml"))


def bench_approximate(n: int, repeats: int, tmp: Path, samples: int = 10_000) -> dict:
    """P(centre | two opposite corners) on an n x n grid: loopy belief propagation (ours and
    pyAgrum's), likelihood weighting (ours, ``samples`` draws) and pyAgrum's importance
    sampling (the same number of draws), and the exact answer where pyAgrum's junction tree
    finds it within the run (12 x 12)."""
    bn, path = grid_network(n, tmp)
    program = bayesprog.load(path)
    target, evidence = f"X{n // 2}_{n // 2}", {"X0_0": 1, f"X{n - 1}_{n - 1}": 0}
    question = f"P({target} | X0_0=1, X{n - 1}_{n - 1}=0)"
    row: dict = {"grid": f"{n} x {n}", "variables": n * n, "samples": samples}

    def agrum(engine_class, setup=lambda e: None):
        engine = engine_class(bn)
        engine.setEvidence(evidence)
        setup(engine)
        engine.makeInference()
        return engine.posterior(target).toarray()

    ours_lbp = program.ask(question, method="lbp").probabilities
    theirs_lbp = agrum(gum.LoopyBeliefPropagation)
    row["lbp_seconds"] = {
        "bayesprog": median_time(lambda: program.ask(question, method="lbp"), repeats),
        "pyagrum": median_time(lambda: agrum(gum.LoopyBeliefPropagation), repeats)}
    row["lbp_max_difference"] = float(np.abs(ours_lbp - theirs_lbp).max())
    lw = program.ask(question, method="lw", samples=samples, rng=0)
    row["lw"] = {"p": float(lw.probabilities[0]), "stderr": float(lw.stderr[0]),
                 "ess": float(lw.ess)}

    def sampled():
        def fixed(engine):
            engine.setMaxIter(samples)
            engine.setEpsilon(1e-12)
            engine.setMinEpsilonRate(1e-12)
            engine.setMaxTime(60)
        return agrum(gum.ImportanceSampling, fixed)

    row["lw_seconds"] = {
        "bayesprog": median_time(lambda: program.ask(question, method="lw", samples=samples,
                                                     rng=0), repeats),
        "pyagrum_importance_sampling": median_time(sampled, 1)}
    row["pyagrum_importance_sampling_p"] = float(sampled()[0])
    if n <= 12:
        exact = agrum(gum.LazyPropagation, lambda e: e.addTarget(target))
        row["exact_p"] = float(exact[0])
        row["lw_error_in_stderr"] = abs(row["lw"]["p"] - row["exact_p"]) / row["lw"]["stderr"]
        row["lbp_error"] = float(abs(ours_lbp[0] - exact[0]))
    return row


def approximate_table(rows: list[dict]) -> str:
    head = (f"{'grid':<8} {'lbp s ours':>10} {'lbp s agrum':>11} {'max diff':>9}  "
            f"{'lw s ours':>9} {'IS s agrum':>10}  {'lw p +- se':>18} {'agrum IS p':>10} "
            f"{'exact p':>8}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lw = r["lw"]
        exact = f"{r['exact_p']:.4f}" if "exact_p" in r else "-"
        lines.append(f"{r['grid']:<8} {r['lbp_seconds']['bayesprog']:>10.3f} "
                     f"{r['lbp_seconds']['pyagrum']:>11.3f} {r['lbp_max_difference']:>9.1e}  "
                     f"{r['lw_seconds']['bayesprog']:>9.3f} "
                     f"{r['lw_seconds']['pyagrum_importance_sampling']:>10.3f}  "
                     f"{lw['p']:>9.4f} +- {lw['stderr']:.4f} "
                     f"{r['pyagrum_importance_sampling_p']:>10.4f} {exact:>8}")
    lines.append(f"P(centre | two corners), {rows[0]['samples'] if rows else 0} draws for "
                 "likelihood weighting and for pyAgrum's importance sampling.")
    return "\n".join(lines)


def _network_question(name: str, tmp: Path) -> tuple[Path, str, dict]:
    """The benchmark's question on network ``name`` and one evidence set (the first forward
    sample: evidence of probability above zero)."""
    model, path, target, observed, rng = load_network(name, tmp)
    cpds = {c.variable: c for c in model.get_cpds()}
    sample = forward_sample(model, 1, rng)
    evidence = {v: str(cpds[v].state_names[v][int(sample[v][0])]) for v in observed}
    return path, f"P({target} | {', '.join(observed)})", evidence


def cost_model(networks: list[str], grids: list[int], repeats: int, tmp: Path) -> dict:
    """The cost model's estimates beside measured times: for each network and grid, the
    contraction of one question (warm) and the compilation of its table, in operations
    (``Cost.operations + fixed``, ``Cost.setup``) and seconds. One rate (operations per second,
    the median over every measurement) turns estimates into predicted seconds; the ratio of
    measured to predicted says how far the model is from the clock. Also the first query of
    each grid (the method the cost model chose, and its seconds)."""
    from bayesprog.inference.binding import bind
    from bayesprog.inference.cost import ranked
    from bayesprog.inference.methods import registered_methods
    from bayesprog.inference.plan import QuestionPlan

    cases = [(name, *_network_question(name, tmp)) for name in networks]
    for n in grids:
        _, path = grid_network(n, tmp)
        cases.append((f"grid {n} x {n}", path, f"P(X{n // 2}_{n // 2} | X0_0, X{n - 1}_{n - 1})",
                      {"X0_0": 1, f"X{n - 1}_{n - 1}": 0}))
    points, first = [], {}
    for name, path, question, evidence in cases:
        program = bayesprog.load(path)
        if name.startswith("grid"):
            start = time.perf_counter()
            answer = program.ask(question, evidence)
            first[name] = {"seconds": time.perf_counter() - start, "method": answer.method}
        plan = QuestionPlan(program, program.question(question),
                            bind(program, program.question(question), evidence, None, None), {})
        costs = {method.name: cost for method, cost in ranked(plan)}
        program.ask(question, evidence, method="contraction")
        seconds = call_time(lambda p=program, q=question, e=evidence:
                            p.ask(q, e, method="contraction"), repeats)
        c = costs["contraction"]
        points.append({"case": name, "what": "contraction", "operations": c.operations + c.fixed,
                       "seconds": seconds})
        if "table" in costs:
            def compile_table(p=path, q=question, e=evidence):
                fresh = bayesprog.load(p)
                plan = QuestionPlan(fresh, fresh.question(q),
                                    bind(fresh, fresh.question(q), e, None, None), {})
                # the methods ranked first, as a first question does: the estimate has found
                # the compilation's contraction path, which the compilation then reuses
                ranked(plan)
                start = time.perf_counter()
                table_method._compile(plan)
                return time.perf_counter() - start
            points.append({"case": name, "what": "table compilation",
                           "operations": costs["table"].setup,
                           "seconds": statistics.median(compile_table() for _ in range(repeats))})
        if name.startswith("grid"):  # the approximate methods, where they would be asked
            for method in ("lbp", "lw"):
                estimate = registered_methods()[method].estimate(plan)
                seconds = median_time(lambda p=program, q=question, e=evidence, m=method:
                                      p.ask(q, e, method=m, rng=0), repeats)
                points.append({"case": name, "what": method,
                               "operations": estimate.operations + estimate.fixed,
                               "seconds": seconds})
    rate = statistics.median(p["operations"] / p["seconds"] for p in points)
    for p in points:
        p["measured_over_predicted"] = p["seconds"] / (p["operations"] / rate)
    worst = max(max(p["measured_over_predicted"], 1 / p["measured_over_predicted"])
                for p in points)
    return {"operations_per_second": rate, "points": points, "worst_factor": worst,
            "first_query": first}


def cost_model_table(result: dict) -> str:
    lines = [f"{'case':<16} {'estimate':<18} {'operations':>11} {'seconds':>9} "
             f"{'measured / predicted':>21}"]
    lines.append("-" * len(lines[0]))
    for p in result["points"]:
        lines.append(f"{p['case']:<16} {p['what']:<18} {p['operations']:>11.3g} "
                     f"{p['seconds']:>9.5f} {p['measured_over_predicted']:>21.2f}")
    lines.append(f"one rate for every estimate: {result['operations_per_second']:.3g} operations "
                 f"per second; the estimates are within {result['worst_factor']:.1f}x of the "
                 "clock")
    for name, f in result["first_query"].items():
        lines.append(f"{name}: first query {f['seconds']:.3f} s ({f['method']}, chosen by the "
                     "cost model)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", nargs="+", default=NETWORKS)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default="results/benchmarks/engine.json")
    parser.add_argument("--questions", type=int, default=QUESTIONS,
                        help="drawn questions per network and relation of the target to its "
                        f"evidence (default: {QUESTIONS})")
    parser.add_argument("--grids", nargs="*", type=int, default=GRIDS,
                        help="sizes of the grid networks for the approximate methods "
                        "(none: skip them)")
    args = parser.parse_args(argv)
    # a peer that asks for more memory than the machine has fails with MemoryError instead of
    # taking the machine down
    import os
    import resource

    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    resource.setrlimit(resource.RLIMIT_AS, (int(0.8 * total), resource.RLIM_INFINITY))
    rows, approximate = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for tables in (True, False):
            for name in args.networks:
                rows.append(bench_network(name, args.repeats, Path(tmp), tables))
                print(f"measured {rows[-1]['network']}", file=sys.stderr)
        asked = []
        for name in args.networks:
            asked.append(bench_questions(name, args.repeats, Path(tmp), args.questions))
            print(f"measured the questions of {name}", file=sys.stderr)
        for n in args.grids:
            approximate.append(bench_approximate(n, min(args.repeats, 3), Path(tmp)))
            print(f"measured the {n} x {n} grid", file=sys.stderr)
        table_method.TABLE_LIMIT = TABLE_LIMIT
        model = cost_model(args.networks, [n for n in args.grids if n <= 16] or [12, 16],
                           max(args.repeats, 7), Path(tmp))
        print("measured the cost model", file=sys.stderr)
    print(table(rows))
    print()
    print(questions_table(asked))
    if approximate:
        print()
        print(approximate_table(approximate))
    print()
    print(cost_model_table(model))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"repeats": args.repeats, "rows": rows, "questions": asked,
                               "approximate": approximate, "cost_model": model}, indent=2))
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
