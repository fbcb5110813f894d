"""The engine at scale against pyAgrum (not a test): every marginal, loading and importing on
bnlearn's larger discrete networks, as pgmpy ships them (``pgmpy/utils/example_models``).

* **All marginals** (``--networks``, default hepar2 andes pigs diabetes munin): five variables
  observed (chosen with a seed per network), their values drawn by forward sampling from the
  network (pyAgrum's ``BNDatabaseGenerator`` after ``gum.initRandom``), ``--sets`` evidence
  sets of the same five variables. bayesprog: ``program.marginals(evidence)``, the posterior of
  every unobserved variable. pyAgrum: ``LazyPropagation``, ``eraseAllEvidence();
  setEvidence(ev); makeInference()``, then ``posterior(v)`` for every unobserved ``v``.

  - cold: bayesprog's first call on a program just loaded (its junction tree built within the
    time; the load itself, from the program cache, is not timed); pyAgrum's a new
    ``LazyPropagation`` per call, made within the time. ``--cold-repeats`` calls each (default
    3: pyAgrum's cold call on munin takes about ten seconds; ``--repeats`` where the first
    pair takes under a second), interleaved;
  - warm: bayesprog's program has answered another evidence set of the same observed variables;
    pyAgrum's ``LazyPropagation`` is the same object, its evidence changed. ``--repeats``
    rounds over the evidence sets, each call timed alone, the two libraries interleaved;
  - varied: as warm, but each call observes five other variables (twice ``--sets`` sets,
    each a seeded choice of variables with values drawn by forward sampling): what a session
    of questions does. Our junction tree is the program's whatever is observed (the observed
    states enter as zeros), so it is built once.

  pyAgrum's time up to the end of ``makeInference`` is kept beside (reading hundreds of
  posteriors, each a product of a clique's factors, is most of its time on pigs and munin).

  Ratios are bayesprog's time over pyAgrum's: the median of the ratios of calls made side by
  side (the machine's load varies by 2x over a run; a pair shares it), beside the medians of
  each. Exactness: the largest ``|bayesprog - pyAgrum|`` over every marginal of every evidence
  set, and over ``log P(evidence)``. pyAgrum's network is read from the same BIF
  (``gum.loadBN``) with every CPT normalised (``normalizeAsCPT``), as our importer renormalises
  rows within 1e-6 of 1; but pyAgrum's BIF reader keeps single-precision numbers (0.05882353
  becomes 0.05882352963...), so its CPTs are then filled in double precision with the
  program's tables: that network is the one timed and the one the error is reported against;
  the error against the network as pyAgrum reads it is reported beside (``parsed``, ~1e-8).
  Our junction tree's size (cliques, entries in all, the largest clique) beside the junction
  tree pyAgrum triangulates (which ``LazyPropagation`` never fills: it keeps lists of factors).
* **Loading** (``--loading``, default andes barley diabetes munin), in fresh processes:
  ``from bayesprog import load; import bayesprog.program`` before the clock, then
  ``load(path)`` timed; ``import pyagrum as gum`` before the clock, then
  ``gum.loadBN(path.bif)`` (the uncompressed BIF) timed. bayesprog twice: with the program
  cache off (``BAYESPROG_CACHE=off``: the YAML read and checked) and on (a cache folder in the
  work folder, filled by one load first, whose time is reported). ``--repeats`` processes
  each, interleaved; a cached load that missed the cache (a module of the package changed
  under the run) is left out and counted.
* **Import**: the whole ``bayesprog import NET.bif.gz -o NET.yaml`` command (pgmpy's reader,
  the YAML written, then loaded and checked, with the program cache off), once per network of
  the loading set, wall time; informative.

The imported programs and the uncompressed BIF files are kept in the work folder (``--work``)
across runs; the import rows rewrite them (``--no-import`` skips those rows; a program
missing then is imported in-process, untimed). Results to standard output and, with the mode of
every row, every time measured and the commit each part ran on (with the package's files
changed in the work tree), as JSON to ``--out``.

    python benchmarks/scale.py [--networks hepar2 andes pigs diabetes munin]
        [--loading andes barley diabetes munin] [--repeats 5] [--cold-repeats 3] [--sets 5]
        [--work results/benchmarks/scale] [--no-import] [--out results/benchmarks/scale.json]
"""

from __future__ import annotations

import argparse
import gc
import gzip
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyagrum as gum

import bayesprog
from bayesprog import load
from bayesprog.io import import_network

