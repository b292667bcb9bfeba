"""Benchmark of the Arrow answer against the JSON answer (``make bench-arrow``).

The answer: ``/v1/flatten`` of ``make bench-service``'s head (``lee-perry-smith.obj``
subdivided 3 times, 1,130,880 faces, sent as GLB), the whole mesh as the region, computed
once. Timed, median of several runs after a warm-up:

* on the server: the route's encoding of that result (:meth:`MeshCapability.render`), JSON
  (orjson) and Arrow (nanoarrow), and the answers' sizes;
* in the browser (headless Chromium, the answers served from 127.0.0.1): the JSON answer
  decoded and parsed (``TextDecoder``, ``JSON.parse``) against the Arrow answer read by Arrow
  JS (``tableFromIPC``) with every column's typed array taken; what a client does before it
  can use the arrays.

    python -m benchmarks.arrow_bench [--runs 5] [--write-docs]

Needs the test extra (playwright), Chromium (``/usr/bin/chromium``) and
``npm ci --prefix tests/js`` (Arrow JS).
"""

from __future__ import annotations

import functools
import http.server
import statistics
import tempfile
import threading
import time
from importlib.metadata import version
from pathlib import Path

import orjson
import trimesh

from benchmarks.docs import run_report
from fixtures.meshes import subdivided
from service.capabilities import MESH_COMMANDS
from service.capabilities.context import Context
from service.capabilities.inputs import Upload, parse_params
from service.outputs import Output
from service.timings import Timings

ARROW_JS = Path(__file__).parent.parent / "tests" / "js" / "node_modules" / "apache-arrow"
CHROMIUM = "/usr/bin/chromium"
PARAMS = {"rotation": {"pole": [0, -1, 0], "up": [0, 0, 1]}}
#: In the page: each answer fetched once, then ``runs`` times read as a client reads it.
READ_IN_PAGE = """async (runs) => {
    const json = await (await fetch("answer.json")).arrayBuffer();
    const arrow = await (await fetch("answer.arrow")).arrayBuffer();
    const times = {json: [], arrow: []};
    for (let k = 0; k <= runs; k++) {
        let start = performance.now();
        const answer = JSON.parse(new TextDecoder().decode(json));
        const jsonMs = performance.now() - start;
        start = performance.now();
        const table = Arrow.tableFromIPC(new Uint8Array(arrow));
        let numbers = 0;
        for (const field of table.schema.fields) {
            let vector = table.getChild(field.name).get(0);
            while (vector.type.typeId === Arrow.Type.FixedSizeList) vector = vector.getChildAt(0);
            numbers += vector.toArray().length;
        }
        const arrowMs = performance.now() - start;
        if (k > 0) {  // after a warm-up
            times.json.push(jsonMs);
            times.arrow.push(arrowMs);
        }
        if (answer.faces.ids.length !== table.getChild("faces.ids").get(0).length)
            throw new Error("the answers differ");
    }
    return times;
}"""


def answers(runs: int) -> tuple[dict[Output, bytes], dict[Output, float], int]:
    """The two answers, the median time of encoding each, and the face count."""
    vertices, faces = subdivided("lee-perry-smith.obj", 3)
    glb = trimesh.Trimesh(vertices, faces, process=False).export(file_type="glb")
    flatten = MESH_COMMANDS["flatten"]
    params = parse_params(flatten.params, orjson.dumps(PARAMS))
    ctx = Context()
    given = flatten.input_of(params, {"mesh": Upload("head.glb", glb)}, ctx)
    result = flatten.operation(given, ctx)
    data, times = {}, {}
    for output in (Output.JSON, Output.ARROW):
        taken = []
        for _ in range(runs + 1):
            start = time.perf_counter()
            data[output] = flatten.render(result, given.params, output, ctx, Timings())
            taken.append(time.perf_counter() - start)
        times[output] = 1e3 * statistics.median(taken[1:])
    return data, times, len(faces)


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # no line a request on the benchmark's report
        pass


def read_in_browser(data: dict[Output, bytes], runs: int) -> dict[str, float]:
    """The median times of reading each answer in headless Chromium, ms."""
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as folder:
        for output, body in data.items():
            (Path(folder) / f"answer.{output.value}").write_bytes(body)
        (Path(folder) / "index.html").write_text("<!doctype html><title>arrow</title>")
        handler = functools.partial(_Quiet, directory=folder)
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        try:
            with sync_playwright() as playwright:
                browser = playwright.chromium.launch(
                    executable_path=CHROMIUM, args=["--no-sandbox"]
                )
                page = browser.new_page()
                page.goto(f"http://127.0.0.1:{server.server_address[1]}/index.html")
                page.add_script_tag(path=str(ARROW_JS / "Arrow.es2015.min.js"))
                times = page.evaluate(READ_IN_PAGE, runs)
                browser.close()
        finally:
            server.shutdown()
    return {name: statistics.median(values) for name, values in times.items()}


def measure(runs: int) -> str:
    data, encoded, faces = answers(runs)
    read = read_in_browser(data, runs)
    arrow_js = orjson.loads((ARROW_JS / "package.json").read_bytes())["version"]
    size = {output: len(body) / 1e6 for output, body in data.items()}
    lines = [
        f"`/v1/flatten` of `lee-perry-smith.obj` subdivided 3 times ({faces:,} faces, sent as "
        f"GLB), the whole mesh as the region; median of {runs} runs after a warm-up. Encoding "
        "is the route's, from the computed result to the answer's bytes; reading is headless "
        "Chromium's, from the answer's bytes to arrays a client can use: `JSON.parse` of the "
        f"decoded text, or Arrow JS {arrow_js}'s `tableFromIPC` and every column's typed "
        "array.",
        "",
        "| form | answer (MB) | encoding on the server (ms) | reading in the browser (ms) |",
        "|---|---:|---:|---:|",
        f"| JSON (orjson) | {size[Output.JSON]:.1f} | {encoded[Output.JSON]:,.0f} "
        f"| {read['json']:,.0f} |",
        f"| Arrow IPC stream (nanoarrow {version('nanoarrow')}) | {size[Output.ARROW]:.1f} "
        f"| {encoded[Output.ARROW]:,.0f} | {read['arrow']:,.1f} |",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    return run_report(
        argv,
        __doc__,
        "arrow-bench",
        "The Arrow answer against the JSON answer (`make bench-arrow`)",
        measure,
    )


if __name__ == "__main__":
    raise SystemExit(main())
