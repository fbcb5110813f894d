"""Parameter learning against pgmpy and pyAgrum (not a test).

For each bnlearn network (asia with 10,000 rows; alarm, insurance and hepar2 with 20,000), rows
drawn by pgmpy's ``BayesianModelSampling.forward_sample`` (seeded) and written as a CSV file;
the program is the network as ``bayesprog import`` writes it. Every table gets the same
uniform Dirichlet pseudo-counts on each side (``--pseudo-counts``, 1 by default: ours
``learn: {pseudo_counts: 1}``, pgmpy's ``DiscreteBayesianEstimator(prior_type="dirichlet",
pseudo_counts=1)``, pyAgrum's ``useSmoothingPrior(1)``), since the larger networks have parent
configurations no row shows; asia, whose configurations all have rows, is also learned by
maximum likelihood (pgmpy's ``DiscreteMLE``, pyAgrum without a prior).

* in process, interleaved, medians of ``--repeats``: ``Program.fit`` on the CSV file and on
  the data frame; pgmpy's ``model.fit(frame, estimator=...)`` on the same data frame (its CSV
  reading not counted); pyAgrum's ``BNLearner(csv, template).learnParameters(dag)`` (its CSV
  reading counted: it learns from files);
* whole commands in fresh processes, interleaved, medians of ``--command-repeats``:
  ``bayesprog learn PROGRAM.yaml DATA.csv -o OUT.yaml``; a pgmpy script (the structure and
  states from a small JSON file, not from its slow BIF reader; ``pd.read_csv``; the fit;
  ``BIFWriter``) and a pyAgrum script (``loadBN`` of the BIF file, ``BNLearner``,
  ``learnParameters``, ``saveBN``); beside them, what any ``bayesprog`` command takes to start
  and load the program (``bayesprog validate PROGRAM.yaml``) and the interpreter alone;
* the largest difference between our learned tables and pgmpy's (and pyAgrum's).

Ratios are theirs over ours: above 1, bayesprog is faster.

    python benchmarks/learning.py [--networks asia alarm insurance hepar2] [--repeats 7]
        [--command-repeats 5] [--pseudo-counts 1] [--out results/benchmarks/learning.json]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import logging
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import pandas as pd
    import pgmpy
    import pyagrum as gum
    from pgmpy.models import DiscreteBayesianNetwork
    from pgmpy.parameter_estimator import DiscreteBayesianEstimator, DiscreteMLE

import bayesprog

EXAMPLES = Path(pgmpy.__file__).parent / "utils" / "example_models"
ROWS = {"asia": 10_000, "alarm": 20_000, "insurance": 20_000, "hepar2": 20_000}
SEED = 1

PGMPY_SCRIPT = """\
import json, sys
import pandas as pd
from pgmpy.models import DiscreteBayesianNetwork
from pgmpy.parameter_estimator import DiscreteBayesianEstimator, DiscreteMLE
from pgmpy.readwrite import BIFWriter
structure, data, out, pseudo = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
spec = json.load(open(structure))
model = DiscreteBayesianNetwork([tuple(e) for e in spec["edges"]])
model.add_nodes_from(spec["states"])
frame = pd.read_csv(data, dtype=str, keep_default_na=False)
estimator = (DiscreteBayesianEstimator(prior_type="dirichlet", pseudo_counts=pseudo,
                                       state_names=spec["states"]) if pseudo > 0
             else DiscreteMLE(state_names=spec["states"]))
model.fit(frame, estimator=estimator)
BIFWriter(model).write(out)
"""

AGRUM_SCRIPT = """\
import sys
import pyagrum as gum
network, data, out, pseudo = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
template = gum.loadBN(network)
learner = gum.BNLearner(data, template)
if pseudo > 0:
    learner.useSmoothingPrior(pseudo)
