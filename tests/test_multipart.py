"""The multipart parser (service.server.multipart) reads a form as python-multipart, the
parser of Starlette, does, or refuses it with a 4xx: the Content-Type's parameters by
their whole names (a decoy ``xboundary`` is not the boundary), quoted or not, in any order,
none twice; and the body's parts as python-multipart splits them. Checked on crafted
bodies, through the app, and on generated ones against python-multipart itself."""

from __future__ import annotations

import json
import string

import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st
from python_multipart.multipart import MultipartParser, parse_options_header

from service.problems import Problem
from service.samples import SAMPLES
from service.server.multipart import parse_form

from .test_measure import NAME
from .test_measure import PARAMS as SCALP

# -- the independent reading: python-multipart, driven as Starlette drives it -----------------


class Refused(Exception):
    """What Starlette answers with a 400 (a part without a name)."""


def reference(body: bytes, content_type: str) -> list[tuple[bytes, bytes | None, bytes]] | None:
    """The parts (name, file name, bytes) python-multipart finds, as Starlette's
    ``MultiPartParser`` collects them; None when it refuses the form."""
    _, options = parse_options_header(content_type)
    if b"boundary" not in options:
        return None  # Starlette: "Missing boundary in multipart."
    parts: list[tuple[bytes, bytes | None, bytes]] = []
    header = {"field": b"", "value": b""}
    part: dict = {}

    def header_end():
        if header["field"].lower() == b"content-disposition":
            part["disposition"] = header["value"]
        header.update(field=b"", value=b"")

    def headers_finished():
        _, values = parse_options_header(part.get("disposition", b""))
        if b"name" not in values:
            raise Refused
        part.update(name=values[b"name"], filename=values.get(b"filename"))

    callbacks = {
        "on_part_begin": lambda: (part.clear(), part.update(data=bytearray())),
        "on_part_data": lambda data, start, end: part["data"].extend(data[start:end]),
        "on_part_end": lambda: parts.append((part["name"], part["filename"], bytes(part["data"]))),
        "on_header_field": lambda data, start, end: header.update(
            field=header["field"] + data[start:end]
        ),
        "on_header_value": lambda data, start, end: header.update(
            value=header["value"] + data[start:end]
        ),
        "on_header_end": header_end,
        "on_headers_finished": headers_finished,
    }
    try:
        parser = MultipartParser(options[b"boundary"], callbacks)
        parser.write(body)
        parser.finalize()
    except (ValueError, Refused):
        return None
    return parts


def read(body: bytes, content_type: str) -> list[tuple[bytes, bytes | None, bytes]] | int:
    """The service's parts in the reference's terms, or the status it refuses with."""
    try:
        form = parse_form(body, content_type)
    except Problem as problem:
        return problem.status
    return [
        (
            part.name.encode("latin-1"),
            None if part.filename is None else part.filename.encode("latin-1"),
            bytes(part.data),
        )
        for part in form.values()
    ]


def agrees(body: bytes, content_type: str) -> list | int:
    """The service's reading, checked: python-multipart's parts, or a 4xx."""
    got = read(body, content_type)
    if isinstance(got, int):
        assert 400 <= got < 500
    else:
        assert got == reference(body, content_type), (body, content_type)
    return got


def form(boundary: bytes, parts, epilogue: bytes = b"") -> bytes:
    """A body of ``parts`` (header lines, data) between ``boundary``s."""
    body = b"".join(
        b"--" + boundary + b"\r\n" + b"".join(line + b"\r\n" for line in lines) + b"\r\n" + data
        + b"\r\n"
        for lines, data in parts
    )  # fmt: skip
    return body + b"--" + boundary + b"--\r\n" + epilogue


def field(name: str, data: bytes, filename: str | None = None):
    disposition = f'Content-Disposition: form-data; name="{name}"'
    if filename is not None:
        disposition += f'; filename="{filename}"'
    return [disposition.encode()], data


