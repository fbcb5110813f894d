"""The ``bayesprog`` command line: validate, show, graph, query, sample, learn, import, export,
schema, examples. An application adds its own commands: every runner plugin found through the
``bayesprog.runners`` entry point group is asked for them (its ``add_commands(subparsers)``).

User errors print ``bayesprog: ...`` (or ``FILE:LINE:COL: ...`` lines) on stderr and exit with
status 2, never with a traceback.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import textwrap
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.errors import BayesprogError, SpecError

if TYPE_CHECKING:
    from bayesprog.program import Program

EXIT_USER_ERROR = 2


class _UserError(Exception):
    pass


def _load(name: str) -> Program:
    """The program file ``name``, or the bundled program of that name."""
    from bayesprog.bundled import bundled_path
    from bayesprog.program import load

    path = str(bundled_path(name, "program"))
    try:
        return load(path)
    except SpecError:
        hint = _kind_hint(path)
        if hint:
            raise _UserError(hint) from None
        raise
    except FileNotFoundError:
        raise _UserError(f"cannot read {path}: no such file, and no bundled program of that "
                         "name (bayesprog examples lists them)") from None
    except IsADirectoryError:
        raise _UserError(f"cannot read {path}: it is a directory") from None
    except UnicodeDecodeError:
        raise _UserError(f"cannot read {path}: expected UTF-8 text") from None


def _ablated(program: Program, terms: Sequence[str]) -> Program:
    """``program`` with each ``--ablate`` term uniform."""
    for term in terms:
        try:
            program = program.ablate(term)
        except BayesprogError as exc:
            raise _UserError(f"--ablate {term!r}: {exc}") from None
    return program


def _kind_hint(file: str) -> str | None:
    """Why a file is not a program, when it is plainly another kind of file."""
    from bayesprog.files import wrong_kind

    return wrong_kind(file, "program", "this command reads programs; `bayesprog run` reads "
                      "experiments and their scenarios")


def _plugin_validate(file: str, kind: str) -> list[str] | None:
    """The warnings of a file of another kind than a program, checked by the runner plugin
    that knows that kind (its module's ``validate(path, kind)``); None when none does."""
    for _, plugin in _plugins(quiet=True):
        check = getattr(plugin, "validate", None)
        found = check(file, kind) if check is not None else None
        if found is not None:
            return list(found)
    return None


def cmd_validate(args: argparse.Namespace) -> int:
    from bayesprog.bundled import bundled_path
    from bayesprog.files import KINDS, file_kind

    problems = 0
    for name in args.files:
        file = str(bundled_path(name))
        kind = file_kind(file) if Path(file).is_file() else None
        if kind is not None and kind != KINDS["bayesprog"]:  # not a program: a plugin's file
            try:
                warnings = _plugin_validate(file, kind)
            except SpecError as exc:
                problems += len(exc.diagnostics)
                for d in exc.diagnostics:
                    print(d, file=sys.stderr)
                continue
            except BayesprogError as exc:
                problems += 1
                print(f"bayesprog: {file}: {exc}", file=sys.stderr)
                continue
            if warnings is not None:
                for warning in warnings:
                    print(warning, file=sys.stderr)
                if not args.quiet:
                    print(f"{file}: ok ({kind})")
                continue
        try:
            _load(file)
        except _UserError as exc:  # not a program (another kind of file), or unreadable
            problems += 1
            print(f"bayesprog: {exc}", file=sys.stderr)
            continue
        except SpecError as exc:
            problems += len(exc.diagnostics)
            for d in exc.diagnostics:
                print(d, file=sys.stderr)
            continue
        if not args.quiet:
            print(f"{file}: ok")
    return EXIT_USER_ERROR if problems else 0


def cmd_examples(args: argparse.Namespace) -> int:
    from bayesprog.bundled import bundled_root, find, listing

    entries = listing()
    # the name that designates each one: its short name where that finds it, else its path
    names = [e.short if find(e.short) == e.path else e.name for e in entries]
    if args.json:
        print(json.dumps([{"name": n, "kind": e.kind, "path": str(e.path),
                           "description": e.description} for n, e in zip(names, entries,
                                                                         strict=True)],
                         indent=2))
        return 0
    width = max(len(n) for n in names)
    print(f"bundled models, in {bundled_root()}")
    print("(run or query one by its name; bayesprog examples copy NAME DIR copies it out)")
    kind = None
    for name, entry in zip(names, entries, strict=True):
        if entry.kind != kind:
            kind = entry.kind
            print(f"\n{kind}s:" if kind != "data" else "\ndata:")
        description = textwrap.shorten(entry.description, 96 - width, placeholder="...")
        print(f"  {name:<{width}}  {description}")
    return 0


def cmd_examples_copy(args: argparse.Namespace) -> int:
    from bayesprog.bundled import copy

    folder = Path(args.folder)
    if folder.exists() and not folder.is_dir():
        raise _UserError(f"{folder}: not a folder")
    written = copy(args.name, folder, force=args.force)
    print(f"copied {args.name} into {folder}:")
    for path in written:
        print(f"  {path}")
    return 0


def _renames(items: Sequence[str]) -> dict[str, str]:
    columns: dict[str, str] = {}
    for item in items:
        column, eq, variable = item.partition("=")
        if not eq or not column.strip() or not variable.strip():
            raise _UserError(f"--column {item!r}: expected COLUMN=VARIABLE")
        if column.strip() in columns:
            raise _UserError(f"--column {column.strip()} is given twice: expected each column "
                             "once")
        columns[column.strip()] = variable.strip()
    return columns


def cmd_discover(args: argparse.Namespace) -> int:
    from bayesprog.bundled import bundled_path
    from bayesprog.discovery import discover

    data = str(bundled_path(args.data, "data"))
    out = Path(args.output)
    if out.exists() and out.resolve() == Path(data).resolve():
        raise _UserError(f"-o {args.output}: that is the data file; expected a new program file")
    if out.suffix not in (".yaml", ".yml"):
        raise _UserError(f"-o {args.output}: expected a .yaml program file")
    if not np.isfinite(args.significance) or not 0 < args.significance < 1:
        raise _UserError(f"--significance: expected a number in (0, 1), found "
                         f"{args.significance}")
    if not (np.isfinite(args.ess) and args.ess > 0):
        raise _UserError(f"--ess: expected a number > 0, found {args.ess}")
    for option, value in (("--max-conditioning", args.max_conditioning),
                          ("--restarts", args.restarts), ("--tabu", args.tabu),
                          ("--max-parents", args.max_parents), ("--seed", args.seed)):
        if value is not None and value < 0:
            raise _UserError(f"{option}: expected a number >= 0, found {value}")
    if args.discretise is not None and args.discretise < 2:
        raise _UserError(f"--discretise: expected a number of bins >= 2, found {args.discretise}")
    for option, value in (("--score", args.score), ("--start", args.start),
                          ("--max-parents", args.max_parents), ("--restarts", args.restarts)):
        if args.method == "pc" and value is not None:
            raise _UserError(f"{option} applies to hill climbing (--method hc), not to pc")
    start = _load(args.start) if args.start else None
    found = discover(data, method=args.method, score=args.score or "bic",
                     equivalent_sample_size=args.ess, test=args.test,
                     significance=args.significance, max_conditioning=args.max_conditioning,
                     forbid=args.forbid, require=args.require, tiers=args.tiers,
                     max_parents=args.max_parents, start=start, restarts=args.restarts,
                     tabu=args.tabu, seed=args.seed, discretise=args.discretise,
                     columns=_renames(args.column) or None, name=args.name or out.stem)
    try:
        found.save(out)
    except OSError as exc:
        raise _UserError(f"cannot write {args.output}: {exc.strerror or exc}") from None
    record = found.record.structure
    arcs = sum(len(ps) for ps in found.parents.values())
    how = (f"score {record.score} {record.score_value:.6g}, {record.iterations} operations"
           if record.method == "hc" else
           f"{record.tests} {record.test} tests at {record.significance:g}"
           + (f", {len(record.oriented_by_choice)} arcs oriented by choice"
              if record.oriented_by_choice else ""))
    print(f"wrote {out}: {len(found.parents)} variables, {arcs} arcs ({record.method}, {how})")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from bayesprog.bundled import bundled_path
    from bayesprog.learning.evidence import compare

    if len(args.files) < 2:
        raise _UserError("compare: expected one or more programs, then the data file")
    *files, data = args.files
    if not np.isfinite(args.ess) or args.ess <= 0:
        raise _UserError(f"--ess: expected a number > 0, found {args.ess}")
    programs = [_load(f) for f in files]
    rows = compare(programs, str(bundled_path(data, "data")), score=args.score,
                   equivalent_sample_size=args.ess, names=files)
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    width = max(len(r["program"]) for r in rows)
    print(f"{'program':<{width}}  {'log evidence':>14}  {'log BF':>10}  method")
    for r in rows:
        factor = r["log_bayes_factor"] if abs(r["log_bayes_factor"]) >= 5e-5 else 0.0
        print(f"{r['program']:<{width}}  {r['log_evidence']:>14.4f}  "
              f"{factor:>10.4f}  {r['method']}")
    print(f"(natural logarithms; {rows[0]['rows']} rows; the Bayes factor is against the best)")
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    from bayesprog.show import render

    print(render(_ablated(_load(args.file), args.ablate)))
    return 0


def cmd_graph(args: argparse.Namespace) -> int:
    from bayesprog.draw import write_graph

    program = _load(args.file)
    out = Path(args.output)
    if out.suffix.lower() not in (".dot", ".png", ".pdf", ".svg"):
        raise _UserError(f"-o {args.output}: expected a .dot, .png, .pdf or .svg file")
    question = program.question(args.question) if args.question else None
    write_graph(program, out, question=question)
    print(f"wrote {out}")
    return 0


def _pairs(items: Sequence[str], option: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or not name or not value:
            raise _UserError(f"{option} {item!r}: expected NAME=VALUE")
        name = name.strip()
        if name in out:
            raise _UserError(f"{option} {name} is given twice ({name}={out[name]} and "
                             f"{item.strip()}): expected each name once{_ONCE.get(option, '')}")
        out[name] = value.strip()
    return out


#: how to give several values where one option takes one value per name
_ONCE = {
    "--evidence": "; for a batch of rows, VAR=FILE.npy; for one value per step of a program "
                  "over time, VAR=v1,v2,... with --over-time",
    "--soft": " (one likelihood per variable: VAR=p1,p2,...)",
    "--input": " (one array per input: NAME=FILE.npy, with a batch axis for several rows)",
}


def _npy(path: str, option: str) -> np.ndarray:
    try:
        return np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise _UserError(f"{option}: cannot read {path}: no such file") from None
    except IsADirectoryError:
        raise _UserError(f"{option}: cannot read {path}: it is a directory") from None
    except (ValueError, OSError, EOFError):
        raise _UserError(f"{option}: cannot read {path} as an array: expected a .npy file "
                         "of numbers written by numpy.save") from None


def _evidence_value(text: str) -> object:
    """A ``.npy`` file (arrays: fields, batches), else the text: a state, a value or an index,
    read by the engine according to the variable's kind."""
    if text.endswith(".npy"):
        return _npy(text, "--evidence")
    return text


def _check_seed(seed: int) -> int:
    if seed < 0:
        raise _UserError(f"--seed: expected a non-negative integer, found {seed}")
    return seed


def cmd_query(args: argparse.Namespace) -> int:
    _check_seed(args.seed)
    if args.limit < 1:
        raise _UserError(f"--limit: expected at least 1 row, found {args.limit}")
    program = _ablated(_load(args.file), args.ablate)
    inputs = {k: _npy(v, "--input") for k, v in _pairs(args.input, "--input").items()}
    evidence = {k: _evidence_value(v) for k, v in _pairs(args.evidence, "--evidence").items()}
    kind = args.over_time or ("map" if args.map else None)
    if args.over_time and args.map:
        raise _UserError("--map and --over-time: expected one of them (--over-time sequence "
                         "asks the most likely sequence)")
    named = program.question(args.question).kind
    if args.map and named in ("filter", "smooth", "sequence"):
        raise _UserError(f"--map: {args.question!r} is a {named} question over steps; leave "
                         "out --map (--over-time sequence asks the most likely sequence)")
    if (kind or named) in ("filter", "smooth", "sequence"):
        # evidence over steps: one value per step, separated by commas
        evidence = {k: v.split(",") if isinstance(v, str) else v for k, v in evidence.items()}
    else:
        _no_steps(program, evidence)
    soft = {}
    for name, text in _pairs(args.soft, "--soft").items():
        if text.endswith(".npy"):  # a batch of likelihoods, or one per step over time
            soft[name] = np.asarray(_npy(text, "--soft"), dtype=float)
            continue
        try:
            soft[name] = np.array([float(x) for x in text.split(",")])
        except ValueError:
            raise _UserError(f"--soft {name}={text}: expected numbers separated by commas, or "
                             "FILE.npy") from None
    if args.samples < 1:
        raise _UserError(f"--samples: expected at least 1, found {args.samples}")
    if args.burn_in < 0 or args.thin < 1:
        raise _UserError(f"--burn-in: expected at least 0, found {args.burn_in}"
                         if args.burn_in < 0 else
                         f"--thin: expected at least 1, found {args.thin}")
    result = program.ask(
        args.question,
        evidence,
        inputs=inputs,
        soft=soft,
        kind=kind,
        rng=args.seed,
        method=None if args.method == "auto" else args.method,
        samples=args.samples,
        bins=args.bins,
        burn_in=args.burn_in if args.method == "gibbs" else None,
        thin=args.thin if args.method == "gibbs" else None,
    )
    from bayesprog.show import format_result

    if args.plot:
        _plot_density(result, args.plot)

    if args.json:
        print(json.dumps(result.to_json()))
    else:
        print(format_result(result, limit=args.limit))
    return 0


def _no_steps(program: Program, evidence: dict[str, object]) -> None:
    """A comma list given to a question that is not over steps: say how to ask one that is."""
    for name, value in evidence.items():
        if not isinstance(value, str) or "," not in value:
            continue
        var = program.variables.get(name)
        if var is not None and var.is_discrete and value in var.states:  # type: ignore[union-attr]
            continue  # a state whose name has a comma
        if program.time is not None:
            raise _UserError(
                f"--evidence {name}={value}: one value per step (separated by commas) is read "
                "by a question over steps: add --over-time filter|smooth|sequence (or ask a "
                "named question of one of these kinds)")
        raise _UserError(
            f"--evidence {name}={value}: expected one value; values separated by commas are "
            "steps, for a program that repeats over time (a time: section) with --over-time; "
            f"for a batch of rows, give {name}=FILE.npy")


def _plot_density(result: Any, path: str) -> None:
    """The density of each searched real variable (the first batch row), to an image file."""
    from bayesprog.inference.density import Density

    if not isinstance(result, Density):
        raise _UserError("--plot: expected a question on real variables (a density); this one "
                         "searches discrete variables")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(result.variables), figsize=(5 * len(result.variables), 3.5),
                             squeeze=False)
    for ax, v in zip(axes[0], result.variables, strict=True):
        lo, hi = (float(np.ravel(result.quantile(v, q))[0]) for q in (0.0005, 0.9995))
        pad = 0.1 * (hi - lo or 1.0)
        x = np.linspace(lo - pad, hi + pad, 801)
        ax.plot(x, np.asarray(result.pdf(v, x)).reshape(-1, x.size)[0])
        ax.axvline(float(np.ravel(result.mean(v))[0]), color="k", lw=0.8, ls="--",
                   label="mean")
        ax.set_xlabel(v)
        ax.set_ylabel("density")
        ax.legend(frameon=False)
    fig.suptitle(result.question)
    fig.tight_layout()
    try:
        fig.savefig(path)
    except (OSError, ValueError) as exc:
        raise _UserError(f"--plot {path}: cannot write it: {exc}") from None
    finally:
        plt.close(fig)


def cmd_sample(args: argparse.Namespace) -> int:
    _check_seed(args.seed)
    if args.n < 1:
        raise _UserError(f"-n: expected at least 1 draw, found {args.n}")
    out = Path(args.output)
    if out.suffix.lower() not in (".csv", ".parquet"):
        raise _UserError(f"-o {args.output}: expected a .csv or .parquet file")
    if out.suffix.lower() == ".parquet":
        from bayesprog.extras import require_extra

        require_extra("pyarrow", "parquet", f"writing {args.output}")
    program = _ablated(_load(args.file), args.ablate)
    inputs = {k: _npy(v, "--input") for k, v in _pairs(args.input, "--input").items()}
    evidence = {k: _evidence_value(v) for k, v in _pairs(args.evidence, "--evidence").items()}
    draws = program.sample(args.n, evidence, inputs=inputs, rng=args.seed, method=args.method)
    try:
        if out.suffix.lower() == ".csv":
            draws.to_csv(out, index=False)
        else:
            draws.to_parquet(out, index=False)
    except OSError as exc:
        raise _UserError(f"cannot write {args.output}: {exc.strerror or exc}") from None
    weighted = " (weighted: the column weight)" if "weight" in draws.columns else ""
    print(f"wrote {out}: {len(draws)} draws of {', '.join(c for c in draws.columns if c != 'weight')}"
          f"{weighted}")
    return 0


def cmd_learn(args: argparse.Namespace) -> int:
    if args.max_iter < 1:
        raise _UserError(f"--max-iter: expected at least 1, found {args.max_iter}")
    from bayesprog.bundled import bundled_path

    program = _load(args.file)
    args.data = str(bundled_path(args.data, "data"))
    if Path(args.output).resolve() == Path(args.data).resolve():
        raise _UserError(f"-o {args.output}: that is the data file; expected a new program file")
    if not (args.tol >= 0 and np.isfinite(args.tol)):
        raise _UserError(f"--tol: expected a number >= 0, found {args.tol}")
    columns = _renames(args.column)
    fit = program.fit(args.data, freeze=args.freeze, max_iter=args.max_iter, tol=args.tol,
                      columns=columns or None, states_from_data=args.states_from_data)
    try:
        out = fit.save(args.output)
    except OSError as exc:
        raise _UserError(f"cannot write {args.output}: {exc.strerror or exc}") from None
    record = fit.record
    iterations = f", {record.iterations} iterations" if record.iterations > 1 else ""
    print(f"{out}: {', '.join(record.terms)} learned from {record.rows_used} of {record.rows} "
          f"rows of {record.data} ({record.method}{iterations}); log-likelihood "
          f"{record.log_likelihood:.6g}; values written to the precision "
          f"{record.rows_supporting} rows support ({record.digits} significant digits, means to "
          "a twentieth of their standard error)")
    if not fit.converged:
        print(f"bayesprog: EM stopped after {args.max_iter} iterations before converging "
              "(raise --max-iter)", file=sys.stderr)
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    from bayesprog.io import import_network

    out = import_network(args.network, args.output)
    _load(str(out))  # what we write must load
    print(f"wrote {out}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from bayesprog.io import export_program

    program = _ablated(_load(args.file), args.ablate)
    print(f"wrote {export_program(program, args.output)}")
    return 0


def cmd_schema(args: argparse.Namespace) -> int:
    from bayesprog.language.json_schema import json_schema

    text = json.dumps(json_schema(), indent=2) + "\n"
    if args.output:
        Path(args.output).write_text(text, encoding="utf-8")
    else:
        sys.stdout.write(text)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="bayesprog",
        description="Bayesian programs as YAML files: check, show, draw and ask them questions.",
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("validate", help="check program files; list every problem")
    p.add_argument("files", nargs="+", metavar="FILE",
                   help="programs, and any file a runner plugin knows (scenarios, "
                        "experiments, sensor models), told apart by their first key")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="print nothing for valid files (default: print FILE: ok)")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser("show", help="print a program in Bayesian-programming notation")
    p.add_argument("file", metavar="FILE", help="a program file, or the name of a bundled "
                   "one (bayesprog examples)")
    p.add_argument("--ablate", action="append", default=[], metavar="TERM",
                   help='show the program with this term uniform, e.g. "P(S | M)"; repeatable '
                   "(default: none)")
    p.set_defaults(func=cmd_show)

    p = sub.add_parser("graph", help="draw the graphical model (.dot, .png, .pdf, .svg)")
    p.add_argument("file", metavar="FILE", help="a program file, or the name of a bundled "
                   "one (bayesprog examples)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="the drawing: .dot (Graphviz text), .png, .pdf or .svg")
    p.add_argument("--question", help="shade the known variables of this question (a name of "
                   "the file's, or P(searched | known)); default: none")
    p.set_defaults(func=cmd_graph)

    p = sub.add_parser("query", help='ask a question, e.g. "P(A B | C=c1, D=0.3)"')
    p.add_argument("file", metavar="FILE", help="a program file, or the name of a bundled "
                   "one (bayesprog examples)")
    p.add_argument("question", help="a named question of the file, or P(searched | known)")
    p.add_argument("--map", action="store_true",
                   help="the joint argmax instead of the posterior (default: the posterior)")
    p.add_argument("--over-time", choices=["filter", "smooth", "sequence"],
                   help="a program with time: the state at every step, from the steps so far "
                   "(filter) or from all (smooth), or the most likely sequence; evidence as "
                   "VAR=v1,v2,... (default: the question's own kind)")
    p.add_argument("--ablate", action="append", default=[], metavar="TERM",
                   help='replace a term by a uniform, e.g. --ablate "P(S | O, T)"; repeatable '
                   "(default: none)")
    p.add_argument("--input", action="append", default=[], metavar="NAME=FILE.npy",
                   help="bind a runtime input to an array; repeatable (default: none)")
    p.add_argument("--evidence", action="append", default=[], metavar="VAR=VALUE",
                   help="evidence for a known variable: a state, a number, or FILE.npy "
                   "(an array: a field, or a batch of values); repeatable (default: none)")
    p.add_argument("--soft", action="append", default=[], metavar="VAR=p1,p2,...",
                   help="soft evidence: one likelihood per state of VAR, or VAR=FILE.npy (a "
                   "batch, or one per step with --over-time) (default: none)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed for breaking MAP ties and for sampling (default: %(default)s)")
    p.add_argument("--method", default="auto",
                   choices=["auto", "table", "contraction", "gaussian", "lbp", "lw", "gibbs",
                            "grid", "pf"],
                   help="auto: the cheapest exact method (with unknown real variables that are "
                   "not linear-Gaussian: grid); table, contraction, gaussian: exact; lbp: loopy "
                   "belief propagation; lw: likelihood weighting, with standard errors; gibbs: "
                   "Gibbs sampling, with standard errors from batch means; grid: unknown real "
                   "variables on bins, with estimated errors; pf: a particle filter, for a "
                   "filter question over real states (default: %(default)s)")
    p.add_argument("--samples", type=int, default=10_000,
                   help="draws per evidence set for --method lw, kept sweeps for gibbs, "
                   "particles per sequence for pf (default: %(default)s)")
    p.add_argument("--burn-in", type=int, default=1_000, metavar="N",
                   help="gibbs: sweeps forgotten before any is kept (default: %(default)s)")
    p.add_argument("--thin", type=int, default=1, metavar="K",
                   help="gibbs: keep one sweep in K (default: %(default)s)")
    p.add_argument("--bins", type=int, default=None,
                   help="bins per unknown real variable for the grid method (default: 128; "
                   "the answer uses twice as many and estimates its error from the change)")
    p.add_argument("--plot", metavar="FILE.png",
                   help="a question on real variables: draw each one's density to FILE "
                   "(default: no plot)")
    p.add_argument("--limit", type=int, default=20,
                   help="rows shown for large tables (default: %(default)s)")
    p.add_argument("--json", action="store_true",
                   help="print JSON (with log_evidence) instead of a table (default: a table)")
    p.set_defaults(func=cmd_query)

    p = sub.add_parser("sample", help="draw joint samples of a program to CSV or Parquet")
    p.add_argument("file", metavar="FILE", help="a program file, or the name of a bundled "
                   "one (bayesprog examples)")
    p.add_argument("-n", type=int, required=True, metavar="N", help="number of draws")
    p.add_argument("-o", "--output", required=True, metavar="OUT.csv|.parquet",
                   help="one column per variable, states by name; its format from the "
                   "extension")
    p.add_argument("--evidence", action="append", default=[], metavar="VAR=VALUE",
                   help="condition on a known variable; repeatable (default: none)")
    p.add_argument("--method", choices=["forward", "lw", "rejection"],
                   help="forward (no evidence), lw (weighted draws, a weight column) or "
                   "rejection (discrete evidence) (default: forward, or lw with evidence)")
    p.add_argument("--input", action="append", default=[], metavar="NAME=FILE.npy",
                   help="bind a runtime input to an array; repeatable (default: none)")
    p.add_argument("--ablate", action="append", default=[], metavar="TERM",
                   help="draw with this term uniform; repeatable (default: none)")
    p.add_argument("--seed", type=int, default=0, help="seed of the draws (default: %(default)s)")
    p.set_defaults(func=cmd_sample)

    p = sub.add_parser("learn", help="learn a program's parameters from data (CSV or Parquet)")
    p.add_argument("file", metavar="PROGRAM.yaml", help="the program whose parameters to learn")
    p.add_argument("data", metavar="DATA.csv|.parquet",
                   help="one column per variable; empty cells are missing values")
    p.add_argument("-o", "--output", required=True, metavar="FITTED.yaml",
                   help="the fitted program: the input file with learned values and the fit's "
                   "record")
    p.add_argument("--freeze", action="append", default=[], metavar="TERM",
                   help='keep a term as written, e.g. --freeze "P(M)"; repeatable (default: '
                   "the terms marked learn: false)")
    p.add_argument("--max-iter", type=int, default=200,
                   help="most EM iterations (default: %(default)s)")
    p.add_argument("--tol", type=float, default=1e-8,
                   help="EM stops when the log-likelihood gains less than this, relative "
                   "(default: %(default)s)")
    p.add_argument("--column", action="append", default=[], metavar="COLUMN=VARIABLE",
                   help="read the data's column COLUMN as the variable VARIABLE, e.g. --column "
                   "material=M; repeatable (default: columns named like the variables)")
    p.add_argument("--states-from-data", action="append", default=[], metavar="VARIABLE",
                   help="the variable takes the states found in its column (sorted), the terms "
                   "over it learned anew, e.g. a lab's own materials; repeatable (default: the "
                   "states declared)")
    p.set_defaults(func=cmd_learn)

    p = sub.add_parser("discover", help="discover a program's decomposition from data (hill "
                       "climbing or PC), its tables fitted")
    p.add_argument("data", metavar="DATA.csv|.parquet",
                   help="one column per variable (its states are the values found); empty "
                   "cells are missing values")
    p.add_argument("-o", "--output", required=True, metavar="PROGRAM.yaml",
                   help="the discovered program, its tables fitted, with a learned: record")
    p.add_argument("--method", choices=("hc", "pc"), default="hc",
                   help="hc: hill climbing on a score; pc: the stable PC algorithm "
                   "(default: %(default)s)")
    p.add_argument("--score", choices=("bic", "bdeu", "k2"),
                   help="hc: the score climbed (default: bic)")
    p.add_argument("--ess", type=float, default=10.0, metavar="X",
                   help="bdeu: the equivalent sample size of its prior (default: %(default)s)")
    p.add_argument("--test", choices=("chi2", "g"), default="chi2",
                   help="pc: the independence test, Pearson's chi-square or the G-test "
                   "(default: %(default)s)")
    p.add_argument("--significance", type=float, default=0.01, metavar="A",
                   help="pc: an edge goes when a test's p-value is at least A (default: "
                   "%(default)s)")
    p.add_argument("--max-conditioning", type=int, default=5, metavar="K",
                   help="pc: the largest conditioning set tested (default: %(default)s)")
    p.add_argument("--forbid", action="append", default=[], metavar="A->B",
                   help="no arc from A to B; repeatable (default: none)")
    p.add_argument("--require", action="append", default=[], metavar="A->B",
                   help="an arc from A to B in any case; repeatable (default: none)")
    p.add_argument("--tiers", metavar="FILE",
                   help="ordered groups of variables, one group per line (or a YAML list of "
                   "lists): no arc from a later group into an earlier one (default: none)")
    p.add_argument("--max-parents", type=int, metavar="K",
                   help="hc: at most K parents per variable (default: no limit but the size "
                   "of a family's table)")
    p.add_argument("--start", metavar="PROGRAM.yaml",
                   help="hc: start from this program's decomposition (default: no arc)")
    p.add_argument("--restarts", type=int, metavar="N",
                   help="hc: random restarts, from the best graph perturbed or from the start "
                   "with ties broken otherwise (default: 5)")
    p.add_argument("--tabu", type=int, default=100, metavar="N",
                   help="hc: the last N operations may not be undone (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, metavar="N",
                   help="hc: seed of the restarts (default: %(default)s)")
    p.add_argument("--discretise", type=int, metavar="K",
                   help="cut each column of numbers with more than K values into K bins of "
                   "equal counts (default: every value is a state)")
    p.add_argument("--column", action="append", default=[], metavar="COLUMN=VARIABLE",
                   help="name the variable of column COLUMN otherwise; repeatable")
    p.add_argument("--name", help="the program's name (default: the output file's stem)")
    p.set_defaults(func=cmd_discover)

    p = sub.add_parser("compare", help="compare programs by their evidence of a data set "
                       "(log marginal likelihood, Bayes factors)")
    p.add_argument("files", nargs="+", metavar="PROGRAM.yaml ... DATA",
                   help="the programs, then the data (CSV or Parquet) last")
    p.add_argument("--score", choices=("bdeu", "k2"), default="bdeu",
                   help="the tables' Dirichlet prior: BDeu or K2 (default: %(default)s)")
    p.add_argument("--ess", type=float, default=1.0, metavar="X",
                   help="bdeu: the equivalent sample size of its prior (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print the table as JSON")
    p.set_defaults(func=cmd_compare)

    p = sub.add_parser("import", help="convert a BIF, XMLBIF or UAI network into a program file")
    p.add_argument("network", metavar="FILE.bif|.xmlbif|.uai",
                   help="a network file (optionally .gz)")
    p.add_argument("-o", "--output", required=True, metavar="OUT.yaml",
                   help="the program file to write")
    p.set_defaults(func=cmd_import)

    p = sub.add_parser("export", help="write a discrete program as BIF, XMLBIF or UAI")
    p.add_argument("file", metavar="FILE", help="a discrete program with literal tables")
    p.add_argument("-o", "--output", required=True, metavar="OUT.bif|.xmlbif|.uai",
                   help="the network file; its format from the extension")
    p.add_argument("--ablate", action="append", default=[], metavar="TERM",
                   help="write the program with this term uniform; repeatable (default: none)")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("examples", help="list the bundled models (the paper's experiment, "
                       "example programs), or copy one out to edit")
    p.add_argument("--json", action="store_true",
                   help="the list as JSON: name, kind, path, description (default: a table)")
    p.set_defaults(func=cmd_examples)
    actions = p.add_subparsers(dest="action", metavar="ACTION",
                               help="copy: copy one out (default: list them)")
    c = actions.add_parser("copy", help="copy a bundled model, with every file it names, "
                           "into a folder")
    c.add_argument("name", metavar="NAME", help="a name that bayesprog examples lists")
    c.add_argument("folder", metavar="DIR", help="the folder to copy into (made if missing); "
                   "the files keep their layout, so relative references still hold")
    c.add_argument("--force", action="store_true",
                   help="overwrite files that exist (default: refuse)")
    c.set_defaults(func=cmd_examples_copy)

    p = sub.add_parser("schema", help="print the JSON Schema of program files")
    p.add_argument("-o", "--output", metavar="FILE",
                   help="write the schema there (default: print it)")
    p.set_defaults(func=cmd_schema)
    _plugin_commands(sub)
    return parser


def _plugins(quiet: bool = False) -> Iterator[tuple[str, Any]]:
    """The runner plugins of the ``bayesprog.runners`` entry point group, by name, loaded; one
    that cannot be loaded is left out, and says why on stderr unless ``quiet``."""
    from importlib.metadata import entry_points

    for ep in sorted(entry_points(group="bayesprog.runners"), key=lambda ep: ep.name):
        try:
            plugin = ep.load()
        except Exception as exc:  # a broken plugin must not take the framework's CLI down
            if not quiet:
                print(f"bayesprog: runner {ep.name!r} not loaded: {exc}", file=sys.stderr)
            continue
        yield ep.name, plugin


def _plugin_commands(sub: argparse._SubParsersAction) -> None:
    """The commands runner plugins add (their module's ``add_commands(subparsers)``); a plugin
    that cannot be loaded adds none, and says why on stderr."""
    for name, plugin in _plugins():
        add = getattr(plugin, "add_commands", None)
        if add is None:
            continue
        try:
            add(sub)
        except argparse.ArgumentError as exc:  # e.g. a command the framework has already
            print(f"bayesprog: runner {name!r}: {exc}", file=sys.stderr)


def _version() -> str:
    from bayesprog import __version__

    return f"bayesprog {__version__}"


#: The exit status when the reader of the output went away (a shell's for SIGPIPE, 128 + 13),
#: and when the command was asked to stop (SIGTERM, 128 + 15).
EXIT_CLOSED_PIPE = 141
EXIT_TERMINATED = 143


class _Terminated(BaseException):
    """SIGTERM, raised where the command is, so that it stops as after Ctrl-C: its workers
    stopped, what is finished kept, its files and semaphores released."""


def _terminate(signum: int, frame: Any) -> None:
    if not _in_finaliser(frame, signum):
        raise _Terminated()


def _interrupt(signum: int, frame: Any) -> None:
    """Ctrl-C, raised where the command is; but not inside a finaliser (see below)."""
    if not _in_finaliser(frame, signum):
        raise KeyboardInterrupt


#: the files whose functions run as finalisers: weakref callbacks, multiprocessing's Finalize
_FINALISERS = ("weakref.py", "multiprocessing/util.py", "multiprocessing\\util.py")


def _in_finaliser(frame: Any, signum: int) -> bool:
    """Whether the signal arrived while a finaliser runs (a ``__del__``, a weakref callback,
    multiprocessing's cleanup of a lock or a queue). An exception raised there would be printed
    and lost, and the finaliser cut short (a semaphore left registered, reported as leaked at
    exit): the signal is then sent again a moment later, once the finaliser has returned."""
    while frame is not None:
        code = frame.f_code
        if code.co_name == "__del__" or code.co_filename.endswith(_FINALISERS):
            _send_again(signum)
            return True
        frame = frame.f_back
    return False


def _send_again(signum: int) -> None:
    import signal
    import threading

    # a real signal, not a flag: it also wakes a main thread blocked in a system call
    again = threading.Timer(_AGAIN_AFTER, signal.pthread_kill,
                            (threading.main_thread().ident, signum))
    again.daemon = True
    again.start()


def _deliver_again(unraisable: Any) -> None:
    """``sys.unraisablehook`` while a command runs. Python cannot raise from a finaliser or a
    weakref callback: a Ctrl-C or SIGTERM that lands in one would be printed as "Exception
    ignored in ..." and lost, and the command would go on. Such a stop is sent to the main
    thread again a moment later, once the finaliser has returned, to be raised where the command
    is (a signal that lands in a finaliser again is sent again); anything else is reported as
    Python does. (The signal handlers themselves send a stop again when it arrives inside a
    finaliser; this catches what they cannot see, such as a stop raised by other code.)"""
    import signal

    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        _send_again(signal.SIGINT)
    elif isinstance(unraisable.exc_value, _Terminated):
        _send_again(signal.SIGTERM)
    else:
        sys.__unraisablehook__(unraisable)


#: seconds after which a stop that landed in a finaliser is sent again
_AGAIN_AFTER = 0.01


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 2 user error, 130 interrupted,
    141 when the output's reader closed the pipe, as ``bayesprog query ... | head``, 143 when
    terminated)."""
    import signal
    import threading

    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if main_thread else None
    previous_int = signal.getsignal(signal.SIGINT)
    previous_hook = sys.unraisablehook
    if main_thread:
        if previous_int is signal.default_int_handler:  # (an ignored Ctrl-C stays ignored)
            signal.signal(signal.SIGINT, _interrupt)
        sys.unraisablehook = _deliver_again
    try:
        return _main(argv)
    except _Terminated:
        print("bayesprog: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except BrokenPipeError:
        # the reader is gone: nothing more can be said to it, and the interpreter must not
        # complain when it flushes standard output at exit
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return EXIT_CLOSED_PIPE
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)
            signal.signal(signal.SIGINT, previous_int)
            sys.unraisablehook = previous_hook


def command() -> int:
    """The ``bayesprog`` program (and ``python -m bayesprog``): :func:`main`, then the heap it
    leaves is frozen, so that the interpreter's last collections at exit do not visit every
    object the command's imports made (a third of a second after a report); what the command
    wrote is closed by then."""
    import gc

    status = main()
    gc.freeze()
    return status


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse has printed the usage and the problem
        return int(exc.code or 0)
    try:
        status = int(args.func(args))
        sys.stdout.flush()  # a closed pipe is found here, not at the interpreter's exit
        return status
    except SpecError as exc:
        for d in exc.diagnostics:
            print(d, file=sys.stderr)
        return EXIT_USER_ERROR
    except (BayesprogError, _UserError) as exc:
        print(f"bayesprog: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("bayesprog: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
