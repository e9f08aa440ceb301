"""``python -m tools.results write|check|measure NAME``: render, check or measure the result records."""

from __future__ import annotations

import argparse
from pathlib import Path

import tools.results
from tools.results.measuring import measure
from tools.results.pages import stale, write_pages
from tools.results.records import REPO


def main(argv: list[str] | None = None) -> int:
    about = (tools.results.__doc__ or "").split("\n")[0]
    parser = argparse.ArgumentParser(prog="python -m tools.results", description=about)
    sub = parser.add_subparsers(dest="action", required=True)
    m = sub.add_parser("measure", help="run a measured record's commands again and rewrite the record")
    m.add_argument("names", nargs="+", metavar="NAME")
    m.add_argument("--real", type=Path, default=None, help="where rbc data fetch put the public recordings")
    sub.add_parser("write", help="render every results block of docs/ and the README, and every CSV table, "
                                 "from its record")
    sub.add_parser("check", help="exit 1 when a results block of docs/ is not its record's rendering")
    args = parser.parse_args(argv)
    if args.action == "measure":
        for name in args.names:
            measure(name, args.real)
        return 0
    if args.action == "write":
        for page in write_pages():
            print(f"wrote {page.relative_to(REPO)}")
        return 0
    wrong = stale()
    for line in wrong:
        print(f"stale: {line}")
    return 1 if wrong else 0


if __name__ == "__main__":
    raise SystemExit(main())
