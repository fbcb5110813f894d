"""Structure learning against pyAgrum and pgmpy (not a test): on rows sampled from bnlearn
networks (asia 8 variables, 10,000 rows; child 20, insurance 27, alarm 37, 20,000 rows; pgmpy's
``forward_sample``, seeded), hill climbing on BIC:

* ours: ``bayesprog.discover(frame, method="hc", score="bic")``, the whole of it (the data
  coded, the search with its default restarts, the tables fitted, the program written and
  loaded), and its search alone (the data coded, :class:`Scores`, :func:`hill_climb`);
* pyAgrum: ``gum.BNLearner(frame)`` with ``useGreedyHillClimbing()``, ``useScoreBIC()`` and
  ``useSmoothingPrior(1e-6)`` (a negligible prior for the parent configurations the data never
  show), then ``learnBN()``, from the same DataFrame; with its default threads and with one;
* pgmpy: ``HillClimbSearch(frame).estimate(scoring_method=BIC(frame))``.

Each repeat runs them all in turn (the order rotated from repeat to repeat), after one run of
each that is not timed (imports, numba's compiled kernels loaded); the first call of ours in
the process (the first network's) is reported apart. Reported per network: the median of each time, the medians of
the paired ratios (theirs / ours, each within one repeat), and the BIC of each search's DAG as
pgmpy's ``BIC`` scores it (and as our scorer does: the two agree). With ``--fresh N``, also
the first search of a fresh process, N processes each, interleaved: ours (``import
bayesprog``, pandas and the data read before the clock; the compiled kernels loaded within it)
against pyAgrum's one-thread learner (``import pyagrum`` before the clock). With ``--pc``,
also the PC skeleton against pgmpy's ``build_skeleton`` (chi-square at 0.01, conditioning sets
up to 5; pgmpy's takes minutes, run ``--pc-repeats`` times). To ``--out`` as JSON and to
standard output.

    python benchmarks/structure.py [--networks asia child insurance alarm] [--rows N]
        [--repeats 5] [--pgmpy-repeats 3] [--fresh N] [--pc]
        [--out results/benchmarks/structure.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

#: rows sampled from each network when --rows is not given
ROWS = {"asia": 10_000, "child": 20_000, "insurance": 20_000, "alarm": 20_000}
#: no search has run in this process yet
_FIRST = True


def sample(name: str, rows: int, seed: int = 1) -> tuple[Any, Any]:
    from pgmpy.sampling import BayesianModelSampling
    from pgmpy.utils import get_example_model

    model = get_example_model(name)
    frame = BayesianModelSampling(model).forward_sample(size=rows, seed=seed,
                                                        show_progress=False)
    return frame.astype(str), model


def pgmpy_bic(frame: Any, parents: dict[str, list[str]]) -> float:
    """The BIC of a DAG (each variable's parents) as pgmpy's scorer gives it."""
    from pgmpy.estimators import BIC
    from pgmpy.models import DiscreteBayesianNetwork

    model = DiscreteBayesianNetwork()
    model.add_nodes_from(list(frame.columns))
    model.add_edges_from((p, c) for c, ps in parents.items() for p in ps)
    return float(BIC(frame).score(model))


def ours_bic(frame: Any, parents: dict[str, list[str]]) -> float:
    """The BIC of a DAG as our scorer gives it (the sum of its families' scores)."""
    from bayesprog.learning.structure import Scores
    from bayesprog.program.discovery import code_data

    coded = code_data(frame)
    scores = Scores(coded.codes, coded.card, "bic")
    index = {n: i for i, n in enumerate(coded.names)}
    return float(sum(scores.local(index[c], tuple(sorted(index[p] for p in ps)))
                     for c, ps in parents.items()))


FRESH_OURS = """
import pickle, sys, time
import pandas
import bayesprog
frame = pickle.load(open(sys.argv[1], "rb"))
clock = time.perf_counter()
bayesprog.discover(frame, method="hc", score="bic")
print(time.perf_counter() - clock)
"""

FRESH_PYAGRUM = """
import pickle, sys, time
import pandas
import pyagrum as gum
frame = pickle.load(open(sys.argv[1], "rb"))
clock = time.perf_counter()
learner = gum.BNLearner(frame)
learner.setNumberOfThreads(1)
learner.useGreedyHillClimbing()
learner.useScoreBIC()
learner.useSmoothingPrior(1e-6)
learner.learnBN()
print(time.perf_counter() - clock)
"""


def bench_fresh(frame: Any, processes: int) -> dict[str, Any]:
    """The first search of a fresh process, ours against pyAgrum's on one thread, in turn."""
    import pickle

    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "frame.pickle"
        data.write_bytes(pickle.dumps(frame))
        times: dict[str, list[float]] = {"ours": [], "pyagrum_1_thread": []}
        for _ in range(processes):
            for name, code in (("ours", FRESH_OURS), ("pyagrum_1_thread", FRESH_PYAGRUM)):
                out = subprocess.run([sys.executable, "-c", code, str(data)], check=True,
                                     capture_output=True, text=True).stdout
                times[name].append(float(out.split()[-1]))
    paired = [t / o for t, o in zip(times["pyagrum_1_thread"], times["ours"], strict=True)]
    return {"ours_s": float(np.median(times["ours"])),
            "pyagrum_1_thread_s": float(np.median(times["pyagrum_1_thread"])),
            "pyagrum_1_thread_over_ours": float(np.median(paired)), "times": times}


def ours(frame: Any) -> dict[str, list[str]]:
    import bayesprog

    return bayesprog.discover(frame, method="hc", score="bic").parents


def ours_search(frame: Any) -> dict[str, list[str]]:
    from bayesprog.learning.structure import Constraints, Scores, hill_climb
    from bayesprog.program.discovery import code_data

    coded = code_data(frame)
    climb = hill_climb(Scores(coded.codes, coded.card, "bic"), Constraints(len(coded.names)))
    return {coded.names[v]: [coded.names[p] for p in ps] for v, ps in enumerate(climb.parents)}


def pyagrum(frame: Any, threads: int | None = None) -> dict[str, list[str]]:
    import pyagrum as gum

    learner = gum.BNLearner(frame)
    if threads is not None:
        learner.setNumberOfThreads(threads)
    learner.useGreedyHillClimbing()
    learner.useScoreBIC()
    learner.useSmoothingPrior(1e-6)
    bn = learner.learnBN()
    return {bn.variable(i).name(): [bn.variable(p).name() for p in bn.parents(i)]
            for i in bn.nodes()}


def pgmpy_hc(frame: Any) -> dict[str, list[str]]:
    from pgmpy.estimators import BIC, HillClimbSearch

    dag = HillClimbSearch(frame).estimate(scoring_method=BIC(frame), show_progress=False)
    return {v: list(dag.predecessors(v)) for v in frame.columns}


def bench_hc(frame: Any, repeats: int, pgmpy_repeats: int) -> dict[str, Any]:
    global _FIRST
    searches: dict[str, Callable[[Any], dict[str, list[str]]]] = {
        "ours": ours, "ours_search": ours_search, "pyagrum": pyagrum,
        "pyagrum_1_thread": lambda f: pyagrum(f, threads=1), "pgmpy": pgmpy_hc}
    start = time.perf_counter()
    found = {"ours": ours(frame)}
    first_call = time.perf_counter() - start
    for name, search in searches.items():  # once, untimed
        if name != "ours" and name != "pgmpy":
            found[name] = search(frame)
    times: dict[str, list[float]] = {name: [] for name in searches}
    names = list(searches)
    for r in range(repeats):
        for name in names[r % len(names):] + names[:r % len(names)]:
            if name == "pgmpy" and len(times["pgmpy"]) >= pgmpy_repeats:
                continue
            clock = time.perf_counter()
            found[name] = searches[name](frame)
            times[name].append(time.perf_counter() - clock)
    out: dict[str, Any] = {}
    if _FIRST:  # numba imported and its kernels loaded from the cache by this call
        out["ours_first_call_s"] = first_call
        _FIRST = False
    for name in names:
        out[f"{name}_s"] = float(np.median(times[name]))
    for name in ("pyagrum", "pyagrum_1_thread", "pgmpy"):
        paired = [t / o for t, o in zip(times[name], times["ours"], strict=False)]
        out[f"{name}_over_ours"] = float(np.median(paired))
        paired = [t / o for t, o in zip(times[name], times["ours_search"], strict=False)]
        out[f"{name}_over_ours_search"] = float(np.median(paired))
    for name in ("ours", "pyagrum", "pgmpy"):
        out[f"{name}_bic"] = pgmpy_bic(frame, found[name])
        out[f"{name}_bic_by_our_scorer"] = ours_bic(frame, found[name])
        out[f"{name}_arcs"] = sum(len(ps) for ps in found[name].values())
    out["ours_bic_less_pyagrum"] = out["ours_bic"] - out["pyagrum_bic"]
    out["ours_bic_less_pgmpy"] = out["ours_bic"] - out["pgmpy_bic"]
    return out


def f1(found: set, true: set) -> float:
    return 2 * len(found & true) / (len(found) + len(true)) if found or true else 1.0


def bench_pc(frame: Any, model: Any, repeats: int) -> dict[str, Any]:
    from pgmpy.estimators import PC

    from bayesprog.learning.structure import Constraints, pc_skeleton
    from bayesprog.program.discovery import code_data

    coded = code_data(frame)
    names = coded.names
    rules = Constraints(len(names))

    def timed(function: Callable[[], Any]) -> tuple[float, Any]:
        times, result = [], None
        for _ in range(repeats):
            clock = time.perf_counter()
            result = function()
            times.append(time.perf_counter() - clock)
        return float(np.median(times)), result

    ours_s, skeleton = timed(lambda: pc_skeleton(coded.codes, coded.card, rules, test="chi2",
                                                 significance=0.01))
    theirs_s, (their_skeleton, _) = timed(lambda: PC(frame).build_skeleton(
        ci_test="chi_square", significance_level=0.01, show_progress=False))
    true = {frozenset(e) for e in model.edges()}
    our_edges = {frozenset((names[u], names[v])) for u in range(len(names))
                 for v in skeleton.adjacent[u]}
    their_edges = {frozenset(e) for e in their_skeleton.edges()}
    return {"ours_s": ours_s, "pgmpy_s": theirs_s, "pgmpy_over_ours": theirs_s / ours_s,
            "ours_f1": f1(our_edges, true), "pgmpy_f1": f1(their_edges, true),
            "edges_differing_from_pgmpy": len(our_edges ^ their_edges),
            "tests": skeleton.tests}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--networks", nargs="+", default=list(ROWS))
    parser.add_argument("--rows", type=int, default=None,
                        help="rows sampled from every network (default: asia 10,000, the "
                             "others 20,000)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--pgmpy-repeats", type=int, default=3,
                        help="timed runs of pgmpy's hill climbing (seconds each)")
    parser.add_argument("--fresh", type=int, default=0, metavar="N",
                        help="also the first search of N fresh processes each, ours and "
                             "pyAgrum's on one thread")
    parser.add_argument("--pc", action="store_true", help="also the PC skeleton (minutes)")
    parser.add_argument("--pc-repeats", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("results/benchmarks/structure.json"))
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # pgmpy's deprecation notices
    results = []
    for name in args.networks:
        rows = args.rows or ROWS.get(name, 20_000)
        frame, model = sample(name, rows)
        load = os.getloadavg()[0]
        found: dict[str, Any] = {"network": name, "variables": frame.shape[1], "rows": rows,
                                 "load_average": load,
                                 "hc": bench_hc(frame, args.repeats, args.pgmpy_repeats)}
        if args.fresh:
            found["fresh"] = bench_fresh(frame, args.fresh)
        if args.pc:
            found["pc"] = bench_pc(frame, model, args.pc_repeats)
        results.append(found)
        hc = found["hc"]
        print(f"{name} ({found['variables']} variables, {rows} rows, load {load:.1f}): "
              f"ours {hc['ours_s']:.3f} s (search {hc['ours_search_s']:.3f} s), pyAgrum "
              f"{hc['pyagrum_s']:.3f} s (1 thread {hc['pyagrum_1_thread_s']:.3f} s), pgmpy "
              f"{hc['pgmpy_s']:.2f} s; pyAgrum/ours {hc['pyagrum_over_ours']:.1f}x "
              f"(1 thread {hc['pyagrum_1_thread_over_ours']:.2f}x), "
              f"pgmpy/ours {hc['pgmpy_over_ours']:.1f}x; BIC ours {hc['ours_bic']:.1f}, "
              f"pyAgrum {hc['pyagrum_bic']:.1f}, pgmpy {hc['pgmpy_bic']:.1f}", flush=True)
        if args.fresh:
            fresh = found["fresh"]
            print(f"  first search of a fresh process: ours {fresh['ours_s']:.3f} s, pyAgrum "
                  f"1 thread {fresh['pyagrum_1_thread_s']:.3f} s; pyAgrum/ours "
                  f"{fresh['pyagrum_1_thread_over_ours']:.2f}x", flush=True)
        if args.pc:
            pc = found["pc"]
            print(f"  pc {pc['ours_s']:.2f} s vs pgmpy {pc['pgmpy_s']:.1f} s "
                  f"({pc['pgmpy_over_ours']:.0f}x), F1 {pc['ours_f1']:.3f} vs "
                  f"{pc['pgmpy_f1']:.3f}, {pc['edges_differing_from_pgmpy']} edges differ",
                  flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