MARGINAL_NETWORKS = ["hepar2", "andes", "pigs", "diabetes", "munin"]
LOADING_NETWORKS = ["andes", "barley", "diabetes", "munin"]
OBSERVED = 5

MODES = {
    "marginals cold": "bayesprog: program.marginals(evidence), the first call on a program just "
                      "loaded (junction tree built in the time); pyAgrum: a new "
                      "LazyPropagation, setEvidence, makeInference, posterior(v) for every "
                      "unobserved v, all in the time",
    "marginals warm": "bayesprog: program.marginals(evidence) on a program that answered another "
                      "evidence set of the same observed variables; pyAgrum: the same "
                      "LazyPropagation, eraseAllEvidence, setEvidence, makeInference, "
                      "posterior(v) for every unobserved v",
    "marginals varied": "as warm, but each call observes another five variables (a seeded "
                        "choice, values drawn by forward sampling): bayesprog's tree is the "
                        "program's whatever is observed, pyAgrum's engine is the same "
                        "LazyPropagation",
    "load cache off": "bayesprog load(path) in a fresh process, BAYESPROG_CACHE=off (YAML read "
                      "and checked); package imported before the clock",
    "load cache on": "bayesprog load(path) in a fresh process, BAYESPROG_CACHE=<work>/cache "
                     "filled by a first load; package imported before the clock",
    "load cache fill": "the first load with the cache on: read, checked and kept (one process)",
    "pyagrum load": "gum.loadBN(path.bif) in a fresh process, pyagrum imported before the clock",
    "import": "the whole `bayesprog import NET.bif.gz -o NET.yaml` command (BAYESPROG_CACHE=off), "
              "wall time of the process, once",
}


def examples() -> Path:
    import pgmpy

    return Path(pgmpy.__file__).parent / "utils" / "example_models"


def network_files(name: str, work: Path) -> tuple[Path, Path, Path]:
    """The network's gzipped BIF as pgmpy ships it, its uncompressed copy in the work folder,
    and where its program is kept (the copy made now when missing)."""
    gz = examples() / f"{name}.bif.gz"
    bif = work / f"{name}.bif"
    if not bif.exists():
        bif.write_text(gzip.open(gz, "rt", encoding="utf-8").read(), encoding="utf-8")
    return gz, bif, work / f"{name}.yaml"


def program_file(name: str, work: Path) -> Path:
    """The network's program, imported in-process (untimed) when the work folder lacks it."""
    gz, _, path = network_files(name, work)
    if not path.exists():
        print(f"  importing {name} (kept in {path})", flush=True)
        import_network(gz, path)
    return path


# all marginals ---------------------------------------------------------------------------------
def agrum_network(bif: Path) -> gum.BayesNet:
    """pyAgrum's network read from the BIF, every CPT normalised as our importer does."""
    bn = gum.loadBN(str(bif))
    for node in bn.nodes():
        bn.cpt(node).normalizeAsCPT()
    return bn


def agrum_as_ours(bif: Path, program) -> gum.BayesNet:
    """pyAgrum's network read from the BIF, its CPTs then filled in double precision with the
    program's tables (pyAgrum's BIF reader keeps single-precision numbers: its CPTs differ from
    the file's by up to 3e-8, and its marginals from the exact ones by as much)."""
    bn = gum.loadBN(str(bif))
    for term in program.terms:
        child = term.child.name
        axes = [*term.expression.right, child]  # the table's: parents, then the child
        cpt = bn.cpt(child)
        along = list(cpt.names)[::-1]  # toarray()'s axes, fillWith's order
        table = np.asarray(term.params["table"].array, dtype=float)
        cpt.fillWith(np.transpose(table, [axes.index(n) for n in along]).ravel().tolist())
        cpt.normalizeAsCPT()
    return bn


def evidence_sets(name: str, bn: gum.BayesNet, count: int) -> tuple[list[str], list[dict]]:
    """Five variables (a seeded choice) and ``count`` joint values of them drawn by forward
    sampling (state indices)."""
    rng = np.random.default_rng(sum(map(ord, name)))
    names = sorted(bn.names())
    observed = [names[i] for i in sorted(rng.choice(len(names), size=OBSERVED, replace=False))]
    gum.initRandom(sum(map(ord, name)))
    generator = gum.BNDatabaseGenerator(bn)
    generator.drawSamples(count)
    column = {v: i for i, v in enumerate(generator.varOrderNames())}
    sets = [{v: int(generator.samplesAt(row, column[v])) for v in observed}
            for row in range(count)]
    return observed, sets


