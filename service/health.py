"""The container's health check: ``python3 -m service.health`` (the image's HEALTHCHECK, and
``meshflat health``) exits 0 when the local service's ``/healthz`` answers 200 within 5 s.

Standard library only, so that a check every 15 s costs little, and no proxy: the request
goes straight to 127.0.0.1 whatever HTTP_PROXY says.
"""

from __future__ import annotations

import os
import sys
import urllib.request


def check(port: int | None = None) -> int:
    port = port or int(os.environ.get("MESHFLAT_PORT", "8000"))
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(f"http://127.0.0.1:{port}/healthz", timeout=5) as answer:
            return 0 if answer.status == 200 else 1
    except (OSError, ValueError) as error:
        print(f"meshflat: /healthz on port {port}: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    raise SystemExit(check())