VISIBLE = [field("mesh", b"v 0 0 0\n", "a.obj"), field("params", b'{"sigma": 0.3}')]
HIDDEN = [field("params", b'{"sigma": 0.9}')]
#: A form on boundary REAL with a second form, on EVIL, in its epilogue.
SMUGGLED = form(b"REAL", VISIBLE, form(b"EVIL", HIDDEN))
VISIBLE_PARTS = [(b"mesh", b"a.obj", b"v 0 0 0\n"), (b"params", None, b'{"sigma": 0.3}')]


# -- the Content-Type's parameters ----------------------------------------------------------


@pytest.mark.parametrize(
    "content_type",
    [
        "multipart/form-data; xboundary=EVIL; boundary=REAL",
        "multipart/form-data; boundary=REAL; xboundary=EVIL",
        "multipart/form-data; x-boundary=EVIL; boundary=REAL",
        'multipart/form-data; note="boundary=EVIL"; boundary=REAL',
        'multipart/form-data; note="a;boundary=EVIL"; boundary=REAL',
        'multipart/form-data; note="a\\";boundary=EVIL"; boundary=REAL',
        'multipart/form-data; charset=utf-8; BOUNDARY="REAL"',
        "Multipart/Form-Data;boundary = REAL ;",
    ],
)
def test_the_boundary_is_the_parameter_of_that_whole_name_quoted_or_not(content_type):
    assert agrees(SMUGGLED, content_type) == VISIBLE_PARTS


@pytest.mark.parametrize(
    ("content_type", "says"),
    [
        ("multipart/form-data; boundary=REAL; boundary=EVIL", "boundary more than once"),
        ("multipart/form-data; BOUNDARY=EVIL; boundary=REAL", "boundary more than once"),
        ("multipart/form-data; boundary*=utf-8''EVIL; boundary=REAL", "boundary*"),
        ("multipart/form-data; boundary*0=REAL", "boundary*0"),
        ('multipart/form-data; x="a\\\\"; boundary=REAL; y="; boundary=EVIL"', "two ways"),
        ('multipart/form-data; boundary="R\\EAL"', "two ways"),
        ('multipart/form-data; boundary="REAL', "malformed"),
        ("multipart/form-data; boundary", "malformed"),
        ("multipart/form-data; xboundary=REAL", "no boundary"),
        ("multipart/form-data", "no boundary"),
        ('multipart/form-data; boundary=""', "1 to 70"),
        ('multipart/form-data; boundary="REAL "', "1 to 70"),
        ("multipart/form-data; boundary=" + "R" * 71, "1 to 70"),
    ],
)
def test_a_boundary_given_twice_ambiguously_or_not_at_all_is_refused(content_type, says):
    with pytest.raises(Problem) as refused:
        parse_form(SMUGGLED, content_type)
    assert refused.value.status == 400 and says in refused.value.detail
    assert reference(SMUGGLED, content_type) in (None, VISIBLE_PARTS)


def test_a_form_hidden_inside_a_field_is_that_fields_bytes():
    mesh = b"v 0 0 0\n" + form(b"EVIL", HIDDEN)
    body = form(b"REAL", [field("mesh", mesh, "a.obj"), field("params", b"{}")])
    content_type = "multipart/form-data; xboundary=EVIL; boundary=REAL"
    assert agrees(body, content_type) == [(b"mesh", b"a.obj", mesh), (b"params", None, b"{}")]


