"""The documentation keeps up with the code: every route of the committed OpenAPI document is
in docs/api.md, every command of ``meshflat`` in docs/cli.md, every setting in
docs/operations.md; the README stays a front door; and every relative link of README.md and
docs/*.md points at a file (and a heading) that exists."""

from __future__ import annotations

import json
import re
from dataclasses import fields
from pathlib import Path

import pytest

from service.cli import parser
from service.settings import Settings

ROOT = Path(__file__).parent.parent
DOCS = ROOT / "docs"
README = ROOT / "README.md"
#: The README is the front door: what meshflat is, two commands, a first request, links.
README_MAX_LINES = 150
#: Every Markdown file whose links are checked.
MARKDOWN = [README, *sorted(DOCS.glob("*.md"))]

FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1", re.S)
#: ``[text](target)`` and ``![alt](target)``, the target without spaces (an optional title
#: after it).
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HEADING = re.compile(r"^#{1,6}\s+(.+?)\s*#*\s*$", re.M)


def text(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def prose(markdown: str) -> str:
    """The Markdown without its fenced code blocks and code spans, where a link is text."""
    return CODE_SPAN.sub("", FENCE.sub("", markdown))


def anchors(markdown: str) -> set[str]:
    """The anchors GitHub gives the headings: lower case, punctuation dropped, spaces as
    hyphens, a repeated one numbered."""
    seen: dict[str, int] = {}
    found = set()
    for heading in HEADING.findall(FENCE.sub("", markdown)):
        plain = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "")
        slug = re.sub(r"[^\w\- ]", "", plain.lower()).replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        found.add(slug if count == 0 else f"{slug}-{count}")
    return found


def named(name: str, markdown: str) -> bool:
    """Whether ``name`` (a path, a command, a variable) is in ``markdown`` as a whole word:
    ``/v1/points`` is not named by ``/v1/points/inverse``, nor ``MESHFLAT_API_KEYS`` by
    ``MESHFLAT_API_KEYS_FILE``."""
    pattern = rf"(?<![\w/{{}}-]){re.escape(name)}(?![\w/{{}}-])"
    return re.search(pattern, markdown) is not None


def openapi_routes() -> list[str]:
    document = json.loads(text(ROOT / "openapi" / "openapi.json"))
    return sorted(document["paths"])


def commands() -> list[str]:
    subparsers = next(
        action for action in parser()._actions if action.dest == "command" and action.choices
    )
    return sorted(subparsers.choices)


def settings_variables() -> list[str]:
    return [f"MESHFLAT_{item.name.upper()}" for item in fields(Settings)]


@pytest.mark.parametrize("route", openapi_routes())
def test_every_route_is_in_the_api_doc(route):
    assert named(route, text(DOCS / "api.md")), f"{route} is not named in docs/api.md"


@pytest.mark.parametrize("command", commands())
def test_every_command_is_in_the_cli_doc(command):
    cli = text(DOCS / "cli.md")
    assert named(f"meshflat {command}", cli) or f"`{command}`" in cli, (
        f"meshflat {command} is not named in docs/cli.md"
    )


@pytest.mark.parametrize("variable", settings_variables())
def test_every_setting_is_in_the_operations_doc(variable):
    assert named(variable, text(DOCS / "operations.md")), f"{variable} is not in docs/operations.md"


def test_the_readme_is_a_front_door():
    lines = text(README).count("\n")
    assert lines <= README_MAX_LINES, (
        f"README.md has {lines} lines (at most {README_MAX_LINES}): the reference belongs in docs/"
    )


def broken_links(path: Path) -> list[str]:
    """The relative links of ``path`` whose file, or heading, does not exist."""
    broken = []
    for target in LINK.findall(prose(text(path))):
        if re.match(r"[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto:, ...
            continue
        file_part, _, anchor = target.partition("#")
        linked = (path.parent / file_part).resolve() if file_part else path
        if not linked.exists():
            broken.append(f"{target}: no such file")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(text(linked)):
            broken.append(f"{target}: no heading #{anchor} in {linked.name}")
    return broken


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda path: str(path.relative_to(ROOT)))
def test_every_relative_link_points_at_what_exists(path):
    broken = broken_links(path)
    assert not broken, f"{path.relative_to(ROOT)}: " + "; ".join(broken)


def test_the_link_check_finds_broken_links(tmp_path):
    # The check above can fail: a missing file and a missing heading are reported, while a
    # link in code, a URL and a heading that exists are not.
    (tmp_path / "other.md").write_text("# Other\n\n## A `code` heading: here\n")
    doc = tmp_path / "doc.md"
    doc.write_text(
        "# A title\n\n[gone](gone.md), [here](#a-title), [not here](#nowhere),\n"
        "[there](other.md#a-code-heading-here), [not there](other.md#other-1),\n"
        "[web](https://example.com/x.md), `[code](code.md)`\n\n```\n[block](block.md)\n```\n"
    )
    assert broken_links(doc) == [
        "gone.md: no such file",
        "#nowhere: no heading #nowhere in doc.md",
        "other.md#other-1: no heading #other-1 in other.md",
    ]


def test_names_are_matched_as_whole_words():
    assert named("/v1/points", "`/v1/points` and `/v1/points/inverse`")
    assert not named("/v1/points", "only `/v1/points/inverse`")
    assert not named("MESHFLAT_API_KEYS", "only MESHFLAT_API_KEYS_FILE")
    assert named("/v1/samples/{name}", "`GET /v1/samples/{name}`")