def varied_sets(name: str, bn: gum.BayesNet, count: int) -> list[dict]:
    """``count`` evidence sets, each of another five variables (a seeded choice) and their
    values drawn by forward sampling (state indices)."""
    rng = np.random.default_rng(sum(map(ord, name)) + 1)
    names = sorted(bn.names())
    gum.initRandom(sum(map(ord, name)) + 1)
    generator = gum.BNDatabaseGenerator(bn)
    generator.drawSamples(count)
    column = {v: i for i, v in enumerate(generator.varOrderNames())}
    return [{names[i]: int(generator.samplesAt(row, column[names[i]]))
             for i in sorted(rng.choice(len(names), size=OBSERVED, replace=False))}
            for row in range(count)]


def agrum_marginals(engine: gum.LazyPropagation, evidence: dict, unobserved: list[str],
                    inferred: list[float] | None = None) -> list:
    """pyAgrum's marginals; ``inferred`` is given the clock's time once ``makeInference`` has
    returned (the rest is reading the posteriors, most of the time on large networks)."""
    engine.eraseAllEvidence()
    engine.setEvidence(evidence)
    engine.makeInference()
    if inferred is not None:
        inferred.append(time.perf_counter())
    return [engine.posterior(v) for v in unobserved]


def agrum_tree(engine: gum.LazyPropagation, bn: gum.BayesNet) -> dict:
    tree = engine.junctionTree()
    sizes = [math.prod(bn.variable(n).domainSize() for n in tree.clique(c)) for c in tree.nodes()]
    return {"cliques": len(sizes), "entries": int(sum(sizes)), "largest": int(max(sizes))}


