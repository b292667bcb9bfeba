"""Benchmark of the transform core against VTK's plain spherical map (``make bench``).

Builds a mesh of at least a million faces by subdividing a bundled scan, then times, as the
median of several runs after a warm-up:

* the distorted forward transform (world points -> theta, phi, r, frame included);
* the separable forward transform;
* validation (per-face measurements, flags, margins, loops) plus distortion metrics;

and, in the same run on the same points, VTK's ``vtkTextureMapToSphere`` (the peer). It runs
twice, in child processes: once with glibc's default allocator settings and once with the
settings the service starts with (:func:`service.allocator.keep_large_blocks`: large blocks
stay in the process instead of going back to the kernel, so numpy's temporaries do not fault
in fresh zeroed pages on every call). Prints Markdown tables; ``--write-docs`` also records them in
``docs/benchmarks.md``.

    python -m benchmarks.transforms_bench [--subdivisions 3] [--runs 11] [--write-docs]
"""

from __future__ import annotations

import argparse
import datetime
import io
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh

from service.allocator import keep_large_blocks
from service.samples import SAMPLES
from transforms import Chart, Frame, PoleCap, assess_region, world_to_angles

DOCS = Path(__file__).resolve().parent.parent / "docs" / "benchmarks.md"
BEGIN, END = "<!-- transforms-bench:begin -->", "<!-- transforms-bench:end -->"
#: Targets from the issue, as multiples of VTK's time.
TARGETS = {"distorted forward": 1.0, "validation + metrics": 5.0}


