"""Command line for workflow files (the lead's ``printeps`` CLI may wrap these):

    python -m gateway.workflow validate workflows/*.yaml      # file:line:column: path: message; exit 1 on errors
    python -m gateway.workflow generate workflows/7_thanking.yaml [-o thanking_node.py]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gateway.workflow.codegen import generate
from gateway.workflow.loader import WorkflowInvalid, load


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gateway.workflow", description="PRINTEPS workflow files")
    sub = ap.add_subparsers(dest="command", required=True)
    check = sub.add_parser("validate", help="check workflow files against the schema and their references")
    check.add_argument("files", nargs="+", type=Path)
    gen = sub.add_parser("generate", help="write the standalone rclpy node of a workflow")
    gen.add_argument("file", type=Path)
    gen.add_argument("-o", "--output", type=Path, default=None, help="default: standard output")
    args = ap.parse_args(argv)
    if args.command == "validate":
        failed = False
        for path in args.files:
            try:
                wf = load(path)
            except WorkflowInvalid as exc:
                failed = True
                for problem in exc.problems:
                    print(problem, file=sys.stderr)
            except OSError as exc:
                failed = True
                print(f"{path}: {exc.strerror}", file=sys.stderr)
            else:
                print(f"{path}: ok ({wf.name})")
        return 1 if failed else 0
    try:
        source = generate(load(args.file))
    except WorkflowInvalid as exc:
        print(exc, file=sys.stderr)
        return 1
    if args.output:
        args.output.write_text(source, encoding="utf-8")
    else:
        sys.stdout.write(source)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