def bench_marginals(name: str, work: Path, repeats: int, cold_repeats: int, count: int) -> dict:
    _, bif, _ = network_files(name, work)
    path = program_file(name, work)
    program = load(path)
    parsed = agrum_network(bif)
    bn = agrum_as_ours(bif, program)
    observed, sets = evidence_sets(name, bn, count)
    states = {v: program.variables[v].states for v in observed}
    labels_agree = all(tuple(program.variables[v].states) == tuple(bn.variable(v).labels())
                       for v in bn.names())

    def ours(i: int) -> dict:  # states given by name; pyAgrum's by index, the same order
        return {v: states[v][k] for v, k in sets[i].items()}

    unobserved = [v for v in program.variables if v not in observed]
    assert set(program.variables) == set(bn.names()), "variables renamed by the importer"
    print(f"{name}: {len(program.variables)} variables, observed {', '.join(observed)}",
          flush=True)

    # cold: a program just loaded (from the cache, untimed), and a new LazyPropagation
    cold_ours, cold_theirs, cold_inference = [], [], []
    calls, r = cold_repeats, 0
    while r < calls:
        i = r % count
        del program
        gc.collect()
        program = load(path)
        assert not program.inference_cache.layouts, "a loaded program that answered before"
        pair = []
        for side in ("ours", "theirs") if r % 2 == 0 else ("theirs", "ours"):
            t = time.perf_counter()
            if side == "ours":
                program.marginals(ours(i))
            else:
                inferred: list[float] = []
                agrum_marginals(gum.LazyPropagation(bn), sets[i], unobserved, inferred)
                cold_inference.append(inferred[0] - t)
            pair.append((side, time.perf_counter() - t))
        times = dict(pair)
        cold_ours.append(times["ours"])
        cold_theirs.append(times["theirs"])
        if r == 0 and times["ours"] + times["theirs"] < 1:  # cheap: as many as warm rounds
            calls = max(cold_repeats, repeats)
        r += 1
        print(f"  cold {r}/{calls}: bayesprog {times['ours']:.3f} s, pyAgrum "
              f"{times['theirs']:.3f} s", flush=True)
    tree = [v for k, v in program.inference_cache.layouts.items() if k[0] == "junction"][0]

    # warm: the program above has answered set (cold_repeats - 1) % count; pyAgrum's engine
    # answers set 0 before the clock
    engine = gum.LazyPropagation(bn)
    agrum_marginals(engine, sets[0], unobserved)
    program.marginals(ours(0))
    warm_ours, warm_theirs, warm_inference = [], [], []
    for r in range(repeats):
        for i in range(1, count):
            for side in ("ours", "theirs") if (r + i) % 2 == 0 else ("theirs", "ours"):
                t = time.perf_counter()
                if side == "ours":
                    program.marginals(ours(i))
                else:
                    inferred = []
                    agrum_marginals(engine, sets[i], unobserved, inferred)
                    warm_inference.append(inferred[0] - t)
                (warm_ours if side == "ours" else warm_theirs).append(time.perf_counter() - t)
    print(f"  warm: bayesprog {statistics.median(warm_ours) * 1000:.1f} ms, pyAgrum "
          f"{statistics.median(warm_theirs) * 1000:.1f} ms", flush=True)

    # warm, each call observing other variables
    varied = varied_sets(name, bn, 2 * count)
    varied_ours, varied_theirs, varied_inference = [], [], []
    for r in range(repeats):
        for i, chosen in enumerate(varied):
            named = {v: program.variables[v].states[k] for v, k in chosen.items()}
            others = [v for v in program.variables if v not in chosen]
            for side in ("ours", "theirs") if (r + i) % 2 == 0 else ("theirs", "ours"):
                t = time.perf_counter()
                if side == "ours":
                    program.marginals(named)
                else:
                    inferred = []
                    agrum_marginals(engine, chosen, others, inferred)
                    varied_inference.append(inferred[0] - t)
                (varied_ours if side == "ours" else varied_theirs).append(
                    time.perf_counter() - t)
    print(f"  varied: bayesprog {statistics.median(varied_ours) * 1000:.1f} ms, pyAgrum "
          f"{statistics.median(varied_theirs) * 1000:.1f} ms", flush=True)

    # exactness, untimed: every marginal of every evidence set, against pyAgrum on our tables
    # and on its own reading of the BIF
    errors = {"ours": 0.0, "parsed": 0.0, "log_evidence": 0.0}
    parsed_engine = gum.LazyPropagation(parsed)
    for i in range(count):
        found = program.marginals(ours(i))
        for key, peer in (("ours", engine), ("parsed", parsed_engine)):
            theirs = agrum_marginals(peer, sets[i], unobserved)
            for v, tensor in zip(unobserved, theirs, strict=True):
                difference = np.abs(found[v].probabilities - np.asarray(tensor.toarray()))
                errors[key] = max(errors[key], float(difference.max()))
            if key == "ours":
                log_evidence = float(next(iter(found.values())).log_evidence)
                errors["log_evidence"] = max(errors["log_evidence"], abs(
                    log_evidence - math.log(engine.evidenceProbability())))
    del parsed_engine

    return {
        "network": name, "variables": len(program.variables), "observed": observed,
        "evidence_sets": [{v: states[v][k] for v, k in s.items()} for s in sets],
        "labels_agree": labels_agree,
        "cold": summary(cold_ours, cold_theirs, cold_inference, "marginals cold"),
        "warm": summary(warm_ours, warm_theirs, warm_inference, "marginals warm"),
        "varied": summary(varied_ours, varied_theirs, varied_inference, "marginals varied"),
        "max_abs_error": errors["ours"],
        "max_abs_error_mode": "pyAgrum's CPTs filled in double precision with our tables",
        "max_abs_log_evidence_error": errors["log_evidence"],
        "max_abs_error_pyagrum_parsed": errors["parsed"],
        "max_abs_error_pyagrum_parsed_mode": "pyAgrum's CPTs as gum.loadBN reads the BIF "
                                             "(single precision), normalised",
        "tree": {"cliques": len(tree.cliques), "entries": int(tree.entries),
                 "largest": int(tree.largest)},
        "pyagrum_tree": agrum_tree(engine, bn),
    }


def summary(ours: list[float], theirs: list[float], inference: list[float], mode: str) -> dict:
    """Medians, the ratio of the medians and the median of the paired ratios (bayesprog's time
    over pyAgrum's); ``inference``: pyAgrum's times up to the end of ``makeInference``."""
    return {
        "mode": MODES[mode], "calls": len(ours),
        "bayesprog_s": statistics.median(ours), "pyagrum_s": statistics.median(theirs),
        "pyagrum_until_make_inference_s": statistics.median(inference),
        "ratio_of_medians": statistics.median(ours) / statistics.median(theirs),
        "paired_ratio": statistics.median(a / b for a, b in zip(ours, theirs, strict=True)),
        "bayesprog_all_s": ours, "pyagrum_all_s": theirs,
    }


# loading ---------------------------------------------------------------------------------------
OURS_LOAD = """
import json, os, sys, time
from pathlib import Path
from bayesprog import load
import bayesprog.program
from bayesprog.support import cache
path = Path(sys.argv[1])
place = cache.folder()
before = set(os.listdir(place)) if place is not None and place.is_dir() else set()
t = time.perf_counter()
program = load(path)
seconds = time.perf_counter() - t
key = cache.key(path, path.read_bytes())
print(json.dumps({"seconds": seconds, "variables": len(program.variables),
                  "cached": key is not None and key + ".pickle" in before}))
"""

