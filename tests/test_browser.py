"""End to end in a real browser: headless Chromium opens the demo page served by a real
uvicorn that requires an API key, enters the key, flattens a bundled scan, then the default
sample in automatic mode, and the test checks what the page shows; then draws a zone on the
map, which the page measures (/v1/measure) and lifts onto the 3D view. The screenshots are
kept in ``artifacts/demo.png``, ``artifacts/demo-auto.png`` and ``artifacts/demo-zone.png``
(and the others' in ``artifacts/``); the plan's, the 200k-face region's colours and the page
at 1366 x 900 and the strands grown too, or, with MESHFLAT_WRITE_FIGURES=1, in
``docs/figures/`` (demo-plan, demo-colour-200k, demo-colour, demo-strands), the figures the
docs show.
The page is opened at 1366 x 900, the laptop screen it is laid out for."""

from __future__ import annotations

import json
import math
import os
import shutil
from contextlib import contextmanager
from pathlib import Path

import httpx
import numpy as np
import pytest

from fixtures.meshes import subdivided_ply
from service.samples import SAMPLES

from .conftest import real_servers, slow
from .test_serve import running
from .tools import JS_TOOLS, require

pytestmark = [slow, real_servers]

CHROMIUM = os.environ.get("MESHFLAT_CHROMIUM", "/usr/bin/chromium")
ARTIFACTS = Path(__file__).parent.parent / "artifacts"
#: Where the figures the docs show are written: refreshed on request, so that a test run
#: leaves the checkout as it was.
FIGURES = (
    Path(__file__).parent.parent / "docs" / "figures"
    if os.environ.get("MESHFLAT_WRITE_FIGURES") == "1"
    else ARTIFACTS
)
SAMPLE = "fsaverage-head.ply"
KEY = "browser-test-key"
#: What the page's preset for the sample sends (web/demo.js, PRESETS): with facing, its up
#: is where the face looks.
PARAMS = {
    "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}},
    "layout": "theta_phi",
    "center": "bbox_center",
    "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
    "facing": [0, 1, 0],
    "sigma": 0.3,
}
#: The screen the page is laid out for: a common laptop's.
SCREEN = {"width": 1366, "height": 900}


@pytest.fixture(scope="module")
def server():
    """``meshflat serve`` on a free port of 127.0.0.1, requiring a key, ready."""
    with running(MESHFLAT_API_KEYS=KEY) as server:
        yield server.url


def post(server: str, route: str, params: dict) -> dict:
    """The JSON answer of a mesh route for the sample, with the key."""
    response = httpx.post(
        f"{server}{route}",
        files={"mesh": (SAMPLE, SAMPLES[SAMPLE].path.read_bytes())},
        data={"params": json.dumps(params)},
        headers={"X-API-Key": KEY},
        timeout=60,
    )
    assert response.status_code == 200, response.text
    return response.json()


@contextmanager
def chromium():
    """The system's headless Chromium, driven by playwright, with WebGL in software."""
    require(
        shutil.which(CHROMIUM) is not None or Path(CHROMIUM).exists(),
        "Chromium",
        "apt-get install chromium (or set MESHFLAT_CHROMIUM)",
    )
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=CHROMIUM,
            args=["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"],
        )
        try:
            yield browser
        finally:
            browser.close()


def demo_page(browser, server: str, problems: list[str]):
    """The demo page, loaded and ready; its errors go to ``problems``. The one console
    error expected: the samples asked for before the key is given (401)."""
    page = browser.new_page(viewport=SCREEN)
    page.on(
        "console",
        lambda m: m.type == "error" and "401" not in m.text and problems.append(m.text),
    )
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.on("requestfailed", lambda r: problems.append(f"{r.url}: {r.failure}"))
    page.goto(server, wait_until="load")
    page.wait_for_selector("body[data-state=ready]", timeout=30_000)
    return page


def flatten_sample(page) -> None:
    """Enter the key, pick the sample (its preset) and flatten it, until it is shown."""
    page.fill("#apikey", KEY)
    page.locator("#apikey").blur()  # a change event, as when the user moves on
    page.wait_for_selector(f"#sample option[value='{SAMPLE}']", state="attached")
    page.select_option("#sample", SAMPLE)
    page.click("#go")
    page.wait_for_selector("body[data-state=shown]", timeout=60_000)


def test_demo_page_flattens_a_sample_and_shows_map_and_textured_mesh(server):
    # What the API answers for the same request: the page must show the same region.
    expected = post(server, "/v1/flatten", PARAMS)
    vertex_count = len(expected["vertices"]["ids"])

    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        assert "enter the API key" in page.locator("#status").inner_text()
        flatten_sample(page)
        page.wait_for_timeout(500)  # a few frames of the 3D view
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "demo.png"), full_page=True)

        # The map: the SVG from /v1/flatten, drawn triangle by triangle, with its legend.
        assert page.locator("#map svg path.triangles").count() >= 1
        legend = page.locator("#map svg g.legend").text_content()
        faces = len(expected["faces"]["ids"])
        assert f"region: {faces:,} triangles" in legend
        # The 3D view: the GLB loaded by three.js, with the region's vertex count.
        assert page.locator("body").get_attribute("data-vertices") == str(vertex_count)
        assert page.locator("#vertices").inner_text() == f"{vertex_count:,}"
        summary = page.locator("#summary").inner_text()
        assert "seam-free, star-shaped" in summary
        # The energy as the captions quote it: the trusted median and p95, the flagged count.
        trusted = expected["metrics"]["trusted"]
        energy = trusted["isometric"]
        assert (
            f"isometric energy p50 {energy['p50']:.3f}, p95 {energy['p95']:.3f} on the trusted "
            f"faces ({trusted['flagged_faces']} flagged"
        ) in summary, summary
        # The canvas shows something besides the background.
        drawn = page.evaluate(NOT_BACKGROUND)
        assert drawn > 0.02, drawn
        # The centre field shows the centre used, three numbers.
        assert len(page.locator("#center").input_value().split(",")) == 3

        # Automatic mode on the default sample (the first listed): chosen, untangled,
        # one piece and fold-free.
        default = page.locator("#sample option").first.get_attribute("value")
        page.select_option("#sample", default)
        page.check("#auto")
        page.click("#go")
        page.wait_for_selector("body[data-state=shown]", timeout=120_000)
        automatic = page.locator("#summary").inner_text()
        assert automatic.startswith("seam-free"), automatic
        assert "0 folded after" in automatic, automatic
        page.screenshot(path=str(ARTIFACTS / "demo-auto.png"), full_page=True)
    assert not problems, problems


#: Pixels of the 3D view that differ from those kept by the last call with ``true``.
#: The 3D view's pixels, RGBA a pixel (w by h), as the statements below read them.
READ_VIEW = """
    const canvas = document.getElementById('view');
    const gl = canvas.getContext('webgl2') || canvas.getContext('webgl');
    const w = gl.drawingBufferWidth, h = gl.drawingBufferHeight;
    const pixels = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, pixels);"""
#: The share of the view's pixels other than its background (#f4f6f8).
NOT_BACKGROUND = f"""() => {{{READ_VIEW}
    let other = 0;
    for (let i = 0; i < pixels.length; i += 4)
        if (Math.abs(pixels[i] - 0xf4) > 8 || Math.abs(pixels[i + 2] - 0xf8) > 8) other++;
    return other / (w * h);
}}"""
CHANGED_PIXELS = f"""(keep) => {{{READ_VIEW}
    const kept = window.keptPixels;
    if (keep) window.keptPixels = pixels;
    let changed = 0;
    for (let i = 0; kept && i < pixels.length; i += 4)
        if (Math.max(...[0, 1, 2].map((c) => Math.abs(pixels[i + c] - kept[i + c]))) > 40)
            changed++;
    return changed;
}}"""


