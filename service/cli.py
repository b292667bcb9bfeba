"""``meshflat``: the service's computations from a shell, and the server itself.

    meshflat serve [--host H] [--port P] [--workers N]    (defaults: MESHFLAT_HOST, ...)
    meshflat health [--port P]                            (exit 0 when /healthz answers)
    meshflat flatten MESH --region-cone AXIS:DEG [--apex X,Y,Z]
                          [--sigma S | --pole-angle DEG | --auto]
                          [--center X,Y,Z | bbox_center | centroid] [--pole X,Y,Z --up X,Y,Z]
                          [--layout theta_phi|mercator] [--params JSON] --out FILE
    meshflat validate MESH ... [--out FILE.json]
    meshflat fit MESH ... [--out FILE.json]
    meshflat locate MESH ... --params '{"theta": [...], "phi": [...]}'
    meshflat measure MESH ... --zones zones.json [--units mm] [--out FILE.json|.svg|.png]
    meshflat plan MESH ... --units mm --params '{"recipient": [...], "donor": [...]}'
                     [--out FILE.json|.svg|.png]
    meshflat sites MESH ... [--density 40] [--zones zones.json] [--units mm] [--out sites.ply]
                      [--flow flow.json]
                      [--density-map map.png --params '{"density_range": [20, 60]}']
    meshflat register BASE FOLLOW_UP ... [--units mm] [--params JSON] --out frame.json
    meshflat compare BASE FOLLOW_UP ... --units mm --params '{"zones": [...], "spots": [...]}'
                     [--baseline-values B.png] [--follow-up-values F.png]
                     [--out FILE.json|.svg|.png]
    meshflat batch MANIFEST.jsonl --out DIR [--allow-root DIR] [--processes N]
        [--shard-count N [--shard-index I]]

One command per mesh route of :mod:`service.capabilities`, running the same operation: the
parameters are the API's (``--params`` takes any of them as JSON, the options override it),
checked by the same models, and the answers are the API's bytes (``flatten`` writes JSON,
GLB, SVG or PNG by the extension of ``--out``); errors are the API's messages, on stderr,
with exit status 2 (1 for anything unexpected).

``batch`` (:mod:`service.batch`) runs those commands over a manifest of scans, one JSON line
each, on N processes: resumable (a scan whose digest and outputs match is skipped), a failure
logged per scan while the others go on (exit status 1), a bad manifest line named before
anything runs (2); ``--shard-count`` splits a manifest over the pods of an Indexed Job.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import orjson

from transforms import Layout

from .capabilities import MESH_COMMANDS, MeshCapability
from .capabilities.context import Context
from .capabilities.inputs import MeshPart, PngPart, Upload, parse_params
from .capabilities.region.params import CENTERS
from .capabilities.units import LengthUnit
from .meshio import READERS
from .outputs import Output
from .problems import Problem, core_errors_as_problems
from .progress import Progress
from .server import PROTOCOL
from .settings import Settings
from .timings import Timings


def _vector(text: str, option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3:
        raise Problem(422, f"{option}: expected three numbers X,Y,Z, got {text!r}", field=option)
    return values


def params_of(args: argparse.Namespace) -> dict:
    """The API's params from the command line: ``--params`` JSON, then the options."""
    params = _json_params(args.params)
    if args.region_cone:
        params["region"] = {"cone": _cone(args.region_cone)}
        if args.apex:
            params["region"]["cone"]["apex"] = _vector(args.apex, "--apex")
    if args.auto:
        params.update(center="auto", rotation="auto", sigma="auto")
    options = {"sigma": args.sigma, "pole_angle_deg": args.pole_angle, "layout": args.layout}
    params.update({name: value for name, value in options.items() if value is not None})
    if args.center:
        named = args.center in CENTERS
        params["center"] = args.center if named else _vector(args.center, "--center")
    params.update(_roll(args))
    if getattr(args, "zones", None):
        params.update(_drawn(args.zones))
    if getattr(args, "flow", None):
        params["growth"] = _growth(args.flow)
    for option, name in (("density", "density_per_cm2"), ("units", "units")):
        if getattr(args, option, None) is not None:
            params[name] = getattr(args, option)
    return params


def _roll(args: argparse.Namespace) -> dict:
    """``rotation`` from ``--pole`` and ``--up``, and ``facing`` from ``--facing``, as given."""
    given = {}
    if args.pole or args.up:
        if not (args.pole and args.up):
            raise Problem(422, "--pole, --up: give both", field="--pole")
        given["rotation"] = {"pole": _vector(args.pole, "--pole"), "up": _vector(args.up, "--up")}
    if args.facing:
        given["facing"] = _vector(args.facing, "--facing")
    return given


