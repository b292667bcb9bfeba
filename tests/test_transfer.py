"""Values between the map and the mesh (``POST /v1/transfer``, ``meshflat transfer``;
docs/math.md, section 16): values drawn on the map come back onto the mesh, a picture of
/v1/flatten painted over lands on the triangles under the paint, and the look-up images name
the triangle and its weights at every pixel."""

from __future__ import annotations

import base64
import io
import json
import struct
import zlib

import numpy as np
import pytest
from PIL import Image

from service.cli import main
from service.outputs.lookup import read_lookup
from service.samples import SAMPLES

from .conftest import load_sample
from .test_api import SCALP, problem
from .test_painted import ply_with

pytestmark = pytest.mark.anyio

NAME = "fsaverage-head.ply"
PARAMS = {**SCALP[NAME], "image_width": 900, "image_height": 600}
VERTICES, FACES = load_sample(NAME)
#: A smooth function of the surface: what a front end might measure a vertex.
VALUES = VERTICES[:, 0] / 100 + (VERTICES[:, 1] / 120) ** 2


async def transfer(client, params: dict, files: dict | None = None, data: bytes | None = None):
    form = {"mesh": (NAME, SAMPLES[NAME].path.read_bytes() if data is None else data)}
    form.update(files or {})
    fields = {"params": json.dumps({**PARAMS, **params})}
    return await client.post("/v1/transfer", files=form, data=fields)


def png_of(url: str) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))))


def nullable(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], dtype=float)


async def test_values_drawn_on_the_map_come_back_onto_the_mesh(client):
    drawn = (await transfer(client, {"values": VALUES.tolist()})).json()
    low, high = drawn["value_range"]
    image, mask = png_of(drawn["image"]), png_of(drawn["mask"])
    assert image.dtype == np.uint16 and image.shape == (600, 900) and mask.dtype == np.uint8
    assert (image[mask == 0] == 0).all() and image.max() > 60000
    png = base64.b64decode(drawn["image"].split(",", 1)[1])
    back = await transfer(client, {"value_range": [low, high]}, {"image": ("map.png", png)})
    answer = back.json()
    ids, values = np.array(answer["vertices"]["ids"]), nullable(answer["vertices"]["values"])
    spread = high - low
    # Interpolation error: the function's change over about a pixel, far below its spread.
    error = np.abs(values - VALUES[ids])
    assert np.isfinite(values).all() and np.median(error) < 1e-3 * spread
    assert error.max() < 0.02 * spread
    face_ids = np.array(answer["faces"]["ids"])
    face_values = nullable(answer["faces"]["values"])
    # A face's mean over its triangle: its corners' mean, for a function linear on it.
    np.testing.assert_allclose(
        face_values, VALUES[FACES[face_ids]].mean(axis=1), atol=0.01 * spread
    )
    np.testing.assert_allclose(answer["faces"]["coverage"], 1.0)


async def test_a_flatten_picture_painted_over_comes_back_onto_the_triangles_under_the_paint(
    client,
):
    params = {**PARAMS, "output": "png"}
    form = {"mesh": (NAME, SAMPLES[NAME].path.read_bytes())}
    picture = await client.post("/v1/flatten", files=form, data={"params": json.dumps(params)})
    canvas = np.asarray(Image.open(io.BytesIO(picture.content)).convert("RGB")).copy()
    grey = np.zeros(canvas.shape[:2], dtype=np.uint8)
    grey[250:330, 380:520] = 255  # a surgeon's rectangle, painted white over the map
    painted = io.BytesIO()
    Image.fromarray(grey).save(painted, format="PNG")
    answer = (await transfer(client, {}, {"image": ("painted.png", painted.getvalue())})).json()
    lookup = await transfer(client, {"output": "face_ids"})
    ids, weights = read_lookup(lookup.content)
    assert weights is None and ids.shape == (600, 900)
    painted_area = np.zeros(ids.shape, dtype=bool)
    painted_area[250:330, 380:520] = True
    # Faces wholly under the paint (none of their pixels off it, a pixel clear of its edge),
    # and faces wholly off it (none of their pixels within a pixel of it).
    near = np.zeros(ids.shape, dtype=bool)
    near[249:331, 379:521] = True
    under = set(np.unique(ids[252:328, 382:518])) - set(np.unique(ids[~painted_area])) - {-1}
    outside = set(np.unique(ids)) - set(np.unique(ids[near])) - {-1}
    values = dict(zip(answer["faces"]["ids"], answer["faces"]["values"], strict=True))
    assert under and all(values[face] == pytest.approx(1.0) for face in under)
    assert outside and all(values[face] == pytest.approx(0.0) for face in outside)


