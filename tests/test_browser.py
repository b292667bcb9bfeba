"""End to end in a real browser: headless Chromium opens the demo page served by a real
uvicorn that requires an API key, enters the key, flattens a bundled scan, then the default
sample in automatic mode, and the test checks what the page shows. The screenshots are kept
in ``artifacts/demo.png`` and ``artifacts/demo-auto.png``."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import httpx
import pytest

from service.samples import SAMPLES

from .test_serve import running
from .tools import require

CHROMIUM = os.environ.get("MESHFLAT_CHROMIUM", "/usr/bin/chromium")
ARTIFACTS = Path(__file__).parent.parent / "artifacts"
SAMPLE = "fsaverage-head.ply"
KEY = "browser-test-key"
#: What the page's preset for the sample sends (web/demo.js, PRESETS).
PARAMS = {
    "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}},
    "layout": "theta_phi",
    "center": "bbox_center",
    "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
    "sigma": 0.3,
}


@pytest.fixture(scope="module")
def server():
    """``meshflat serve`` on a free port of 127.0.0.1, requiring a key, ready."""
    with running(MESHFLAT_API_KEYS=KEY) as server:
        yield server.url


def test_demo_page_flattens_a_sample_and_shows_map_and_textured_mesh(server):
    require(
        shutil.which(CHROMIUM) is not None or Path(CHROMIUM).exists(),
        "Chromium",
        "apt-get install chromium (or set MESHFLAT_CHROMIUM)",
    )
    from playwright.sync_api import sync_playwright

    # What the API answers for the same request: the page must show the same region.
    data = SAMPLES[SAMPLE].path.read_bytes()
    expected = httpx.post(
        f"{server}/v1/flatten",
        files={"mesh": (SAMPLE, data)},
        data={"params": json.dumps(PARAMS)},
        headers={"X-API-Key": KEY},
        timeout=60,
    ).json()
    vertex_count = len(expected["vertices"]["ids"])

    problems: list[str] = []
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=CHROMIUM,
            args=["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"],
        )
        try:
            page = browser.new_page(viewport={"width": 1600, "height": 900})
            # The one console error expected: the samples asked for before the key is given.
            page.on(
                "console",
                lambda m: m.type == "error" and "401" not in m.text and problems.append(m.text),
            )
            page.on("pageerror", lambda e: problems.append(str(e)))
            page.on("requestfailed", lambda r: problems.append(f"{r.url}: {r.failure}"))
            page.goto(server, wait_until="load")
            page.wait_for_selector("body[data-state=ready]", timeout=30_000)
            assert "enter the API key" in page.locator("#status").inner_text()
            page.fill("#apikey", KEY)
            page.locator("#apikey").blur()  # a change event, as when the user moves on
            page.wait_for_selector(f"#sample option[value='{SAMPLE}']", state="attached")
            page.select_option("#sample", SAMPLE)
            page.click("#go")
            page.wait_for_selector("body[data-state=shown]", timeout=60_000)
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
            assert "seam-free, star-shaped" in page.locator("#summary").inner_text()
            # The canvas shows something besides the background.
            drawn = page.evaluate(
                """() => {
                    const canvas = document.getElementById('view');
                    const gl = canvas.getContext('webgl2') || canvas.getContext('webgl');
                    const w = gl.drawingBufferWidth, h = gl.drawingBufferHeight;
                    const pixels = new Uint8Array(w * h * 4);
                    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
                    let other = 0;
                    for (let i = 0; i < pixels.length; i += 4)
                        if (Math.abs(pixels[i] - 0xf4) > 8 || Math.abs(pixels[i + 2] - 0xf8) > 8)
                            other++;
                    return other / (w * h);
                }"""
            )
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
        finally:
            browser.close()
    assert not problems, problems


def test_docs_page_lists_the_operations_with_nothing_fetched_from_elsewhere(server):
    """/docs works behind a firewall: Swagger UI's script and styles come from the service
    (fastapi-offline), and the page lists every route of the document."""
    require(
        shutil.which(CHROMIUM) is not None or Path(CHROMIUM).exists(),
        "Chromium",
        "apt-get install chromium (or set MESHFLAT_CHROMIUM)",
    )
    from playwright.sync_api import sync_playwright

    paths = httpx.get(f"{server}/openapi.json", timeout=30).json()["paths"]
    elsewhere: list[str] = []
    failed: list[str] = []
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        try:
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
        finally:
            browser.close()
    assert set(paths) <= shown, set(paths) - shown
    assert not elsewhere, elsewhere
    assert not failed, failed
