"""The scan zoo (``make bench-zoo``): every scan the project can cite, and variants of them as
users send them (fixtures/zoo.py), flattened the way a front-end engineer would ask, giving
the region alone.

Per case the table gives: the region's size; whether the map is seam-free with the region
alone (the default centre, rotation and sigma) and with ``"auto"`` (the fit, and
``untangle: true``); with auto, the folded and the stretched faces, and the trusted faces'
isometric energy (median); the relative spread of that energy over three random poses of the
scan (plain cases); whether a soup's answer equals its welded twin's; the answer's warnings
(and, for a scan declared in the wrong unit, whether the warning or the refusal names the
unit); the time; and whether the answer's ``params`` sent back give identical numbers. It
exits 1 when a case is not seam-free with auto (unless it was refused with a reason), not
fold-free after untangling (a stray box, a piece of its own, must be warned of instead), not
identical on the round trip, pose-dependent beyond 1e-9, a soup unequal to its twin, or a
wrong unit passes silently.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import time

import orjson

from benchmarks.docs import machine, publish
from fixtures.zoo import ALL_CASES, POSE_SEEDS, SETTINGS, Case, available, case_mesh, welded_twin
from service.capabilities import MESH_COMMANDS
from service.capabilities.context import Context
from service.capabilities.inputs import parse_params
from service.meshio import Mesh
from service.problems import problem_of
from service.timings import Timings

#: The largest relative spread of the trusted energy over poses counted as none.
POSE_RTOL = 1e-9
#: How far a soup's numbers may be from its welded twin's, relative (rounding only).
SOUP_RTOL = 1e-9
#: What /v1/sites is asked for on a scan declared in the wrong unit.
SITES_PER_CM2 = 1.0


def answer(mesh: Mesh, params: dict, command: str = "validate") -> dict:
    """The route's JSON answer (warnings included) as the API's JSON holds it."""
    capability = MESH_COMMANDS[command]
    parsed = parse_params(capability.params, json.dumps(params).encode())
    extra = {part.name: None for part in capability.parts if part.name != "mesh"}
    given = capability.input(mesh=mesh, params=parsed, **extra)
    ctx = Context(SETTINGS)
    result = capability.operation(given, ctx)
    return orjson.loads(capability.encoded(result, ctx, Timings()))


def refused(call) -> tuple[dict | None, str | None]:
    """The answer of ``call()``, or None and the refusal's words (a 4xx of the service)."""
    try:
        return call(), None
    except Exception as error:  # problem_of raises TypeError again on any other error
        problem = problem_of(error)
        return None, f"{problem.status}: {problem.detail}"


def trusted_energy(metrics: dict) -> float:
    """The trusted faces' isometric energy: the median where the answer gives it."""
    trusted = metrics.get("trusted")
    if not trusted:
        return float("nan")
    summary = trusted["isometric"]
    return summary.get("p50", summary["mean"])


def codes(reply: dict | None) -> list[str]:
    return [w["code"] for w in (reply or {}).get("warnings", [])]


def auto_params(region: dict) -> dict:
    return {"region": region, "center": "auto", "untangle": True}


def pose_spread(case: Case) -> float:
    """The relative spread of the trusted energy with auto over :data:`POSE_SEEDS` poses."""
    energies = []
    for seed in POSE_SEEDS:
        mesh, region = case_mesh(case.posed(seed))
        energies.append(trusted_energy(answer(mesh, auto_params(region))["metrics"]))
    return (max(energies) - min(energies)) / abs(sum(energies) / len(energies))


def soup_equal(mesh: Mesh, region: dict, auto: dict) -> bool:
    """Whether the soup's answer (auto) equals its welded twin's, field by field."""
    twin = answer(welded_twin(mesh), auto_params(region))
    twin["params"]["format"] = auto["params"]["format"]  # the twin is written as a PLY
    return all(close(twin[k], auto[k]) for k in ("params", "validation", "metrics"))


