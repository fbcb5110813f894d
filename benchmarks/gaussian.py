"""Linear-Gaussian networks against pgmpy's LinearGaussianBayesianNetwork (not a test).

bnlearn's Gaussian networks as pgmpy ships them (ecoli70, magic-niab, magic-irri, arth150,
JSON) are imported as programs (``bayesprog import``) and loaded by pgmpy
(``LinearGaussianBayesianNetwork.load``). Each network is asked a few drawn questions
P(target | 4 observed variables) (seeded), with evidence sets drawn from the network's joint
Gaussian, in one run against pgmpy's fastest documented conditional query,
``predict_probability`` (a DataFrame of the observed values in, the conditional means and
covariance of every unobserved variable out; ``predict`` wraps it in one more DataFrame;
pgmpy 1.1 has no inference engine for this model: VariableElimination refuses it). Its
DataFrames are built before the clock starts; ours are dictionaries of floats or arrays.

* first question: right after loading the model (ours from the YAML file, pgmpy's from the
  JSON file; not timed), from flushed CPU caches, ``2 * repeats + 1`` times; the load times are
  given beside it, and the ratio of load and first question together;
* warm single: one evidence set per call, the set changed at every call;
* batch: 1,000 evidence sets in one call (pgmpy's ``predict_probability`` takes a DataFrame of
  rows too);
* accuracy: the largest difference of each library's conditional means and standard deviations
  from the joint Gaussian computed here from the JSON alone (``Sigma = (I - B)^-1 D
  (I - B)^-T``, then Gaussian conditioning); pgmpy rounds its joint to 8 decimals.

Every figure is the median of several repeats (loops of at least a few milliseconds for a warm
call); ratios are pgmpy's time over ours (above 1: we are faster). The JSON written to
``--out`` holds every figure and ratio.

    python benchmarks/gaussian.py [--networks ecoli70 arth150] [--repeats 5] [--questions 3]
        [--out results/benchmarks/gaussian.json]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import bayesprog
from bayesprog.io.gaussian import formula_names, import_gaussian

EXAMPLES = Path(importlib.util.find_spec("pgmpy").origin).parent / "utils" / "example_models"
NETWORKS = ["ecoli70", "magic-niab", "magic-irri", "arth150"]
OBSERVED = 4
BATCH = 1_000
#: evidence sets a warm loop cycles through
SETS = 50
#: written over before a cold query: larger than the machine's last-level cache
_SWEEP = np.zeros(2**23)  # 64 MiB


def flush_caches() -> None:
    """Evict what the CPU caches hold (by writing 64 MiB), so that a first question starts
    from the same state whichever library asks it."""
    np.add(_SWEEP, 1.0, out=_SWEEP)


def per_call(calls: list[Callable[[], Any]], repeats: int, least: float = 5e-3) -> float:
    """Seconds per call: the median of ``repeats`` loops over ``calls`` (cycled, each loop
    at least ``least`` seconds and at least one call)."""
    calls[0]()
    times = []
    for _ in range(repeats):
        done, start = 0, time.perf_counter()
        while True:
            calls[done % len(calls)]()
            done += 1
            elapsed = time.perf_counter() - start
            if elapsed >= least:
                break
        times.append(elapsed / done)
    return statistics.median(times)


def joint_gaussian(data: dict) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Nodes, mean and covariance of the network's linear structural equations."""
    nodes = list(data["nodes"])
    at = {v: i for i, v in enumerate(nodes)}
    n = len(nodes)
    weights, intercept, noise = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    for v, cpd in data["cpds"].items():
        intercept[at[v]] = cpd["coefficients"]["(Intercept)"][0]
        noise[at[v]] = cpd["variance"][0]
        for p in cpd["parents"]:
            weights[at[v], at[p]] = cpd["coefficients"][p][0]
    solve = np.linalg.solve(np.eye(n) - weights, np.eye(n))
    return nodes, solve @ intercept, solve @ np.diag(noise) @ solve.T


