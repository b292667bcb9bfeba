"""The Arrow form of every mesh answer (``application/vnd.apache.arrow.stream``), read with
pyarrow, Arrow's reference implementation (the service writes it with nanoarrow): each
column is the JSON answer's array at its dotted path, bit for bit; the schema's metadata is
the rest of the JSON answer; the two put together are the JSON answer."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import orjson
import pyarrow as pa
import pyarrow.ipc
import pytest
from pydantic import Field

from service.capabilities import MESH_CAPABILITIES
from service.capabilities.context import Context
from service.capabilities.inputs import MeshPart, Upload, parse_params
from service.encoding import Answer, encode
from service.examples import icosahedron_obj, request_example
from service.outputs import Output
from service.outputs.arrow import ARROW_BYTES_PER_BYTE, METADATA_KEY, arrow_stream
from service.samples import SAMPLES
from service.settings import Settings
from service.timings import Timings

from .test_api import SCALP, problem
from .test_measure import PARAMS as MEASURE_PARAMS
from .test_sites import PARAMS as SITES_PARAMS
from .test_sites import rectangle

pytestmark = pytest.mark.anyio

ARROW = "application/vnd.apache.arrow.stream"
NAME = "fsaverage-head.ply"


def read_arrow(data: bytes) -> tuple[pa.Table, dict]:
    """The stream's one batch of one row, and its metadata's JSON."""
    reader = pyarrow.ipc.open_stream(data)
    batches = list(reader)
    assert len(batches) == 1 and batches[0].num_rows == 1
    return pa.Table.from_batches(batches), json.loads(reader.schema.metadata[METADATA_KEY.encode()])


def at(answer, path: str):
    node = answer
    for key in path.split("."):
        node = node[int(key)] if isinstance(node, list) else node[key]
    return node


def put(rest, path: str, value) -> None:
    *parents, name = path.split(".")
    node = at(rest, ".".join(parents)) if parents else rest
    node[name] = value


def column_numbers(table: pa.Table, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """A column's one list as numpy: its numbers (``(n, k)`` for fixed-size lists of
    ``k``, and so on; a null item's placeholder included) and, when it has nulls, where its
    items (numbers, or rows) are valid."""
    items = table.column(name).chunk(0).values
    valid = None if items.null_count == 0 else ~np.asarray(items.is_null())
    shape = [len(items)]
    while pa.types.is_fixed_size_list(items.type):
        shape.append(items.type.list_size)
        items = items.values
    return items.fill_null(0).to_numpy().reshape(shape), valid


def expected_at(answer, path: str) -> tuple[list, bool]:
    """The JSON's array a column holds, and whether it is a field of a list of rows
    (``hits.face``: each row's face, None where the row is null)."""
    *parents, name = path.split(".")
    node = at(answer, ".".join(parents)) if parents else answer
    if isinstance(node, list):
        return [None if row is None else row[name] for row in node], True
    return node[name], False


def assert_same_answer(json_bytes: bytes, arrow_bytes: bytes) -> list[str]:
    """The Arrow answer holds the JSON answer: every column its array bit for bit (ints as
    ints, floats as the doubles the JSON text denotes, nulls where it has null), and the
    metadata with the columns put back is the JSON answer. Returns the columns' names."""
    answer = orjson.loads(json_bytes)
    table, rest = read_arrow(arrow_bytes)
    rows: dict[str, dict[str, list]] = {}
    for name in table.column_names:
        expected, of_rows = expected_at(answer, name)
        numbers, valid = column_numbers(table, name)
        present = np.array([item is not None for item in expected])
        if present.all():
            assert valid is None, name
        else:
            assert np.array_equal(valid, present), name
        wanted = np.asarray([item for item in expected if item is not None])
        got = numbers[present]
        assert got.shape == wanted.shape, name
        if got.dtype.kind == "f":
            assert wanted.dtype.kind == "f", name
            same = np.array_equal(got.view(np.uint64), wanted.astype(np.float64).view(np.uint64))
        else:
            assert got.dtype in (np.int32, np.int64) and wanted.dtype.kind == "i", name
            same = np.array_equal(got, wanted)
        assert same, name
        values = table.column(name)[0].as_py()
        if of_rows:
            parent, _, field = name.rpartition(".")
            rows.setdefault(parent, {})[field] = values
        else:
            put(rest, name, values)
    for parent, fields in rows.items():  # a row is null in every column where it is null
        first = next(iter(fields.values()))
        put(
            rest,
            parent,
            [
                None if first[i] is None else {field: v[i] for field, v in fields.items()}
                for i in range(len(first))
            ],
        )
    assert rest == answer
    return table.column_names


def example_result(capability):
    """The result of ``capability``'s request example on the icosahedron (what the OpenAPI
    document's example answers), and its context."""
    params = parse_params(capability.params, orjson.dumps(request_example(capability.params)))
    upload = Upload("icosahedron.obj", icosahedron_obj())
    files = {part.name: upload for part in capability.parts if isinstance(part, MeshPart)}
    ctx = Context(Settings())
    given = capability.input_of(params, files, ctx)
    return capability.operation(given, ctx), given.params, ctx


@pytest.mark.parametrize("capability", MESH_CAPABILITIES, ids=lambda c: c.name)
def test_every_mesh_routes_arrow_answer_holds_its_json_answer(capability):
    assert capability.outputs[-1] is Output.ARROW
    result, params, ctx = example_result(capability)
    as_json = capability.render(result, params, Output.JSON, ctx, Timings())
    as_arrow = capability.render(result, params, Output.ARROW, ctx, Timings())
    names = assert_same_answer(as_json, as_arrow)
    assert "params.center" in names


async def post(client, route: str, params: dict, accept: str | None = None):
    headers = {"Accept": accept} if accept else {}
    response = await client.post(
        route,
        files={"mesh": (NAME, _sample())},
        data={"params": json.dumps(params)},
        headers=headers,
    )
    assert response.status_code == 200, response.text
    return response


def _sample() -> bytes:
    return SAMPLES[NAME].path.read_bytes()


async def test_flatten_by_accept_answers_its_arrays_as_columns_bit_for_bit(client):
    params = SCALP[NAME]
    as_json = await post(client, "/v1/flatten", params)
    as_arrow = await post(client, "/v1/flatten", params, ARROW)
    assert as_arrow.headers["content-type"] == ARROW
    assert "Accept" in as_arrow.headers["vary"]
    assert 'filename="region.arrow"' in as_arrow.headers["content-disposition"]
    names = assert_same_answer(as_json.content, as_arrow.content)
    vertices = ("ids", "theta", "phi", "r", "x", "y")
    assert {f"vertices.{n}" for n in vertices} | {"faces.ids", "faces.vertices"} <= set(names)
    table, rest = read_arrow(as_arrow.content)
    # The triangles are a list of fixed-size lists of 3 of int32; the angles float64.
    assert table.schema.field("faces.vertices").type.value_type == pa.list_(pa.int32(), 3)
    assert table.schema.field("vertices.theta").type == pa.list_(pa.float64())
    assert rest["vertices"] == {} and rest["faces"] == {}  # every field a column
    assert rest["metrics"] == as_json.json()["metrics"]
    assert len(as_arrow.content) < len(as_json.content)


async def test_params_output_arrow_answers_arrow_without_accept(client):
    response = await post(client, "/v1/flatten", {**SCALP[NAME], "output": "arrow"})
    assert response.headers["content-type"] == ARROW
    table, rest = read_arrow(response.content)
    assert "vertices.x" in table.column_names and rest["params"]["layout"] == "theta_phi"


async def test_sites_are_columns_and_their_zones_stay_in_the_metadata(client):
    zones = [
        rectangle("crown", -1.9, -1.4, 1.3, 1.7, density=20),
        rectangle("side", -0.9, -0.5, 1.35, 1.7, density=10),
    ]
    params = {**SITES_PARAMS, "zones": zones, "seed": 3}
    as_json = await post(client, "/v1/sites", params)
    as_arrow = await post(client, "/v1/sites", params, ARROW)
    names = assert_same_answer(as_json.content, as_arrow.content)
    assert {"sites.position", "sites.face", "sites.barycentric"} <= set(names), names
    table, rest = read_arrow(as_arrow.content)
    assert table.schema.field("sites.position").type.value_type == pa.list_(pa.float64(), 3)
    assert [zone["name"] for zone in rest["zones"]] == ["crown", "side"]


async def test_a_measured_curves_nulls_are_nulls_of_its_column(client):
    # A curve that leaves the map at its edge and comes back: the piece off the map runs
    # over no face (null in the JSON).
    curve = {"name": "out-and-back", "x": [-1.8, -1.6, -1.4], "y": [1.5, 2.8, 1.5]}
    zone = {"name": "crown", "outer": {"x": [-1.9, -1.3, -1.3, -1.9], "y": [1.3, 1.3, 1.7, 1.7]}}
    params = {**MEASURE_PARAMS, "zones": [zone], "curves": [curve]}
    as_json = await post(client, "/v1/measure", params)
    as_arrow = await post(client, "/v1/measure", params, ARROW)
    names = assert_same_answer(as_json.content, as_arrow.content)
    assert {"zones.0.partial_faces", "zones.0.outline.0.points", "curves.0.faces"} <= set(names)
    table, _ = read_arrow(as_arrow.content)
    assert table.column("curves.0.faces").chunk(0).values.null_count > 0


async def test_validate_answers_arrow_by_accept_and_refuses_what_it_cannot_answer(client):
    as_arrow = await post(client, "/v1/validate", SCALP[NAME], ARROW)
    assert as_arrow.headers["content-type"] == ARROW
    as_json = await post(client, "/v1/validate", SCALP[NAME])
    assert_same_answer(as_json.content, as_arrow.content)
    refused = await client.post(
        "/v1/validate",
        files={"mesh": (NAME, _sample())},
        data={"params": json.dumps(SCALP[NAME])},
        headers={"Accept": "image/png"},
    )
    body = problem(refused, 406, "Accept")
    assert ARROW in body["detail"]


async def test_locates_hits_are_a_column_a_field_null_where_a_ray_misses(client):
    # Two rays into the scalp, one towards the chin (outside the cone): a miss.
    params = {**SCALP[NAME], "theta": [1.5, 3.1, 1.6], "phi": [-1.6, 0.0, -1.5]}
    as_json = await post(client, "/v1/locate", params)
    as_arrow = await post(client, "/v1/locate", params, ARROW)
    assert None in as_json.json()["hits"]
    names = assert_same_answer(as_json.content, as_arrow.content)
    assert {"hits.face", "hits.barycentric", "hits.point"} <= set(names)
    table, rest = read_arrow(as_arrow.content)
    assert "hits" not in rest
    assert table.column("hits.point").chunk(0).values.null_count == 1


class Inner(Answer):
    values: list[int | None] = Field()
    label: str = Field()


class Sample(Answer):
    ids: list[int] = Field()
    narrow: list[float] = Field()
    small: list[int] = Field()
    large: list[int] = Field()
    points: list[list[float]] = Field()
    strands: list[list[list[float]]] = Field()
    ragged: list[list[int]] = Field()
    empty: list[int] = Field()
    flags: list[bool] = Field()
    names: list[str] = Field()
    missing: list[float] | None = Field()
    inner: list[Inner] = Field()


def sample_answer() -> Sample:
    return Sample.build(
        ids=np.array([3, 1, 2], dtype=np.int32),
        narrow=np.array([0.1, 1 / 3, -0.0], dtype=np.float32),
        small=np.array([1, 2], dtype=np.uint16),
        large=[1, 2**40],
        points=[[0.1, 0.2], [1e-300, -5e300]],
        strands=np.arange(24, dtype=np.float64).reshape(2, 4, 3) / 7,
        ragged=[[1, 2], [3]],
        empty=np.array([], dtype=np.int64),
        flags=np.array([True, False]),
        names=["a", "b"],
        missing=None,
        inner=[Inner.build(values=[1, None, 3], label="x"), Inner.build(values=[], label="y")],
    )


def test_columns_keep_the_jsons_ints_and_doubles_and_the_rest_stays_json():
    answer = sample_answer()
    as_json, as_arrow = encode(answer), arrow_stream(answer, lambda _: None)
    names = assert_same_answer(as_json, as_arrow)
    assert names == ["ids", "narrow", "small", "large", "points", "strands", "inner.0.values"]
    table, rest = read_arrow(as_arrow)
    types = {name: table.schema.field(name).type.value_type for name in names}
    # Integers as int32 where they all fit, else int64.
    assert types["ids"] == types["small"] == types["inner.0.values"] == pa.int32()
    assert types["large"] == pa.int64()
    # A float32 array is the doubles its JSON text denotes: 0.1, not float32's 0.1.
    assert table.column("narrow")[0].as_py()[0] == 0.1
    assert types["points"] == pa.list_(pa.float64(), 2)
    assert types["strands"] == pa.list_(pa.list_(pa.float64(), 3), 4)
    assert table.column("inner.0.values")[0].as_py() == [1, None, 3]
    assert rest["ragged"] == [[1, 2], [3]] and rest["flags"] == [True, False]
    assert rest["empty"] == [] and rest["missing"] is None and rest["names"] == ["a", "b"]
    assert rest["inner"] == [{"label": "x"}, {"values": [], "label": "y"}]


def test_writing_charges_its_columns_before_it_builds_them():
    charged = []
    arrow_stream(sample_answer(), charged.append)
    numbers = 3 + 3 + 2 + 2 + 4 + 24 + 3  # ids ... inner.0.values
    assert sum(charged) >= ARROW_BYTES_PER_BYTE * 8 * numbers


def test_a_nan_is_refused_as_the_json_refuses_it():
    answer = Inner.build(values=np.array([1.0, np.nan]), label="x")
    with pytest.raises(ValueError, match="NaN"):
        arrow_stream(answer, lambda _: None)


def test_the_document_gives_every_mesh_route_its_arrow_form():
    document = json.loads((Path(__file__).parent.parent / "openapi" / "openapi.json").read_text())
    for capability in MESH_CAPABILITIES:
        operation = document["paths"][capability.path]["post"]
        assert ARROW in operation["responses"]["200"]["content"], capability.path
        assert "406" in operation["responses"], capability.path
        assert "application/vnd.apache.arrow.stream" in operation["description"]