def on_screen(page, flat: dict, ring: list[tuple[float, float]]):
    """Where the page shows the layout's points of ``ring`` (a theta_phi map), in the
    viewport's pixels, as the picture draws the layout (service/outputs/picture.py,
    ``describe``): its box padded by 4 % of its larger side, scaled into the plot box inside
    the margins (70, 48, 270, 96 pixels) and centred there. Also answers a pixel of the
    picture and one of the screen in layout units: how closely the page can read a click."""
    svg = page.locator("#map svg")
    svg.scroll_into_view_if_needed()
    _, _, width, height = map(float, svg.get_attribute("viewBox").split())
    xs, ys = flat["vertices"]["x"], flat["vertices"]["y"]
    pad = 0.04 * max(max(xs) - min(xs), max(ys) - min(ys))
    x_low, y_low = min(xs) - pad, min(ys) - pad
    view_w, view_h = max(xs) + pad - x_low, max(ys) + pad - y_low
    box_w, box_h = width - 70 - 270, height - 48 - 96
    scale = min(box_w / view_w, box_h / view_h)
    left, top = round(70 + (box_w - view_w * scale) / 2), round(48 + (box_h - view_h * scale) / 2)
    bounds = svg.bounding_box()
    points = [
        (
            bounds["x"] + (left + (x - x_low) * scale) * bounds["width"] / width,
            bounds["y"] + (top + (y - y_low) * scale) * bounds["height"] / height,
        )
        for x, y in ring
    ]
    return points, (1.0 + width / bounds["width"]) / scale


def pentagon(
    flat: dict, size: float, at: tuple[float, float] = (0.0, 0.0)
) -> list[tuple[float, float]]:
    """A pentagon about the middle of the map (or ``at`` that offset from it, in shares of
    the map's width and height), in the layout's coordinates, its corners ``size`` times the
    map's width and height from its centre."""
    xs, ys = flat["vertices"]["x"], flat["vertices"]["y"]
    mid_x = (min(xs) + max(xs)) / 2 + at[0] * (max(xs) - min(xs))
    mid_y = (min(ys) + max(ys)) / 2 + at[1] * (max(ys) - min(ys))
    radius_x, radius_y = size * (max(xs) - min(xs)), size * (max(ys) - min(ys))
    angles = [math.pi / 2 + 2 * math.pi * k / 5 for k in range(5)]
    return [(mid_x + radius_x * math.cos(a), mid_y + radius_y * math.sin(a)) for a in angles]


def draw(page, flat: dict, ring: list[tuple[float, float]]) -> float:
    """Draw ``ring`` as a user does: Draw, a click at each point but the last, a double click
    at the last (which closes the outline); then wait for its area. Answers how closely the
    page can read a click, in layout units (:func:`on_screen`)."""
    page.click("#draw")  # first: it may scroll the page
    clicks, tolerance = on_screen(page, flat, ring)
    for x, y in clicks[:-1]:
        page.mouse.click(x, y)
    # While drawing: the points and the open polyline through them.
    assert page.locator("#map svg .zone-drawing circle").count() == len(clicks) - 1
    assert page.locator("#map svg .zone-drawing polyline").count() == 1
    page.mouse.dblclick(*clicks[-1])
    page.wait_for_selector("#zone-area[data-state=measured]", timeout=30_000)
    assert page.locator("#map svg .zone-drawing circle").count() == len(clicks)
    assert page.locator("#map svg .zone-drawing polygon").count() == 1
    return tolerance


def measured(page, server: str, units: str) -> tuple[dict, dict]:
    """The ring the page posted (``data-ring``) and what /v1/measure answers for it."""
    ring = json.loads(page.locator("#zone-area").get_attribute("data-ring"))
    params = {**PARAMS, "zones": [{"name": "zone", "outer": ring}], "units": units}
    return ring, post(server, "/v1/measure", params)["zones"][0]


def units_of_samples(page, names: list[str]) -> list[str]:
    """The units the page sets as each sample is picked in turn (/v1/samples' units)."""
    found = []
    for name in names:
        page.select_option("#sample", name)
        found.append(page.locator("#units").input_value())
    return found


def zone_warnings(page) -> list[str]:
    """The warnings the page lists for its last answer."""
    return page.locator("#warnings li").all_inner_texts()


def test_a_zone_drawn_on_the_map_is_measured_and_outlined_on_the_3d_view(server):
    """Five points clicked on the map (the last a double click, which closes the outline):
    the page posts the ring at those points of the layout to /v1/measure, shows its area in
    cm² as the API answers it, draws the outline lifted onto the surface in the 3D view, and
    measures again when the units change, listing the answer's warnings (a scalp in cm is
    implausibly large); Clear takes it all away. The units are the sample's."""
    flat = post(server, "/v1/flatten", PARAMS)
    ring = pentagon(flat, 0.3)

    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        assert page.locator("#draw").is_disabled()  # no map to draw on yet
        flatten_sample(page)
        assert units_of_samples(page, ["lee-perry-smith.obj", SAMPLE]) == ["cm", "mm"]
        page.wait_for_timeout(500)  # a few frames of the 3D view
        assert page.evaluate(CHANGED_PIXELS, True) == 0

        tolerance = draw(page, flat, ring)
        page.wait_for_timeout(500)  # a few frames with the outline
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "demo-zone.png"), full_page=True)

        # The ring the page posted: the clicked points of the layout; its area as the
        # API answers it.
        posted, zone = measured(page, server, "mm")
        got = list(zip(posted["x"], posted["y"], strict=True))
        assert len(got) == 5
        for (x, y), (got_x, got_y) in zip(ring, got, strict=True):
            assert abs(got_x - x) < tolerance and abs(got_y - y) < tolerance, (got, ring)
        assert zone["area_outside_region"] == 0.0  # drawn inside the region
        text = page.locator("#zone-area").inner_text()
        assert text == f"Zone: {zone['area_cm2']:.2f} cm²", text
        assert zone_warnings(page) == []  # the sample's units: nothing to warn of
        # The 3D view: one line segment per piece of the lifted outline, none off the
        # region, and the canvas shows them.
        faces = zone["outline"][0]["faces"]
        assert None not in faces and len(faces) >= 5
        assert page.locator("#zone-area").get_attribute("data-segments") == str(len(faces))
        assert page.evaluate(CHANGED_PIXELS, False) > 50

        # Other units: measured again, 100 times as many cm² in cm as in mm.
        page.select_option("#units", "cm")
        page.wait_for_selector("#zone-area[data-state=measured]", timeout=30_000)
        _, in_cm = measured(page, server, "cm")
        assert in_cm["area_cm2"] == pytest.approx(100 * zone["area_cm2"])
        assert page.locator("#zone-area").inner_text() == f"Zone: {in_cm['area_cm2']:.2f} cm²"
        (warning,) = zone_warnings(page)  # a scalp some 3 m across: the answer's warning
        assert warning.startswith("params.units: with units 'cm' the region is")
        assert "with units 'mm' it would be" in warning

        # A zone that runs off the region (a new drawing replaces the last): its outline
        # in the 3D view breaks there, no segment where a piece has no face.
        draw(page, flat, pentagon(flat, 0.52))
        _, off = measured(page, server, "cm")
        faces = off["outline"][0]["faces"]
        assert None in faces and off["area_outside_region"] > 0
        segments = len(faces) - faces.count(None)
        assert page.locator("#zone-area").get_attribute("data-segments") == str(segments)
        assert page.locator("#zone-area").inner_text() == f"Zone: {off['area_cm2']:.2f} cm²"

        # Clear: the drawing, the area and the outline go; the 3D view is as before.
        page.click("#clear-zone")
        assert page.locator("#map svg .zone-drawing").count() == 0
        assert page.locator("#zone-area").inner_text() == ""
        assert page.locator("#zone-area").get_attribute("data-segments") is None
        page.wait_for_timeout(500)
        assert page.evaluate(CHANGED_PIXELS, False) == 0
    assert not problems, problems


