"""Forms of installed packages (the ``bayesprog.forms`` entry point group), found by the command
line and by ``bayesprog.load``. Each test runs a fresh interpreter whose path holds a folder
laid out as an installed package is (``NAME-VERSION.dist-info/`` with its ``METADATA`` and
``entry_points.txt``, beside the package's module)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

WAITING = '''\
import numpy as np

import bayesprog
from bayesprog.forms import positive
from bayesprog.forms.base import Estimator


class RateEstimator(Estimator):
    """Maximum likelihood: the weighted count over the weighted sum of the values."""

    learned = ("rate",)

    def statistics(self, term, x, weights, params):
        shape = weights.shape[1:]
        flat = weights.reshape(len(x), -1)
        return {"count": flat.sum(0).reshape(shape),
                "total": (flat * x[:, None]).sum(0).reshape(shape)}

    def estimate(self, term, stats, options, params):
        axes = tuple(p.name for p in term.parents if p.is_discrete)
        return {"rate": bayesprog.ParamValue(axes, stats["count"] / stats["total"])}

    def free_parameters(self, term, params, options):
        return int(np.prod([p.card for p in term.parents if p.is_discrete]))


class Exponential(bayesprog.Form):
    """rate * exp(-rate * x) for x >= 0."""

    name = "exponential"
    child_kinds = ("continuous",)
    params = (bayesprog.Param("rate", positive, doc="events per unit, > 0"),)

    def estimator(self, child):
        return RateEstimator()

    def log_factor(self, ctx):
        x, rate = ctx.child_value(), ctx.param("rate")
        return np.where(x >= 0, np.log(rate) - rate * x, -np.inf)


class FixedExponential(Exponential):
    name = "fixed_exponential"

    def estimator(self, child):
        return None


NOT_A_FORM = {"name": "not_a_form"}
'''

PACKAGES = {
    "bayesprog_waiting-0.1.dist-info": {
        "METADATA": "Metadata-Version: 2.1\nName: bayesprog-waiting\nVersion: 0.1\n",
        "entry_points.txt": "[bayesprog.forms]\n"
                            "exponential = bayesprog_waiting:Exponential\n"
                            "fixed_exponential = bayesprog_waiting:FixedExponential\n"
                            "not_a_form = bayesprog_waiting:NOT_A_FORM\n"
                            "misnamed = bayesprog_waiting:Exponential\n",
    },
    "bayesprog_broken-0.2.dist-info": {
        "METADATA": "Metadata-Version: 2.1\nName: bayesprog-broken\nVersion: 0.2\n",
        "entry_points.txt": "[bayesprog.forms]\nbroken = bayesprog_broken:Broken\n",
    },
}

PROGRAM = """\
bayesprog: 1
variables:
  M: {states: [busy, idle]}
  T: {continuous: [0, .inf]}
decomposition:
  - {term: P(M), form: uniform}
  - {term: P(T | M), form: FORM, rate: {busy: 2.0, idle: 0.5}}
"""

RATES = np.array([2.0, 0.5])


@pytest.fixture
def site(tmp_path):
    """A folder of two installed packages, and a program per form name in ``tmp_path``."""
    folder = tmp_path / "site"
    folder.mkdir()
    for info, files in PACKAGES.items():
        (folder / info).mkdir()
        for name, text in files.items():
            (folder / info / name).write_text(text)
    (folder / "bayesprog_waiting.py").write_text(WAITING)
    (folder / "bayesprog_broken.py").write_text("import a_module_that_is_not_installed\n")
    for form in ("exponential", "fixed_exponential", "exponentail", "broken", "not_a_form",
                 "misnamed"):
        (tmp_path / f"{form}.yaml").write_text(PROGRAM.replace("FORM", form))
    return folder


def _run(site: Path, *argv: str, cwd: Path) -> subprocess.CompletedProcess:
    """``argv`` run by a fresh interpreter with the packages of ``site`` installed."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(site), env.get("PYTHONPATH")) if p)
    return subprocess.run([sys.executable, *argv], capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=120)


def _refused(done: subprocess.CompletedProcess) -> str:
    assert done.returncode == 2, (done.returncode, done.stdout, done.stderr)
    assert "Traceback" not in done.stderr, done.stderr
    return done.stderr


