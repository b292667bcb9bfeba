"""The layout docs/architecture.md describes holds: every module is listed there, imports go
one way (no cycle; the core imports nothing of the service; use-cases import nothing of HTTP)
and no module grows far beyond a screenful of ideas."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).parent.parent
ARCHITECTURE = ROOT / "docs" / "architecture.md"
#: The packages whose imports are checked for cycles.
PACKAGES = ("service", "transforms", "tests", "benchmarks", "fixtures")
#: The packages whose every module docs/architecture.md lists.
LISTED = ("service", "transforms")
#: "About 600 lines": a module beyond this has become two ideas.
MAX_LINES = 650
#: What a use-case may not import: the HTTP edge and the server around it.
HTTP = ("fastapi", "starlette", "uvicorn", "service.problems", "service.server", "service.forms",
        "service.routes", "service.app")  # fmt: skip


def modules(root: Path, packages) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file of ``packages`` under ``root``."""
    found = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            if "node_modules" in path.parts:
                continue
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def imported(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The modules of ``known`` that ``name`` (at ``path``) imports, anywhere in it (in a
    function, under ``TYPE_CHECKING``): a name imported from a package counts as its module
    when it is one, else as the package."""
    found = set()
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            prefix = ".".join([*base, *([node.module] if node.module else [])])
            targets = [f"{prefix}.{alias.name}" for alias in node.names]
        else:
            continue
        for target in targets:
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def import_graph(root: Path, packages) -> dict[str, set[str]]:
    known = modules(root, packages)
    return {name: imported(name, path, known) for name, path in known.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module."""
    names = sorted(graph)
    number = {name: k for k, name in enumerate(names)}
    edges = [(number[a], number[b]) for a in names for b in graph[a]]
    rows, columns = zip(*edges, strict=True) if edges else ((), ())
    adjacency = coo_matrix((np.ones(len(edges)), (rows, columns)), shape=(len(names),) * 2)
    count, labels = connected_components(adjacency, directed=True, connection="strong")
    members = [[names[k] for k in np.flatnonzero(labels == label)] for label in range(count)]
    return sorted(component for component in members if len(component) > 1)


def test_no_import_cycles():
    found = cycles(import_graph(ROOT, PACKAGES))
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_the_cycle_check_finds_a_cycle(tmp_path):
    # The check above can fail: a cycle through a function-level import is found.
    package = tmp_path / "service"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from .b import thing\n")
    (package / "b.py").write_text("def thing():\n    from service import a\n")
    (package / "c.py").write_text("from service.a import thing\n")
    assert cycles(import_graph(tmp_path, ["service"])) == [["service.a", "service.b"]]


@pytest.mark.parametrize("name", sorted(modules(ROOT, LISTED)))
def test_every_module_is_in_the_architecture_doc(name):
    path = modules(ROOT, LISTED)[name].relative_to(ROOT).as_posix()
    assert f"`{path}`" in ARCHITECTURE.read_text(encoding="utf-8"), (
        f"{path} is not listed in docs/architecture.md"
    )


def test_every_module_the_doc_lists_exists():
    _, _, listing = ARCHITECTURE.read_text(encoding="utf-8").partition("## The modules")
    listed = re.findall(r"`((?:service|transforms)/[\w/]+\.py)`", listing)
    missing = [path for path in listed if not (ROOT / path).is_file()]
    assert listed and not missing, f"docs/architecture.md lists modules that are gone: {missing}"


@pytest.mark.parametrize("name", sorted(modules(ROOT, LISTED)))
def test_modules_stay_about_600_lines_at_most(name):
    path = modules(ROOT, LISTED)[name]
    lines = path.read_text(encoding="utf-8").count("\n")
    assert lines <= MAX_LINES, f"{path.relative_to(ROOT)}: {lines} lines; split it by idea"


def test_the_core_imports_nothing_of_the_service_or_the_web():
    graph = import_graph(ROOT, ("service", "transforms"))
    for name, path in modules(ROOT, ("transforms",)).items():
        text = path.read_text(encoding="utf-8")
        assert not {m for m in graph[name] if m.startswith("service")}, name
        for web in ("fastapi", "starlette", "pydantic", "httpx"):
            assert not re.search(rf"^\s*(from|import) {web}\b", text, re.M), (name, web)


def test_use_cases_import_nothing_of_http():
    graph = import_graph(ROOT, ("service", "transforms"))
    for name, path in modules(ROOT, ("service/capabilities",)).items():
        text = path.read_text(encoding="utf-8")
        for edge in HTTP:
            local = edge.startswith("service.")
            hit = (
                edge in graph[name]
                if local
                else re.search(rf"^\s*(from|import) {edge}\b", text, re.M)
            )
            assert not hit, f"{name} imports {edge}: use-cases know no HTTP"