# -- the body ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "body",
    [
        # A part with no headers whose data looks like headers: no name, to any parser.
        b'--B\r\n\r\nContent-Disposition: form-data; name="params"\r\n\r\n{}\r\n--B--\r\n',
        # The data starts after the blank line: a boundary line there is data.
        b'--B\r\nContent-Disposition: form-data; name="mesh"; filename="a.obj"\r\n\r\n--B\r\n'
        b'Content-Disposition: form-data; name="params"\r\n\r\n{}\r\n--B--\r\n',
        # A preamble whose last line ends in the delimiter.
        b'junk--B\r\nContent-Disposition: form-data; name="params"\r\n\r\n{}\r\n--B--\r\n',
        # A header line that is not one.
        b'--B\r\nContent-Disposition: form-data; name="mesh"\r\nname="params"\r\n\r\n{}\r\n--B--',
        b'--B\r\nContent-Disposition: form-data; name="a"\nname="b"\r\n\r\n{}\r\n--B--',
        # A delimiter followed by neither CRLF nor "--".
        b'--B\r\nContent-Disposition: form-data; name="a"\r\n\r\nx\r\n--Bx\r\n--B--',
        # Two names, or a name escaped in a way parsers undo differently.
        b'--B\r\nContent-Disposition: form-data; name="params"; name="mesh"\r\n\r\nx\r\n--B--',
        b'--B\r\nContent-Disposition: form-data; name="p\\arams"\r\n\r\nx\r\n--B--',
        b"--B\r\nContent-Disposition: form-data; name*=utf-8''params; name=\"a\"\r\n\r\nx\r\n--B--",
    ],
)
def test_parts_other_parsers_do_not_see_are_not_read(body):
    got = agrees(body, "multipart/form-data; boundary=B")
    assert isinstance(got, int) or b"params" not in [name for name, _, _ in got]


def test_names_and_file_names_are_unquoted_as_other_parsers_do():
    body = form(b"B", [field('p\\"q', b"x", 'a \\"b\\\\.obj')])
    assert agrees(body, "multipart/form-data; boundary=B") == [(b'p"q', b'a "b\\.obj', b"x")]


# -- through the app --------------------------------------------------------------------------

pytestmark = pytest.mark.anyio


async def test_a_form_smuggled_behind_a_decoy_xboundary_is_not_what_is_computed(client):
    """The answer to the form the visible boundary delimits is the one a plain request for
    the same parts gets; the smuggled params would have changed it."""
    mesh = SAMPLES[NAME].path.read_bytes()
    visible = {**SCALP, "units": "mm", "density_per_cm2": 0.2}
    hidden = {**visible, "density_per_cm2": 0.6}

    def parts(params):
        return [field("mesh", mesh, NAME), field("params", json.dumps(params).encode())]

    smuggled = form(b"REAL", parts(visible), form(b"EVIL", parts(hidden)))
    response = await client.post(
        "/v1/sites",
        content=smuggled,
        headers={"content-type": "multipart/form-data; xboundary=EVIL; boundary=REAL"},
    )
    assert response.status_code == 200, response.text

    async def plain(params):  # httpx's own multipart encoder
        files = {"mesh": (NAME, mesh)}
        answer = await client.post("/v1/sites", files=files, data={"params": json.dumps(params)})
        return answer.json()

    assert response.json() == await plain(visible)
    assert response.json()["count"] < (await plain(hidden))["count"]


# -- generated forms against python-multipart -------------------------------------------------

#: RFC 2046's boundary characters.
BCHARS = string.ascii_letters + string.digits + "'()+_,-./:=? "
TOKEN = set(string.ascii_letters + string.digits + "!#$%&'*+-.^_`|~")
boundaries = st.text(BCHARS, min_size=1, max_size=8).map(lambda b: b.rstrip(" ") or "b")


def rarely(often, *rare):
    """``often`` three times in four, else one of ``rare``."""
    return st.sampled_from([often] * 3 * len(rare) + list(rare))


@st.composite
def value(draw, text: str, hostile: bool) -> str:
    """``text`` as a header parameter's value: a token when it can be and is drawn so, else
    quoted, escaping what must be and, when ``hostile``, a character that need not be."""
    if text and set(text) <= TOKEN and draw(st.booleans()):
        return text
    at = draw(st.integers(0, len(text) - 1)) if text and hostile else None
    quoted = ("\\" + c if c in '"\\' or k == at else c for k, c in enumerate(text))
    return '"' + "".join(quoted) + '"'


