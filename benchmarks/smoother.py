"""The particle smoother's memory and time (not a test): peak resident memory and wall time of
``program.ask(..., kind="smooth", method="pf")`` against the number of particles.

The program is the docs' ``cart`` (one real state, a linear-Gaussian step: ``X ~ N(0.9
X_before + 0.5, 0.3)``, ``Y ~ N(2 X, 0.5)``), over four steps of evidence, so the exact
smoother (Rauch-Tung-Striebel) gives the answer the particles estimate. Each run is a fresh
interpreter (``import bayesprog`` and loading the program are in its memory, not its time),
its address space capped (``--cap-gb``, ``RLIMIT_AS``) so that a smoother that needs ``n^2``
memory fails with a MemoryError instead of taking the machine. For each number of particles:

* ``filter``: the particle filter alone (the same particles the smoother starts from);
* ``smooth``: the particle smoother (forward filtering, backward smoothing);
* its peak resident set (``getrusage``'s ``ru_maxrss`` of the process), its time, and each
  step's error against the exact smoother in standard errors: with ``--replications R`` above
  1, the spread of ``R`` independent runs (a batch of ``R`` copies of the sequence, asked at
  once: each sequence of a batch has its own streams; their mean is compared, Student's t with
  ``R - 1`` degrees of freedom), else the approximation ``sd / sqrt(ess)`` of one run, with the
  effective sample size of its weights.

    python benchmarks/smoother.py [--particles 4000 20000] [--replications 1] [--seed 1]
        [--cap-gb 4] [--out results/benchmarks/smoother.json]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

CART = """\
bayesprog: 1
name: cart
variables:
  X_before: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
time:
  previous: {X_before: X}
decomposition:
  - {term: P(X_before), form: normal, mean: 0.0, sigma: 1.0}
  - {term: P(X | X_before), form: normal, mean: "0.9*X_before + 0.5", sigma: 0.3}
  - {term: P(Y | X), form: normal, mean: "2*X", sigma: 0.5}
"""
READINGS = [1.0, 2.1, 2.9, 1.7]

#: what a fresh interpreter runs: one question, then its figures as one line of JSON
CHILD = """
import json, resource, sys, time
import numpy as np
import bayesprog
cart = bayesprog.loads(sys.argv[1])
kind, n, seed, ys = sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), json.loads(sys.argv[5])
runs = int(sys.argv[6])
exact = np.asarray(cart.ask("P(X | Y)", {"Y": ys}, kind=kind).mean("X"))
evidence = {"Y": np.tile(ys, (runs, 1)).T if runs > 1 else ys}
try:
    start = time.perf_counter()
    answer = cart.ask("P(X | Y)", evidence, kind=kind, method="pf", samples=n, rng=seed)
    seconds = time.perf_counter() - start
except MemoryError as exc:
    out = {"failed": f"MemoryError: {exc}"}
else:
    means = np.asarray(answer.mean("X")).reshape(len(ys), runs)
    if runs > 1:
        mean, error = means.mean(axis=1), means.std(axis=1, ddof=1) / np.sqrt(runs)
    else:
        mean = means[:, 0]
        error = np.asarray(answer.sd("X")).reshape(-1) / np.sqrt(answer.ess.reshape(-1))
    out = {"seconds": seconds, "runs": runs, "mean": mean.tolist(), "exact": exact.tolist(),
           "error": error.tolist(), "z": ((mean - exact) / error).tolist()}
out["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps(out))
"""


def run(kind: str, n: int, runs: int, seed: int, cap_gb: float) -> dict:
    """One question (``runs`` sequences) in a fresh interpreter whose address space is capped
    at ``cap_gb``."""
    cap = int(cap_gb * 2**30)

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    with tempfile.TemporaryDirectory() as away:  # bayesprog as PYTHONPATH or the venv has it
        done = subprocess.run([sys.executable, "-c", CHILD, CART, kind, str(n), str(seed),
                               json.dumps(READINGS), str(runs)], capture_output=True, text=True,
                              preexec_fn=limit, check=False, cwd=away)
    lines = done.stdout.strip().splitlines()
    if done.returncode != 0 or not lines:
        return {"failed": f"exit status {done.returncode}: "
                         f"{(done.stderr.strip().splitlines() or [''])[-1]}"}
    return json.loads(lines[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, nargs="+", default=[4_000, 20_000])
    parser.add_argument("--replications", type=int, default=1,
                        help="independent runs per question, for the standard error")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--cap-gb", type=float, default=4.0,
                        help="address space of each run (RLIMIT_AS), in GiB")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    results = []
    error = ("the spread of the runs" if args.replications > 1 else "sd / sqrt(ess)")
    print(f"cart over {len(READINGS)} steps, {args.replications} run(s) per question, each "
          f"in a fresh interpreter capped at {args.cap_gb:g} GiB; errors in standard errors "
          f"({error})")
    for n in args.particles:
        for kind in ("filter", "smooth"):
            figures = {"particles": n, "kind": kind, **run(kind, n, args.replications, args.seed,
                                                          args.cap_gb)}
            results.append(figures)
            if "failed" in figures:
                print(f"{n:>8,} particles  {kind:<6}  failed: {figures['failed']}")
                continue
            worst = max(abs(z) for z in figures["z"])
            print(f"{n:>8,} particles  {kind:<6}  peak {figures.get('peak_mb', 0):7.0f} MB  "
                  f"{figures['seconds']:7.1f} s  largest error {worst:.2f} standard errors")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
