"""Where the benchmarks record their latest tables: sections of docs/benchmarks.md between
HTML comment markers, rewritten by each run with ``--write-docs``."""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"


def record(name: str, heading: str, report: str) -> None:
    """Put ``report`` between the ``<!-- name:begin -->`` and ``<!-- name:end -->`` markers,
    adding a section titled ``heading`` at the end when the page has none yet."""
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    text = DOCS.read_text() if DOCS.exists() else "# Benchmarks\n"
    if begin not in text:
        text += f"\n## {heading}\n\n{begin}\n{end}\n"
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    DOCS.write_text(f"{head}{begin}\n{report}\n{end}{tail}")
    print(f"\nrecorded in {DOCS}", file=sys.stderr)


def publish(name: str, heading: str, report: str, write_docs: bool) -> None:
    """Print ``report``, and with ``write_docs`` (``--write-docs``) :func:`record` it too."""
    print(report)
    if write_docs:
        record(name, heading, report)


def run_report(
    argv: list[str] | None, doc: str, name: str, heading: str, measure, runs: int = 5
) -> int:
    """A benchmark's command line: ``--runs`` and ``--write-docs``, the service's allocator
    settings, then ``measure(runs)``'s report with the machine's footer, published."""
    import argparse

    import numpy as np

    from benchmarks.transforms_bench import footer
    from service.server.allocator import keep_large_blocks

    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=runs)
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    args = parser.parse_args(argv)
    keep_large_blocks()
    report = measure(args.runs) + "\n\n" + footer(f"numpy {np.__version__}")
    publish(name, heading, report, args.write_docs)
    return 0