def test_validate_and_query_find_an_installed_packages_form(site, tmp_path):
    done = _run(site, "-m", "bayesprog", "validate", "exponential.yaml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "exponential.yaml: ok"
    done = _run(site, "-m", "bayesprog", "query", "exponential.yaml", "P(M | T=1.5)", "--json",
                cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    answer = json.loads(done.stdout)
    density = RATES * np.exp(-RATES * 1.5)  # the prior over M is uniform
    np.testing.assert_allclose(answer["probabilities"], density / density.sum(), rtol=1e-12)


def test_load_finds_the_form_and_imports_only_its_own_package(site, tmp_path):
    code = ("import sys, bayesprog\n"
            "p = bayesprog.load('exponential.yaml')\n"
            "print(p.ask('P(M | T)', {'T': [0.1, 4.0]}).probabilities.tolist())\n"
            "print('bayesprog_waiting' in sys.modules, 'bayesprog_broken' in sys.modules)")
    done = _run(site, "-c", code, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    probabilities, imported = done.stdout.splitlines()
    t = np.array([[0.1], [4.0]])
    density = RATES * np.exp(-RATES * t)
    np.testing.assert_allclose(json.loads(probabilities), density / density.sum(-1, keepdims=True),
                               rtol=1e-12)
    assert imported == "True False"  # the broken package is never imported


def test_a_program_of_built_in_forms_reads_no_package_metadata(site, tmp_path):
    (tmp_path / "coin.yaml").write_text("bayesprog: 1\nvariables:\n  C: {states: [h, t]}\n"
                                        "decomposition:\n  - {term: P(C), form: uniform}\n")
    code = ("import sys, bayesprog\n"
            "bayesprog.load('coin.yaml').ask('P(C)')\n"
            "print('importlib.metadata' in sys.modules, 'bayesprog.forms.plugins' in sys.modules)")
    done = _run(site, "-c", code, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False False"


def test_learn_fits_a_form_that_has_an_estimator(site, tmp_path):
    t = np.array([0.3, 2.0, 0.1, 1.1, 0.45, 3.5])
    m = ["busy", "idle", "busy", "idle", "busy", "idle"]
    (tmp_path / "waits.csv").write_text("M,T\n" + "".join(f"{a},{b}\n" for a, b in zip(m, t,
                                                                                     strict=True)))
    done = _run(site, "-m", "bayesprog", "learn", "exponential.yaml", "waits.csv", "-o",
                "fitted.yaml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    fitted = yaml.safe_load((tmp_path / "fitted.yaml").read_text())
    rate = fitted["decomposition"][1]["rate"]
    busy = np.array(m) == "busy"
    # maximum likelihood of an exponential: the count over the sum
    np.testing.assert_allclose([rate["busy"], rate["idle"]],
                               [busy.sum() / t[busy].sum(), (~busy).sum() / t[~busy].sum()],
                               rtol=1e-12)


def test_learn_says_a_form_without_an_estimator_cannot_be_learned(site, tmp_path):
    (tmp_path / "waits.csv").write_text("M,T\nbusy,0.3\nidle,2.0\n")
    done = _run(site, "-m", "bayesprog", "learn", "fixed_exponential.yaml", "waits.csv", "-o",
                "fitted.yaml", cwd=tmp_path)
    assert _refused(done).strip() == (
        "bayesprog: term P(T | M) (form fixed_exponential) cannot be learned from data: freeze "
        "it (learn: false) or with --freeze")
    assert not (tmp_path / "fitted.yaml").exists()


def test_a_misspelt_form_is_told_the_closest_name_among_the_installed_packages(site, tmp_path):
    for command in ("validate", "query"):
        argv = ["exponentail.yaml"] + (["P(M | T=1)"] if command == "query" else [])
        message = _refused(_run(site, "-m", "bayesprog", command, *argv, cwd=tmp_path))
        assert "exponentail.yaml:7:28: unknown form 'exponentail': did you mean 'exponential'?" \
            in message
        # every form, the installed packages' with the built-in ones
        assert "fixed_exponential" in message and "normal" in message and "broken" in message


@pytest.mark.parametrize(("form", "why"), [
    ("broken", "form 'broken' comes from the entry point 'broken = bayesprog_broken:Broken' of "
               "package bayesprog-broken 0.2, which cannot be loaded: ModuleNotFoundError: No "
               "module named 'a_module_that_is_not_installed'"),
    ("not_a_form", "form 'not_a_form' comes from the entry point 'not_a_form = "
                   "bayesprog_waiting:NOT_A_FORM' of package bayesprog-waiting 0.1, which gives "
                   "dict {'name': 'not_a_form'}: expected a subclass of bayesprog.Form (or an "
                   "instance of one)"),
    ("misnamed", "form 'misnamed' comes from the entry point 'misnamed = "
                 "bayesprog_waiting:Exponential' of package bayesprog-waiting 0.1, which gives "
                 "the form 'exponential': expected an entry point named after its form "
                 "(exponential = bayesprog_waiting:Exponential)"),
])
def test_a_plugin_that_cannot_give_its_form_is_named_with_its_package(site, tmp_path, form,
                                                                      why):
    for argv in (["validate", f"{form}.yaml"], ["query", f"{form}.yaml", "P(M | T=1)"],
                 ["learn", f"{form}.yaml", "data.csv", "-o", "out.yaml"]):
        message = _refused(_run(site, "-m", "bayesprog", *argv, cwd=tmp_path))
        assert f"{form}.yaml:7:28: {why}" in message, message


def test_a_plugin_that_cannot_give_its_form_leaves_the_other_forms_working(site, tmp_path):
    code = ("import bayesprog\n"
            "try:\n"
            "    bayesprog.load('broken.yaml')\n"
            "except bayesprog.SpecError as exc:\n"
            "    print('refused:', 'bayesprog-broken 0.2' in str(exc))\n"
            "print(bayesprog.load('exponential.yaml').ask('P(M | T=1.5)').probabilities.tolist())")
    done = _run(site, "-c", code, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    refused, probabilities = done.stdout.splitlines()
    assert refused == "refused: True"
    density = RATES * np.exp(-RATES * 1.5)
    np.testing.assert_allclose(json.loads(probabilities), density / density.sum(), rtol=1e-12)
