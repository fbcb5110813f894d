"""The commands that learn from data: ``learn`` (a program's parameters, by EM),
``discover`` (a decomposition, by hill climbing or PC, its tables fitted) and ``compare``
(programs by their evidence of a data set).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from bayesprog.cli.common import UserError, column_renames, load_program, output_file
from bayesprog.support.files import atomic_write

if TYPE_CHECKING:
    from bayesprog.learning.csv_rows import BadRow


def add_learn(sub: argparse._SubParsersAction) -> None:
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
    p.add_argument("--max-iter", type=int, default=10_000,
                   help="most EM iterations (default: %(default)s)")
    p.add_argument("--tol", type=float, default=1e-8,
                   help="EM stops when the log-likelihood per row is estimated within this of "
                   "its limit (default: %(default)s)")
    p.add_argument("--column", action="append", default=[], metavar="COLUMN=VARIABLE",
                   help="read the data's column COLUMN as the variable VARIABLE, e.g. --column "
                   "material=M; repeatable (default: columns named like the variables)")
    p.add_argument("--states-from-data", action="append", default=[], metavar="VARIABLE",
                   help="the variable takes the states found in its column (sorted), the terms "
                   "over it learned anew, e.g. a lab's own materials; repeatable (default: the "
                   "states declared)")
    p.add_argument("--ignore-other-columns", action="store_true",
                   help="read past the columns that are no variable's (a session log's cells, "
                   "timings and decisions beside its readings) instead of refusing them")
    p.add_argument("--rounded", action="store_true",
                   help="write the learned values to the precision their rows support "
                   "(significant digits; a mean to a twentieth of its standard error) instead "
                   "of as fitted")
    p.add_argument("--on-bad-lines", choices=("error", "warn", "skip"), default="error",
                   help="a bad row (more or fewer fields than the header, a line that is not "
                   "UTF-8, a value that is not a number or outside its support, a state not "
                   "declared): error refuses the first, naming its line; skip sets every bad "
                   "row aside, says how many and lists them (line and why) in "
                   "FITTED.set-aside.txt; warn also prints them. Empty cells are missing "
                   "values, never bad (default: %(default)s)")
    p.set_defaults(func=cmd_learn)


def cmd_learn(args: argparse.Namespace) -> int:
    if args.max_iter < 1:
        raise UserError(f"--max-iter: expected at least 1, found {args.max_iter}")
    from bayesprog.learning.plain_csv import ReadAhead
    from bayesprog.support.bundled import bundled_path

    args.data = str(bundled_path(args.data, "data"))
    data = ReadAhead(args.data)  # read on a thread while the program loads
    from bayesprog.learning.data import BadRowError

    program = load_program(args.file)
    output_file(args.output)
    if Path(args.output).resolve() == Path(args.data).resolve():
        raise UserError(f"-o {args.output}: that is the data file; expected a new program file")
    set_aside = args.on_bad_lines != "error"
    listing = Path(args.output).with_suffix(".set-aside.txt")
    if set_aside and listing.resolve() in (Path(args.data).resolve(), Path(args.file).resolve()):
        raise UserError(f"-o {args.output}: the list of bad rows set aside would be written "
                        f"to {listing}, the data or the program; name the output otherwise")
    if not (args.tol >= 0 and math.isfinite(args.tol)):
        raise UserError(f"--tol: expected a number >= 0, found {args.tol}")
    columns = column_renames(args.column)
    try:
        fit = program.fit(data, freeze=args.freeze, max_iter=args.max_iter, tol=args.tol,
                          columns=columns or None, states_from_data=args.states_from_data,
                          on_bad_lines="skip" if set_aside else "error",
                          other_columns="ignore" if args.ignore_other_columns else "refuse")
    except BadRowError as exc:
        raise UserError(str(exc.fixed("--on-bad-lines skip sets bad rows aside"))) from None
    try:
        out = fit.save(args.output, rounded=args.rounded)
        if set_aside:
            atomic_write(listing, "".join(f"{_bad_place(args.data, b)}: {b.why}\n"
                                          for b in fit.set_aside).encode("utf-8"),
                         parents=False)
    except OSError as exc:
        raise UserError(f"cannot write {exc.filename or args.output}: "
                        f"{exc.strerror or exc}") from None
    record = fit.record
    rows = record.rows_supporting or record.rows_used
    iterations = f", {record.iterations} iterations" if record.iterations > 1 else ""
    if args.rounded:
        from bayesprog.learning.write import supported_digits

        written = (f"values written to the precision {rows} rows support "
                   f"({supported_digits(rows)} significant digits, means to a twentieth of "
                   "their standard error)")
    else:
        written = "values written as fitted"
    print(f"{out}: {', '.join(record.terms)} learned from {record.rows_used} of {record.rows} "
          f"rows of {record.data} ({record.method}{iterations}); log-likelihood "
          f"{record.log_likelihood:.6g}; {written}")
    if set_aside:
        if args.on_bad_lines == "warn":
            for bad in fit.set_aside:
                print(f"{_bad_place(args.data, bad)}: set aside: {bad.why}", file=sys.stderr)
        n = len(fit.set_aside)
        print(f"{n or 'no'} bad row{'s' if n != 1 else ''} of {record.data} set aside, listed "
              f"in {listing}")
    if not fit.converged:
        print(f"bayesprog: EM stopped before converging: {fit.stopped} (raise --max-iter)",
              file=sys.stderr)
    return 0


def _bad_place(data: str, bad: BadRow) -> str:
    """``DATA:LINE`` (as compilers name a place, for an editor to open), or ``DATA: row R``."""
    return f"{data}:{bad.line}" if bad.line is not None else f"{data}: row {bad.row}"


def add_discover(sub: argparse._SubParsersAction) -> None:
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


def cmd_discover(args: argparse.Namespace) -> int:
    from bayesprog.program.discovery import StructureWarning, discover
    from bayesprog.support.bundled import bundled_path

    data = str(bundled_path(args.data, "data"))
    out = output_file(args.output)
    if out.exists() and out.resolve() == Path(data).resolve():
        raise UserError(f"-o {args.output}: that is the data file; expected a new program file")
    if out.suffix not in (".yaml", ".yml"):
        raise UserError(f"-o {args.output}: expected a .yaml program file")
    if not math.isfinite(args.significance) or not 0 < args.significance < 1:
        raise UserError(f"--significance: expected a number in (0, 1), found "
                        f"{args.significance}")
    if not (math.isfinite(args.ess) and args.ess > 0):
        raise UserError(f"--ess: expected a number > 0, found {args.ess}")
    for option, value in (("--max-conditioning", args.max_conditioning),
                          ("--restarts", args.restarts), ("--tabu", args.tabu),
                          ("--max-parents", args.max_parents), ("--seed", args.seed)):
        if value is not None and value < 0:
            raise UserError(f"{option}: expected a number >= 0, found {value}")
    if args.discretise is not None and args.discretise < 2:
        raise UserError(f"--discretise: expected a number of bins >= 2, found {args.discretise}")
    for option, value in (("--score", args.score), ("--start", args.start),
                          ("--max-parents", args.max_parents), ("--restarts", args.restarts)):
        if args.method == "pc" and value is not None:
            raise UserError(f"{option} applies to hill climbing (--method hc), not to pc")
    start = load_program(args.start) if args.start else None
    with warnings.catch_warnings():  # said once below, as the command's own words
        warnings.simplefilter("ignore", StructureWarning)
        found = discover(data, method=args.method, score=args.score or "bic",
                         equivalent_sample_size=args.ess, test=args.test,
                         significance=args.significance,
                         max_conditioning=args.max_conditioning, forbid=args.forbid,
                         require=args.require, tiers=args.tiers,
                         max_parents=args.max_parents, start=start, restarts=args.restarts,
                         tabu=args.tabu, seed=args.seed, discretise=args.discretise,
                         columns=column_renames(args.column) or None,
                         name=args.name or out.stem)
    try:
        found.save(out)
    except OSError as exc:
        raise UserError(f"cannot write {args.output}: {exc.strerror or exc}") from None
    record = found.record.structure
    arcs = sum(len(ps) for ps in found.parents.values())
    how = (f"score {record.score} {record.score_value:.6g}, {record.iterations} operations"
           if record.method == "hc" else
           f"{record.tests} {record.test} tests at {record.significance:g}"
           + (f", {len(record.oriented_by_choice)} arcs oriented by choice"
              if record.oriented_by_choice else ""))
    print(f"wrote {out}: {len(found.parents)} variables, {arcs} arcs ({record.method}, {how})")
    for message in record.warnings:
        print(f"bayesprog: warning: {message}", file=sys.stderr)
    return 0


def add_compare(sub: argparse._SubParsersAction) -> None:
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


def cmd_compare(args: argparse.Namespace) -> int:
    from bayesprog.learning.evidence import compare
    from bayesprog.support.bundled import bundled_path

    if len(args.files) < 2:
        raise UserError("compare: expected one or more programs, then the data file")
    *files, data = args.files
    if not math.isfinite(args.ess) or args.ess <= 0:
        raise UserError(f"--ess: expected a number > 0, found {args.ess}")
    programs = [load_program(f) for f in files]
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