async def test_the_look_up_images_give_each_pixel_its_face_and_weights(client):
    flat = (await transfer(client, {"output": "barycentric"})).content
    ids, weights = read_lookup(flat)
    held = ids >= 0
    assert held.mean() > 0.2 and (ids[~held] == -1).all()
    flattened = await client.post(
        "/v1/flatten",
        files={"mesh": (NAME, SAMPLES[NAME].path.read_bytes())},
        data={"params": json.dumps(PARAMS)},
    )
    region = set(flattened.json()["faces"]["ids"])
    assert set(np.unique(ids[held])) <= region
    np.testing.assert_allclose(weights[held].sum(axis=1), 1.0, atol=1e-5)
    assert (weights[held] > -1e-5).all() and (weights[~held] == 0).all()
    # The weights read the values a vertex back as the drawing does, pixel by pixel.
    drawn = (await transfer(client, {"values": VALUES.tolist()})).json()
    low, high = drawn["value_range"]
    image = png_of(drawn["image"]) / 65535 * (high - low) + low
    rebuilt = np.einsum("pk,pk->p", weights[held], VALUES[FACES[ids[held]]])
    np.testing.assert_allclose(rebuilt, image[held], atol=2e-4 * (high - low))


def decode_grey_alpha_16(data: bytes) -> np.ndarray:
    """(h, w, 2) uint16 of a 16-bit grey and alpha PNG with filter 0 rows (as written)."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height, depth, kind = struct.unpack(">IIBB", data[16:26])
    assert (depth, kind) == (16, 4)
    at, idat = 8, b""
    while at < len(data):
        (length,) = struct.unpack(">I", data[at : at + 4])
        if data[at + 4 : at + 8] == b"IDAT":
            idat += data[at + 8 : at + 8 + length]
        at += 12 + length
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(height, 1 + 4 * width)
    assert (rows[:, 0] == 0).all()
    return rows[:, 1:].copy().view(">u2").reshape(height, width, 2)


#: Seen from near the forehead, the scalp's map crosses the seam and holds a singular point.
TURNED = {
    **PARAMS,
    "center": [0, 80, 40],
    "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70, "apex": [1.3, -12.5, -32.3]}},
}


async def test_faces_that_wrap_round_the_map_hold_no_pixel(client):
    form = {"mesh": (NAME, SAMPLES[NAME].path.read_bytes())}
    flat = await client.post("/v1/flatten", files=form, data={"params": json.dumps(TURNED)})
    validation = flat.json()["validation"]
    wrapping = set(validation["seam_faces"]) | set(validation["singular_point_faces"])
    assert len(wrapping) > 5
    ids, _ = read_lookup((await transfer(client, {**TURNED, "output": "face_ids"})).content)
    assert (ids >= 0).mean() > 0.02 and not wrapping & set(np.unique(ids).tolist())
    white = io.BytesIO()
    Image.new("L", (900, 600), 255).save(white, format="PNG")
    answer = (await transfer(client, TURNED, {"image": ("white.png", white.getvalue())})).json()
    faces = answer["faces"]
    for face, value, coverage in zip(faces["ids"], faces["values"], faces["coverage"], strict=True):
        if face in wrapping:
            assert value is None and coverage == 0.0


def colour_png16(channels: np.ndarray) -> bytes:
    """A 16-bit RGB or RGBA PNG ((h, w, 3 or 4) uint16) with filter 0 rows."""
    height, width, count = channels.shape
    rows = np.zeros((height, 1 + 2 * count * width), dtype=np.uint8)
    rows[:, 1:] = channels.astype(">u2").view(np.uint8).reshape(height, -1)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    header = struct.pack(">IIBBBBB", width, height, 16, {3: 2, 4: 6}[count], 0, 0, 0)
    idat = zlib.compress(rows.tobytes())
    return (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")
    )


@pytest.mark.parametrize("value", [3.0, -1e15, 0.0])
async def test_values_all_equal_come_back_through_the_range_answered(client, value):
    drawn = (await transfer(client, {"values": [value] * len(VERTICES)})).json()
    png = base64.b64decode(drawn["image"].split(",", 1)[1])
    back = await transfer(client, {"value_range": drawn["value_range"]}, {"image": ("m.png", png)})
    assert back.status_code == 200, back.text
    assert set(back.json()["vertices"]["values"]) == {value}


@pytest.mark.parametrize("channels", [3, 4])
async def test_a_16_bit_colour_image_keeps_its_16_bits(client, channels):
    drawn = (await transfer(client, {"values": VALUES.tolist()})).json()
    grey = png_of(drawn["image"])
    colour = np.repeat(grey[..., None], channels, axis=2)
    if channels == 4:
        colour[..., 3] = 65535
    range_ = {"value_range": drawn["value_range"]}
    by_grey = (
        await transfer(
            client, range_, {"image": ("g.png", base64.b64decode(drawn["image"].split(",", 1)[1]))}
        )
    ).json()
    by_colour = await transfer(client, range_, {"image": ("c.png", colour_png16(colour))})
    assert by_colour.status_code == 200, by_colour.text
    # Grey in every channel is its own luminance: to the rounding of a 16-bit level, not 8.
    for part in ("vertices", "faces"):
        np.testing.assert_allclose(
            nullable(by_colour.json()[part]["values"]),
            nullable(by_grey[part]["values"]),
            atol=1e-6 * np.ptp(drawn["value_range"]),
        )


async def test_the_png_answer_comes_back_as_an_image_part(client):
    drawn = await transfer(client, {"values": VALUES.tolist(), "output": "png"})
    low, high = (await transfer(client, {"values": VALUES.tolist()})).json()["value_range"]
    back = await transfer(client, {"value_range": [low, high]}, {"image": ("p.png", drawn.content)})
    assert back.status_code == 200, back.text
    values = nullable(back.json()["vertices"]["values"])
    ids = np.array(back.json()["vertices"]["ids"])
    # A 16-bit grey-and-alpha PNG is read at 8 bits: within a level of 255 and the drawing.
    assert np.nanmedian(np.abs(values - VALUES[ids])) < 0.01 * (high - low)


async def test_the_png_answer_is_the_drawing_with_its_coverage_as_alpha(client):
    answer = await transfer(client, {"values": VALUES.tolist(), "output": "png"})
    assert answer.headers["content-type"] == "image/png"
    pixels = decode_grey_alpha_16(answer.content)
    drawn = (await transfer(client, {"values": VALUES.tolist()})).json()
    np.testing.assert_array_equal(pixels[..., 0], png_of(drawn["image"]))
    np.testing.assert_array_equal(pixels[..., 1], (png_of(drawn["mask"]) > 0) * 65535)


async def test_values_may_name_a_vertex_property_of_the_file(client):
    data = ply_with({"thickness": ("float", VALUES.astype(np.float32))})
    by_name = (await transfer(client, {"values": "thickness"}, data=data)).json()
    listed = (await transfer(client, {"values": VALUES.astype(np.float32).tolist()})).json()
    assert by_name["value_range"] == pytest.approx(listed["value_range"])
    np.testing.assert_array_equal(png_of(by_name["image"]), png_of(listed["image"]))


async def test_bad_transfers_name_the_part_or_field(client):
    red = io.BytesIO()
    Image.new("L", (300, 200)).save(red, format="PNG")
    small = {"image": ("small.png", red.getvalue())}
    body = problem(await transfer(client, {}, small), 422, "image")
    assert "300 x 200" in body["detail"] and "900 x 600" in body["detail"]
    body = problem(await transfer(client, {"values": [1.0, 2.0]}), 422, "params.values")
    assert f"{len(VERTICES):,} vertices" in body["detail"]
    body = problem(await transfer(client, {"values": "thickness"}), 422, "params.values")
    assert "no per-vertex property 'thickness'" in body["detail"]
    # A list with a bad item: what is wrong with the item, not that it is no property name.
    body = problem(await transfer(client, {"values": [0.5, None]}), 422, "params.values.1")
    assert body["detail"] == "params.values.1: Input should be a valid number"
    body = problem(await transfer(client, {}), 422, "image")
    assert "nothing to carry" in body["detail"]
    body = problem(await transfer(client, {}, {"imgae": ("m.png", b"")}), 422, "imgae")
    assert body["detail"] == (
        "imgae: this route reads no part of that name; it reads params, mesh, mask, image"
    )
    right = io.BytesIO()
    Image.new("L", (900, 600)).save(right, format="PNG")
    both = {"image": ("map.png", right.getvalue())}
    problem(await transfer(client, {"values": VALUES.tolist()}, both), 422, "image")
    problem(await transfer(client, {"output": "png"}, both), 422, "params.values")
    problem(
        await transfer(client, {"value_range": [1, 1], "values": [0.0]}), 422, "params.value_range"
    )
    # Transfer draws no picture: what colours or grids one is refused, not ignored.
    for drawing in ({"colour_by": "isometric"}, {"grid_lines": 4}):
        problem(
            await transfer(client, {**drawing, "output": "face_ids"}),
            422,
            "params." + next(iter(drawing)),
        )


def test_the_command_line_carries_an_image_onto_the_mesh(tmp_path, capsys):
    mesh = tmp_path / NAME
    mesh.write_bytes(SAMPLES[NAME].path.read_bytes())
    params = json.dumps({**PARAMS, "values": VALUES.tolist()})
    drawing = tmp_path / "drawing.png"
    assert main(["transfer", str(mesh), "--params", params, "--out", str(drawing)]) == 0
    assert decode_grey_alpha_16(drawing.read_bytes()).shape == (600, 900, 2)
    painted = tmp_path / "painted.png"
    Image.new("L", (900, 600), 128).save(painted)
    out = tmp_path / "values.json"
    size = json.dumps({**PARAMS})
    assert (
        main(["transfer", str(mesh), "--params", size, "--image", str(painted), "--out", str(out)])
        == 0
    )
    answer = json.loads(out.read_text())
    assert nullable(answer["faces"]["values"]) == pytest.approx(128 / 255)
    lookup = tmp_path / "ids.bin"
    ids_params = json.dumps({**PARAMS, "output": "face_ids"})
    assert main(["transfer", str(mesh), "--params", ids_params, "--out", str(lookup)]) == 0
    assert read_lookup(lookup.read_bytes())[0].shape == (600, 900)


async def test_a_value_range_beyond_the_coordinates_bound_is_refused(client):
    huge = {"value_range": [-1.7e308, 1.7e308]}
    right = io.BytesIO()
    Image.new("L", (900, 600)).save(right, format="PNG")
    answer = await transfer(client, huge, {"image": ("map.png", right.getvalue())})
    problem(answer, 422, "params.value_range.0")


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("extreme", [1e100, -1e308, "both"])
async def test_a_values_property_beyond_the_bound_is_a_422_naming_values(client, extreme):
    """A file's property is held to the bound of listed values (+-1e15): at 1e100 the range
    of values all equal was low = high, at +-1e308 its width overflowed; every pixel was 0
    and numpy warned."""
    both = np.where(VERTICES[:, 0] > 0, 1.7e308, -1.7e308)
    values = both if extreme == "both" else np.full(len(VERTICES), extreme)
    data = ply_with({"v": ("double", values)})
    body = problem(await transfer(client, {"values": "v"}, data=data), 422, "params.values")
    assert "within +-1e15" in body["detail"] and body["indices"][0] == 0
    bound = np.where(VERTICES[:, 0] > 0, 1e15, -1e15)
    drawn = await transfer(client, {"values": "v"}, data=ply_with({"v": ("double", bound)}))
    assert drawn.json()["value_range"] == [-1e15, 1e15]
    assert png_of(drawn.json()["image"]).max() == 65535


@pytest.mark.filterwarnings("error::RuntimeWarning")
async def test_a_value_range_too_narrow_for_the_values_is_a_422_naming_it(client):
    """Values of tens drawn on [0, 5e-324] overflowed to infinity; a range 1e12 times
    narrower than the values' distance from it is refused, one within is drawn."""
    narrow = {"values": VALUES.tolist(), "value_range": [0.0, 5e-324]}
    body = problem(await transfer(client, narrow), 422, "params.value_range")
    assert "too narrow for the values" in body["detail"]
    reach = float(np.abs(VALUES).max())
    within = {"values": VALUES.tolist(), "value_range": [0.0, reach * 1e-12]}
    assert (await transfer(client, within)).status_code == 200
