"""Structure learning against pgmpy (not a test): on rows sampled from bnlearn networks of 20 to
40 variables (child 20, insurance 27, alarm 37), hill climbing on BIC (ours with its default
restarts, against pgmpy's HillClimbSearch) and the PC skeleton (ours, the stable PC, against
pgmpy's PC ``build_skeleton``, the chi-square test at 0.01, conditioning sets up to 5), in this
process, each pair timed interleaved.

Reported per network: the medians of the times and their ratio (pgmpy / ours), the BIC of each
search's DAG (scored by the same scorer) and its difference, and for PC the skeleton's F1
against the true network's, and the number of skeleton edges that differ from pgmpy's; to
``--out`` as JSON and to standard output. pgmpy's PC takes minutes on a network: its repeats
are ``--pc-repeats`` (1 by default).

    python benchmarks/structure.py [--networks child insurance alarm] [--rows 20000]
        [--repeats 3] [--pc-repeats 1] [--out results/benchmarks/structure.json]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np


def sample(name: str, rows: int, seed: int = 1):
    from pgmpy.sampling import BayesianModelSampling
    from pgmpy.utils import get_example_model

    model = get_example_model(name)
    frame = BayesianModelSampling(model).forward_sample(size=rows, seed=seed,
                                                        show_progress=False)
    return frame.astype(str), model


def timed(function, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def f1(found: set, true: set) -> float:
    return 2 * len(found & true) / (len(found) + len(true)) if found or true else 1.0


def bench(name: str, rows: int, repeats: int, pc_repeats: int) -> dict:
    from pgmpy.estimators import BIC, PC, HillClimbSearch

    from bayesprog.discovery import code_data
    from bayesprog.learning.structure import Constraints, Scores, hill_climb, pc_skeleton

    frame, model = sample(name, rows)
    coded = code_data(frame)
    names = coded.names
    rules = Constraints(len(names))
    out: dict = {"network": name, "variables": len(names), "rows": rows}

    # hill climbing on BIC: a fresh scorer each time (no score kept from a previous search)
    ours_times, theirs_times = [], []
    ours = theirs = None
    for _ in range(repeats):
        start = time.perf_counter()
        ours = hill_climb(Scores(coded.codes, coded.card, "bic"), rules)
        ours_times.append(time.perf_counter() - start)
        start = time.perf_counter()
        theirs = HillClimbSearch(frame).estimate(scoring_method=BIC(frame), show_progress=False)
        theirs_times.append(time.perf_counter() - start)
    scorer = Scores(coded.codes, coded.card, "bic")
    their_score = scorer.total([[names.index(p) for p in theirs.predecessors(v)] for v in names])
    out["hc"] = {"ours_s": float(np.median(ours_times)),
                 "pgmpy_s": float(np.median(theirs_times)),
                 "speed_ratio": float(np.median(theirs_times) / np.median(ours_times)),
                 "ours_bic": float(ours.score), "pgmpy_bic": float(their_score),
                 "bic_difference": float(ours.score - their_score)}

    # the PC skeleton
    ours_s, skeleton = timed(lambda: pc_skeleton(coded.codes, coded.card, rules,
                                                 test="chi2", significance=0.01), pc_repeats)
    theirs_s, (their_skeleton, _) = timed(lambda: PC(frame).build_skeleton(
        ci_test="chi_square", significance_level=0.01, show_progress=False), pc_repeats)
    true = {frozenset(e) for e in model.edges()}
    our_edges = {frozenset((names[u], names[v])) for u in range(len(names))
                 for v in skeleton.adjacent[u]}
    their_edges = {frozenset(e) for e in their_skeleton.edges()}
    out["pc"] = {"ours_s": ours_s, "pgmpy_s": theirs_s, "speed_ratio": theirs_s / ours_s,
                 "ours_f1": f1(our_edges, true), "pgmpy_f1": f1(their_edges, true),
                 "edges_differing_from_pgmpy": len(our_edges ^ their_edges),
                 "tests": skeleton.tests}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--networks", nargs="+", default=["child", "insurance", "alarm"])
    parser.add_argument("--rows", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--pc-repeats", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("results/benchmarks/structure.json"))
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # pgmpy's deprecation notices of its CI tests
    results = []
    for name in args.networks:
        found = bench(name, args.rows, args.repeats, args.pc_repeats)
        results.append(found)
        hc, pc = found["hc"], found["pc"]
        print(f"{name} ({found['variables']} variables, {found['rows']} rows): "
              f"hc {hc['ours_s']:.2f} s vs pgmpy {hc['pgmpy_s']:.2f} s ({hc['speed_ratio']:.1f}x), "
              f"BIC {hc['bic_difference']:+.1f}; pc {pc['ours_s']:.2f} s vs pgmpy "
              f"{pc['pgmpy_s']:.1f} s ({pc['speed_ratio']:.0f}x), F1 {pc['ours_f1']:.3f} vs "
              f"{pc['pgmpy_f1']:.3f}, {pc['edges_differing_from_pgmpy']} edges differ",
              flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
