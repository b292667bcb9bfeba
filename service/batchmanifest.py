"""The manifest of ``meshflat batch``: its lines read and checked before anything runs, and
the shard a run takes.

A line is one JSON object: ``mesh`` and ``outputs`` required, ``params``, ``command`` and
``name`` optional (:mod:`service.batch` says what each is). Every line is checked as the API
would check it (the params by the command's model, the outputs by its forms) and for what a
line can never be given: a second mesh, or a PNG part (a ``region.texture_mask``'s mask,
``sites``' density map, ``transfer``'s image), or a form the one computation of a scan cannot
answer (``transfer``'s look-up images). A bad line stops the batch, named by its number.
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path

import orjson

from .capabilities import MESH_COMMANDS, MeshCapability
from .capabilities.inputs import MeshPart, parse_params
from .jsonkeys import repeated_key
from .meshio import format_of
from .outputs import Output
from .problems import Problem, core_errors_as_problems

#: Written last into a scan's folder: the inputs' digest and each output's size and SHA-256.
DIGEST_FILE = "digest.json"
#: Written into a scan's folder when it fails: the API's problem and the manifest's line.
ERROR_FILE = "error.json"
#: The keys of a manifest line.
LINE_KEYS = ("mesh", "outputs", "params", "command", "name")
#: A scan's folder and its outputs' file names: one plain path component each.
PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")
#: Kubernetes sets it in each pod of an Indexed Job (its index, from 0).
JOB_INDEX_VARIABLE = "JOB_COMPLETION_INDEX"


@dataclass(frozen=True)
class Scan:
    """One line of the manifest, checked: ``outputs`` are (file name, form) pairs."""

    line: int
    name: str
    mesh: Path
    command: str
    params: dict
    outputs: tuple[tuple[str, Output], ...]
    #: Where the mesh may lie: the manifest's folder, and each --allow-root.
    roots: tuple[Path, ...] = ()

    def digest(self, mesh_bytes: bytes) -> str:
        """SHA-256 of everything the outputs depend on: the mesh's bytes, the command, the
        params (keys sorted), the output names and meshflat's version."""
        recipe = {
            "mesh_sha256": hashlib.sha256(mesh_bytes).hexdigest(),
            "command": self.command,
            "params": self.params,
            "outputs": [name for name, _ in self.outputs],
            "meshflat": version("meshflat"),
        }
        return hashlib.sha256(orjson.dumps(recipe, option=orjson.OPT_SORT_KEYS)).hexdigest()


# -- the manifest --------------------------------------------------------------------------


def read_manifest(path: Path, allowed: tuple[Path, ...] = ()) -> list[Scan]:
    """Every scan of the manifest, checked (params by the API's models, outputs by the
    command's forms, names unique); a scan's mesh may lie in the manifest's folder or one
    of ``allowed``.

    Raises
    ------
    Problem
        The manifest cannot be read, or has bad lines (each named by its number).
    """
    try:
        lines = path.read_bytes().splitlines()
    except OSError as error:
        raise Problem(
            422, f"cannot read {str(path)!r}: {error.strerror}", field="MANIFEST"
        ) from None
    scans, errors, lines_by_name = [], [], {}
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            scan = parse_line(line, number, path.parent, allowed)
            if scan.name in lines_by_name:
                raise Problem(
                    422,
                    f"name: {scan.name!r} is also line {lines_by_name[scan.name]}'s folder; "
                    'give each scan its own "name"',
                )
        except Problem as problem:
            errors.append(f"line {number}: {problem.detail}")
            continue
        lines_by_name[scan.name] = number
        scans.append(scan)
    if errors:
        shown = errors[:20] + ([f"and {len(errors) - 20} more"] if len(errors) > 20 else [])
        raise Problem(422, f"{path.name}: " + "\n  ".join(shown), field="MANIFEST")
    if not scans:
        raise Problem(422, f"{path.name}: no scans (one JSON object per line)", field="MANIFEST")
    return scans


def parse_line(line: bytes, number: int, folder: Path, allowed: tuple[Path, ...] = ()) -> Scan:
    """One manifest line as a :class:`Scan`; ``folder`` is where relative paths start, and
    with ``allowed`` where its mesh may lie.

    Raises
    ------
    Problem
        What is wrong with the line, naming its key (and the params' field).
    """
    entry = _object_of(line)
    mesh = entry.get("mesh")
    if not isinstance(mesh, str) or not mesh:
        raise Problem(422, 'mesh: each line needs "mesh", the path of its scan', field="mesh")
    command = entry.get("command", "flatten")
    if command not in MESH_COMMANDS:
        raise Problem(422, f"command: {command!r} is not one of {', '.join(MESH_COMMANDS)}")
    capability = MESH_COMMANDS[command]
    others = [part.name for part in capability.extra_parts if isinstance(part, MeshPart)]
    if others:  # a line names one mesh
        raise Problem(
            422,
            f"command: {command} reads a second mesh ({', '.join(others)}), which a manifest "
            f"line cannot give; run `meshflat {command}` for each pair",
            field="command",
        )
    params = entry.get("params", {})
    parsed = _check_params(params, capability, Path(mesh).name)
    name = entry.get("name", Path(mesh).stem)
    if not isinstance(name, str) or not PLAIN_NAME.fullmatch(name):
        raise Problem(
            422,
            f"name: {name!r} cannot name a folder: give \"name\", letters, digits, '.', '_' "
            "or '-', starting with a letter or digit, at most 128",
            field="name",
        )
    outputs = _outputs(entry, capability)
    _check_servable(command, parsed, outputs)
    return Scan(number, name, folder / mesh, command, params, outputs, (folder, *allowed))