def test_grafts_placed_in_a_zone_show_on_the_map_the_head_and_in_the_table(server):
    """A zone drawn, 40 grafts per cm², Place grafts: the page shows as many grafts as
    /v1/sites answers for that zone (seed 1), dots on the map, points on the 3D head, and a
    table row with the zone's area, density and grafts; cleared, then over the whole
    region."""
    flat = post(server, "/v1/flatten", PARAMS)
    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        assert page.locator("#place-sites").is_disabled()  # no map yet
        flatten_sample(page)
        draw(page, flat, pentagon(flat, 0.2))
        page.wait_for_timeout(500)
        page.evaluate(CHANGED_PIXELS, True)
        page.fill("#density", "40")
        page.click("#place-sites")
        page.wait_for_selector("#sites-status[data-state=placed]", timeout=30_000)
        ring = json.loads(page.locator("#zone-area").get_attribute("data-ring"))
        zone = {"name": "zone", "outer": ring}
        params = {**PARAMS, "zones": [zone], "units": "mm", "density_per_cm2": 40, "seed": 1}
        answer = post(server, "/v1/sites", params)
        assert page.locator("#sites-status").get_attribute("data-count") == str(answer["count"])
        assert answer["count"] > 100
        cells = page.locator("#sites-table td").all_inner_texts()
        (expected,) = answer["zones"]
        assert cells == [
            "zone",
            f"{expected['area_cm2']:.2f}",
            "40.0",
            f"{expected['sites']:,}",
        ]
        dots = page.locator("#map svg g.sites-drawing path").get_attribute("d")
        assert dots.count("M") == answer["count"]
        page.wait_for_timeout(500)
        assert page.evaluate(CHANGED_PIXELS, False) > 50  # the grafts on the head
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "demo-grafts.png"), full_page=True)
        # Cleared: no zone, no grafts; placed again, over the whole region.
        page.click("#clear-zone")
        assert page.locator("#map svg g.sites-drawing").count() == 0
        assert page.locator("#sites-table td").count() == 0
        page.click("#place-sites")
        page.wait_for_selector("#sites-status[data-state=placed]", timeout=30_000)
        whole = post(
            server, "/v1/sites", {**PARAMS, "units": "mm", "density_per_cm2": 40, "seed": 1}
        )
        assert page.locator("#sites-status").get_attribute("data-count") == str(whole["count"])
        assert page.locator("#sites-table td").first.inner_text() == "region"
    assert not problems, problems


def about_the_middle(flat: dict, offsets: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Points of the layout at ``offsets`` from the middle of the map, in shares of its width
    and height."""
    xs, ys = flat["vertices"]["x"], flat["vertices"]["y"]
    mid_x, mid_y = (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2
    width, height = max(xs) - min(xs), max(ys) - min(ys)
    return [(mid_x + dx * width, mid_y + dy * height) for dx, dy in offsets]


def draw_flow(page, flat: dict, points: list[tuple[float, float]]) -> float:
    """Draw the flow through ``points`` as a user does: Draw the flow, a click at each point
    but the last, a double click at the last (which ends it). Answers how closely the page can
    read a click, in layout units (:func:`on_screen`)."""
    page.click("#draw-flow")
    clicks, tolerance = on_screen(page, flat, points)
    for x, y in clicks[:-1]:
        page.mouse.click(x, y)
    # While drawing: the points and the open polyline through them.
    assert page.locator("#map svg .growth-drawing .flow.drawing circle").count() == len(clicks) - 1
    page.mouse.dblclick(*clicks[-1])
    assert page.locator("#map svg .growth-drawing .flow.drawing").count() == 0
    return tolerance


def place_whorl(page, flat: dict, point: tuple[float, float], turn: str) -> None:
    """Place a whorl turning ``turn`` at ``point`` of the layout: its sense, then a click."""
    page.select_option("#whorl-turn", turn)
    page.click("#place-whorl")
    (click,), _ = on_screen(page, flat, [point])
    page.mouse.click(*click)


def sent_params(request) -> dict:
    """The ``params`` part of the multipart body the page sent."""
    boundary = request.headers["content-type"].split("boundary=")[1].encode()
    for part in request.post_data_buffer.split(b"--" + boundary):
        head, _, content = part.partition(b"\r\n\r\n")
        if b'name="params"' in head:
            return json.loads(content.removesuffix(b"\r\n"))
    raise AssertionError("the request has no params part")


def posted(page, route: str) -> list[dict]:
    """The params the page posts to ``route`` from now on, in order, each request let through
    unchanged (a route: only there does Chromium give a multipart body that holds a Blob)."""
    sent: list[dict] = []

    def keep(intercepted) -> None:
        sent.append(sent_params(intercepted.request))
        intercepted.continue_()

    page.route(f"**{route}", keep)
    return sent


def place_grafts(page, trigger, sent: list[dict]) -> dict:
    """Run ``trigger`` (a click on Place grafts, a new exit angle), wait until the page shows
    the answer or the problem, and answer the params it posted (``sent``: :func:`posted`)."""
    before = len(sent)
    trigger()
    page.wait_for_selector("#sites-status:is([data-state=placed], [data-state=error])",
                           timeout=30_000)  # fmt: skip
    assert len(sent) == before + 1, sent
    return sent[-1]


def strokes_on_map(page) -> np.ndarray:
    """(n, 4): each graft's stroke on the map, its start and its step in SVG pixels."""
    d = page.locator("#map svg g.sites-drawing path.strokes").get_attribute("d")
    return np.array(
        [[float(v) for v in part.replace("l", " ").split()] for part in d.split("M")[1:]]
    )


def assert_sent(growth: dict, flow: list, whorl: tuple[float, float], tolerance: float) -> None:
    """``growth`` as posted holds the one flow, named, through the points of ``flow`` and the
    one counterclockwise whorl at ``whorl``, each to ``tolerance`` (layout units)."""
    (sent_flow,) = growth["flow"]
    assert sent_flow["name"] == "flow 1"
    (sent_whorl,) = growth["whorls"]
    assert sent_whorl["turn"] == "counterclockwise"
    got = [*zip(sent_flow["x"], sent_flow["y"], strict=True), (sent_whorl["x"], sent_whorl["y"])]
    assert len(got) == len(flow) + 1
    for (x, y), (got_x, got_y) in zip([*flow, whorl], got, strict=True):
        assert abs(got_x - x) < tolerance and abs(got_y - y) < tolerance, (got, flow, whorl)


def strokes_about(page, flat: dict, answer: dict, whorl: tuple[float, float]) -> np.ndarray:
    """Checks the map's strokes: one for each site of the /v1/sites ``answer``, each along its
    map direction (theta_phi: the picture's rows run with y). Answers how those within 40
    pixels of ``whorl`` (a layout point) turn about it on the screen: the cross product of
    the way from it and the stroke's, negative for a counterclockwise turn (rows run down)."""
    strokes = strokes_on_map(page)
    assert len(strokes) == answer["count"]
    along = np.asarray(answer["sites"]["map_direction"])
    step = strokes[:, 2:] / np.linalg.norm(strokes[:, 2:], axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip((step * along).sum(axis=1), -1, 1))).max() < 2
    (centre,), _ = on_screen(page, flat, [whorl])
    box = page.locator("#map svg").bounding_box()
    _, _, width, _ = map(float, page.locator("#map svg").get_attribute("viewBox").split())
    away = np.array([box["x"], box["y"]]) + strokes[:, :2] * box["width"] / width - centre
    near = np.linalg.norm(away, axis=1) < 40
    return away[near, 0] * step[near, 1] - away[near, 1] * step[near, 0]