def load_mesh(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """The Lee Perry-Smith head scan, each face split into 4 ``subdivisions`` times."""
    sample = SAMPLES["lee-perry-smith.obj"]
    mesh = trimesh.load(
        io.BytesIO(sample.path.read_bytes()), file_type="obj", process=False, force="mesh"
    )
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    for _ in range(subdivisions):
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    return np.ascontiguousarray(vertices), np.ascontiguousarray(faces, dtype=np.int64)


def timed(work: Callable[[], object], runs: int) -> list[float]:
    """Seconds per call for ``runs`` calls after one warm-up call."""
    work()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return times


def vtk_peer(vertices: np.ndarray, faces: np.ndarray, centre: np.ndarray):
    """A function running ``vtkTextureMapToSphere`` on the mesh, and its texture coordinates."""
    import vtk
    from vtk.util import numpy_support

    points = vtk.vtkPoints()
    points.SetData(numpy_support.numpy_to_vtk(vertices, deep=True))
    cells = vtk.vtkCellArray()
    offsets = np.arange(0, 3 * len(faces) + 1, 3, dtype=np.int64)
    cells.SetData(
        numpy_support.numpy_to_vtkIdTypeArray(offsets, deep=True),
        numpy_support.numpy_to_vtkIdTypeArray(faces.ravel().astype(np.int64), deep=True),
    )
    mesh = vtk.vtkPolyData()
    mesh.SetPoints(points)
    mesh.SetPolys(cells)
    spherical = vtk.vtkTextureMapToSphere()
    spherical.SetInputData(mesh)
    spherical.AutomaticSphereGenerationOff()
    spherical.SetCenter(*centre)
    spherical.PreventSeamOff()

    def run() -> None:
        spherical.Modified()
        spherical.Update()

    def coordinates() -> np.ndarray:
        run()
        return numpy_support.vtk_to_numpy(spherical.GetOutput().GetPointData().GetTCoords())

    return run, coordinates, vtk.vtkVersion.GetVTKVersion()


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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--subdivisions", type=int, default=3, help="4^k times the faces")
    parser.add_argument("--runs", type=int, default=11, help="timed runs per step (median)")
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    parser.add_argument("--child", choices=["default", "service"], help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        if args.child == "service" and not keep_large_blocks():
            raise SystemExit("the service's allocator settings need glibc")
        print(measure(args.subdivisions, args.runs))
        return 0

    sections = []
    for allocator, title in (
        ("default", "glibc's default allocator settings"),
        ("service", "the service's allocator settings (service/allocator.py)"),
    ):
        child = [sys.executable, "-m", "benchmarks.transforms_bench", "--child", allocator]
        child += ["--subdivisions", str(args.subdivisions), "--runs", str(args.runs)]
        table = subprocess.run(child, check=True, capture_output=True, text=True).stdout
        sections.append(f"### With {title}\n\n{table.strip()}")
    report = "\n\n".join(sections)
    print(report)
    if args.write_docs:
        text = DOCS.read_text() if DOCS.exists() else f"# Benchmarks\n\n{BEGIN}\n{END}\n"
        head, rest = text.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        DOCS.write_text(f"{head}{BEGIN}\n{report}\n{END}{tail}")
        print(f"\nrecorded in {DOCS}", file=sys.stderr)
    return 0


def measure(subdivisions: int, runs: int) -> str:
    """Run every step and the peer; return the Markdown table."""
    vertices, faces = load_mesh(subdivisions)
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    frame = Frame.from_pole_up(pole=[0.0, -1.0, 0.0], up=[0.0, 0.0, 1.0], center=centre)
    cap = PoleCap.from_sigma(0.3)
    distorted, separable = Chart.distorted(cap), Chart.separable(cap)
    local = frame.to_local(vertices)
    theta, phi, _ = world_to_angles(vertices, frame, distorted)

    run_vtk, vtk_coordinates, vtk_version = vtk_peer(vertices, faces, centre)
    # The peer must compute what we think it computes: VTK's t is eq. 1's polar angle / pi.
    standard_theta, _, _ = world_to_angles(vertices, Frame.identity(centre), Chart.standard())
    t = vtk_coordinates()[:, 1]
    assert np.allclose(t, standard_theta / np.pi, atol=1e-5) or np.allclose(
        t, 1.0 - standard_theta / np.pi, atol=1e-5
    ), "vtkTextureMapToSphere did not produce the spherical map"

    steps: list[tuple[str, int, Callable[[], object]]] = [
        ("distorted forward", 1, lambda: world_to_angles(vertices, frame, distorted)),
        ("separable forward", 1, lambda: world_to_angles(vertices, frame, separable)),
        ("validation + metrics", 1, lambda: assess_region(local, faces, theta, phi, cap)),
        ("distorted forward", 2, lambda: world_to_angles(vertices, frame, distorted, threads=2)),
        ("separable forward", 2, lambda: world_to_angles(vertices, frame, separable, threads=2)),
        (
            "validation + metrics",
            2,
            lambda: assess_region(local, faces, theta, phi, cap, threads=2),
        ),
    ]
    vtk_times = timed(run_vtk, runs)
    rows = []
    for name, threads, work in steps:
        ours = timed(work, runs)
        peer = timed(run_vtk, runs)  # the peer again, under the same conditions
        vtk_times += peer
        rows.append((name, threads, ours, peer))

    lines = [
        f"Mesh: `lee-perry-smith.obj` subdivided {subdivisions} times: "
        f"{len(vertices):,} vertices, {len(faces):,} faces. Median of {runs} runs after a "
        f"warm-up. Peer: VTK {vtk_version} `vtkTextureMapToSphere` (plain spherical map) on "
        f"the same points, re-timed after each step (median over all its runs "
        f"{statistics.median(vtk_times) * 1e3:.1f} ms).",
        "",
        "| step | threads | meshflat median (ms) | min (ms) | VTK median (ms) "
        "| ratio to VTK | target | met |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for name, threads, ours, peer in rows:
        median, peer_median = statistics.median(ours), statistics.median(peer)
        ratio = median / peer_median
        target = TARGETS.get(name)
        met = f"<= {target:g}x | {'yes' if ratio <= target else 'no'} |" if target else "- | - |"
        lines.append(
            f"| {name} | {threads} | {median * 1e3:.1f} | {min(ours) * 1e3:.1f} | "
            f"{peer_median * 1e3:.1f} | {ratio:.2f}x | {met}"
        )
    lines += [
        "",
        f"Machine: {machine()}. Python {platform.python_version()}, numpy {np.__version__}. "
        f"Run {datetime.datetime.now(datetime.UTC).strftime('%Y-%m-%d %H:%M UTC')}.",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
