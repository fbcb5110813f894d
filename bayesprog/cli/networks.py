"""The commands that convert between programs and the network files other libraries read and
write: ``import`` (BIF, XMLBIF, UAI or a linear-Gaussian JSON network into a program file) and
``export`` (a discrete program as BIF, XMLBIF or UAI, a linear-Gaussian one as JSON).
"""

from __future__ import annotations

import argparse

from bayesprog.cli.common import ablated, load_program, output_file


def add_import(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import", help="convert a BIF, XMLBIF, UAI or linear-Gaussian JSON "
                                      "network into a program file")
    p.add_argument("network", metavar="FILE.bif|.xmlbif|.uai|.json",
                   help="a network file (optionally .gz); .json: a linear-Gaussian network as "
                        "pgmpy ships bnlearn's")
    p.add_argument("-o", "--output", required=True, metavar="OUT.yaml",
                   help="the program file to write")
    p.set_defaults(func=cmd_import)


def cmd_import(args: argparse.Namespace) -> int:
    from bayesprog.io import import_network

    out = import_network(args.network, output_file(args.output))
    load_program(str(out))  # what we write must load
    print(f"wrote {out}")
    return 0


def add_export(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write a discrete program as BIF, XMLBIF or UAI, a "
                                      "linear-Gaussian one as JSON")
    p.add_argument("file", metavar="FILE", help="a discrete program with literal tables, or a "
                                                "linear-Gaussian program")
    p.add_argument("-o", "--output", required=True, metavar="OUT.bif|.xmlbif|.uai|.json",
                   help="the network file; its format from the extension")
    p.add_argument("--ablate", action="append", default=[], metavar="TERM",
                   help="write the program with this term uniform; repeatable (default: none)")
    p.set_defaults(func=cmd_export)


def cmd_export(args: argparse.Namespace) -> int:
    from bayesprog.io import export_program

    program = ablated(load_program(args.file), args.ablate)
    print(f"wrote {export_program(program, output_file(args.output))}")
    return 0