def _files(args: argparse.Namespace, capability: MeshCapability) -> dict[str, Upload]:
    """The route's files from their arguments: ``MESH``, then the other meshes' positional
    arguments (``FOLLOW_UP``) and the images' options (``--density-map``)."""
    files = {}
    for part in capability.parts:
        path = args.mesh if part is capability.mesh else getattr(args, part.name, None)
        if path is None:
            continue
        option = _argument(part, capability)
        try:
            files[part.name] = Upload(Path(path).name, Path(path).read_bytes())
        except OSError as error:
            message = f"{option}: cannot read {path!r}: {error.strerror}"
            raise Problem(422, message, field=None if part is capability.mesh else option) from None
    return files


def _argument(part: MeshPart | PngPart, capability: MeshCapability) -> str:
    """The command line's name of a part: ``MESH``, a positional ``NAME`` for another mesh,
    an option ``--name`` for an image."""
    if part is capability.mesh:
        return "MESH"
    return part.name.upper() if isinstance(part, MeshPart) else "--" + part.name.replace("_", "-")


def _json_params(text: str | None) -> dict:
    """The ``--params`` JSON object ({} without one)."""
    try:
        params = json.loads(text) if text else {}
    except json.JSONDecodeError as error:
        raise Problem(422, f"--params: not JSON ({error})", field="--params") from None
    if not isinstance(params, dict):
        raise Problem(422, "--params: must be a JSON object", field="--params")
    return params


def _json_file(path: str, option: str):
    """The JSON a file holds, or a 422 naming ``option``."""
    try:
        return json.loads(Path(path).read_bytes())
    except OSError as error:
        raise Problem(
            422, f"{option}: cannot read {path!r}: {error.strerror}", field=option
        ) from None
    except ValueError as error:
        raise Problem(422, f"{option}: {path!r} is not JSON ({error})", field=option) from None


def _listed_or_object(path: str, option: str, listed: str, what: str) -> dict:
    """The JSON object a file of ``option`` holds, or ``{listed: [...]}`` for a list (the
    list alone); a 422 naming the option, saying ``what`` it takes, for anything else."""
    given = _json_file(path, option)
    if isinstance(given, list):
        return {listed: given}
    if not isinstance(given, dict):
        raise Problem(422, f"{option}: {what}", field=option)
    return given


def _growth(path: str) -> dict:
    """The ``growth`` params a ``--flow`` file holds: a list of flow curves, or an object of
    them (flow, whorls, exit_angle_deg)."""
    return _listed_or_object(path, "--flow", "flow", "a list of flow curves, or an object "
                             "with flow, whorls and exit_angle_deg")  # fmt: skip


def _drawn(path: str) -> dict:
    """The params a ``--zones`` file holds: a list of zones, or an object of params (zones,
    curves, units)."""
    return _listed_or_object(path, "--zones", "zones", "a list of zones, or an object with "
                             "zones, curves and units")  # fmt: skip


def _cone(text: str) -> dict:
    axis, _, degrees = text.rpartition(":")
    try:
        half_angle = float(degrees)
    except ValueError:
        raise Problem(
            422,
            f"--region-cone: expected AXIS:DEG such as 0,1,0:60, got {text!r}",
            field="--region-cone",
        ) from None
    return {"axis": _vector(axis, "--region-cone"), "half_angle_deg": half_angle}


def _output(capability: MeshCapability, out: str | None) -> Output:
    """The form ``--out``'s extension asks for (every command answers JSON and Arrow, some
    more); JSON on standard output."""
    if not out:
        return Output.JSON
    return capability.output_of_file(out, "--out")