AGRUM_LOAD = """
import json, sys, time
import pyagrum as gum
t = time.perf_counter()
bn = gum.loadBN(sys.argv[1])
seconds = time.perf_counter() - t
print(json.dumps({"seconds": seconds, "variables": bn.size()}))
"""


def child(script: str, path: Path, cache: str) -> dict:
    env = dict(os.environ, BAYESPROG_CACHE=cache)
    done = subprocess.run([sys.executable, "-c", script, str(path)], env=env, check=True,
                          capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def bench_loading(name: str, work: Path, repeats: int) -> dict:
    _, bif, _ = network_files(name, work)
    path = program_file(name, work)
    cache = str(work / "cache")
    fill = child(OURS_LOAD, path, cache)
    off, on, theirs, missed = [], [], [], 0
    for r in range(repeats):
        order = ("off", "on", "pyagrum")
        for side in order[r % 3:] + order[:r % 3]:
            if side == "off":
                off.append(child(OURS_LOAD, path, "off")["seconds"])
            elif side == "on":
                found = child(OURS_LOAD, path, cache)
                if found["cached"]:
                    on.append(found["seconds"])
                else:
                    missed += 1
            else:
                theirs.append(child(AGRUM_LOAD, bif, "off")["seconds"])
    agrum = statistics.median(theirs)
    row = {"network": name, "variables": fill["variables"],
           "yaml_bytes": path.stat().st_size, "bif_bytes": bif.stat().st_size,
           "pyagrum_s": agrum, "pyagrum_mode": MODES["pyagrum load"], "pyagrum_all_s": theirs,
           "fill_s": fill["seconds"], "fill_mode": MODES["load cache fill"],
           "fill_was_cached": fill["cached"]}
    for label, times in (("cache_off", off), ("cache_on", on)):
        row[label] = {"mode": MODES[f"load {label.replace('_', ' ')}"], "processes": len(times),
                      "bayesprog_s": statistics.median(times) if times else None,
                      "ratio": statistics.median(times) / agrum if times else None,
                      "all_s": times}
    row["cache_on"]["missed_cache"] = missed
    print(f"{name}: load off {row['cache_off']['bayesprog_s']:.3f} s, on "
          f"{row['cache_on']['bayesprog_s'] or float('nan'):.3f} s, pyAgrum {agrum:.3f} s",
          flush=True)
    return row


# import ----------------------------------------------------------------------------------------
def bench_import(name: str, work: Path) -> dict:
    gz, _, path = network_files(name, work)
    env = dict(os.environ, BAYESPROG_CACHE="off")
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "bayesprog", "import", str(gz), "-o", str(path)],
                   env=env, check=True, capture_output=True)
    seconds = time.perf_counter() - t
    print(f"{name}: import {seconds:.1f} s", flush=True)
    return {"network": name, "mode": MODES["import"], "seconds": seconds,
            "yaml_bytes": path.stat().st_size}


# report ----------------------------------------------------------------------------------------
def ms(seconds: float | None) -> str:
    if seconds is None:
        return "-"
    return f"{seconds * 1000:.1f} ms" if seconds < 1 else f"{seconds:.2f} s"


