"""The scan zoo (``make bench-zoo``): every scan the project can cite, and variants of them as
users send them, flattened the way a front-end engineer would ask, giving the region alone.

Scans: the bundled samples (``service/samples``) and the project's shared meshes
(``../shared/data/meshes``, credits in its ``SOURCES.md``) when they are beside the
repository. Variants are made here, in memory, never committed: Z-up and Y-up turns,
millimetres, far from the origin, noise, decimation, subdivision, and the scan written as PLY
triangle strips.

Per case the table gives: the region's size; with the region alone (the default rotation
and sigma), whether the map is seam-free and how many triangles fold; with ``center:
"auto"`` and ``untangle: true``, the folds before and after untangling, the isometric energy
over all triangles and over the trusted ones, and the time; and whether the answer's
``params`` sent back give identical numbers. It exits 1 when a case is not seam-free with the
defaults, not fold-free after untangling, or not identical on the round trip.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import orjson
import trimesh
from scipy.spatial.transform import Rotation

from benchmarks.docs import publish
from benchmarks.transforms_bench import machine
from service.capabilities import MESH_COMMANDS
from service.capabilities.context import Context
from service.capabilities.inputs import parse_params
from service.capabilities.region.resolve import MeshInput
from service.encoding import encode
from service.meshio import Mesh, format_of, read_mesh
from service.samples import SAMPLES
from service.settings import Settings

SHARED = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "meshes"
SETTINGS = Settings()


@dataclass(frozen=True)
class Case:
    """A scan, a variant of it, and the region a user would give (in the scan's axes; the
    variant turns, scales and moves it with the mesh)."""

    name: str
    scan: str
    region: dict
    turn: tuple | None = None  # rows of a rotation applied to the scan
    scale: float = 1.0
    offset: tuple = (0.0, 0.0, 0.0)
    noise: float = 0.0  # Gaussian, as a fraction of the bounding box's diagonal
    strips: bool = False
    decimate: float | None = None  # the share of the faces kept

    @property
    def changed(self) -> bool:
        return (self.turn, self.scale, self.offset, self.noise) != (None, 1.0, (0.0,) * 3, 0.0)

    def point(self, points: np.ndarray) -> np.ndarray:
        turned = points if self.turn is None else points @ np.asarray(self.turn).T
        return turned * self.scale + np.asarray(self.offset)

    def direction(self, direction) -> list[float]:
        d = np.asarray(direction, dtype=float)
        return (d if self.turn is None else np.asarray(self.turn) @ d).tolist()

    def vertices(self, vertices: np.ndarray) -> np.ndarray:
        moved = self.point(vertices)
        if self.noise:
            size = float(np.linalg.norm(moved.max(axis=0) - moved.min(axis=0)))
            moved = moved + np.random.default_rng(7).normal(size=moved.shape) * self.noise * size
        return moved


def scan_bytes(name: str) -> bytes:
    if name in SAMPLES:
        return SAMPLES[name].path.read_bytes()
    return (SHARED / name).read_bytes()


def available(name: str) -> bool:
    return name in SAMPLES or (SHARED / name).exists()


Y_TO_Z = tuple(map(tuple, Rotation.from_euler("x", 90, degrees=True).as_matrix()))
Z_TO_Y = tuple(map(tuple, np.asarray(Y_TO_Z).T))
FS = "fsaverage-head.ply"
LPS = "lee-perry-smith.glb"
SCALP_FS = {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}
SCALP_LPS = {"cone": {"axis": [0, 1, 0], "half_angle_deg": 60, "apex": [0, 1.2, -0.3]}}
TOP_NEFERTITI = {"cone": {"axis": [0, 0, 1], "half_angle_deg": math.degrees(1.0)}}
TOP_GOAT = {"cone": {"axis": [0, 1, 0], "half_angle_deg": 60}}

CASES = (
    Case("fsaverage scalp (Z-up, mm)", FS, SCALP_FS),
    Case("fsaverage scalp, Y-up", FS, SCALP_FS, turn=Z_TO_Y),
    Case("Lee Perry-Smith scalp (Y-up, with shoulders)", LPS, SCALP_LPS),
    Case("Lee Perry-Smith, Z-up", LPS, SCALP_LPS, turn=Y_TO_Z),
    Case(
        "Lee Perry-Smith, millimetres, 5 km from the origin",
        LPS,
        SCALP_LPS,
        scale=1000.0,
        offset=(5e6, -3e6, 2e6),
    ),
    Case("Lee Perry-Smith, noisy (0.1%)", LPS, SCALP_LPS, noise=1e-3),
    Case("Lee Perry-Smith, decimated to 25%", LPS, SCALP_LPS, decimate=0.25),
    Case("Lee Perry-Smith, PLY triangle strips", LPS, SCALP_LPS, strips=True),
    Case("Nefertiti top (overhanging crown)", "nefertiti-lowres.obj", TOP_NEFERTITI),
    Case("goat head top (horn and ears)", "goathead.obj", TOP_GOAT),
)


def strips_ply(mesh: Mesh) -> bytes:
    """The mesh as a binary PLY of triangle strips: each triangle a strip ended by -1."""
    items = np.hstack([mesh.faces, -np.ones((len(mesh.faces), 1), dtype=np.int64)]).ravel()
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(mesh.vertices)}\nproperty double x\nproperty double y\n"
        "property double z\nelement tristrips 1\nproperty list int int vertex_indices\n"
        "end_header\n"
    ).encode()
    body = mesh.vertices.astype("<f8").tobytes() + np.array([len(items)], "<i4").tobytes()
    return header + body + items.astype("<i4").tobytes()


def case_mesh(case: Case) -> tuple[Mesh, dict]:
    """The variant's mesh (read back through the service's reader) and its region."""
    mesh = read_mesh(scan_bytes(case.scan), format_of(case.scan, None), SETTINGS.limits)
    vertices, faces = case.vertices(mesh.vertices), mesh.faces
    if case.decimate is not None:
        simplified = trimesh.Trimesh(vertices, faces, process=False).simplify_quadric_decimation(
            percent=1.0 - case.decimate
        )
        vertices, faces = np.asarray(simplified.vertices), np.asarray(simplified.faces)
    variant = Mesh(vertices=vertices, faces=faces, format=mesh.format)
    if case.strips:
        variant = read_mesh(strips_ply(variant), "ply", SETTINGS.limits)
    elif case.changed or case.decimate is not None:
        out = trimesh.Trimesh(variant.vertices, variant.faces, process=False).export(
            file_type="ply"
        )
        variant = read_mesh(out, "ply", SETTINGS.limits)
    region = json.loads(json.dumps(case.region))
    cone = region.get("cone")
    if cone is not None:
        cone["axis"] = case.direction(cone["axis"])
        if "apex" in cone:
            cone["apex"] = case.point(np.asarray([cone["apex"]], dtype=float))[0].tolist()
    return variant, region


def answer(mesh: Mesh, params: dict, command: str = "validate"):
    capability = MESH_COMMANDS[command]
    parsed = parse_params(capability.params, json.dumps(params).encode())
    return capability.response.of(capability.operation(MeshInput(mesh, parsed), Context(SETTINGS)))


def plain(model) -> dict:
    """The answer as the API's JSON holds it."""
    return orjson.loads(encode(model))