def test_flows_and_a_whorl_drawn_on_the_map_grow_the_grafts_as_strokes(server):
    """A zone, a flow of three points (the last a double click) and a counterclockwise whorl
    drawn on the map, exit angle 15°, Place grafts: the page posts the flow and the whorl at
    the clicked points of the layout, and shows each graft /v1/sites answers for that request
    as a stroke along its map direction on the map and as a line segment on the head; the
    strokes about the whorl turn the way its arrow does; the table gives the zone's exit angle
    and largest turn. Another exit angle places the grafts again, with it."""
    flat = post(server, "/v1/flatten", PARAMS)
    flow = about_the_middle(flat, [(-0.15, 0.06), (0.0, 0.09), (0.15, 0.06)])
    (whorl,) = about_the_middle(flat, [(0.0, -0.06)])
    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        assert page.locator("#draw-flow").is_disabled()  # no map to draw on yet
        sent = posted(page, "/v1/sites")
        flatten_sample(page)
        draw(page, flat, pentagon(flat, 0.2))
        tolerance = draw_flow(page, flat, flow)
        place_whorl(page, flat, whorl, "counterclockwise")
        drawn = page.locator("#growth-status")
        assert [drawn.get_attribute(f"data-{kind}") for kind in ("flows", "whorls")] == ["1", "1"]
        # The flow ends in an arrowhead; the whorl's arrow turns its way.
        assert page.locator("#map svg .growth-drawing .flow polygon").count() == 1
        assert page.locator("#map svg .whorl[data-turn=counterclockwise]").count() == 1
        page.fill("#exit-angle", "15")
        page.wait_for_timeout(500)
        page.evaluate(CHANGED_PIXELS, True)

        params = place_grafts(page, lambda: page.click("#place-sites"), sent)
        # The request carried the flow and the whorl where they were clicked, and the angle.
        assert_sent(params["growth"], flow, whorl, tolerance)
        assert params["growth"]["exit_angle_deg"] == 15

        # As many strokes, on the map and on the head, as /v1/sites answers for that request.
        answer = post(server, "/v1/sites", params)
        count = answer["count"]
        status = page.locator("#sites-status")
        assert status.get_attribute("data-state") == "placed", status.inner_text()
        assert status.get_attribute("data-count") == str(count) and count > 50
        assert status.get_attribute("data-strokes") == str(count)
        turning = strokes_about(page, flat, answer, whorl)
        assert len(turning) >= 5 and (turning < 0).mean() > 0.9, turning  # counterclockwise
        # The head shows them; the table gives the zone's exit angle and largest turn.
        page.wait_for_timeout(500)
        assert page.evaluate(CHANGED_PIXELS, False) > 50
        (zone,) = answer["zones"]
        head = page.locator("#sites-table th").all_inner_texts()
        assert head[-2:] == ["exit angle (°)", "largest turn (°)"]
        cells = page.locator("#sites-table td").all_inner_texts()
        assert cells[-2:] == ["15.0", f"{zone['largest_turn_deg']:.1f}"]
        assert "15° off the scalp" in status.inner_text()
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "demo-growth.png"), full_page=True)

        # Another exit angle: placed again with it.
        page.fill("#exit-angle", "30")
        again = place_grafts(page, lambda: page.locator("#exit-angle").blur(), sent)
        assert again["growth"]["exit_angle_deg"] == 30
        assert page.locator("#sites-table td").all_inner_texts()[-2] == "30.0"
        assert status.get_attribute("data-strokes") == str(count)  # the same sites
    assert not problems, problems


def test_a_flow_or_whorl_the_service_refuses_is_named_and_marked_on_the_map(server):
    """Two flows drawn across each other, then a whorl off the region: Place grafts shows the
    service's 422 in the grafts' status, naming params.growth.flow.1 and then
    params.growth.whorls.0, marks that flow or whorl on the map, and places no grafts; Clear
    takes the flows and whorls away."""
    flat = post(server, "/v1/flatten", PARAMS)
    across = about_the_middle(flat, [(-0.1, 0.0), (0.1, 0.0)])
    down = about_the_middle(flat, [(0.0, -0.1), (0.01, 0.1)])
    xs, ys = flat["vertices"]["x"], flat["vertices"]["y"]
    off_the_region = (min(xs) - 0.02 * (max(xs) - min(xs)), min(ys) - 0.02 * (max(ys) - min(ys)))
    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        sent = posted(page, "/v1/sites")
        flatten_sample(page)
        draw(page, flat, pentagon(flat, 0.2))
        draw_flow(page, flat, across)
        draw_flow(page, flat, down)
        assert page.locator("#growth-status").get_attribute("data-flows") == "2"
        status = page.locator("#sites-status")
        params = place_grafts(page, lambda: page.click("#place-sites"), sent)
        assert [f["name"] for f in params["growth"]["flow"]] == ["flow 1", "flow 2"]
        assert status.get_attribute("data-state") == "error"
        text = status.inner_text()
        assert text.startswith("422: params.growth.flow.1 ('flow 2')"), text
        assert "crosses growth.flow.0" in text, text
        flows = page.locator("#map svg .growth-drawing .flow")
        assert [flows.nth(k).get_attribute("class") for k in range(2)] == ["flow", "flow error"]
        assert page.locator("#map svg g.sites-drawing").count() == 0
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "demo-growth-refused.png"), full_page=True)

        page.click("#clear-growth")
        assert page.locator("#map svg .growth-drawing > *").count() == 0
        assert status.get_attribute("data-state") == "none"
        place_whorl(page, flat, off_the_region, "clockwise")
        place_grafts(page, lambda: page.click("#place-sites"), sent)
        assert status.get_attribute("data-state") == "error"
        assert status.inner_text().startswith("422: params.growth.whorls.0: lies off the region")
        assert page.locator("#map svg .growth-drawing .whorl.error").count() == 1
    # The two 422s, as the browser logs a failed fetch.
    assert [p for p in problems if "422" not in p] == [], problems


def grow_hair(page, sent: list[dict]) -> tuple[dict, dict]:
    """Press Grow hair, wait until the page shows the strands or the problem, and answer the
    params it posted (``sent``: :func:`posted`) and the answer it received."""
    before = len(sent)
    with page.expect_response("**/v1/strands") as received:
        page.click("#grow-hair")
    page.wait_for_selector("#hair-status:is([data-state=grown], [data-state=error])",
                           timeout=60_000)  # fmt: skip
    assert len(sent) == before + 1, sent
    return sent[-1], received.value.json()


def strands_drawn(page, points: int) -> np.ndarray:
    """(n, points, 3): the strands the 3D view draws, read back from its line segments (each
    strand's segments in turn, each one starting where the one before it ends)."""
    ends = page.evaluate("window.meshflatDemo.positions('strands')")
    segments = np.array(ends).reshape(-1, points - 1, 2, 3)
    assert np.array_equal(segments[:, 1:, 0], segments[:, :-1, 1])
    return np.concatenate([segments[:, :, 0], segments[:, -1:, 1]], axis=1)


def assert_grown(drawn: np.ndarray, sites: dict, length: float) -> np.ndarray:
    """Checks that each strand ``drawn`` is rooted at its site of the /v1/sites answer, leaves
    along its direction (the exit angle) and is ``length`` long (the sample's units are
    millimetres). Answers how far each one's tip is from its root."""
    assert np.abs(drawn[:, 0] - np.asarray(sites["sites"]["position"])).max() < 1e-3
    first = drawn[:, 1] - drawn[:, 0]
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    leaving = (first * np.asarray(sites["sites"]["direction"])).sum(axis=1)
    assert np.degrees(np.arccos(np.clip(leaving, -1, 1))).max() < 1
    arc = np.linalg.norm(np.diff(drawn, axis=1), axis=2).sum(axis=1)
    assert np.allclose(arc, length, rtol=1e-3), (arc.min(), arc.max())
    return np.linalg.norm(drawn[:, -1] - drawn[:, 0], axis=1)