def conditioned(mean: np.ndarray, cov: np.ndarray, target: int, observed: list[int],
                values: np.ndarray) -> tuple[np.ndarray, float]:
    """The target's conditional means (one per row of ``values``) and standard deviation."""
    s_oo = cov[np.ix_(observed, observed)]
    gain = np.linalg.solve(s_oo, cov[observed, target])
    means = mean[target] + (values - mean[observed]) @ gain
    return means, float(np.sqrt(cov[target, target] - cov[target, observed] @ gain))


def bench_network(name: str, repeats: int, questions: int, tmp: Path) -> dict[str, Any]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from pgmpy.models import LinearGaussianBayesianNetwork

    source = EXAMPLES / f"{name}.json"
    data = json.loads(source.read_text())
    names = formula_names(data["nodes"])
    program_file = tmp / f"{name}.yaml"
    start = time.perf_counter()
    import_gaussian(source, program_file)
    import_seconds = time.perf_counter() - start

    def load_ours() -> Any:
        return bayesprog.load(program_file)

    def load_pgmpy() -> Any:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return LinearGaussianBayesianNetwork.load(str(source))

    load = {"ours": statistics.median(_timed(load_ours)[0] for _ in range(repeats)),
            "pgmpy": statistics.median(_timed(load_pgmpy)[0] for _ in range(repeats))}
    nodes, mean, cov = joint_gaussian(data)
    rng = np.random.default_rng(sum(map(ord, name)))
    program, model = load_ours(), load_pgmpy()
    rows = []
    for _ in range(questions):
        picked = rng.choice(len(nodes), OBSERVED + 1, replace=False)
        target, observed = int(picked[0]), [int(i) for i in picked[1:]]
        values = rng.multivariate_normal(mean, cov, size=max(SETS, BATCH))[:, observed]
        rows.append(bench_question(
            program, model, load_ours, load_pgmpy, load, repeats,
            [names[v] for v in nodes], nodes, mean, cov, target, observed, values))
    return {"network": name, "nodes": len(nodes), "arcs": len(data["arcs"]),
            "import_seconds": import_seconds, "load_seconds": load, "questions": rows}


def bench_question(program: Any, model: Any, load_ours: Callable[[], Any],
                   load_pgmpy: Callable[[], Any], load: dict[str, float], repeats: int,
                   ours: list[str], nodes: list[str], mean: np.ndarray, cov: np.ndarray,
                   target: int, observed: list[int], values: np.ndarray) -> dict[str, Any]:
    """One question P(target | observed) asked by both libraries (``ours``: our names of
    ``nodes``); ``values``: the observed variables' drawn values, one evidence set a row."""
    import pandas as pd

    question = f"P({ours[target]} | {', '.join(ours[i] for i in observed)})"
    ours_sets = [{ours[i]: float(v) for i, v in zip(observed, row, strict=True)}
                 for row in values[:SETS]]
    frames = [pd.DataFrame([dict(zip([nodes[i] for i in observed], row, strict=True))])
              for row in values[:SETS]]
    batch_ours = {ours[i]: values[:BATCH, k] for k, i in enumerate(observed)}
    batch_frame = pd.DataFrame(values[:BATCH], columns=[nodes[i] for i in observed])

    first_ours, first_pgmpy = [], []
    for _ in range(2 * repeats + 1):  # (a few milliseconds each: more repeats)
        fresh = load_ours()
        flush_caches()
        first_ours.append(_timed(lambda f=fresh: f.ask(question, ours_sets[0]))[0])
        fresh_model = load_pgmpy()
        flush_caches()
        first_pgmpy.append(_timed(lambda m=fresh_model: m.predict_probability(frames[0]))[0])
    warm_ours = per_call([lambda e=e: program.ask(question, e) for e in ours_sets], repeats)
    warm_pgmpy = per_call([lambda f=f: model.predict_probability(f) for f in frames], repeats)
    batch_time_ours = per_call([lambda: program.ask(question, batch_ours)], repeats)
    batch_time_pgmpy = per_call([lambda: model.predict_probability(batch_frame)], repeats)
    # accuracy, on the batch
    want_means, want_sd = conditioned(mean, cov, target, observed, values[:BATCH])
    answer = program.ask(question, batch_ours)
    ours_error = max(float(np.abs(answer.mean(ours[target]) - want_means).max()),
                     float(np.abs(answer.sd(ours[target]) - want_sd).max()))
    missing, pg_means, pg_cov = model.predict_probability(batch_frame)
    k = missing.index(nodes[target])
    pgmpy_error = max(float(np.abs(pg_means[:, k] - want_means).max()),
                      abs(float(np.sqrt(pg_cov[k, k])) - want_sd))
    first = {"ours": statistics.median(first_ours), "pgmpy": statistics.median(first_pgmpy)}
    return {
        "question": question, "method": answer.method,
        "first_seconds": first, "first_ratio": first["pgmpy"] / first["ours"],
        "load_and_first_ratio": (load["pgmpy"] + first["pgmpy"]) / (load["ours"] + first["ours"]),
        "warm_seconds": {"ours": warm_ours, "pgmpy": warm_pgmpy},
        "warm_ratio": warm_pgmpy / warm_ours,
        "batch_seconds": {"ours": batch_time_ours, "pgmpy": batch_time_pgmpy},
        "batch_ratio": batch_time_pgmpy / batch_time_ours,
        "max_error": {"ours": ours_error, "pgmpy": pgmpy_error},
    }