def run_case(case: Case) -> dict:
    mesh, region = case_mesh(case)
    defaults = plain(answer(mesh, {"region": region}))
    started = time.perf_counter()
    auto = plain(answer(mesh, {"region": region, "center": "auto", "untangle": True}))
    seconds = time.perf_counter() - started
    again = plain(answer(mesh, auto["params"]))
    identical = all(again[k] == auto[k] for k in ("params", "validation", "metrics", "untangle"))
    v, u, m = defaults["validation"], auto["untangle"], auto["metrics"]
    trusted = m["trusted"]["isometric"]["mean"] if m["trusted"] else float("nan")
    return dict(
        name=case.name,
        faces=len(mesh.faces),
        region=m["trusted"]["faces"] + m["trusted"]["flagged_faces"] if m["trusted"] else 0,
        seam_free=v["seam_free"],
        folded_defaults=len(v["folded_faces"]),
        folded_before=u["folded_before"],
        folded_after=len(u["folded_after"]),
        energy=m["isometric"]["mean"],
        trusted=trusted,
        seconds=seconds,
        identical=identical,
    )


def table(rows: list[dict]) -> str:
    lines = [
        "| scan | faces | region | seam-free with defaults | folded (defaults) | folded before"
        " / after untangling (auto) | energy: all / trusted (auto) | fit + untangle | round"
        " trip identical |",
        "|---|---:|---:|---|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['faces']:,} | {r['region']:,} | "
            f"{'yes' if r['seam_free'] else 'NO'} | {r['folded_defaults']:,} | "
            f"{r['folded_before']:,} / {r['folded_after']:,} | "
            f"{r['energy']:.3f} / {r['trusted']:.3f} | {r['seconds']:.2f} s | "
            f"{'yes' if r['identical'] else 'NO'} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write-docs", action="store_true")
    parser.add_argument("--only", help="cases whose name contains this")
    args = parser.parse_args(argv)
    cases = [c for c in CASES if available(c.scan) and (not args.only or args.only in c.name)]
    rows = []
    for case in cases:
        rows.append(run_case(case))
        print(f"{case.name}: done", file=sys.stderr)
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    report = f"{stamp}, {machine()}; one thread.\n\n{table(rows)}"
    missing = [c.name for c in CASES if not available(c.scan)]
    if missing:
        report += f"\n\nNot run (their scans are not beside the repository): {', '.join(missing)}."
    publish("zoo", "Scan zoo (make bench-zoo)", report, args.write_docs)
    good = all(r["seam_free"] and r["folded_after"] == 0 and r["identical"] for r in rows)
    return 0 if good else 1


if __name__ == "__main__":
    raise SystemExit(main())