@st.composite
def parameters(draw, first: str, wanted: list[tuple[str, str]], hostile: bool) -> str:
    """``first`` and its parameters: ``wanted`` and decoys (``x`` and a wanted name, one
    whose value holds the name), in any order, names in any case, with any of the usual
    spacing; when ``hostile``, the name again or in RFC 2231's notation too, and
    backslashes that parsers read differently."""
    name, text = wanted[0]
    decoys = [(f"x{name}", text + "x"), ("note", f"a;{name}={text}x")]
    if hostile:
        decoys += [(name, text + "x"), (f"{name}*", text), (f"{name}*0", text)]
        decoys += [("note", f'a\\";{name}={text}x')]
    chosen = draw(
        st.permutations(wanted + draw(st.lists(st.sampled_from(decoys), max_size=2, unique=True)))
    )
    rendered = [first]
    for name, text in chosen:
        spacing = draw(st.sampled_from(["; ", ";", " ;", ";\t", " ; "]))
        case = draw(st.sampled_from([str, str.upper, str.title]))
        equals = draw(rarely("=", " = "))
        rendered.append(f"{spacing}{case(name)}{equals}{draw(value(text, hostile))}")
    return "".join(rendered)


NAMES = st.sampled_from(["mesh", "params", "p q", 'p"q', "p\\q", "p;name=q"])
#: File names; not python-multipart's IE6 paths (``C:\\x``, ``\\\\x``), which it cuts.
FILENAMES = st.text(string.ascii_letters + ' .;"\\=', max_size=6).filter(
    lambda f: f[1:3] != ":\\" and f[:2] != "\\\\"
)
KEYS = st.sampled_from(["Content-Disposition", "content-disposition", "CONTENT-DISPOSITION"])


@st.composite
def part(draw, boundary: str, other: str, hostile: bool) -> tuple[list[bytes], bytes]:
    """A part's header lines and data; the data holds lines like delimiters (of ``other``;
    when ``hostile``, of ``boundary`` too)."""
    wanted = [("name", draw(NAMES))]
    if draw(st.booleans()):
        wanted.append(("filename", draw(FILENAMES)))
    disposition = draw(parameters("form-data", wanted, hostile))
    space = draw(st.sampled_from([" ", "", "  "]))
    lines = [f"{draw(KEYS)}:{space}{disposition}".encode("latin-1")]
    lines += draw(rarely([], [b"Content-Type: application/octet-stream"]))
    fragments = [b"x", b"\r\n", b"-", b"\r", b"\n", b"\r\n\r\n", b"--", b"\r\n--" + other.encode()]
    fragments += [b"--" + boundary.encode() + b"\r\n"]
    if hostile:
        lines = draw(st.sampled_from([lines, lines[::-1], []]))
        fragments += [b"\r\n--" + boundary.encode() + b"x", b"\r\n--" + boundary.encode()]
    data = b"".join(draw(st.lists(st.sampled_from(fragments), max_size=4)))
    return lines, data


@st.composite
def forms(draw, hostile: bool) -> tuple[bytes, str]:
    """A body and its Content-Type, with decoy parameters, decoy boundaries and a form on
    another boundary in its epilogue at times; when ``hostile``, the boundary missing at
    times, and a preamble."""
    boundary, other = draw(boundaries), draw(boundaries)
    media_type = draw(st.sampled_from(["multipart/form-data", "Multipart/Form-Data"]))
    wanted = [("boundary", boundary)]
    content_type = draw(parameters(media_type, wanted, hostile))
    if hostile and draw(st.booleans()):
        content_type = content_type.replace("oundary=", "oundary-=")  # no boundary at all
    parts = draw(st.lists(part(boundary, other, hostile), min_size=not hostile, max_size=3))
    hidden = form(other.encode(), [field("params", b"{}")])
    epilogue = draw(st.sampled_from([b"", b"\r\n", hidden]))
    preamble = draw(st.sampled_from([b"", b"\r\n", b"junk\r\n"])) if hostile else b""
    return preamble + form(boundary.encode(), parts, epilogue), content_type


@settings(max_examples=100)  # about a second; CI's profile would take 300
@given(st.booleans().flatmap(forms))
def test_generated_forms_read_as_python_multipart_reads_them_or_are_refused(case):
    body, content_type = case
    got = agrees(body, content_type)
    event("refused" if isinstance(got, int) else f"{len(got)} parts read")