def _timed(fn: Callable[[], Any]) -> tuple[float, Any]:
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


def table(results: list[dict[str, Any]]) -> str:
    head = (f"{'network':<11} {'load ms ours/pgmpy':>19} {'first ms ours/pgmpy':>20} "
            f"{'x first':>8} {'x load+first':>13} {'warm us ours/pgmpy':>20} {'x warm':>8} "
            f"{'x batch':>8} {'max error ours/pgmpy':>21}")
    lines = [head, "-" * len(head)]
    for r in results:
        load = r["load_seconds"]
        for q in r["questions"]:
            first, warm = q["first_seconds"], q["warm_seconds"]
            lines.append(
                f"{r['network']:<11} {load['ours'] * 1e3:>9.1f}/{load['pgmpy'] * 1e3:<9.1f} "
                f"{first['ours'] * 1e3:>9.2f}/{first['pgmpy'] * 1e3:<10.2f} "
                f"{q['first_ratio']:>8.2f} {q['load_and_first_ratio']:>13.2f} "
                f"{warm['ours'] * 1e6:>9.0f}/{warm['pgmpy'] * 1e6:<10.0f} "
                f"{q['warm_ratio']:>8.1f} {q['batch_ratio']:>8.1f} "
                f"{q['max_error']['ours']:>10.1e}/{q['max_error']['pgmpy']:<10.1e}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", nargs="+", default=NETWORKS, choices=NETWORKS)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--questions", type=int, default=3,
                        help="drawn questions per network (default: 3)")
    parser.add_argument("--out", default="results/benchmarks/gaussian.json")
    args = parser.parse_args(argv)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        # the libraries imported and their code run once before anything is timed
        bench_network("ecoli70", 1, 1, Path(tmp))
        for name in args.networks:
            results.append(bench_network(name, args.repeats, args.questions, Path(tmp)))
            print(f"measured {name}", file=sys.stderr)
    print(table(results))
    ratios = {key: [q[key] for r in results for q in r["questions"]]
              for key in ("first_ratio", "load_and_first_ratio", "warm_ratio", "batch_ratio")}
    summary = {key: {"least": min(v), "median": statistics.median(v)}
               for key, v in ratios.items()}
    summary["max_error_ours"] = max(q["max_error"]["ours"] for r in results
                                    for q in r["questions"])
    print(f"least ratios (pgmpy's time over ours): first {summary['first_ratio']['least']:.2f}, "
          f"load and first {summary['load_and_first_ratio']['least']:.2f}, warm "
          f"{summary['warm_ratio']['least']:.1f}, batch {summary['batch_ratio']['least']:.1f}; "
          f"our largest error from the joint Gaussian {summary['max_error_ours']:.1e}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"repeats": args.repeats, "observed": OBSERVED, "batch": BATCH,
                               "networks": results, "summary": summary}, indent=2))
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
