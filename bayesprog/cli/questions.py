"""The commands that ask a program: ``query`` (a posterior, a MAP, a question over time,
optionally with its density drawn) and ``sample`` (joint draws written to CSV or Parquet).
"""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.cli.common import (
    UserError,
    ablated,
    check_seed,
    evidence_value,
    input_values,
    load_program,
    named_values,
    output_file,
    read_npy,
)

if TYPE_CHECKING:
    from bayesprog.program import Program


def add_query(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("query", help='ask a question, e.g. "P(A B | C=c1, D=0.3)"')
    p.add_argument("file", metavar="FILE", help="a program file, or the name of a bundled "
                   "one (bayesprog examples)")
    p.add_argument("question", nargs="?", help="a named question of the file, or P(searched "
                   "| known) (left out with --marginals)")
    p.add_argument("--marginals", action="store_true",
                   help="the posterior of every discrete variable not given as evidence, in "
                   "one pass (a junction tree), instead of a question (default: a question)")
    p.add_argument("--map", action="store_true",
                   help="the joint argmax instead of the posterior (default: the posterior)")
    p.add_argument("--over-time", choices=["filter", "smooth", "sequence"],
                   help="a program with time: the state at every step, from the steps so far "
                   "(filter) or from all (smooth), or the most likely sequence; evidence as "
                   "VAR=v1,v2,... (default: the question's own kind)")
    p.add_argument("--ablate", action="append", default=[], metavar="TERM",
                   help='replace a term by a uniform, e.g. --ablate "P(S | O, T)"; repeatable '
                   "(default: none)")
    p.add_argument("--input", action="append", default=[], metavar="NAME=VALUE",
                   help="bind a runtime input: a number, numbers separated by commas (a "
                   "vector) or FILE.npy (an array); repeatable (default: none)")
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
                   "variables on bins, with estimated errors; pf: particles, for a filter or a "
                   "smooth question over real states that are not linear-Gaussian "
                   "(default: %(default)s)")
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