def test_grow_hair_draws_the_strands_of_the_grafts_on_the_head(server):
    """A zone and a whorl drawn, exit angle 25°, Place grafts, then Grow hair at 30 mm and at
    60 mm: the page posts the grafts' params with the length and 16 points a strand, and the
    head shows one strand a graft, 16 points each, rooted at its site and leaving along its
    direction, its arc length the length given. Without growth the service's 422 shows in the
    hair's status."""
    flat = post(server, "/v1/flatten", PARAMS)
    (whorl,) = about_the_middle(flat, [(0.0, -0.06)])
    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        sites_sent = posted(page, "/v1/sites")
        strands_sent = posted(page, "/v1/strands")
        flatten_sample(page)
        draw(page, flat, pentagon(flat, 0.2))
        place_whorl(page, flat, whorl, "clockwise")
        page.fill("#exit-angle", "25")
        assert page.locator("#grow-hair").is_disabled()  # no grafts yet
        placed = place_grafts(page, lambda: page.click("#place-sites"), sites_sent)
        sites = post(server, "/v1/sites", placed)
        count = int(page.locator("#sites-status").get_attribute("data-count"))
        assert count == sites["count"] > 50
        status = page.locator("#hair-status")

        tips = {}
        for length in (30, 60):
            page.fill("#hair-length", str(length))
            page.wait_for_timeout(500)
            page.evaluate(CHANGED_PIXELS, True)
            params, answer = grow_hair(page, strands_sent)
            assert params == {**placed, "length_mm": length, "points": 16, "output": "json"}
            assert params["growth"]["exit_angle_deg"] == 25
            assert status.get_attribute("data-state") == "grown", status.inner_text()
            assert status.inner_text() == f"{count:,} strands of {length} mm"
            assert status.get_attribute("data-count") == str(count)
            # One strand a graft, each of 16 points, as the page received them.
            drawn = strands_drawn(page, 16)
            assert drawn.shape == (count, 16, 3)
            assert np.allclose(drawn, answer["points"], atol=1e-3)
            tips[length] = assert_grown(drawn, sites, length)
            assert np.allclose(answer["length_mm"], length)
            page.wait_for_timeout(500)
            assert page.evaluate(CHANGED_PIXELS, False) > 50  # the new strands on the head
        assert np.median(tips[60] / tips[30]) > 1.5  # longer hair reaches further
        for path in (ARTIFACTS / "demo-hair.png", FIGURES / "demo-strands.png"):
            path.parent.mkdir(exist_ok=True)
            page.screenshot(path=str(path), full_page=True)

        # The growth cleared takes the grafts and their strands; grafts placed without it
        # grow none: the service's 422 shows.
        page.click("#clear-growth")
        assert page.evaluate("window.meshflatDemo.positions('strands')") == []
        assert page.locator("#grow-hair").is_disabled()
        assert status.get_attribute("data-state") == "none"
        place_grafts(page, lambda: page.click("#place-sites"), sites_sent)
        params, _ = grow_hair(page, strands_sent)
        assert "growth" not in params
        assert status.get_attribute("data-state") == "error"
        text = status.inner_text()
        assert text.startswith("422: params.growth: strands grow along the hair's"), text
    # The 422, as the browser logs a failed fetch.
    assert [p for p in problems if "422" not in p] == [], problems


def draw_plan_zone(page, flat: dict, kind: str, ring: list[tuple[float, float]]) -> float:
    """Draw ``ring`` as a ``kind`` zone of the plan (recipient or donor) as a user does: its
    Draw button, a click at each point but the last, a double click at the last (which closes
    it). Answers how closely the page can read a click, in layout units (:func:`on_screen`)."""
    zones = page.locator("#plan-zones")
    before = int(zones.get_attribute(f"data-{kind}"))
    page.click(f"#draw-{kind}")
    clicks, tolerance = on_screen(page, flat, ring)
    for x, y in clicks[:-1]:
        page.mouse.click(x, y)
    drawing = page.locator(f"#map svg .plan-drawing .plan-zone.{kind}.drawing circle")
    assert drawing.count() == len(clicks) - 1
    page.mouse.dblclick(*clicks[-1])
    assert page.locator("#map svg .plan-drawing .plan-zone.drawing").count() == 0
    assert zones.get_attribute(f"data-{kind}") == str(before + 1)
    return tolerance


def make_plan(page, trigger, sent: list[dict]) -> dict:
    """Run ``trigger`` (a click on Plan, a new number), wait until the page shows the plan or
    the problem, and answer the params it posted (``sent``: :func:`posted`)."""
    before = len(sent)
    with page.expect_response("**/v1/plan"):
        trigger()
    page.wait_for_selector("#plan-status:is([data-state=planned], [data-state=error])",
                           state="attached", timeout=30_000)  # fmt: skip
    assert len(sent) == before + 1, sent
    return sent[-1]


def assert_rings(zones: list[dict], rings: list[list[tuple[float, float]]], tolerance: float):
    """The zones as posted lie at the points of ``rings`` (layout units), to ``tolerance``."""
    assert len(zones) == len(rings)
    for zone, ring in zip(zones, rings, strict=True):
        got = list(zip(zone["outer"]["x"], zone["outer"]["y"], strict=True))
        assert len(got) == len(ring)
        for (x, y), (got_x, got_y) in zip(ring, got, strict=True):
            assert abs(got_x - x) < tolerance and abs(got_y - y) < tolerance, (got, ring)


#: The table's cell for grafts available of a recipient zone, or needed of a donor zone.
NOT_ITS_KIND = "\N{EN DASH}"


def signed(value: float) -> str:
    """A whole number with its sign, as the page gives the balance: +66, -14, 0."""
    return f"{round(value):+,}" if round(value) else "0"


def assert_plan_shown(page, answer: dict) -> None:
    """The plan's table and balance, as the page shows them, hold the numbers of the
    /v1/plan ``answer``; the balance is the shown available minus the shown needed, each
    number red when short and only then."""
    cells = page.locator("#plan-table td").all_inner_texts()
    (recipient,), (donor,) = answer["recipient"], answer["donor"]
    assert cells == [
        "recipient 1", f"{recipient['area_cm2']:.2f}", f"{recipient['density_per_cm2']:.1f}",
        f"{recipient['grafts_needed']:,}", NOT_ITS_KIND,
        "donor 1", f"{donor['area_cm2']:.2f}", f"{donor['density_per_cm2']:.1f}", NOT_ITS_KIND,
        f"{donor['grafts_available']:,}",
        "total", "", "", f"{answer['grafts_needed']:,}", f"{answer['grafts_available']:,}",
    ]  # fmt: skip
    needed, available = (int(cells[k].replace(",", "")) for k in (13, 14))
    grafts, hairs = page.locator("#plan-balance span").all()
    shown = int(grafts.inner_text().removesuffix(" grafts").replace(",", ""))
    assert shown == available - needed == answer["balance"]["grafts"]
    assert grafts.inner_text() == f"{signed(answer['balance']['grafts'])} grafts"
    assert hairs.inner_text() == f"{signed(answer['balance']['hairs'])} hairs"
    sessions, balance = answer["sessions"], page.locator("#plan-balance").inner_text()
    plural = "" if sessions == 1 else "s"
    assert balance.endswith(f"; {sessions} session{plural} of at most 3,000 grafts"), balance
    red = "rgb(176, 0, 32)"
    for part, value in ((grafts, answer["balance"]["grafts"]), (hairs, answer["balance"]["hairs"])):
        colour = part.evaluate("(e) => getComputedStyle(e).color")
        assert (colour == red) == (round(value) < 0), (part.inner_text(), colour)


def assert_overlap_refused(page, flat: dict, sent: list[dict]) -> None:
    """A second donor zone drawn over the first recipient zone (the plan shown goes), then
    Plan: the service's 422 shows in the plan's status, naming both zones, and the donor zone
    is marked on the map."""
    draw_plan_zone(page, flat, "donor", pentagon(flat, 0.08, (-0.15, 0.0)))
    assert page.locator("#plan-table td").count() == 0
    make_plan(page, lambda: page.click("#plan"), sent)
    status = page.locator("#plan-status")
    assert status.get_attribute("data-state") == "error"
    text = status.inner_text()
    assert text.startswith("422: ") and "params.donor.1" in text, text
    assert "('donor 2')" in text and "overlaps params.recipient.0 ('recipient 1')" in text
    marked = page.locator("#map svg .plan-drawing .plan-zone.error")
    assert marked.count() == 1 and "donor" in marked.get_attribute("class")


