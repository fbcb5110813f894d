"""The commands on program files themselves: ``validate`` (programs, and the files a runner
plugin knows), ``show``, ``graph``, ``examples`` (and ``examples copy``) on the bundled models,
and ``schema``, the JSON Schema of program files.
"""

from __future__ import annotations

import argparse
import json
import sys
import textwrap
from pathlib import Path

from bayesprog.cli.common import (
    EXIT_USER_ERROR,
    UserError,
    ablated,
    load_program,
    output_file,
    plugins,
)
from bayesprog.errors import BayesprogError, SpecError


def add_validate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check program files; list every problem")
    p.add_argument("files", nargs="+", metavar="FILE",
                   help="programs, and any file a runner plugin knows (scenarios, "
                        "experiments, sensor models), told apart by their first key")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="print nothing for valid files (default: print FILE: ok)")
    p.set_defaults(func=cmd_validate)


def cmd_validate(args: argparse.Namespace) -> int:
    from bayesprog.support.bundled import bundled_path
    from bayesprog.support.files import KINDS, file_kind

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
            load_program(file)
        except UserError as exc:  # not a program (another kind of file), or unreadable
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


def _plugin_validate(file: str, kind: str) -> list[str] | None:
    """The warnings of a file of another kind than a program, checked by the runner plugin
    that knows that kind (its module's ``validate(path, kind)``); None when none does."""
    for _, plugin in plugins(quiet=True):
        check = getattr(plugin, "validate", None)
        found = check(file, kind) if check is not None else None
        if found is not None:
            return list(found)
    return None


def add_show(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("show", help="print a program in Bayesian-programming notation, or "
                       "summarise a data file (.csv, .parquet) group by group")
    p.add_argument("file", metavar="FILE", help="a program file, a data file (.csv, .tsv, "
                   ".parquet), or the name of a bundled one (bayesprog examples)")
    p.add_argument("--ablate", action="append", default=[], metavar="TERM",
                   help='show the program with this term uniform, e.g. "P(S | M)"; repeatable '
                   "(default: none)")
    p.add_argument("--by", metavar="COLUMN",
                   help="a data file: the column whose values group the rows (default: the "
                   "column material or M, else the first column that is not numbers)")
    p.add_argument("--columns", metavar="A,B,...",
                   help="a data file: the columns to summarise and draw (default: all but "
                   "--by's)")
    p.add_argument("--plot", metavar="FILE.png",
                   help="a data file: also draw its columns pair by pair, one colour per "
                   "group, each column's distribution on the diagonal (.png, .pdf, .svg; "
                   "default: no drawing)")
    p.set_defaults(func=cmd_show)


#: the suffixes of the data files ``show`` summarises
DATA_SUFFIXES = (".csv", ".tsv", ".parquet", ".pq")


def cmd_show(args: argparse.Namespace) -> int:
    data = _data_file(args.file)
    if data is not None:
        return _show_data(data, args)
    for flag, given in (("--by", args.by), ("--columns", args.columns), ("--plot", args.plot)):
        if given:
            raise UserError(f"{flag}: for a data file (.csv, .tsv, .parquet); {args.file} is "
                            "read as a program")
    from bayesprog.views.show import render

    print(render(ablated(load_program(args.file), args.ablate)))
    return 0


def _data_file(name: str) -> Path | None:
    """``name`` as a data file to summarise: a path (or a bundled name) with a data suffix, or
    the name of a bundled data file when no file or bundled program has that name."""
    from bayesprog.support.bundled import bundled_path, find

    if name.lower().endswith(DATA_SUFFIXES):
        return bundled_path(name, "data")
    program = find(name, "program")
    if Path(name).exists() or program is not None:
        return None
    return find(name, "data")


def _show_data(path: Path, args: argparse.Namespace) -> int:
    from bayesprog.learning.summary import read_typed, summarise_frame

    if args.ablate:
        raise UserError(f"--ablate: for a program; {path} is a data file")
    columns = None
    if args.columns is not None:
        columns = [c.strip() for c in args.columns.split(",") if c.strip()]
        if not columns:
            raise UserError(f"--columns {args.columns!r}: expected column names separated by "
                            "commas")
    out = None
    if args.plot:
        out = output_file(args.plot, "--plot")
        if out.suffix.lower() not in (".png", ".pdf", ".svg"):
            raise UserError(f"--plot {args.plot}: expected a .png, .pdf or .svg file")
    frame, source = read_typed(path)
    summary = summarise_frame(frame, source, args.by, columns)
    figure = None
    if out is not None:  # drawn before anything is printed: a drawing that fails says so alone
        from bayesprog.views.draw import scatter_matrix

        figure = scatter_matrix(frame, summary.by, summary.columns, source=source)
    print(summary.text())
    if figure is not None:
        try:
            figure.savefig(out, dpi=110)
        except (OSError, ValueError) as exc:
            raise UserError(f"--plot {args.plot}: cannot write it: {exc}") from None
        print(f"wrote {out}")
    return 0


def add_graph(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("graph", help="draw the graphical model (.dot, .png, .pdf, .svg)")
    p.add_argument("file", metavar="FILE", help="a program file, or the name of a bundled "
                   "one (bayesprog examples)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="the drawing: .dot (Graphviz text), .png, .pdf or .svg")
    p.add_argument("--question", help="shade the known variables of this question (a name of "
                   "the file's, or P(searched | known)); default: none")
    p.set_defaults(func=cmd_graph)


def cmd_graph(args: argparse.Namespace) -> int:
    from bayesprog.views.draw import write_graph

    program = load_program(args.file)
    out = output_file(args.output)
    if out.suffix.lower() not in (".dot", ".png", ".pdf", ".svg"):
        raise UserError(f"-o {args.output}: expected a .dot, .png, .pdf or .svg file")
    question = program.question(args.question) if args.question else None
    write_graph(program, out, question=question)
    print(f"wrote {out}")
    return 0


def add_examples(sub: argparse._SubParsersAction) -> None:
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
                   "a model of one file lands as DIR/FILE, one that names other files keeps "
                   "their layout, so relative references still hold")
    c.add_argument("--force", action="store_true",
                   help="overwrite files that exist (default: refuse)")
    c.set_defaults(func=cmd_examples_copy)


def cmd_examples(args: argparse.Namespace) -> int:
    from bayesprog.support.bundled import bundled_root, find, listing

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
            print("\ndata:" if kind == "data" else f"\n{kind}:" if kind.endswith("s")
                  else f"\n{kind}s:")
        description = textwrap.shorten(entry.description, 96 - width, placeholder="...")
        print(f"  {name:<{width}}  {description}")
    return 0


def cmd_examples_copy(args: argparse.Namespace) -> int:
    from bayesprog.support.bundled import copy

    folder = Path(args.folder)
    if folder.exists() and not folder.is_dir():
        raise UserError(f"{folder}: not a folder")
    written = copy(args.name, folder, force=args.force)
    print(f"copied {args.name} into {folder}:")
    for path in written:
        print(f"  {path}")
    return 0


def add_schema(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("schema", help="print the JSON Schema of program files")
    p.add_argument("-o", "--output", metavar="FILE",
                   help="write the schema there (default: print it)")
    p.set_defaults(func=cmd_schema)


def cmd_schema(args: argparse.Namespace) -> int:
    from bayesprog.language.json_schema import json_schema

    text = json.dumps(json_schema(), indent=2) + "\n"
    if args.output:
        output_file(args.output)
        Path(args.output).write_text(text, encoding="utf-8")
    else:
        sys.stdout.write(text)
    return 0
