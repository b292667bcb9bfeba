"""End-to-end benchmark of ``POST /v1/flatten`` through a real uvicorn on 127.0.0.1
(``make bench-service``).

A bundled scan subdivided past a million faces is written as GLB and as OBJ (in memory, never
committed). For each, the same multipart body is

* posted to a uvicorn started here on a free local port (latency as the client sees it, the
  full JSON answer read), and
* handed in-process to the function the route runs (parse + compute + encode, no HTTP),

median of several runs each, with the server's peak resident memory (VmHWM) read from /proc
after the runs. Prints a Markdown table; ``--write-docs`` records it in docs/benchmarks.md.
Targets: end to end at most 1.3x in-process; the GLB with JSON output under 1.5 s.
"""

from __future__ import annotations

import argparse
import datetime
import io
import json
import os
import platform
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import trimesh

from benchmarks.transforms_bench import machine, subdivided
from service.allocator import keep_large_blocks
from service.api import _run_mesh_job
from service.settings import Settings

DOCS = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"
BEGIN, END = "<!-- service-bench:begin -->", "<!-- service-bench:end -->"
BOUNDARY = "meshflat-benchmark-boundary"
PARAMS = {"rotation": {"pole": [0, -1, 0], "up": [0, 0, 1]}}


def multipart(filename: str, data: bytes, params: dict) -> bytes:
    """A multipart/form-data body with the ``mesh`` file and the ``params`` JSON."""
    return b"".join(
        [
            f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="params"\r\n\r\n'.encode(),
            json.dumps(params).encode(),
            f'\r\n--{BOUNDARY}\r\nContent-Disposition: form-data; name="mesh"; '
            f'filename="{filename}"\r\nContent-Type: application/octet-stream\r\n\r\n'.encode(),
            data,
            f"\r\n--{BOUNDARY}--\r\n".encode(),
        ]
    )


def mesh_files(subdivisions: int) -> dict[str, bytes]:
    vertices, faces = subdivided("lee-perry-smith.obj", subdivisions)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    obj = io.StringIO()
    obj.write("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in vertices.tolist()))
    obj.write("".join(f"f {a} {b} {c}\n" for a, b, c in (faces + 1).tolist()))
    return {
        "head.glb": mesh.export(file_type="glb"),
        "head.obj": obj.getvalue().encode(),
    }


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def peak_rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--subdivisions", type=int, default=3, help="4^k times the faces")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args(argv)

    keep_large_blocks()  # as the service does at start-up
    files = mesh_files(args.subdivisions)
    settings = Settings()
    port = free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "uvicorn", "service.app:app", "--host", "127.0.0.1",
         "--port", str(port), "--log-level", "warning"],
        env=os.environ | {"PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    rows = []
    try:
        base = f"http://127.0.0.1:{port}"
        with httpx.Client(base_url=base, timeout=120) as client:
            deadline = time.monotonic() + 60
            while True:
                try:
                    if client.get("/readyz").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline:
                    raise SystemExit("the server did not become ready within 60 s")
                time.sleep(0.2)
            for name, data in files.items():
                body = multipart(name, data, PARAMS)
                content_type = f"multipart/form-data; boundary={BOUNDARY}"
                in_process, end_to_end, answer_bytes, timing = [], [], 0, ""
                for _ in range(args.runs + 1):  # the first run warms up
                    start = time.perf_counter()
                    local = _run_mesh_job(body, content_type, settings, True)
                    in_process.append(time.perf_counter() - start)
                    start = time.perf_counter()
                    response = client.post(
                        "/v1/flatten", content=body, headers={"content-type": content_type}
                    )
                    end_to_end.append(time.perf_counter() - start)
                    assert response.status_code == 200, response.text[:300]
                    answer_bytes = len(response.content)
                    timing = response.headers.get("server-timing", "")
                    assert len(local.body) == answer_bytes
                faces = len(json.loads(response.content)["faces"]["ids"])
                rows.append(
                    (name, len(data), answer_bytes, faces, in_process[1:], end_to_end[1:], timing)
                )
            rss = peak_rss_mib(server.pid)
    finally:
        server.terminate()
        server.wait(timeout=30)

    lines = [
        f"`POST /v1/flatten` of `lee-perry-smith.obj` subdivided {args.subdivisions} times, "
        "the whole mesh as the region, JSON answer; a real uvicorn (one worker) on 127.0.0.1. "
        f"Median of {args.runs} runs after a warm-up; in-process is the route's own function "
        "(parse + compute + encode) on the same body. Server peak RSS (VmHWM) after all runs: "
        f"{rss:,.0f} MiB.",
        "",
        "| file | faces | upload (MB) | answer (MB) | in-process (ms) | end to end (ms) "
        "| ratio | target | met | server timing of the last run |",
        "|---|---:|---:|---:|---:|---:|---:|---|---|---|",
    ]
    for name, size, answer, faces, local, remote, timing in rows:
        ratio = statistics.median(remote) / statistics.median(local)
        glb_ok = not name.endswith(".glb") or statistics.median(remote) < 1.5
        target = "<= 1.3x" + (", < 1.5 s" if name.endswith(".glb") else "")
        lines.append(
            f"| {name} | {faces:,} | {size / 1e6:.1f} | {answer / 1e6:.1f} | "
            f"{statistics.median(local) * 1e3:.0f} | {statistics.median(remote) * 1e3:.0f} | "
            f"{ratio:.2f}x | {target} | {'yes' if ratio <= 1.3 and glb_ok else 'no'} | "
            f"`{timing}` |"
        )
    lines += [
        "",
        f"Machine: {machine()}. Python {platform.python_version()}, numpy {np.__version__}. "
        f"Run {datetime.datetime.now(datetime.UTC).strftime('%Y-%m-%d %H:%M UTC')}.",
    ]
    table = "\n".join(lines)
    print(table)
    if args.write_docs:
        text = DOCS.read_text()
        if BEGIN not in text:
            text += f"\n## The service end to end\n\n{BEGIN}\n{END}\n"
        head, rest = text.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        DOCS.write_text(f"{head}{BEGIN}\n{table}\n{END}{tail}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