def run(args: argparse.Namespace) -> bytes:
    """The answer's bytes for a mesh command (the route's capability and operation)."""
    capability = MESH_COMMANDS[args.command]
    settings = Settings.from_env()
    work = "fitting" if args.command == "fit" or args.auto else "flattening"
    progress = Progress(["reading", work, "writing"], args.progress or sys.stderr.isatty())
    with core_errors_as_problems(capability.places):
        with progress.step("reading"):
            params = parse_params(capability.params, orjson.dumps(params_of(args)))
            files = _files(args, capability)
            # params.output, when given, names the form; else --out's extension does.
            output = getattr(params, "output", None) or _output(capability, args.out)
            ctx = Context(settings)
            given = capability.input_of(params, files, ctx)
        with progress.step(work):
            answer = capability.answer(given, ctx, output, Timings())
    with progress.step("writing"):
        if args.out:
            Path(args.out).write_bytes(answer)
        else:
            sys.stdout.buffer.write(answer + b"\n")
    return answer


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(
        prog="meshflat", description="The service's computations from a shell, and the server."
    )
    commands = top.add_subparsers(dest="command", required=True)
    serve = commands.add_parser(
        "serve", help="run the service (uvicorn; settings from MESHFLAT_* variables)"
    )
    serve.add_argument("--host", help="default: MESHFLAT_HOST or 127.0.0.1")
    serve.add_argument("--port", type=int, help="default: MESHFLAT_PORT or 8000")
    serve.add_argument("--workers", type=int, help="processes; default: MESHFLAT_WORKERS or 1")
    health = commands.add_parser("health", help="exit 0 when the local service's /healthz answers")
    health.add_argument("--port", type=int, help="default: MESHFLAT_PORT or 8000")
    _add_batch(commands)
    for name, capability in MESH_COMMANDS.items():
        forms = ", ".join(output.value.upper() for output in capability.outputs)
        command = commands.add_parser(
            name, help=f"{capability.summary[0].lower()}{capability.summary[1:]} ({forms})"
        )
        *most, last = (reader.title.split()[0] for reader in READERS.values())
        command.add_argument("mesh", metavar="MESH", help=f"{', '.join(most)} or {last} file")
        command.add_argument("--region-cone", metavar="AXIS:DEG", help="e.g. 0,1,0:60")
        command.add_argument(
            "--apex", metavar="X,Y,Z", help="where the cone starts (default: the box centre)"
        )
        cap = command.add_mutually_exclusive_group()
        cap.add_argument(
            "--sigma", type=float, help="the warp parameter (default: the largest-cap rule)"
        )
        cap.add_argument("--pole-angle", type=float, metavar="DEG", help="the cap's angle")
        cap.add_argument("--auto", action="store_true", help="choose centre, pole and sigma")
        command.add_argument("--center", help=f"X,Y,Z or one of {', '.join(CENTERS)}")
        command.add_argument(
            "--pole", metavar="X,Y,Z", help="world direction of local +Y (default: chosen)"
        )
        command.add_argument("--up", metavar="X,Y,Z", help="world direction towards local +Z")
        command.add_argument(
            "--facing", metavar="X,Y,Z", help="where the face looks: the front at the top"
        )
        command.add_argument("--layout", choices=[layout.value for layout in Layout])
        command.add_argument("--params", metavar="JSON", help="any of the API's params")
        if "zones" in capability.params.model_fields:
            command.add_argument(
                "--zones",
                metavar="FILE",
                help="JSON: a list of zones, or an object with zones, curves and units",
            )
        fields = capability.params.model_fields
        if "units" in fields:
            units = [unit.value for unit in LengthUnit]
            command.add_argument("--units", choices=units, help="the mesh's length unit")
        for part in capability.parts[1:]:
            what = part.documented.split(":")[0]
            argument = _argument(part, capability)
            if isinstance(part, MeshPart):
                command.add_argument(part.name, metavar=argument, help=what)
            else:
                command.add_argument(argument, dest=part.name, metavar="FILE", help=what)
        if "growth" in fields:
            command.add_argument(
                "--flow",
                metavar="FILE",
                help="JSON: a list of flow curves, or an object with flow, whorls and "
                "exit_angle_deg (params.growth)",
            )
        if "density_per_cm2" in fields:
            command.add_argument(
                "--density",
                type=float,
                metavar="PER_CM2",
                help="sites per cm² (of the region, or of each zone giving none)",
            )
        command.add_argument("--out", metavar="FILE", help="default: JSON on stdout")
        command.add_argument("--progress", action="store_true", help="a progress bar always")
    return top


