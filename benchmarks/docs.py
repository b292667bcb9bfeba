"""Where the benchmarks record their latest tables: sections of docs/benchmarks.md between
HTML comment markers, rewritten by each run with ``--write-docs``; and the line that ends
each table (:func:`footer`: the machine, the libraries, the time)."""

from __future__ import annotations

import datetime
import os
import platform
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"


def machine() -> str:
    """One line describing where the benchmark ran."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    memory = ""
    try:
        kib = int(Path("/proc/meminfo").read_text().split()[1])
        memory = f", {kib / 2**20:.0f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    return f"{cpu}, {cores} cores{memory}; {platform.system()} {platform.release()}"


def footer(*libraries: str) -> str:
    """The line that ends a report: the machine, ``libraries`` (``"numpy 2.4"``, ...) and
    the time of the run."""
    used = ", ".join([f"Python {platform.python_version()}", *libraries])
    when = datetime.datetime.now(datetime.UTC)
    return f"Machine: {machine()}. {used}. Run {when:%Y-%m-%d %H:%M} UTC."


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

    from service.server.allocator import keep_large_blocks

    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=runs)
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    args = parser.parse_args(argv)
    keep_large_blocks()
    report = measure(args.runs) + "\n\n" + footer(f"numpy {np.__version__}")
    publish(name, heading, report, args.write_docs)
    return 0