gum.saveBN(learner.learnParameters(template.dag()), out)
"""


class Case:
    """A network's program (imported, its tables given ``pseudo_counts``), sampled rows as a CSV
    file and a data frame, and each peer's model of it."""

    def __init__(self, name: str, rows: int, pseudo_counts: float, tmp: Path):
        from bayesprog.cli import main as bayesprog_main

        self.name, self.rows, self.pseudo_counts = name, rows, pseudo_counts
        tag = f"{name}-{pseudo_counts:g}"
        self.program_path = tmp / f"{tag}.yaml"
        with contextlib.redirect_stdout(io.StringIO()):
            status = bayesprog_main(["import", str(EXAMPLES / f"{name}.bif.gz"), "-o",
                                     str(self.program_path)])
        if status != 0:
            raise RuntimeError(f"bayesprog import {name} failed")
        if pseudo_counts > 0:
            text = self.program_path.read_text()
            self.program_path.write_text(re.sub(
                r"(?m)^(\s*)form: table$",
                rf"\1form: table\n\1learn: {{pseudo_counts: {pseudo_counts:g}}}", text))
        self.program = bayesprog.load(self.program_path)
        self.csv = tmp / f"{name}.csv"
        if not self.csv.exists():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                from pgmpy.sampling import BayesianModelSampling
                from pgmpy.utils import get_example_model

                sampled = BayesianModelSampling(get_example_model(name)).forward_sample(
                    size=rows, seed=SEED, show_progress=False)
            sampled.astype(str).to_csv(self.csv, index=False)
        self.frame = pd.read_csv(self.csv, dtype=str, keep_default_na=False)
        self.states = {n: list(v.states) for n, v in self.program.variables.items()}
        self.edges = [(p.name, t.child.name) for t in self.program.terms for p in t.parents]
        self.structure = tmp / f"{name}.json"
        self.structure.write_text(json.dumps({"edges": self.edges, "states": self.states}))
        self.bif = tmp / f"{name}.bif"
        self.template = gum.BayesNet(name)
        for n, states in self.states.items():
            self.template.add(gum.LabelizedVariable(n, n, states))
        for a, b in self.edges:
            self.template.addArc(a, b)
        gum.saveBN(self.template, str(self.bif))

    # one learning each ---------------------------------------------------------------------
    def ours_csv(self):
        return self.program.fit(self.csv)

    def ours_frame(self):
        return self.program.fit(self.frame)

    def pgmpy(self):
        model = DiscreteBayesianNetwork(self.edges)
        model.add_nodes_from(self.states)
        estimator = (DiscreteBayesianEstimator(prior_type="dirichlet",
                                               pseudo_counts=self.pseudo_counts,
                                               state_names=self.states)
                     if self.pseudo_counts > 0 else DiscreteMLE(state_names=self.states))
        return model.fit(self.frame, estimator=estimator)

    def agrum(self):
        learner = gum.BNLearner(str(self.csv), self.template)
        if self.pseudo_counts > 0:
            learner.useSmoothingPrior(self.pseudo_counts)
        return learner.learnParameters(self.template.dag())

    # the tables compared -------------------------------------------------------------------
    def differences(self) -> dict:
        ours = self.ours_csv().program
        pgmpy_model, agrum_bn = self.pgmpy(), self.agrum()
        to_pgmpy = to_agrum = 0.0
        for term in ours.terms:
            child, parents = term.child.name, [p.name for p in term.parents]
            table = term.params["table"].array  # [*parents, child] in our state orders
            cpd = pgmpy_model.get_cpds(child)
            theirs = np.transpose(np.asarray(cpd.values),
                                  [cpd.variables.index(p) for p in parents] + [0])
            for axis, var in enumerate([*parents, child]):
                theirs = np.take(theirs, [cpd.state_names[var].index(s)
                                          for s in self.states[var]], axis=axis)
            to_pgmpy = max(to_pgmpy, float(np.abs(table - theirs).max()))
            cpt = agrum_bn.cpt(child)
            names = list(cpt.names)[::-1]  # toarray's axes: the variables in reverse
            theirs = np.transpose(cpt.toarray(), [names.index(v) for v in [*parents, child]])
            to_agrum = max(to_agrum, float(np.abs(table - theirs).max()))
        return {"max_difference_pgmpy": to_pgmpy, "max_difference_pyagrum": to_agrum}


def interleaved(functions: dict, repeats: int) -> dict[str, list[float]]:
    """Each function run once per round, the rounds repeated: load drifts evenly over all."""
    times: dict[str, list[float]] = {k: [] for k in functions}
    for _ in range(repeats):
        for key, function in functions.items():
            start = time.perf_counter()
            function()
            times[key].append(time.perf_counter() - start)
    return times


def in_process(case: Case, repeats: int) -> dict:
    logging.disable(logging.WARNING)  # pgmpy logs each CPD it replaces
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            functions = {"bayesprog_csv": case.ours_csv, "bayesprog_frame": case.ours_frame,
                         "pgmpy": case.pgmpy, "pyagrum": case.agrum}
            interleaved(functions, 1)  # warm: imports and first-call caches
            times = interleaved(functions, repeats)
    finally:
        logging.disable(logging.NOTSET)
    return summary(times, ours="bayesprog_csv", peers=("pgmpy", "pyagrum"),
                   also="bayesprog_frame")