def print_tables(report: dict) -> None:
    if report["marginals"]:
        print("\nAll marginals, 5 observed (ratio: bayesprog / pyAgrum, median of paired calls)")
        print(f"{'network':9s} {'vars':>5s} | {'cold ours':>10s} {'cold pyA':>10s} {'ratio':>6s} "
              f"| {'warm ours':>10s} {'warm pyA':>10s} {'(infer)':>10s} {'ratio':>6s} "
              f"| {'varied':>10s} {'ratio':>6s} "
              f"| {'max err':>8s} "
              f"{'(parsed)':>8s} "
              f"| {'our tree: cliques entries largest':>34s} | pyAgrum tree entries")
        for row in report["marginals"]:
            c, w, t = row["cold"], row["warm"], row["tree"]
            print(f"{row['network']:9s} {row['variables']:5d} | {ms(c['bayesprog_s']):>10s} "
                  f"{ms(c['pyagrum_s']):>10s} {c['paired_ratio']:6.2f} | "
                  f"{ms(w['bayesprog_s']):>10s} {ms(w['pyagrum_s']):>10s} "
                  f"{ms(w['pyagrum_until_make_inference_s']):>10s} "
                  f"{w['paired_ratio']:6.2f} | {ms(row['varied']['bayesprog_s']):>10s} "
                  f"{row['varied']['paired_ratio']:6.2f} | {row['max_abs_error']:8.1e} "
                  f"{row['max_abs_error_pyagrum_parsed']:8.1e} | "
                  f"{t['cliques']:>12d} {t['entries']:>11,d} {t['largest']:>9,d} | "
                  f"{row['pyagrum_tree']['entries']:,d}")
        print("(infer): pyAgrum's warm time up to the end of makeInference, before posterior(v)")
        print("varied: warm calls each observing five other variables (the same engines)")
        print("max err: the largest |bayesprog - pyAgrum| over every marginal of every evidence "
              "set, pyAgrum's CPTs filled with our tables in double precision; (parsed): "
              "pyAgrum's CPTs as its BIF reader makes them (single precision)")
    if report["loading"]:
        print("\nLoading in fresh processes (ratio: bayesprog / pyAgrum, of the medians)")
        print(f"{'network':9s} | {'cache off':>10s} {'ratio':>6s} | {'cache on':>10s} "
              f"{'ratio':>6s} | {'pyAgrum':>10s} | {'first (fill)':>12s}")
        for row in report["loading"]:
            off, on = row["cache_off"], row["cache_on"]
            print(f"{row['network']:9s} | {ms(off['bayesprog_s']):>10s} {off['ratio']:6.1f} | "
                  f"{ms(on['bayesprog_s']):>10s} {on['ratio'] or float('nan'):6.2f} | "
                  f"{ms(row['pyagrum_s']):>10s} | {ms(row['fill_s']):>12s}")
    if report["import"]:
        print("\nImport (the whole command, once, wall time)")
        for row in report["import"]:
            print(f"{row['network']:9s} {row['seconds']:7.1f} s   "
                  f"({row['yaml_bytes'] / 1e3:,.0f} kB of YAML)")


def commit() -> dict:
    """The commit measured, and the package's files changed or added in the work tree."""
    root = Path(__file__).parents[1]
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              cwd=root, check=True).stdout.strip()
        changed = subprocess.run(["git", "status", "--porcelain", "bayesprog"],
                                 capture_output=True, text=True, cwd=root,
                                 check=True).stdout.splitlines()
    except (OSError, subprocess.CalledProcessError):
        return {"head": "unknown"}
    return {"head": head, "changed": [line[3:] for line in changed]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", nargs="*", default=MARGINAL_NETWORKS,
                        help="networks for all marginals")
    parser.add_argument("--loading", nargs="*", default=LOADING_NETWORKS,
                        help="networks for loading and import")
    parser.add_argument("--repeats", type=int, default=5,
                        help="warm rounds over the evidence sets; processes per loading mode")
    parser.add_argument("--cold-repeats", type=int, default=3)
    parser.add_argument("--sets", type=int, default=5, help="evidence sets per network")
    parser.add_argument("--work", default="results/benchmarks/scale")
    parser.add_argument("--no-import", action="store_true", help="skip the import rows")
    parser.add_argument("--out", default="results/benchmarks/scale.json")
    args = parser.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    # programs loaded here (the cold rows load one per call) come from the work folder's cache
    os.environ["BAYESPROG_CACHE"] = str((work / "cache").resolve())
    report: dict = {
        "bayesprog": getattr(bayesprog, "__version__", "?"),
        "pyagrum": gum.__version__, "numpy": np.__version__, "python": platform.python_version(),
        "machine": platform.machine(), "cpus": os.cpu_count(), "repeats": args.repeats,
        "cold_repeats": args.cold_repeats, "evidence_sets": args.sets, "modes": MODES,
        "import": [], "loading": [], "marginals": [],
    }
    # the tree may change under a long run (others commit): each part says what it measured
    report["commits"] = {}
    if not args.no_import:
        print("== import", flush=True)
        report["commits"]["import"] = commit()
        report["import"] = [bench_import(name, work) for name in args.loading]
    print("== loading", flush=True)
    report["commits"]["loading"] = commit()
    report["loading"] = [bench_loading(name, work, args.repeats) for name in args.loading]
    print("== all marginals", flush=True)
    report["commits"]["marginals"] = commit()
    report["marginals"] = [bench_marginals(name, work, args.repeats, args.cold_repeats,
                                           args.sets) for name in args.networks]
    report["commits"]["end"] = commit()
    print_tables(report)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