def _object_of(line: bytes) -> dict:
    try:
        entry = orjson.loads(line)
    except orjson.JSONDecodeError as error:
        raise Problem(422, f"not JSON ({error})") from None
    if not isinstance(entry, dict):
        raise Problem(422, 'not a JSON object such as {"mesh": ..., "outputs": [...]}')
    repeated = repeated_key(line)
    if repeated is not None:
        where = ".".join(str(part) for part in repeated)
        raise Problem(422, f"{where}: given more than once (only one would be used)", field=where)
    unknown = sorted(set(entry) - set(LINE_KEYS))
    if unknown:
        raise Problem(422, f"{unknown[0]}: not a key of a line; the keys: {', '.join(LINE_KEYS)}")
    return entry


def _check_params(params, capability: MeshCapability, mesh_name: str):
    """The params as the API checks them, and the mesh's format known from its name."""
    if not isinstance(params, dict):
        raise Problem(422, "params: must be a JSON object (the API's params)", field="params")
    if "output" in params:
        raise Problem(
            422,
            "params.output: the extensions in outputs choose the forms; leave it out",
            field="params.output",
        )
    with core_errors_as_problems(capability.places):
        parsed = parse_params(capability.params, orjson.dumps(params))
        format_of(mesh_name, parsed.format)
    return parsed


def _check_servable(command: str, params, outputs: tuple[tuple[str, Output], ...]) -> None:
    """What a line asks that needs a file beside its mesh (a PNG part), or a form the one
    computation of a scan cannot answer: it could never succeed.

    Raises
    ------
    Problem
        Naming the field, and the command that can do it.
    """
    region = getattr(params, "region", None)
    needs = None
    if region is not None and getattr(region, "texture_mask", None) is not None:
        needs = ("params.region.texture_mask", "mask")
    elif getattr(params, "density_range", None) is not None:  # sites, strands
        needs = ("params.density_range", "density_map")
    elif getattr(params, "length_range", None) is not None:  # strands
        needs = ("params.length_range", "length_map")
    elif command == "transfer" and params.values is None:
        needs = ("params.values", "image")
    if needs is not None:
        field, part = needs
        raise Problem(
            422,
            f"{field}: {command} then reads a PNG part ({part}), which a manifest line cannot "
            f"give; run `meshflat {command} --{part.replace('_', '-')} FILE` for it",
            field=field,
        )
    lookups = [name for name, output in outputs if output in (Output.FACE_IDS, Output.BARYCENTRIC)]
    if command == "transfer" and lookups:
        raise Problem(
            422,
            f"outputs: {lookups[0]!r} is a look-up image, computed only when asked alone; run "
            f"`meshflat transfer --out {lookups[0]}` for it",
            field="outputs",
        )


def _outputs(entry: dict, capability: MeshCapability) -> tuple[tuple[str, Output], ...]:
    names = entry.get("outputs")
    if not names or not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise Problem(
            422, 'outputs: a list of file names, such as ["map.json", "map.png"]', field="outputs"
        )
    for name in names:
        if not PLAIN_NAME.fullmatch(name) or name in (DIGEST_FILE, ERROR_FILE):
            raise Problem(
                422,
                f"outputs: {name!r} is not a plain file name (letters, digits, '.', '_', '-'; "
                f"not {DIGEST_FILE} or {ERROR_FILE}, which the batch writes)",
                field="outputs",
            )
    if len(set(names)) != len(names):
        raise Problem(422, "outputs: a file name is given twice", field="outputs")
    with core_errors_as_problems(capability.places):
        return tuple((name, capability.output_of_file(name, "outputs")) for name in names)


def shard_of(scans: list[Scan], index: int | None, count: int | None) -> list[Scan]:
    """The scans ``i`` with ``i % count == index``; all of them without a count. The index
    defaults to ``JOB_COMPLETION_INDEX``."""
    if count is None:
        if index is not None:
            raise Problem(422, "--shard-index: give --shard-count too", field="--shard-index")
        return scans
    if index is None:
        given = os.environ.get(JOB_INDEX_VARIABLE)
        if given is None:
            raise Problem(
                422,
                f"--shard-count: give --shard-index, or set {JOB_INDEX_VARIABLE} "
                "(Kubernetes does in an Indexed Job)",
                field="--shard-index",
            )
        try:
            index = int(given)
        except ValueError:
            raise Problem(
                422, f"{JOB_INDEX_VARIABLE}: {given!r} is not a whole number", field="--shard-index"
            ) from None
    if not 0 <= index < count:
        raise Problem(422, f"--shard-index: {index} is outside [0, {count})", field="--shard-index")
    return scans[index::count]