def tools_and_map(page) -> dict:
    """The page's middle column from its tools to the map's bottom, in the page's pixels (a
    full-page screenshot's clip)."""
    return page.evaluate("""() => {
        const top = document.querySelector('main > div').getBoundingClientRect();
        const bottom = document.querySelector('#map svg').getBoundingClientRect();
        return { x: top.x + scrollX, y: top.y + scrollY, width: top.width,
                 height: bottom.bottom - top.y };
    }""")


def test_a_recipient_and_a_donor_zone_drawn_on_the_map_are_planned_with_the_balance(server):
    """Draw recipient and Draw donor, each a pentagon clicked on the map (the last point a
    double click), then Plan at the fields' densities (40 grafts per cm² aimed at, 80
    measured, 2.2 hairs a graft): the page posts both zones at the clicked points of the
    layout, and its table shows each zone's area and grafts needed or available, and the
    balance (available minus needed, short in red) and the sessions, as a direct /v1/plan
    request with those zones answers. Another target density plans again. A donor zone drawn
    over the recipient zone: the service's 422 shows, naming both, and the zone is marked."""
    flat = post(server, "/v1/flatten", PARAMS)
    rings = {
        "recipient": pentagon(flat, 0.12, (-0.2, 0.0)),
        "donor": pentagon(flat, 0.12, (0.2, 0.0)),
    }
    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        assert page.locator("#draw-recipient").is_disabled()  # no map to draw on yet
        sent = posted(page, "/v1/plan")
        flatten_sample(page)
        assert page.locator("#plan").is_disabled()  # no recipient zone yet
        tolerance = draw_plan_zone(page, flat, "recipient", rings["recipient"])
        draw_plan_zone(page, flat, "donor", rings["donor"])
        assert page.locator("#plan-zones").inner_text() == "1 recipient zone, 1 donor zone"
        assert page.locator("#map svg .plan-drawing .plan-zone polygon").count() == 2

        params = make_plan(page, lambda: page.click("#plan"), sent)
        status = page.locator("#plan-status")
        assert status.get_attribute("data-state") == "planned", status.inner_text()
        for kind in ("recipient", "donor"):
            assert_rings(params[kind], [rings[kind]], tolerance)
        # The same zones, asked directly: what the table must show.
        recipient = {"name": "recipient 1", "outer": params["recipient"][0]["outer"]}
        recipient["density_per_cm2"] = 40
        donor = {"name": "donor 1", "outer": params["donor"][0]["outer"]}
        donor |= {"density_per_cm2": 80, "hairs_per_graft": 2.2}
        asked = {**PARAMS, "units": "mm", "recipient": [recipient], "donor": [donor]}
        assert params["recipient"] == [recipient] and params["donor"] == [donor]
        answer = post(server, "/v1/plan", asked)
        assert answer["balance"]["grafts"] < 0  # these two zones: short, in red
        assert_plan_shown(page, answer)
        page.wait_for_timeout(300)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "demo-plan.png"), full_page=True)
        page.screenshot(
            path=str(FIGURES / "demo-plan.png"), clip=tools_and_map(page), full_page=True
        )

        # A lower target: planned again with it, no longer short.
        page.fill("#target-density", "20")
        params = make_plan(page, lambda: page.locator("#target-density").blur(), sent)
        assert params["recipient"][0]["density_per_cm2"] == 20
        recipient["density_per_cm2"] = 20
        answer = post(server, "/v1/plan", asked)
        assert answer["balance"]["grafts"] > 0
        assert_plan_shown(page, answer)

        # A donor zone over the recipient zone: refused, both named, the donor marked.
        assert_overlap_refused(page, flat, sent)
        page.screenshot(path=str(ARTIFACTS / "demo-plan-refused.png"), full_page=True)

        # Clear: the plan's zones and numbers go; Plan waits for a recipient zone.
        page.click("#clear-plan")
        assert page.locator("#map svg .plan-drawing > *").count() == 0
        assert status.get_attribute("data-state") == "none"
        assert page.locator("#plan").is_disabled()
    # The 422, as the browser logs a failed fetch.
    assert [p for p in problems if "422" not in p] == [], problems


#: Which side of the head each landmark is clicked from.
VIEWS = {
    "nasion": "front",
    "inion": "back",
    "left_tragus": "left",
    "right_tragus": "right",
    "vertex": "top",
}


def test_landmarks_clicked_on_the_head_give_the_map_the_heads_frame(server):
    """Place on the head, then each landmark clicked where the page shows it, from its side
    of the head (the whole mesh is loaded for it): the page records surface points near the
    landmarks, and the map flattened with them has the frame /v1/flatten gives them."""
    from .test_landmarks import on_head

    targets = on_head()
    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        assert page.locator("#pick").is_disabled()
        flatten_sample(page)
        page.click("#pick")
        page.wait_for_selector(
            "#landmark-list[data-state=picking]", state="attached", timeout=30_000
        )
        for name, side in VIEWS.items():
            page.select_option("#landmark", name)
            page.click(f"button.view[data-view={side}]")
            page.wait_for_timeout(200)  # a frame with the new view
            x, y = page.evaluate("(p) => window.meshflatDemo.project(p)", targets[name])
            page.mouse.click(x, y)
        listed = page.locator("#landmark-list")
        assert listed.get_attribute("data-count") == "5"
        points = json.loads(listed.get_attribute("data-points"))
        for name, target in targets.items():
            assert math.dist(points[name], target) < 3.0, (name, points[name], target)
        page.screenshot(path=str(ARTIFACTS / "demo-landmarks.png"), full_page=True)
        page.check("#use-landmarks")
        page.click("#go")
        page.wait_for_selector("body[data-state=shown]", timeout=60_000)
        shown = [float(c) for c in page.locator("#center").input_value().split(",")]
        region = PARAMS["region"]
        expected = post(server, "/v1/flatten", {"region": region, "sigma": 0.3,
                                                 "frame": {"landmarks": points}})  # fmt: skip
        assert shown == pytest.approx(expected["params"]["center"], abs=1e-4)
        assert "seam-free" in page.locator("#summary").inner_text()
    assert not problems, problems


def test_a_region_painted_in_vertex_colours_is_flattened_from_an_uploaded_ply(server, tmp_path):
    """A PLY whose top of the head is painted red, uploaded: "the file's vertex colours" as
    the region sends vertex_color (red at least 0.5) and the map shows the painted faces,
    as many as the API selects for the same request."""
    from .test_painted import PAINTED, ply_with

    red = np.where(PAINTED, 255, 0).astype(np.uint8)
    data = ply_with(
        {"red": ("uchar", red), "green": ("uchar", 0 * red), "blue": ("uchar", 0 * red)}
    )
    painted = tmp_path / "painted-head.ply"
    painted.write_bytes(data)
    params = {
        "region": {"vertex_color": {"channel": "r", "min": 0.5}},
        "layout": "theta_phi",
        "center": "bbox_center",
    }
    response = httpx.post(
        f"{server}/v1/flatten",
        files={"mesh": (painted.name, data)},
        data={"params": json.dumps(params)},
        headers={"X-API-Key": KEY},
        timeout=60,
    )
    assert response.status_code == 200, response.text
    faces = len(response.json()["faces"]["ids"])

    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        page.fill("#apikey", KEY)
        page.locator("#apikey").blur()
        page.set_input_files("#file", str(painted))
        page.select_option("#region-kind", "vertex_color")
        page.select_option("#channel", "r")
        page.fill("#color-min", "0.5")
        assert page.locator("#axis").is_hidden() and page.locator("#channel").is_visible()
        page.click("#go")
        page.wait_for_selector("body[data-state=shown]", timeout=60_000)
        # The map holds the painted faces: as many as the API selects from the colours.
        legend = page.locator("#map svg g.legend").text_content()
        assert f"region: {faces:,} triangles" in legend
        page.wait_for_timeout(500)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "demo-painted.png"), full_page=True)
    assert not problems, problems