def cmd_query(args: argparse.Namespace) -> int:
    check_seed(args.seed)
    if args.limit < 1:
        raise UserError(f"--limit: expected at least 1 row, found {args.limit}")
    if args.marginals:
        return _marginals(args)
    if args.question is None:
        raise UserError("query: expected a question (a named question of the file, or "
                        "P(searched | known)), or --marginals for every variable's posterior")
    program = ablated(load_program(args.file), args.ablate)
    inputs = input_values(args.input)
    evidence = {k: evidence_value(v) for k, v in named_values(args.evidence, "--evidence").items()}
    kind = args.over_time or ("map" if args.map else None)
    if args.over_time and args.map:
        raise UserError("--map and --over-time: expected one of them (--over-time sequence "
                        "asks the most likely sequence)")
    named = program.question(args.question).kind
    if args.map and named in ("filter", "smooth", "sequence"):
        raise UserError(f"--map: {args.question!r} is a {named} question over steps; leave "
                        "out --map (--over-time sequence asks the most likely sequence)")
    if (kind or named) in ("filter", "smooth", "sequence"):
        # evidence over steps: one value per step, separated by commas
        evidence = {k: v.split(",") if isinstance(v, str) else v for k, v in evidence.items()}
    else:
        _no_steps(program, evidence)
    soft = {}
    for name, text in named_values(args.soft, "--soft").items():
        if text.endswith(".npy"):  # a batch of likelihoods, or one per step over time
            soft[name] = np.asarray(read_npy(text, "--soft"), dtype=float)
            continue
        try:
            soft[name] = np.array([float(x) for x in text.split(",")])
        except ValueError:
            raise UserError(f"--soft {name}={text}: expected numbers separated by commas, or "
                            "FILE.npy") from None
    if args.samples < 1:
        raise UserError(f"--samples: expected at least 1, found {args.samples}")
    if args.burn_in < 0 or args.thin < 1:
        raise UserError(f"--burn-in: expected at least 0, found {args.burn_in}"
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
    from bayesprog.views.show import format_result

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
            raise UserError(
                f"--evidence {name}={value}: one value per step (separated by commas) is read "
                "by a question over steps: add --over-time filter|smooth|sequence (or ask a "
                "named question of one of these kinds)")
        raise UserError(
            f"--evidence {name}={value}: expected one value; values separated by commas are "
            "steps, for a program that repeats over time (a time: section) with --over-time; "
            f"for a batch of rows, give {name}=FILE.npy")


def _plot_density(result: Any, path: str) -> None:
    """The density of each searched real variable (the first batch row), to an image file."""
    from bayesprog.inference.density import Density

    if not isinstance(result, Density):
        raise UserError("--plot: expected a question on real variables (a density); this one "
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
        raise UserError(f"--plot {path}: cannot write it: {exc}") from None
    finally:
        plt.close(fig)


def _marginals(args: argparse.Namespace) -> int:
    """``query FILE --marginals``: every unobserved discrete variable's posterior."""
    if args.question is not None:
        raise UserError(f"--marginals: expected no question (every variable's posterior is "
                        f"asked), found {args.question!r}")
    for flag, used in (("--map", args.map), ("--over-time", args.over_time),
                       ("--plot", args.plot), ("--method", args.method != "auto")):
        if used:
            raise UserError(f"--marginals and {flag}: expected one of them (--marginals "
                            "answers exactly, in one pass, the posterior of each variable)")
    program = ablated(load_program(args.file), args.ablate)
    inputs = input_values(args.input)
    evidence = {k: evidence_value(v) for k, v in named_values(args.evidence, "--evidence").items()}
    _no_steps(program, evidence)
    soft = {}
    for name, text in named_values(args.soft, "--soft").items():
        try:
            soft[name] = np.asarray(read_npy(text, "--soft"), dtype=float) \
                if text.endswith(".npy") else np.array([float(x) for x in text.split(",")])
        except ValueError:
            raise UserError(f"--soft {name}={text}: expected numbers separated by commas, or "
                            "FILE.npy") from None
    found = program.marginals(evidence, inputs=inputs, soft=soft)
    if args.json:
        first = next(iter(found.values()), None)
        log_evidence = None if first is None else np.asarray(first.log_evidence).tolist()
        print(json.dumps({"evidence": sorted(evidence), "log_evidence": log_evidence,
                          "marginals": {name: answer.to_json()
                                        for name, answer in found.items()}}))
        return 0
    from bayesprog.views.show import format_result

    if not found:
        print("every variable is given as evidence: no posterior to show")
    print("\n\n".join(format_result(answer, limit=args.limit) for answer in found.values()))
    return 0


def add_sample(sub: argparse._SubParsersAction) -> None:
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
    p.add_argument("--input", action="append", default=[], metavar="NAME=VALUE",
                   help="bind a runtime input: a number, numbers separated by commas (a "
                   "vector) or FILE.npy (an array); repeatable (default: none)")
    p.add_argument("--ablate", action="append", default=[], metavar="TERM",
                   help="draw with this term uniform; repeatable (default: none)")
    p.add_argument("--seed", type=int, default=0, help="seed of the draws (default: %(default)s)")
    p.set_defaults(func=cmd_sample)


def cmd_sample(args: argparse.Namespace) -> int:
    check_seed(args.seed)
    if args.n < 1:
        raise UserError(f"-n: expected at least 1 draw, found {args.n}")
    out = output_file(args.output)
    if out.suffix.lower() not in (".csv", ".parquet"):
        raise UserError(f"-o {args.output}: expected a .csv or .parquet file")
    if out.suffix.lower() == ".parquet":
        from bayesprog.support.extras import require_extra

        require_extra("pyarrow", "parquet", f"writing {args.output}")
    program = ablated(load_program(args.file), args.ablate)
    inputs = input_values(args.input)
    evidence = {k: evidence_value(v) for k, v in named_values(args.evidence, "--evidence").items()}
    draws = program.sample(args.n, evidence, inputs=inputs, rng=args.seed, method=args.method)
    try:
        if out.suffix.lower() == ".csv":
            draws.to_csv(out, index=False)
        else:
            draws.to_parquet(out, index=False)
    except OSError as exc:
        raise UserError(f"cannot write {args.output}: {exc.strerror or exc}") from None
    weighted = " (weighted: the column weight)" if "weight" in draws.columns else ""
    print(f"wrote {out}: {len(draws)} draws of {', '.join(c for c in draws.columns if c != 'weight')}"
          f"{weighted}")
    return 0