def _add_batch(commands) -> None:
    batch = commands.add_parser(
        "batch",
        help="a manifest of scans (JSON lines) on N processes: resumable, a failure per scan",
    )
    batch.add_argument(
        "manifest",
        metavar="MANIFEST",
        help='one JSON object a line: {"mesh": PATH, "params": {...}, "outputs": [FILE, ...]}',
    )
    batch.add_argument("--out", metavar="DIR", required=True, help="a folder per scan in DIR")
    batch.add_argument(
        "--allow-root",
        action="append",
        metavar="DIR",
        help="meshes may lie under DIR too (default: only in the manifest's folder); repeatable",
    )
    batch.add_argument(
        "--processes",
        type=_positive,
        metavar="N",
        help="default: the CPUs this may use (within a container's CPU limit)",
    )
    batch.add_argument(
        "--shard-count", type=_positive, metavar="N", help="take the scans i with i %% N == INDEX"
    )
    batch.add_argument(
        "--shard-index", type=int, metavar="INDEX", help="default: $JOB_COMPLETION_INDEX"
    )
    batch.add_argument("--progress", action="store_true", help="a progress bar always")


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: give a whole number of at least 1")
    return value


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        if args.command == "serve":
            serve(args)
            return 0
        if args.command == "health":
            return health(args)
        if args.command == "batch":
            from .batch import run_batch

            return run_batch(args)
        run(args)
    except Problem as problem:
        where = f" ({problem.field})" if problem.field else ""
        print(f"meshflat: error {problem.status}{where}: {problem.detail}", file=sys.stderr)
        return 2
    except ValueError as error:  # a setting (Settings.from_env names the variable)
        if args.command not in ("serve", "health", "batch"):
            raise
        print(f"meshflat: {error}", file=sys.stderr)
        return 2
    return 0


#: Seconds a worker may leave the supervisor's ping unanswered before it is taken for hung and
#: replaced: a worker busy in a long computation answers late. It also bounds how long a
#: worker killed while a ping was on its way goes unnoticed (the supervisor waits for the
#: answer before it looks again).
WORKER_SILENCE_S = 30


def serve(args: argparse.Namespace) -> None:
    """uvicorn with the settings' host, port and workers, JSON logs, and a graceful stop on
    SIGTERM: no new connections, and requests in progress finish (up to their time limit).
    Several workers share their metrics through PROMETHEUS_MULTIPROC_DIR (a fresh temporary
    directory unless one is given)."""
    import uvicorn

    from .observability import capture_warnings, log_config

    settings = Settings.from_env()  # a bad variable stops here, named
    _seed_compiled_kernels()
    workers = args.workers or settings.workers
    # The workers read their settings from the environment: each one's share of the memory
    # budget depends on how many there are (Settings.memory_budget_bytes).
    os.environ["MESHFLAT_WORKERS"] = str(workers)
    capture_warnings()  # the supervisor's own warnings, as JSON too
    with _metrics_directory(workers):
        uvicorn.run(
            "service.app:app",
            host=args.host or settings.host,
            port=args.port or settings.port,
            workers=workers,
            log_config=log_config(),
            access_log=False,  # the service logs each request itself, with its id
            http=PROTOCOL,  # a time limit on headers, a lingering close (service.server)
            timeout_keep_alive=settings.keep_alive_timeout,
            timeout_graceful_shutdown=math.ceil(settings.request_timeout) + 5,
            timeout_worker_healthcheck=WORKER_SILENCE_S,
        )


def _seed_compiled_kernels() -> None:
    """Copy the numba kernels compiled into the image (``MESHFLAT_KERNELS_FROM``) to numba's
    cache (``NUMBA_CACHE_DIR``), each file the cache does not have yet: the image's own
    directory is read-only, and numba only reads a cache it could write
    (transforms/kernels.py). Importing the kernels has made the cache's directories already,
    empty, so files are compared, not directories."""
    given, cache = os.environ.get("MESHFLAT_KERNELS_FROM"), os.environ.get("NUMBA_CACHE_DIR")
    if not (given and cache and Path(given).is_dir()):
        return

    def copy_if_missing(source: str, target: str) -> None:
        if not Path(target).exists():
            shutil.copy2(source, target)

    shutil.copytree(given, cache, dirs_exist_ok=True, copy_function=copy_if_missing)


@contextmanager
def _metrics_directory(workers: int) -> Iterator[None]:
    if workers < 2:
        yield
        return
    given = os.environ.get("PROMETHEUS_MULTIPROC_DIR")
    if given:
        for stale in Path(given).glob("*.db"):  # a previous run's values
            stale.unlink()
        yield
        return
    with tempfile.TemporaryDirectory(prefix="meshflat-metrics-") as directory:
        os.environ["PROMETHEUS_MULTIPROC_DIR"] = directory
        try:
            yield
        finally:
            del os.environ["PROMETHEUS_MULTIPROC_DIR"]


def health(args: argparse.Namespace) -> int:
    """The container's health check (service.health)."""
    from .health import check

    return check(args.port)


if __name__ == "__main__":
    raise SystemExit(main())
