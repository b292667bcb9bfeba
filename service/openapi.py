"""Write the app's OpenAPI document to ``openapi/openapi.json`` (``python -m service.openapi``).

The committed document is what the front end builds against; a test fails when it drifts.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .app import app

DOCUMENT = Path(__file__).resolve().parent.parent / "openapi" / "openapi.json"


def render() -> str:
    """The app's OpenAPI document as the committed file holds it."""
    return json.dumps(app.openapi(), indent=2, sort_keys=True) + "\n"


def main() -> int:
    DOCUMENT.write_text(render())
    print(f"wrote {DOCUMENT}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
