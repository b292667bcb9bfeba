"""``meshflat batch`` over the sample set (``make bench-batch``): scans per minute per core.

The set: the bundled samples (``service/samples``) and the shared meshes
(``../shared/data/meshes``, credits in its ``SOURCES.md``) when they are beside the
repository, one file of each name, each with the region the scan zoo gives it (the region
alone: pole and sigma chosen by the defaults), asked for as a research group would, the JSON
answer, the GLB and the PNG. The manifest repeats the set ``--copies`` times (as many scans
as a data set's first minutes) under distinct names.

The installed ``meshflat batch`` runs it into a fresh folder with 1 and with 2 processes
(``--runs`` times each, the median wall time), then once more over the finished folder (every
scan skipped: what resuming costs). Scans per minute per core divides by the processes, each
of which keeps one core busy (BLAS on one thread). ``--write-docs`` records the table in
docs/benchmarks.md.

    python -m benchmarks.batch_bench [--copies 10] [--runs 3] [--write-docs]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.docs import machine, publish
from fixtures.zoo import SCALP_FS, SCALP_LPS, SHARED, TOP_GOAT, TOP_NEFERTITI
from service.meshio import format_of, read_mesh
from service.samples import SAMPLES
from service.settings import Settings

#: The region of each scan of the set, as the scan zoo gives it (the whole mesh otherwise).
REGIONS = {
    "fsaverage-head.ply": SCALP_FS,
    "lee-perry-smith.glb": SCALP_LPS,
    "lee-perry-smith.obj": SCALP_LPS,
    "nefertiti-lowres.obj": TOP_NEFERTITI,
    "goathead.obj": TOP_GOAT,
}
OUTPUTS = ["map.json", "map.glb", "map.png"]
MESHFLAT = Path(sys.executable).parent / "meshflat"


def sample_set() -> dict[str, Path]:
    """Every scan of the set by file name: the bundled ones, then the shared ones not
    bundled."""
    scans = {name: sample.path for name, sample in SAMPLES.items()}
    if SHARED.is_dir():
        for path in sorted(SHARED.iterdir()):
            if path.name not in scans and path.suffix.lstrip(".") in ("obj", "ply", "glb", "stl"):
                scans[path.name] = path
    return scans


def write_manifest(folder: Path, scans: dict[str, Path], copies: int) -> Path:
    manifest = folder / "manifest.jsonl"
    lines = []
    for copy in range(copies):
        for name, path in scans.items():
            region = REGIONS.get(name)
            lines.append(
                {
                    "mesh": str(path),
                    "name": f"{name.replace('.', '-')}-{copy}",
                    "params": {"region": region} if region else {},
                    "outputs": OUTPUTS,
                }
            )
    manifest.write_text("".join(json.dumps(line) + "\n" for line in lines))
    return manifest


def run(manifest: Path, out: Path, processes: int) -> tuple[float, list[float], dict]:
    """Wall seconds, the CPU seconds of each scan computed (its log line's), and the
    summary."""
    # The scans lie beside the bundled samples and the shared zoo, not in the manifest's folder.
    folders = {str(Path(json.loads(line)["mesh"]).parent) for line in manifest.open()}
    allowed = [option for folder in sorted(folders) for option in ("--allow-root", folder)]
    started = time.perf_counter()
    done = subprocess.run(
        [MESHFLAT, "batch", manifest, "--out", out, "--processes", str(processes), *allowed],
        capture_output=True,
        text=True,
        timeout=3600,
    )
    wall = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"meshflat batch exited {done.returncode}:\n{done.stderr[-4000:]}")
    lines = [json.loads(line) for line in done.stderr.strip().splitlines()]
    seconds = [line["cpu_seconds"] for line in lines if line["message"] == "scan done"]
    return wall, seconds, lines[-1]


def row(label: str, processes: int, scans: int, wall: float, cpu: list[float], load: float) -> str:
    per_minute = scans / wall * 60
    each = f"{statistics.mean(cpu):.2f} | {60 / statistics.mean(cpu):.0f}" if cpu else "- | -"
    return (
        f"| {label} | {processes} | {scans} | {wall:.1f} | {per_minute:.1f} | "
        f"{per_minute / processes:.1f} | {each} | {load:.1f} |"
    )


def measure(manifest: Path, scans: int, runs: int) -> list[str]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="meshflat-batch-bench-") as scratch:
        for processes in (1, 2):
            walls, cpu, loads = [], [], []
            for attempt in range(runs):
                out = Path(scratch) / f"out-{processes}-{attempt}"
                wall, each, summary = run(manifest, out, processes)
                assert summary["done"] == scans, summary
                walls.append(wall)
                cpu += each
                loads.append(os.getloadavg()[0])
                print(f"{processes} process(es), run {attempt + 1}: {wall:.1f} s", file=sys.stderr)
            wall, load = statistics.median(walls), statistics.median(loads)
            rows.append(row("fresh folder", processes, scans, wall, cpu, load))
        wall, each, summary = run(manifest, out, 2)
        assert summary["skipped"] == scans, summary
        rows.append(row("rerun, all done", 2, scans, wall, each, os.getloadavg()[0]))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--copies", type=int, default=10, help="times the set is in the manifest")
    parser.add_argument("--runs", type=int, default=3, help="timed runs per process count")
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    args = parser.parse_args(argv)
    scans = sample_set()
    limits = Settings().limits
    faces = {
        name: len(read_mesh(path.read_bytes(), format_of(name, None), limits).faces)
        for name, path in scans.items()
    }
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="meshflat-batch-manifest-") as folder:
        manifest = write_manifest(Path(folder), scans, args.copies)
        rows = measure(manifest, len(scans) * args.copies, args.runs)
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    listed = ", ".join(f"{name} ({count:,} faces)" for name, count in faces.items())
    report = (
        f"{stamp}, {machine()}. The set: {listed}; {args.copies} copies of each, the region "
        f"alone, outputs {', '.join(OUTPUTS)}; `meshflat batch` as installed, wall time from "
        f"its start (starting its processes included) to its exit, median of {args.runs} "
        "runs; CPU s / scan: the mean of the scans' own CPU time in their processes (their "
        "log lines), so scans / CPU-min is what a core gives when nothing else runs on it; "
        f"load: the 1-minute load average, {load:.1f} before the runs (a load above the "
        "cores means other work took CPU from the batch). The rerun is the command's fixed "
        "cost: starting, checking the manifest, hashing every mesh and output.\n\n"
        "| run | processes | scans | wall s | scans / min | scans / min / core "
        "| CPU s / scan | scans / CPU-min | load after |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|\n" + "\n".join(rows)
    )
    publish("batch-bench", "Batch runs (make bench-batch)", report, args.write_docs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