#: The share of the 3D view's pixels that are clearly coloured (not grey): viridis shows.
COLOURED_PIXELS = f"""() => {{{READ_VIEW}
    let coloured = 0;
    for (let i = 0; i < pixels.length; i += 4) {{
        const r = pixels[i], g = pixels[i + 1], b = pixels[i + 2];
        if (Math.max(r, g, b) - Math.min(r, g, b) > 60) coloured++;
    }}
    return coloured / (w * h);
}}"""


def test_colour_by_shows_the_distortion_on_the_map_and_the_head(server, tmp_path):
    """ "Colour by": the map and the 3D view flattened again, the map's triangles in the
    measure's colours with its bar, the head in the same colours; on the bundled scalp and
    on a generated 200k-face region (beyond the outline limit: the raster carries them)."""

    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        flatten_sample(page)
        page.wait_for_timeout(300)
        before = page.evaluate(COLOURED_PIXELS)  # the grey checker and its two coloured lines
        with page.expect_response(lambda r: r.url.endswith("/v1/flatten")):
            page.select_option("#colour-by", "isometric")
        page.wait_for_selector("#map svg g.colour-bar", timeout=60_000)
        page.wait_for_selector("body[data-state=shown]", timeout=60_000)
        page.wait_for_timeout(500)
        bar = page.locator("#map svg g.colour-bar").text_content()
        assert "isometric distortion" in bar and "p50" in bar and "p95" in bar
        assert page.locator("#map svg path.triangles[class*=colour-]").count() > 20
        after = page.evaluate(COLOURED_PIXELS)  # the head in viridis
        assert after > before + 0.05, (before, after)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "demo-colour.png"), full_page=True)

        big = tmp_path / "fsaverage-260k.ply"
        big.write_bytes(subdivided_ply(SAMPLE, 3))
        page.set_input_files("#file", str(big))
        page.fill("#axis", "0, 0, 1")
        page.fill("#angle", "130")
        page.click("#go")
        page.wait_for_selector("body[data-state=shown]", timeout=120_000)
        page.wait_for_function(
            "() => document.querySelector('#map svg g.legend')"
            ".textContent.includes('200,280 triangles')",
            timeout=120_000,
        )
        assert page.locator("#map svg path.fill[class*=colour-]").count() > 20
        assert "isometric distortion" in page.locator("#map svg g.colour-bar").text_content()
        page.wait_for_timeout(500)
        page.screenshot(path=str(FIGURES / "demo-colour-200k.png"), full_page=True)
    assert not problems, problems


def test_docs_page_lists_the_operations_with_nothing_fetched_from_elsewhere(server):
    """/docs works behind a firewall: Swagger UI's script and styles come from the service
    (fastapi-offline), and the page lists every route of the document."""
    paths = httpx.get(f"{server}/openapi.json", timeout=30).json()["paths"]
    elsewhere: list[str] = []
    failed: list[str] = []
    with chromium() as browser:
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.on(
            "request",
            lambda r: (
                r.url.startswith(("http", "ws"))
                and not r.url.startswith(server)
                and elsewhere.append(r.url)
            ),
        )
        page.on("requestfailed", lambda r: failed.append(f"{r.url}: {r.failure}"))
        page.goto(f"{server}/docs", wait_until="load")
        page.wait_for_selector(".opblock-summary-path", timeout=30_000)
        shown = {
            text.strip().replace("\u200b", "")
            for text in page.locator(".opblock-summary-path").all_inner_texts()
        }
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "docs.png"))
    assert set(paths) <= shown, set(paths) - shown
    assert not elsewhere, elsewhere
    assert not failed, failed


#: The map's width on the page, its viewBox's and the least font size of its text (the
#: SVG's own units, inherited where a text sets none), in the page's pixels.
MAP_TEXT = """() => {
    const svg = document.querySelector('#map svg');
    const shown = svg.getBoundingClientRect().width;
    const drawn = Number(svg.getAttribute('viewBox').split(/\\s+/)[2]);
    const sizes = [...svg.querySelectorAll('text')]
        .map((t) => parseFloat(getComputedStyle(t).fontSize));
    return { shown, drawn, smallest: Math.min(...sizes), texts: sizes.length };
}"""


def requests_to(page) -> list[tuple[str, str]]:
    """The (method, path) of every request the page sends to the API from now on."""
    seen: list[tuple[str, str]] = []

    def keep(request) -> None:
        if "/v1/" in request.url:
            seen.append((request.method, request.url.split("/", 3)[3]))

    page.on("request", keep)
    return seen


def mesh_names(page, route: str) -> list[str]:
    """The file name of the ``mesh`` part of each request the page posts to ``route`` from
    now on (through a route, as :func:`posted`)."""
    names: list[str] = []

    def keep(intercepted) -> None:
        body = intercepted.request.post_data_buffer
        names.append(body.split(b'name="mesh"; filename="')[1].split(b'"')[0].decode())
        intercepted.continue_()

    page.route(f"**{route}", keep)
    return names


def assert_legible(page) -> None:
    """The map at least 600 px wide, drawn at its own scale or larger, so that its text shows
    at 12 px or more; front at the top, back at the bottom."""
    text = page.evaluate(MAP_TEXT)
    assert text["shown"] >= 600, text
    assert text["texts"] > 10 and text["smallest"] * text["shown"] / text["drawn"] >= 12, text
    labels = page.locator("#map svg g.orientation text")
    assert labels.all_text_contents() == ["front", "back"]
    front, back = (float(labels.nth(k).get_attribute("y")) for k in (0, 1))
    assert front < back


def drawn_on_the_map(page) -> dict:
    """The zone's area and the grafts' count the page shows; checks the map draws both."""
    grafts = page.locator("#sites-status").get_attribute("data-count")
    assert page.locator("#map svg .zone-drawing polygon").count() == 1
    dots = page.locator("#map svg g.sites-drawing path").get_attribute("d")
    assert dots.count("M") == int(grafts)
    return {"area": page.locator("#zone-area").inner_text(), "grafts": grafts}


def assert_recolours_keeping(page, drawn: dict) -> None:
    """Colour by, twice: the same map recoloured (its SVG and GLB from /v1/flatten, nothing
    else asked), the zone and the grafts kept; the first kept as the README's figure."""
    seen = requests_to(page)
    for measure in ("isometric", "conformal"):
        page.select_option("#colour-by", measure)
        page.wait_for_selector("body[data-state=shown]", timeout=60_000)
        page.wait_for_function(
            "(m) => document.querySelector('#map svg g.colour-bar')?.textContent.includes(m)",
            arg=measure,
            timeout=60_000,
        )
        assert drawn_on_the_map(page) == drawn
        if measure == "isometric":
            page.wait_for_timeout(500)  # a few frames of the 3D view
            page.screenshot(path=str(FIGURES / "demo-colour.png"), full_page=True)
    assert seen == [("POST", "v1/flatten")] * 4, seen
    # Flatten again, the same mesh and region: kept too; the sample is not downloaded again.
    seen.clear()
    page.click("#go")
    page.wait_for_selector("body[data-state=shown]", timeout=60_000)
    assert drawn_on_the_map(page) == drawn
    assert seen == [("POST", "v1/flatten")] * 2, seen


def assert_values_used(page, server: str) -> None:
    """Automatic mode: the greyed fields show what the answer used (the same request, asked
    directly); the zone is measured and the grafts placed again on the new map."""
    sent = posted(page, "/v1/flatten")
    page.check("#auto")
    page.click("#go")
    page.wait_for_selector("body[data-state=shown]", timeout=120_000)
    assert sent[-1]["sigma"] == "auto" and sent[-1]["facing"] == [0, 1, 0]
    used = post(server, "/v1/flatten", sent[-1])["params"]
    for field in ("center", "pole", "sigma"):
        assert page.locator(f"#{field}").is_disabled(), field
    expected = {
        "center": used["center"],
        "pole": used["rotation"][1],
        "up": used["rotation"][2],
        "sigma": [used["sigma"]],
    }
    for field, values in expected.items():
        shown = [float(v) for v in page.locator(f"#{field}").input_value().split(",")]
        assert shown == pytest.approx(values, rel=1e-5, abs=1e-6), field
    page.wait_for_selector("#zone-area[data-state=measured]", timeout=30_000)
    page.wait_for_selector("#sites-status[data-state=placed]", timeout=30_000)
    assert page.locator("#map svg .zone-drawing polygon").count() == 1
    page.unroute("**/v1/flatten")
    page.uncheck("#auto")