def close(a, b, rtol: float = SOUP_RTOL) -> bool:
    """Equal, numbers to ``rtol`` relative (sums over the soup's corners and over the twin's
    vertices add in another order), everything else exactly."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(close(a[k], b[k], rtol) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(close(x, y, rtol) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) or isinstance(b, float):
        return abs(a - b) <= rtol * max(abs(a), abs(b), 1.0)
    return a == b


def units_row(case: Case, mesh: Mesh, region: dict) -> dict:
    """A scan declared in the wrong unit, asked for sites: a warning or a refusal that names
    the unit, or it is silent."""
    params = {"region": region, "units": case.declared, "density_per_cm2": SITES_PER_CM2}
    reply, refusal = refused(lambda: answer(mesh, params, "sites"))
    said = codes(reply)
    named = any("unit" in code for code in said) or (refusal is not None and "unit" in refusal)
    what = ", ".join(said) if reply is not None else f"refused {refusal[:60]}"
    return dict(warnings=what or "none", units_named=named)


def run_case(case: Case, poses: bool = True) -> dict:
    mesh, region = case_mesh(case)
    row = dict(name=case.name, faces=len(mesh.faces), units_named=None, soup_equal=None,
               spread=None, stray=case.stray)  # fmt: skip
    if case.declared is not None:
        return row | units_row(case, mesh, region) | dict(region=None)
    alone, refusal = refused(lambda: answer(mesh, {"region": region}))
    started = time.perf_counter()
    auto, auto_refusal = refused(lambda: answer(mesh, auto_params(region)))
    row["seconds"] = time.perf_counter() - started
    if auto is None:
        return row | dict(region=None, refused=auto_refusal or refusal, warnings="")
    again = answer(mesh, auto["params"])
    v, m = auto["validation"], auto["metrics"]
    row |= dict(
        region=m["trusted"]["faces"] + m["trusted"]["flagged_faces"] if m["trusted"] else 0,
        seam_free_alone=alone is not None and alone["validation"]["seam_free"],
        seam_free_auto=v["seam_free"],
        folded=len(auto["untangle"]["folded_after"]),
        stretched=len(v.get("stretched_faces", [])),
        trusted=trusted_energy(m),
        identical=all(again[k] == auto[k] for k in ("params", "validation", "metrics")),
        warnings=", ".join(codes(auto)) or "none",
    )
    if case.soup is not None:
        row["soup_equal"] = soup_equal(mesh, region, auto)
    if poses and case == case.base and not case.strips and case.decimate is None:
        row["spread"] = pose_spread(case)
    return row


def flag(value, good: str = "yes", bad: str = "NO") -> str:
    return "-" if value is None else (good if value else bad)


def table(rows: list[dict]) -> str:
    lines = [
        "| scan | faces | region | seam-free: alone / auto | folded / stretched (auto) | "
        "trusted energy p50 (auto) | pose spread | soup = welded | warnings | fit + untangle"
        " | round trip identical |",
        "|---|---:|---:|---|---:|---:|---:|---|---|---:|---|",
    ]
    for r in rows:
        if r.get("units_named") is not None:
            lines.append(
                f"| {r['name']} | {r['faces']:,} | - | - | - | - | - | - | {r['warnings']}"
                f" (unit named: {flag(r['units_named'])}) | - | - |"
            )
            continue
        if r.get("refused"):
            lines.append(f"| {r['name']} | {r['faces']:,} | - | refused: {r['refused']} |"
                         " - | - | - | - | - | - | - |")  # fmt: skip
            continue
        spread = "-" if r["spread"] is None else f"{r['spread']:.1e}"
        lines.append(
            f"| {r['name']} | {r['faces']:,} | {r['region']:,} | "
            f"{flag(r['seam_free_alone'])} / {flag(r['seam_free_auto'])} | "
            f"{r['folded']:,} / {r['stretched']:,} | {r['trusted']:.3f} | {spread} | "
            f"{flag(r['soup_equal'])} | {r['warnings']} | {r['seconds']:.2f} s | "
            f"{flag(r['identical'])} |"
        )
    return "\n".join(lines)


def good(row: dict) -> bool:
    """Whether a case meets the zoo's bar (the module's docstring)."""
    if row.get("units_named") is not None:
        return row["units_named"]
    if row.get("refused"):
        return True
    if row["stray"]:  # the box beside the head is a piece of its own: said, not untangled
        return row["seam_free_auto"] and "region_pieces" in row["warnings"]
    return (
        row["seam_free_auto"]
        and row["folded"] == 0
        and row["identical"]
        and row["soup_equal"] is not False
        and (row["spread"] is None or row["spread"] <= POSE_RTOL)
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write-docs", action="store_true")
    parser.add_argument("--only", help="cases whose name contains this")
    args = parser.parse_args(argv)
    cases = [c for c in ALL_CASES if available(c.scan) and (not args.only or args.only in c.name)]
    rows = []
    for case in cases:
        rows.append(run_case(case))
        print(f"{case.name}: done", file=sys.stderr)
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    report = f"{stamp}, {machine()}; one thread.\n\n{table(rows)}"
    missing = [c.name for c in ALL_CASES if not available(c.scan)]
    if missing:
        report += f"\n\nNot run (their scans are not beside the repository): {', '.join(missing)}."
    publish("zoo", "Scan zoo (make bench-zoo)", report, args.write_docs)
    return 0 if all(good(r) for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
