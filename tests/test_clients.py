"""The TypeScript client and the demo page's bundle keep up with their sources, as the OpenAPI
document does with the service (tests/test_service.py): ``clients/typescript/schema.d.ts`` is
what the pinned openapi-typescript writes from the committed ``openapi/openapi.json``; the
client and the page's TypeScript typecheck (``tsc --noEmit``); and the committed
``service/static/demo.js`` is what the pinned esbuild bundles from ``web/``. Each runs the
tools its folder's ``package.json`` pins, with that file's own command: without
``node_modules`` (``npm ci --prefix ...``) a test is skipped with the reason, or fails under
``MESHFLAT_REQUIRE_TOOLS=1`` (CI)."""

from __future__ import annotations

import difflib
import json
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

from .conftest import slow
from .tools import require

ROOT = Path(__file__).parent.parent
CLIENT = ROOT / "clients" / "typescript"
WEB = ROOT / "web"
BUNDLE = ROOT / "service" / "static" / "demo.js"


def installed(*folders: Path) -> None:
    """Skip (or, in CI, fail) unless Node and each folder's pinned packages are installed."""
    missing = [f for f in folders if not (f / "node_modules").is_dir()]
    require(
        shutil.which("node") is not None and not missing,
        "Node with the pinned packages of " + ", ".join(str(f.relative_to(ROOT)) for f in folders),
        "install Node and run "
        + " and ".join(f"`npm ci --prefix {f.relative_to(ROOT)}`" for f in missing or folders),
    )


def script(folder: Path, name: str) -> list[str]:
    """The first command of ``package.json``'s script ``name``, split into words: the test runs
    what ``npm run`` runs, not a copy of it."""
    scripts = json.loads((folder / "package.json").read_text())["scripts"]
    return shlex.split(scripts[name].split("&&")[0])


def writing_to(words: list[str], option: str, path: Path) -> list[str]:
    """``words`` with the output ``option`` (``--output FILE`` or ``--outfile=FILE``) set to
    ``path``."""
    if f"{option}" in words:
        at = words.index(option)
        return [*words[:at], option, str(path), *words[at + 2 :]]
    (at,) = [i for i, word in enumerate(words) if word.startswith(f"{option}=")]
    return [*words[:at], f"{option}={path}", *words[at + 1 :]]


def run(folder: Path, words: list[str], tools: Path | None = None) -> subprocess.CompletedProcess:
    """``words`` run in ``folder`` with the tool from ``tools`` (default: the folder's own)
    ``node_modules/.bin``; a failure shows its output."""
    tool = (tools or folder) / "node_modules" / ".bin" / words[0]
    done = subprocess.run(
        [str(tool), *words[1:]], cwd=folder, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, f"{' '.join(words)} failed:\n{done.stdout}\n{done.stderr}"
    return done


def drift(committed: Path, fresh: Path) -> str:
    """The first lines of the difference between two text files ('' when the same)."""
    lines = difflib.unified_diff(
        committed.read_text().splitlines(),
        fresh.read_text().splitlines(),
        "committed",
        "regenerated",
        lineterm="",
    )
    return "\n".join(list(lines)[:40])


def test_the_committed_client_types_are_what_the_generator_writes_from_the_document(tmp_path):
    """Regenerate with `npm run generate --prefix clients/typescript` after the document
    changes (`python -m service.openapi`; `make openapi` does both)."""
    installed(CLIENT)
    fresh = tmp_path / "schema.d.ts"
    run(CLIENT, writing_to(script(CLIENT, "generate"), "--output", fresh))
    difference = drift(CLIENT / "schema.d.ts", fresh)
    assert not difference, (
        "clients/typescript/schema.d.ts is not what openapi/openapi.json gives: "
        f"`npm run generate --prefix clients/typescript`\n{difference}"
    )


def test_the_client_types_would_see_a_changed_field(tmp_path):
    """The comparison above catches drift: a document with a field renamed gives other types."""
    installed(CLIENT)
    document = json.loads((ROOT / "openapi" / "openapi.json").read_text())
    params = document["components"]["schemas"]["FlattenParams"]["properties"]
    params["colour_by_renamed"] = params.pop("colour_by")
    changed = tmp_path / "openapi.json"
    changed.write_text(json.dumps(document))
    words = [changed if w.endswith("openapi.json") else w for w in script(CLIENT, "generate")]
    fresh = tmp_path / "schema.d.ts"
    run(CLIENT, writing_to([str(w) for w in words], "--output", fresh))
    assert drift(CLIENT / "schema.d.ts", fresh)
    assert "colour_by_renamed?:" in fresh.read_text()


@slow  # tsc takes some 3 s alone on a core, 8 s on a busy one
@pytest.mark.parametrize("folder", [CLIENT, WEB], ids=["client", "web"])
def test_the_typescript_typechecks(folder):
    """`tsc --noEmit` with the folder's tsconfig.json: the client against the generated types,
    and the page's requests against the client (the pinned TypeScript is the client's)."""
    installed(CLIENT)
    run(folder, ["tsc", "--noEmit", "-p", "tsconfig.json"], tools=CLIENT)


def test_the_committed_demo_bundle_is_what_web_builds(tmp_path):
    """Rebuild with `npm run build --prefix web` after changing web/ or the client: the page
    that is served is the source that is read."""
    installed(WEB, CLIENT)
    fresh = tmp_path / "demo.js"
    run(WEB, writing_to(script(WEB, "build"), "--outfile", fresh))
    assert fresh.read_bytes() == BUNDLE.read_bytes(), (
        "service/static/demo.js is not what web/ builds: `npm run build --prefix web`"
    )