def assert_upload_shown(page, upload: Path) -> None:
    """An upload: the sample selector says so, it is what is flattened (no front named, no
    labels); a sample picked again lets it go."""
    upload.write_bytes(SAMPLES[SAMPLE].path.read_bytes())
    page.set_input_files("#file", str(upload))
    assert page.locator("#sample").input_value() == ""
    assert page.locator("#sample option:checked").inner_text() == f"uploaded: {upload.name}"
    assert page.locator("#facing").input_value() == ""  # the sample's front is not its
    names = mesh_names(page, "/v1/flatten")
    page.click("#go")
    page.wait_for_selector("body[data-state=shown]", timeout=60_000)
    assert names == [upload.name] * 2
    assert page.locator("#map svg g.orientation").count() == 0
    page.select_option("#sample", SAMPLE)
    assert page.evaluate("() => document.getElementById('file').files.length") == 0
    assert page.locator("#sample option.upload").count() == 0
    assert page.locator("#facing").input_value() == "0, 1, 0"


def test_the_demo_reads_on_a_laptop_screen_and_keeps_what_is_drawn(server, tmp_path):
    """At 1366 x 900: the sample's units preselected; the map at least 600 px wide, its text
    at 12 px or more, front and back labelled; "Colour by" recolours the same map (two
    /v1/flatten requests, the SVG and the GLB; no sample downloaded again) and keeps the zone
    and the grafts, as a new Flatten of the same mesh and region does; in automatic mode the
    greyed fields show the values the answer used; an upload is what the sample selector
    shows, and a sample picked again lets the upload go."""
    flat = post(server, "/v1/flatten", PARAMS)
    samples = httpx.get(f"{server}/v1/samples", headers={"X-API-Key": KEY}, timeout=30).json()
    problems: list[str] = []
    with chromium() as browser:
        page = demo_page(browser, server, problems)
        page.fill("#apikey", KEY)
        page.locator("#apikey").blur()
        page.wait_for_selector(f"#sample option[value='{SAMPLE}']", state="attached")
        # The first sample is selected, and its units with it.
        assert page.locator("#sample").input_value() == samples[0]["name"]
        assert page.locator("#units").input_value() == samples[0]["units"]
        flatten_sample(page)
        assert page.locator("#units").input_value() == "mm"
        assert_legible(page)
        draw(page, flat, pentagon(flat, 0.2))
        page.click("#place-sites")
        page.wait_for_selector("#sites-status[data-state=placed]", timeout=30_000)
        assert_recolours_keeping(page, drawn_on_the_map(page))
        assert_values_used(page, server)
        assert_upload_shown(page, tmp_path / "my-scan.ply")
    assert not problems, problems


#: Arrow JS's browser bundle (tests/js, npm ci), which defines the global ``Arrow``.
ARROW_JS = JS_TOOLS / "node_modules" / "apache-arrow" / "Arrow.es2015.min.js"
#: In the page: the sample's /v1/flatten answered as JSON and as Arrow, each read as a
#: browser client reads it (JSON.parse; Arrow JS's tableFromIPC), timed; then every column
#: compared with the JSON's array at its path, number by number (floats by their bits, int64
#: as BigInt, nulls by validity), and the metadata's JSON handed back.
ARROW_IN_PAGE = """async ({sample, params, key}) => {
    const headers = {"X-API-Key": key};
    const mesh = await (await fetch(`/v1/samples/${sample}`, {headers})).blob();
    const post = async (accept) => {
        const form = new FormData();
        form.append("params", JSON.stringify(params));
        form.append("mesh", mesh, sample);
        const response = await fetch("/v1/flatten", {
            method: "POST", body: form, headers: {...headers, Accept: accept},
        });
        return {type: response.headers.get("content-type"), bytes: await response.arrayBuffer()};
    };
    const asJson = await post("application/json");
    const asArrow = await post("application/vnd.apache.arrow.stream");
    let start = performance.now();
    const answer = JSON.parse(new TextDecoder().decode(asJson.bytes));
    const jsonMs = performance.now() - start;
    start = performance.now();
    const table = Arrow.tableFromIPC(new Uint8Array(asArrow.bytes));
    const arrowMs = performance.now() - start;
    const at = (path) => path.split(".").reduce((node, key) => node[key], answer);
    const columns = {};
    for (const field of table.schema.fields) {
        const items = table.getChild(field.name).get(0);
        const fixed = items.type.typeId === Arrow.Type.FixedSizeList;
        const numbers = fixed ? items.getChildAt(0) : items;
        const values = numbers.toArray();
        const expected = fixed ? at(field.name).flat() : at(field.name);
        let mismatches = values.length === expected.length ? 0 : 1;
        for (let i = 0; !mismatches && i < values.length; i++) {
            const value = numbers.isValid(i) ? values[i] : null;
            // Object.is: the same double, -0 apart from 0 (the answer has no NaN).
            const want = typeof value === "bigint" ? BigInt(expected[i]) : expected[i];
            mismatches += !Object.is(value, want);
        }
        columns[field.name] = {
            type: values.constructor.name,
            length: values.length,
            width: fixed ? items.type.listSize : 1,
            mismatches,
        };
    }
    return {
        types: [asJson.type, asArrow.type],
        bytes: [asJson.bytes.byteLength, asArrow.bytes.byteLength],
        ms: [jsonMs, arrowMs],
        columns,
        rest: JSON.parse(table.schema.metadata.get("meshflat")),
    };
}"""


def test_the_arrow_answer_reads_in_the_browser_as_the_json_answers_arrays(server):
    """Arrow JS in Chromium reads /v1/flatten's Arrow answer into typed arrays equal, bit
    for bit, to the JSON answer's arrays, and its metadata is the rest of that answer."""
    require(ARROW_JS.is_file(), "Arrow JS (apache-arrow)", "run `npm ci --prefix tests/js`")
    expected = post(server, "/v1/flatten", PARAMS)
    with chromium() as browser:
        page = browser.new_page()
        page.goto(f"{server}/healthz")  # the service's origin: its routes without CORS
        page.add_script_tag(path=str(ARROW_JS))
        found = page.evaluate(ARROW_IN_PAGE, {"sample": SAMPLE, "params": PARAMS, "key": KEY})
    assert found["types"] == ["application/json", "application/vnd.apache.arrow.stream"]
    columns = found["columns"]
    for name in ("ids", "theta", "phi", "r", "x", "y"):
        assert columns[f"vertices.{name}"]["length"] == len(expected["vertices"]["ids"])
    assert columns["vertices.x"]["type"] == "Float64Array"
    assert columns["faces.vertices"]["type"] == columns["vertices.ids"]["type"] == "Int32Array"
    assert columns["faces.vertices"]["width"] == 3
    assert columns["faces.vertices"]["length"] == 3 * len(expected["faces"]["ids"])
    assert [name for name, column in columns.items() if column["mismatches"]] == []
    # The metadata: the JSON answer without the columns' arrays.
    rest = expected
    for name in columns:
        *parents, last = name.split(".")
        node = rest
        for key in parents:
            node = node[int(key)] if isinstance(node, list) else node[key]
        del node[last]
    assert found["rest"] == rest
    json_bytes, arrow_bytes = found["bytes"]
    print(
        f"flatten of {SAMPLE}: JSON {json_bytes:,} B parsed in {found['ms'][0]:.1f} ms; "
        f"Arrow {arrow_bytes:,} B read in {found['ms'][1]:.1f} ms"
    )
