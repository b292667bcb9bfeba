"""External tools some tests drive (Node's glTF-Validator, Chromium): found, or the test is
skipped with the reason, unless ``MESHFLAT_REQUIRE_TOOLS=1`` (set by CI), which turns a
missing tool into a failure."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

JS_TOOLS = Path(__file__).parent / "js"


def require(found: bool, what: str, how: str) -> None:
    """Skip (or, in CI, fail) when a tool is missing."""
    if found:
        return
    message = f"{what} is not installed: {how}"
    if os.environ.get("MESHFLAT_REQUIRE_TOOLS") == "1":
        pytest.fail(message)
    pytest.skip(message)


def node_tool(script: str) -> list[str]:
    """The command that runs ``tests/js/<script>`` with Node."""
    node = shutil.which("node")
    require(
        node is not None and (JS_TOOLS / "node_modules").is_dir(),
        "Node with the test tools",
        "install Node and run `npm ci --prefix tests/js`",
    )
    return [node, str(JS_TOOLS / script)]
