"""What a user waits for before the first answer (not a test): ``import bayesprog`` against
``import pyagrum`` and ``import pgmpy``, the package with its engine (``from bayesprog import
Program``) against ``import pyagrum``, a script that loads the bundled ``student`` and asks it
one question against a pyAgrum script doing the same (``fastBN``, ``LazyPropagation``,
``posterior``), and a question asked on the command line against the same question asked of
pyAgrum in a fresh interpreter.

Each pair is timed interleaved (bayesprog, then the reference, ``--repeats`` times) in fresh
interpreters, with their bytecode cached as an installed package has it (in a folder of their
own, whatever ``PYTHONDONTWRITEBYTECODE`` says: compiling the sources at every start is not
what a user waits for): the wall time of the process, and the import time Python itself
reports (``python -X importtime``: the cumulative time of the top-level module). Reported:
the medians, their ratio and the median of the paired ratios, to ``--out`` as JSON and to
standard output.

The script pair is also timed where no bytecode is written (``PYTHONDONTWRITEBYTECODE=1``, as
some development environments set it): the libraries' bytecode is then read as installed, but
a source checkout of this package with no ``__pycache__`` (an editable install) has its modules
compiled at every start; the row says whether the package had bytecode.

    python benchmarks/startup.py [--repeats 15] [--out results/benchmarks/startup.json]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

STUDENT = (Path(__file__).parents[1] / "models" / "examples" / "student.yaml").read_text()

PYAGRUM_QUESTION = """
import pyagrum as gum
bn = gum.BayesNet()
d = bn.add(gum.LabelizedVariable("D", "D", ["easy", "hard"]))
i = bn.add(gum.LabelizedVariable("I", "I", ["low", "high"]))
g = bn.add(gum.LabelizedVariable("G", "G", ["A", "B", "C"]))
bn.addArc(d, g); bn.addArc(i, g)
bn.cpt(d).fillWith([0.6, 0.4]); bn.cpt(i).fillWith([0.7, 0.3])
bn.cpt(g)[{"I": "low", "D": "easy"}] = [0.3, 0.4, 0.3]
bn.cpt(g)[{"I": "low", "D": "hard"}] = [0.05, 0.25, 0.7]
bn.cpt(g)[{"I": "high", "D": "easy"}] = [0.9, 0.08, 0.02]
bn.cpt(g)[{"I": "high", "D": "hard"}] = [0.5, 0.3, 0.2]
ie = gum.LazyPropagation(bn); ie.setEvidence({"G": "A"}); ie.makeInference()
print(ie.posterior("I"))
"""


BAYESPROG_SCRIPT = """
import bayesprog
program = bayesprog.load(bayesprog.bundled_path("student", "program"))
print(program.ask("P(I | G=A)").probabilities)
"""

PYAGRUM_SCRIPT = """
import pyagrum as gum
bn = gum.fastBN("D{easy|hard}->G{A|B|C}<-I{low|high}")
bn.cpt("D").fillWith([0.6, 0.4])
bn.cpt("I").fillWith([0.7, 0.3])
bn.cpt("G")[{"I": "low", "D": "easy"}] = [0.3, 0.4, 0.3]
bn.cpt("G")[{"I": "low", "D": "hard"}] = [0.05, 0.25, 0.7]
bn.cpt("G")[{"I": "high", "D": "easy"}] = [0.9, 0.08, 0.02]
bn.cpt("G")[{"I": "high", "D": "hard"}] = [0.5, 0.3, 0.2]
ie = gum.LazyPropagation(bn)
ie.setEvidence({"G": "A"})
ie.makeInference()
print(ie.posterior("I"))
"""

#: the environment of every timed process: bytecode written once, then read, in a folder of
#: its own (set in main)
ENV: dict[str, str] = {}


def wall(command: list[str], cwd: Path) -> float:
    start = time.perf_counter()
    subprocess.run(command, check=True, cwd=cwd, capture_output=True, env=ENV or None)
    return time.perf_counter() - start


def import_time(module: str) -> float:
    """Seconds Python reports for importing ``module`` (cumulative, -X importtime)."""
    err = subprocess.run([sys.executable, "-X", "importtime", "-c", f"import {module}"],
                         check=True, capture_output=True, text=True, env=ENV or None).stderr
    line = [x for x in err.splitlines() if re.search(rf"\|\s*{re.escape(module)}$", x)][-1]
    return int(line.split("|")[1]) / 1e6


def _has_bytecode() -> bool:
    """Whether this package's modules have bytecode beside their sources (as an installed wheel
    has it), which a process that writes none still reads."""
    import importlib.util

    source = Path(__file__).parents[1] / "bayesprog" / "program.py"
    return Path(importlib.util.cache_from_source(str(source))).exists()


def paired(ours: list[str], reference: list[str], repeats: int, cwd: Path) -> dict:
    a, b = [], []
    wall(ours, cwd), wall(reference, cwd)  # warm the file cache
    for _ in range(repeats):
        a.append(wall(ours, cwd))
        b.append(wall(reference, cwd))
    return {"bayesprog_s": float(np.median(a)), "reference_s": float(np.median(b)),
            "ratio": float(np.median(a) / np.median(b)),
            "paired_ratio": float(np.median(np.asarray(a) / np.asarray(b)))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--out", default="results/benchmarks/startup.json")
    args = parser.parse_args()
    py = sys.executable
    bayesprog = str(Path(py).with_name("bayesprog"))
    report: dict = {"repeats": args.repeats}
    with tempfile.TemporaryDirectory() as tmp:
        cwd = Path(tmp)
        ENV.update(os.environ, PYTHONPYCACHEPREFIX=str(cwd / "bytecode"))
        ENV.pop("PYTHONDONTWRITEBYTECODE", None)
        (cwd / "student.yaml").write_text(STUDENT)
        (cwd / "bayesprog_script.py").write_text(BAYESPROG_SCRIPT)
        (cwd / "pyagrum_script.py").write_text(PYAGRUM_SCRIPT)
        # a script that loads the bundled student and asks one question, and pyAgrum's
        report["script_question_vs_pyagrum"] = paired(
            [py, "bayesprog_script.py"], [py, "pyagrum_script.py"], args.repeats, cwd)
        # the same where no bytecode is written (PYTHONDONTWRITEBYTECODE=1): the libraries'
        # bytecode is read as installed, and a source checkout of this package without
        # __pycache__ (an editable install) has its modules compiled at every start
        installed = dict(ENV)
        ENV.clear()
        ENV.update(os.environ, PYTHONDONTWRITEBYTECODE="1")
        ENV.pop("PYTHONPYCACHEPREFIX", None)
        report["script_question_vs_pyagrum_no_bytecode_written"] = dict(paired(
            [py, "bayesprog_script.py"], [py, "pyagrum_script.py"], args.repeats, cwd),
            package_bytecode=_has_bytecode())
        ENV.clear()
        ENV.update(installed)
        for ref in ("pyagrum", "pgmpy"):
            report[f"import_vs_{ref}"] = paired([py, "-c", "import bayesprog"],
                                                [py, "-c", f"import {ref}"], args.repeats, cwd)
            ours = [import_time("bayesprog") for _ in range(args.repeats)]
            theirs = [import_time(ref) for _ in range(args.repeats)]
            report[f"importtime_vs_{ref}"] = {
                "bayesprog_s": float(np.median(ours)), "reference_s": float(np.median(theirs)),
                "ratio": float(np.median(ours) / np.median(theirs))}
        # the package with its engine loaded, as a Python session that asks a question has it
        report["engine_import_vs_pyagrum"] = paired(
            [py, "-c", "from bayesprog import Program"], [py, "-c", "import pyagrum"],
            args.repeats, cwd)
        report["cli_question_vs_pyagrum"] = paired(
            [bayesprog, "query", "student.yaml", "P(I | G)", "--evidence", "G=A"],
            [py, "-c", PYAGRUM_QUESTION], args.repeats, cwd)
    for key, value in report.items():
        if isinstance(value, dict):
            paired_ratio = (f"   paired {value['paired_ratio']:.2f}"
                            if "paired_ratio" in value else "")
            print(f"{key:48s} bayesprog {value['bayesprog_s'] * 1000:7.1f} ms   reference "
                  f"{value['reference_s'] * 1000:7.1f} ms   ratio {value['ratio']:.2f}"
                  f"{paired_ratio}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
