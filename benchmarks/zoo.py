"""The scan zoo (``make bench-zoo``): every scan the project can cite, and variants of them as
users send them (fixtures/zoo.py), flattened the way a front-end engineer would ask, giving
the region alone.

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
import sys
import time

import orjson

from benchmarks.docs import machine, publish
from fixtures.zoo import CASES, SETTINGS, Case, available, case_mesh
from service.capabilities import MESH_COMMANDS
from service.capabilities.context import Context
from service.capabilities.inputs import parse_params
from service.capabilities.region.resolve import MeshInput
from service.encoding import encode
from service.meshio import Mesh


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
