"""Peak memory of each mesh route, each measured in a fresh process (``make bench-memory``).

On the scalp of ``fsaverage-head.ply`` subdivided 3 and 5 times (about 100k and 1.6M faces,
built as in :mod:`benchmarks.fit_bench`) it runs, one child process per (route, region):

* the core's flatten (:func:`transforms.flatten_region`, fixed parameters) and fit
  (:func:`transforms.fit_region`) on the region's arrays;
* the routes in-process as the service runs them: the region's GLB read from bytes
  (:func:`service.meshio.read_mesh`), the operation, and the JSON answer encoded
  (``MeshCapability.answer``) for /v1/flatten, /v1/validate, /v1/fit and /v1/locate (one
  click on the map).

Each child applies the service's allocator settings (:mod:`service.server.allocator`) and runs BLAS
on one thread, as the service does, warms up on the bundled scalp (imports, caches), then
resets its peak (``/proc/self/clear_refs``) and reads ``VmRSS`` before the call and ``VmHWM``
after it. A call's temporaries are that peak less what the call had to hold anyway: the mesh
it read and its answer (the returned arrays, or the JSON bytes).

    python -m benchmarks.memory_bench [--subdivisions 3 5] [--write-docs]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks.docs import footer, publish
from benchmarks.server import status_bytes

#: Targets from the issue: a flatten's temporaries per face, and a fit's peak against the
#: flatten's on the same region.
FLATTEN_TEMPORARIES_PER_FACE = 300
FIT_PEAK_OVER_FLATTEN = 1.0

#: (name, what it runs) in table order; "core" rows run on arrays, the others on a GLB.
ROUTES = {
    "flatten": "core flatten_region",
    "fit": "core fit_region",
    "/v1/flatten": "read GLB, flatten, encode JSON",
    "/v1/validate": "read GLB, flatten, encode JSON",
    "/v1/fit": "read GLB, fit, encode JSON",
    "/v1/locate": "read GLB, one click, encode JSON",
}
#: Which flatten row each fit row is held against.
FIT_AGAINST = {"fit": "flatten", "/v1/fit": "/v1/flatten"}


def region(times: int) -> tuple[np.ndarray, np.ndarray]:
    """The fsaverage scalp subdivided ``times`` times, compacted (a rung of
    :mod:`benchmarks.fit_bench`'s ladder)."""
    from benchmarks.fit_bench import ladder_rung

    return ladder_rung(times)


def fixed_params(vertices: np.ndarray) -> dict:
    """The parameters fit_bench flattens with: the box centre, pole at the chin, sigma 0.3."""
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    return {
        "center": centre.tolist(),
        "rotation": {"pole": [0.0, 0.0, -1.0], "up": [0.0, 1.0, 0.0]},
        "sigma": 0.3,
    }


# -- the child: one call measured ----------------------------------------------------------


def held_bytes(value) -> int:
    """Bytes of the numpy arrays a result holds (dataclasses followed, each array once)."""
    seen: set[int] = set()

    def walk(item) -> int:
        if id(item) in seen:
            return 0
        seen.add(id(item))
        if isinstance(item, np.ndarray):
            return item.nbytes if item.base is None else walk(item.base)
        if hasattr(item, "__dataclass_fields__"):
            return sum(walk(getattr(item, name)) for name in item.__dataclass_fields__)
        return 0

    return walk(value)


def core_call(route: str, vertices: np.ndarray, faces: np.ndarray) -> Callable[[], object]:
    from transforms import Chart, Frame, PoleCap, fit_region, flatten_region

    if route == "fit":
        return lambda: fit_region(vertices, faces)
    params = fixed_params(vertices)
    rotation = params["rotation"]
    frame = Frame.from_pole_up(rotation["pole"], rotation["up"], params["center"])
    chart = Chart.distorted(PoleCap.from_sigma(params["sigma"]))
    return lambda: flatten_region(vertices, faces, frame, chart)


def route_call(route: str, glb: bytes, vertices: np.ndarray) -> Callable[[], tuple]:
    """The route in-process: (mesh read, JSON bytes) from the GLB's bytes."""
    from service.capabilities import MESH_CAPABILITIES
    from service.capabilities.context import Context
    from service.capabilities.region.resolve import MeshInput
    from service.meshio import read_mesh
    from service.outputs import Output
    from service.settings import Settings
    from service.timings import Timings

    capability = next(c for c in MESH_CAPABILITIES if c.path == route)
    params = {} if route == "/v1/fit" else fixed_params(vertices)
    if route == "/v1/locate":
        params |= {"theta": [1.2], "phi": [-1.6]}  # a click on the map
    params = capability.params.model_validate(params)
    settings = Settings()

    def call() -> tuple:
        mesh = read_mesh(glb, "glb", settings.limits)
        given = MeshInput(mesh, params)
        return mesh, capability.answer(given, Context(settings), Output.JSON, Timings())

    return call


def child(route: str, data: Path) -> dict:
    """Measure one call of ``route`` on the region saved at ``data`` (.npz and .glb)."""
    from service.server.allocator import keep_large_blocks

    keep_large_blocks()
    arrays = np.load(data.with_suffix(".npz"))
    vertices, faces = arrays["vertices"], arrays["faces"]
    glb = data.with_suffix(".glb").read_bytes()
    small = np.load(data.parent / "warm-up.npz")
    small_glb = (data.parent / "warm-up.glb").read_bytes()
    if route.startswith("/"):
        route_call(route, small_glb, small["vertices"])()
        call = route_call(route, glb, vertices)
    else:
        core_call(route, small["vertices"], small["faces"])()
        call = core_call(route, vertices, faces)
    Path("/proc/self/clear_refs").write_text("5")  # VmHWM back to VmRSS
    before = status_bytes("VmRSS")
    start = time.perf_counter()
    result = call()
    seconds = time.perf_counter() - start
    peak = status_bytes("VmHWM") - before
    if isinstance(result, tuple):
        mesh, answer = result
        read, answered = mesh.vertices.nbytes + mesh.faces.nbytes, len(answer)
    else:
        read, answered = 0, held_bytes(result)
    return {"faces": len(faces), "seconds": seconds, "peak": peak, "read": read, "answer": answered}


# -- the parent: one child per measurement -----------------------------------------------


def save_region(directory: Path, name: str, vertices: np.ndarray, faces: np.ndarray) -> Path:
    """The region as the children read it: ``name.npz`` (arrays) and ``name.glb``."""
    import trimesh

    path = directory / name
    np.savez(path.with_suffix(".npz"), vertices=vertices, faces=faces)
    glb = trimesh.Trimesh(vertices, faces, process=False).export(file_type="glb")
    path.with_suffix(".glb").write_bytes(glb)
    return path


def measured(route: str, data: Path) -> dict:
    command = [sys.executable, "-m", "benchmarks.memory_bench", "--child", route, str(data)]
    env = os.environ | {"OPENBLAS_NUM_THREADS": "1"}  # as the service runs BLAS
    done = subprocess.run(command, check=True, capture_output=True, text=True, env=env)
    return json.loads(done.stdout.splitlines()[-1])


def rows_of(title: str, data: Path) -> list[str]:
    """Every route on one region; Markdown rows."""
    results = {}
    for route in ROUTES:
        print(f"{title}: {route}", file=sys.stderr, flush=True)
        results[route] = measured(route, data)
    rows = []
    for route, found in results.items():
        faces = found["faces"]
        temporaries = found["peak"] - found["read"] - found["answer"]
        target, met = "-", "-"
        if route in FIT_AGAINST:
            ratio = found["peak"] / results[FIT_AGAINST[route]]["peak"]
            target = f"peak <= {FIT_PEAK_OVER_FLATTEN:g}x {FIT_AGAINST[route]}'s ({ratio:.2f}x)"
            met = "yes" if ratio <= FIT_PEAK_OVER_FLATTEN else "no"
        elif route.endswith("flatten"):
            target = f"temporaries <= {FLATTEN_TEMPORARIES_PER_FACE} B/face"
            met = "yes" if temporaries <= FLATTEN_TEMPORARIES_PER_FACE * faces else "no"
        rows.append(
            f"| {title} ({faces:,} faces) | {route} | {ROUTES[route]} | "
            f"{found['seconds'] * 1e3:,.0f} | {found['peak'] / 2**20:,.1f} | "
            f"{found['peak'] / faces:,.0f} | {found['read'] / faces:,.0f} | "
            f"{found['answer'] / faces:,.0f} | {temporaries / faces:,.0f} | {target} | {met} |"
        )
    return rows


def measure(subdivisions: list[int]) -> str:
    lines = [
        "Each row is one call in a fresh process (the service's allocator settings, BLAS and "
        "the call on one thread, after a warm-up on the bundled scalp): peak is VmHWM less "
        "VmRSS before the call; read is the mesh's arrays the route read from the GLB; answer "
        "is the returned arrays (core) or the JSON bytes (routes); temporaries are the peak "
        "less both. Bytes per face of the region.",
        "",
        "| region | route | call | time (ms) | peak (MiB) | peak (B/face) | read (B/face) "
        "| answer (B/face) | temporaries (B/face) | target | met |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    with tempfile.TemporaryDirectory(prefix="memory-bench-") as directory:
        folder = Path(directory)
        save_region(folder, "warm-up", *region(0))
        for times in subdivisions:
            title = f"fsaverage scalp, subdivided {times}x"
            lines += rows_of(title, save_region(folder, f"scalp-{times}", *region(times)))
    lines += [
        "",
        footer(f"numpy {np.__version__}"),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--subdivisions", type=int, nargs="+", default=[3, 5], help="of the fsaverage scalp"
    )
    parser.add_argument("--write-docs", action="store_true", help="record in docs/benchmarks.md")
    parser.add_argument("--child", nargs=2, metavar=("ROUTE", "DATA"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        route, data = args.child
        print(json.dumps(child(route, Path(data))))
        return 0
    report = measure(args.subdivisions)
    publish("memory-bench", "Peak memory per route (make bench-memory)", report, args.write_docs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