def commands(case: Case, repeats: int, tmp: Path) -> dict:
    python = sys.executable
    pgmpy_script, agrum_script = tmp / "pgmpy_learn.py", tmp / "agrum_learn.py"
    pgmpy_script.write_text(PGMPY_SCRIPT)
    agrum_script.write_text(AGRUM_SCRIPT)
    pseudo = str(case.pseudo_counts)
    lines = {
        "bayesprog": [python, "-m", "bayesprog", "learn", str(case.program_path), str(case.csv),
                      "-o", str(tmp / "fitted.yaml")],
        "pgmpy": [python, str(pgmpy_script), str(case.structure), str(case.csv),
                  str(tmp / "pgmpy.bif"), pseudo],
        "pyagrum": [python, str(agrum_script), str(case.bif), str(case.csv),
                    str(tmp / "pyagrum.bif"), pseudo],
        "bayesprog_validate": [python, "-m", "bayesprog", "validate", str(case.program_path)],
        "python": [python, "-c", "pass"],
    }

    # as a user runs them: Python keeps the modules it compiled (PYTHONDONTWRITEBYTECODE, set
    # in some environments, would make every run compile every module of bayesprog and pgmpy)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}

    def run(line: list[str]):
        return lambda: subprocess.run(line, check=True, capture_output=True, env=env)

    runs = {k: run(v) for k, v in lines.items()}
    interleaved(runs, 1)  # each command once first: its modules compiled and kept
    times = interleaved(runs, repeats)
    return summary(times, ours="bayesprog", peers=("pgmpy", "pyagrum"),
                   also="bayesprog_validate")


def summary(times: dict[str, list[float]], ours: str, peers: tuple[str, ...], also: str) -> dict:
    medians = {k: statistics.median(v) for k, v in times.items()}
    out = {f"{k}_s": medians[k] for k in times}
    out["times_s"] = times
    for peer in peers:  # theirs over ours: above 1, bayesprog is faster
        out[f"ratio_{peer}"] = medians[peer] / medians[ours]
        out[f"ratio_{peer}_{also}"] = medians[peer] / medians[also]
    return out


def table(rows: list[dict]) -> str:
    head = (f"{'network':<10} {'prior':>6} {'ours csv':>9} {'ours df':>8} {'pgmpy':>8} "
            f"{'pyAgrum':>8} {'pg/ours':>8} {'ag/ours':>8} | {'learn':>7} {'pgmpy':>7} "
            f"{'pyAgrum':>7} {'pg/ours':>8} {'ag/ours':>8} {'validate':>8} | {'max diff':>8}")
    lines = [head, "-" * len(head)]
    for r in rows:
        i, c = r["in_process"], r["command"]
        lines.append(
            f"{r['network']:<10} {r['pseudo_counts']:>6g} {1e3 * i['bayesprog_csv_s']:>7.1f}ms "
            f"{1e3 * i['bayesprog_frame_s']:>6.1f}ms {1e3 * i['pgmpy_s']:>6.1f}ms "
            f"{1e3 * i['pyagrum_s']:>6.1f}ms {i['ratio_pgmpy']:>8.2f} {i['ratio_pyagrum']:>8.2f} | "
            f"{c['bayesprog_s']:>6.2f}s {c['pgmpy_s']:>6.2f}s {c['pyagrum_s']:>6.2f}s "
            f"{c['ratio_pgmpy']:>8.2f} {c['ratio_pyagrum']:>8.2f} "
            f"{c['bayesprog_validate_s']:>7.2f}s | {r['max_difference_pgmpy']:>8.1e}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", nargs="+", default=list(ROWS))
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--command-repeats", type=int, default=5)
    parser.add_argument("--pseudo-counts", type=float, default=1.0)
    parser.add_argument("--out", default="results/benchmarks/learning.json")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.networks:
            priors = [args.pseudo_counts] + ([0.0] if name == "asia" else [])
            for pseudo in priors:
                case = Case(name, ROWS.get(name, 20_000), pseudo, Path(tmp))
                row = {"network": name, "rows": case.rows, "variables": len(case.states),
                       "pseudo_counts": pseudo, **case.differences(),
                       "in_process": in_process(case, args.repeats),
                       "command": commands(case, args.command_repeats, Path(tmp))}
                rows.append(row)
                print(f"measured {name} (pseudo-counts {pseudo:g})", file=sys.stderr)
    print(table(rows))
    print("\nin process: medians; ratios are pgmpy's (pyAgrum's) time over ours on the CSV file. "
          "Commands: whole fresh processes; validate is what any bayesprog command takes to "
          "start and load the program.")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"repeats": args.repeats, "command_repeats": args.command_repeats,
                               "seed": SEED, "rows": rows}, indent=2))
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
