"""Regions as a front end paints them (docs/math.md, section 16): the readers keep the file's
vertex colours, ids and texture coordinates in its order, and ``vertex_color``,
``feature_id`` and ``texture_mask`` regions select the faces painted, through the API."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import trimesh
from PIL import Image

from service.meshio import read_mesh
from service.samples import SAMPLES

from .conftest import load_sample
from .test_api import problem
from .test_meshio import LIMITS, container, read_in_chunks

pytestmark = pytest.mark.anyio

NAME = "fsaverage-head.ply"
VERTICES, FACES = load_sample(NAME)
#: The painted part: the vertices more than 40 mm up (the top of the head).
PAINTED = VERTICES[:, 2] > 40.0


def ply_with(columns: dict[str, tuple[str, np.ndarray]], face_columns=None) -> bytes:
    """fsaverage as a binary PLY with extra vertex (and face) properties: name -> (PLY type,
    values)."""
    vertex = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    types = {"uchar": "u1", "ushort": "<u2", "float": "<f4", "double": "<f8", "int": "<i4"}
    vertex += [(name, types[kind]) for name, (kind, _) in columns.items()]
    rows = np.zeros(len(VERTICES), dtype=vertex)
    for axis, name in enumerate("xyz"):
        rows[name] = VERTICES[:, axis]
    for name, (_, values) in columns.items():
        rows[name] = values
    face_columns = face_columns or {}
    face = [("n", "u1"), ("ids", "<i4", (3,))]
    face += [(name, types[kind]) for name, (kind, _) in face_columns.items()]
    face_rows = np.zeros(len(FACES), dtype=face)
    face_rows["n"], face_rows["ids"] = 3, FACES
    for name, (_, values) in face_columns.items():
        face_rows[name] = values
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(VERTICES)}"]
    header += ["property float x", "property float y", "property float z"]
    header += [f"property {kind} {name}" for name, (kind, _) in columns.items()]
    header += [f"element face {len(FACES)}", "property list uchar int vertex_indices"]
    header += [f"property {kind} {name}" for name, (kind, _) in face_columns.items()]
    header.append("end_header")
    return ("\n".join(header) + "\n").encode() + rows.tobytes() + face_rows.tobytes()


def glb_with(attributes: dict[str, tuple[np.ndarray, int, str, bool]]) -> bytes:
    """fsaverage as a GLB with extra vertex attributes: name -> (values, componentType,
    type, normalized)."""
    arrays = [np.asarray(VERTICES, dtype="<f4"), np.asarray(FACES, dtype="<u4").ravel()]
    specs = [(5126, "VEC3", False), (5125, "SCALAR", False)]
    for values, component, kind, normalized in attributes.values():
        arrays.append(np.ascontiguousarray(values))
        specs.append((component, kind, normalized))
    binary, views, accessors = b"", [], []
    for k, (array, (component, kind, normalized)) in enumerate(zip(arrays, specs, strict=True)):
        data = array.tobytes()
        views.append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(data)})
        count = len(array) if kind != "SCALAR" or k != 1 else array.size
        accessor = {"bufferView": k, "componentType": component, "count": count, "type": kind}
        if normalized:
            accessor["normalized"] = True
        if k == 0:
            accessor["min"], accessor["max"] = array.min(0).tolist(), array.max(0).tolist()
        accessors.append(accessor)
        binary += data + b"\0" * (-len(data) % 4)
    names = {"POSITION": 0, **{name: 2 + k for k, name in enumerate(attributes)}}
    document = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": names, "indices": 1}]}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(binary)}],
    }
    return container(document, binary)


def expected_faces(passes: np.ndarray, need: int = 3) -> list[int]:
    return np.flatnonzero(passes[FACES].sum(axis=1) >= need).tolist()


async def selected(client, data: bytes, filename: str, region: dict, files=None) -> list[int]:
    form = {"mesh": (filename, data), **(files or {})}
    params = {"region": region, "center": "bbox_center"}
    response = await client.post("/v1/flatten", files=form, data={"params": json.dumps(params)})
    assert response.status_code == 200, response.text
    return response.json()["faces"]["ids"]


# -- readers ----------------------------------------------------------------------------------


def test_ply_colours_scale_by_their_type_and_face_properties_follow_the_fan():
    red = np.where(PAINTED, 255, 0).astype(np.uint8)
    green = np.full(len(VERTICES), 65535 // 2, dtype=np.uint16)
    segment = np.arange(len(FACES), dtype=np.int32) % 7
    data = ply_with(
        {"red": ("uchar", red), "green": ("ushort", green), "label": ("int", PAINTED)},
        {"segment": ("int", segment)},
    )
    mesh = read_mesh(data, "ply", LIMITS)
    colors = mesh.attributes.colors
    np.testing.assert_allclose(colors[:, 0], red / 255.0, atol=1e-7)
    np.testing.assert_allclose(colors[:, 1], 0.5, atol=1e-4)
    assert (colors[:, 2] == 0).all() and (colors[:, 3] == 1).all()
    np.testing.assert_array_equal(mesh.attributes.vertex["label"], PAINTED)
    np.testing.assert_array_equal(mesh.attributes.face["segment"], segment)


def test_ply_polygon_properties_repeat_on_each_triangle_of_the_fan():
    text = (
        "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
        "property float z\nproperty float u\nproperty float v\nelement face 2\n"
        "property list uchar int vertex_indices\nproperty uchar part\nend_header\n"
        "0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n2 2 0 0.5 0.5\n4 0 1 2 3 7\n3 2 4 3 9\n"
    )
    mesh = read_mesh(text.encode(), "ply", LIMITS)
    np.testing.assert_array_equal(mesh.attributes.face["part"], [7, 7, 9])
    # v turned over: (0, 0) is the image's top-left corner.
    np.testing.assert_allclose(mesh.attributes.uv[:4], [[0, 1], [1, 1], [1, 0], [0, 0]])
    assert mesh.attributes.uv_faces is mesh.faces


def test_gltf_colours_ids_and_texture_coordinates_are_kept_a_vertex():
    rgba = np.zeros((len(VERTICES), 4), dtype=np.uint8)
    rgba[:, 0], rgba[:, 3] = np.where(PAINTED, 255, 0), 128
    uv = np.column_stack([VERTICES[:, 0], VERTICES[:, 1]]).astype("<f4") / 200 + 0.5
    feature = PAINTED.astype("<u2") + 3
    data = glb_with(
        {
            "COLOR_0": (rgba, 5121, "VEC4", True),
            "TEXCOORD_0": (uv, 5126, "VEC2", False),
            "_FEATURE_ID_0": (feature, 5123, "SCALAR", False),
            "NORMAL": (np.zeros((len(VERTICES), 3), "<f4"), 5126, "VEC3", False),
        }
    )
    mesh = read_mesh(data, "glb", LIMITS)
    attributes = mesh.attributes
    np.testing.assert_allclose(attributes.colors[:, 0], PAINTED.astype(float))
    np.testing.assert_allclose(attributes.colors[:, 3], 128 / 255, atol=1e-7)
    np.testing.assert_allclose(attributes.uv, uv, atol=1e-7)
    np.testing.assert_array_equal(attributes.vertex["_FEATURE_ID_0"], feature)
    assert set(attributes.vertex) == {"_FEATURE_ID_0"}  # NORMAL is not an id


@pytest.mark.parametrize("chunk", [5, 37, 1 << 18])
def test_obj_colours_and_texture_references_read_alike_in_any_chunks(chunk):
    lines = [
        "v 0 0 0 1 0 0",
        "v 1 0 0 0 255 0",  # a writer of 0 to 255 (any number above 1 says so)
        "v 1 1 0",
        "v 0 1 0 0.5 0.5 0.5",
        "vt 0 0",
        "vt 1 0",
        "vt 1 1 0",
        "vt 0.25",
        "f 1/1/1 2/2/1 3/3/1 4/4/1",
        "f 1//1 3//1 4//1",
        "f -4/-4 -3/-3 -2/-2",
        "f 1 2 3",
    ]
    mesh = read_in_chunks(("\n".join(lines) + "\n").encode(), "obj", chunk)
    attributes = mesh.attributes
    np.testing.assert_array_equal(
        mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 2, 3], [0, 1, 2], [0, 1, 2]]
    )
    np.testing.assert_allclose(attributes.uv, [[0, 1], [1, 1], [1, 0], [0.25, 1]])
    np.testing.assert_array_equal(
        attributes.uv_faces, [[0, 1, 2], [0, 2, 3], [-1, -1, -1], [0, 1, 2], [-1, -1, -1]]
    )
    np.testing.assert_allclose(
        attributes.colors[:, :3],
        [[1 / 255, 0, 0], [0, 1, 0], [1, 1, 1], [0.5 / 255, 0.5 / 255, 0.5 / 255]],
        atol=1e-7,
    )


def test_an_obj_reference_to_a_missing_texture_coordinate_names_the_line():
    text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/2\n"
    with pytest.raises(ValueError, match="line 5 refers to texture coordinate 2"):
        read_mesh(text, "obj", LIMITS)


# -- regions through the API ------------------------------------------------------------------


@pytest.mark.parametrize(("rule", "need"), [("all", 3), ("majority", 2), ("any", 1)])
async def test_a_vertex_colour_region_is_the_faces_painted_by_the_rule(client, rule, need):
    red = np.where(PAINTED, 255, 0).astype(np.uint8)
    data = ply_with({"red": ("uchar", red), "green": ("uchar", red), "blue": ("uchar", red)})
    region = {"vertex_color": {"channel": "r", "min": 0.5, "rule": rule}}
    assert await selected(client, data, "painted.ply", region) == expected_faces(PAINTED, need)
    region = {"vertex_color": {"channel": "luminance", "min": 0.99, "rule": rule}}
    assert await selected(client, data, "painted.ply", region) == expected_faces(PAINTED, need)


async def test_gltf_and_obj_colours_select_alike(client):
    colors = np.where(PAINTED[:, None], [255, 0, 0, 255], [0, 0, 255, 255]).astype(np.uint8)
    mesh = trimesh.Trimesh(VERTICES, FACES, vertex_colors=colors, process=False)
    region = {"vertex_color": {"channel": "b", "min": 0.5}}
    want = expected_faces(~PAINTED)
    assert await selected(client, mesh.export(file_type="glb"), "head.glb", region) == want
    lines = [
        f"v {x!r} {y!r} {z!r} {r / 255} {g / 255} {b / 255}"
        for (x, y, z), (r, g, b, _) in zip(VERTICES.tolist(), colors.tolist(), strict=True)
    ]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in FACES]
    assert await selected(client, "\n".join(lines).encode(), "head.obj", region) == want


async def test_feature_ids_of_vertices_and_of_faces(client):
    segment = np.where(PAINTED[FACES].all(axis=1), 5, 2).astype(np.int32)
    data = ply_with({"label": ("int", PAINTED.astype(int) + 1)}, {"segment": ("int", segment)})
    by_vertex = {"feature_id": {"attribute": "label", "values": [2]}}
    assert await selected(client, data, "ids.ply", by_vertex) == expected_faces(PAINTED)
    by_face = {"feature_id": {"attribute": "segment", "values": [5, 9]}}
    assert await selected(client, data, "ids.ply", by_face) == np.flatnonzero(segment == 5).tolist()
    feature = (PAINTED.astype("<u2") + 3,)
    glb = glb_with({"_FEATURE_ID_0": (*feature, 5123, "SCALAR", False)})
    gltf_ids = {"feature_id": {"values": [4], "rule": "any"}}
    assert await selected(client, glb, "ids.glb", gltf_ids) == expected_faces(PAINTED, 1)


def mask_png(mask: np.ndarray, mode: str = "L") -> bytes:
    image = Image.fromarray((mask * 255).astype(np.uint8), "L").convert(mode)
    out = io.BytesIO()
    image.save(out, format="PNG")
    return out.getvalue()


def textured_obj(uv: np.ndarray) -> bytes:
    """fsaverage as an OBJ whose vertex i has the texture coordinates uv[i] (OBJ's v up)."""
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in VERTICES.tolist()]
    lines += [f"vt {u!r} {v!r}" for u, v in uv.tolist()]
    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in (FACES + 1).tolist()]
    return ("\n".join(lines) + "\n").encode()


@pytest.mark.parametrize("mode", ["L", "RGB", "RGBA"])
async def test_a_texture_mask_selects_the_faces_whose_mean_passes(client, mode):
    # Texture coordinates from x and y (the head seen from above); the mask's left half
    # white: a face is in when its mean over its texture triangle is at least 0.5.
    uv = np.column_stack([VERTICES[:, 0], VERTICES[:, 1]]) / 260 + 0.5  # all on the image
    mask = np.zeros((256, 256))
    mask[:, :128] = 1.0
    files = {"mask": ("mask.png", mask_png(mask, mode))}
    region = {"texture_mask": {"min": 0.5}}
    got = set(await selected(client, textured_obj(uv), "head.obj", region, files))
    u = uv[FACES][:, :, 0]
    edge = 2 / 256  # within two pixels of the line, a small face's samples blend the halves
    assert set(np.flatnonzero((u < 0.5 - edge).all(axis=1))) <= got  # on the white half
    assert not got & set(np.flatnonzero((u > 0.5 + edge).all(axis=1)))  # on the black half
    # Faces across the line: in when more than half their texture area is on the white.
    corners = uv[FACES] * 256
    across = np.flatnonzero((u < 0.5).any(axis=1) & (u > 0.5).any(axis=1))
    for face in across:
        a, b, c = corners[face]
        samples = np.random.default_rng(face).dirichlet([1, 1, 1], 4000) @ np.stack([a, b, c])
        share = float(np.mean(samples[:, 0] < 128))
        if abs(share - 0.5) > 0.1:
            assert (face in got) == (share > 0.5), (face, share)


async def test_painted_regions_refuse_what_the_file_lacks(client):
    plain = SAMPLES[NAME].path.read_bytes()

    async def refused(region, data=plain, name=NAME, files=None, field=None):
        form = {"mesh": (name, data), **(files or {})}
        params = json.dumps({"region": region})
        return problem(
            await client.post("/v1/flatten", files=form, data={"params": params}), 422, field
        )

    body = await refused({"vertex_color": {"channel": "r"}}, field="params.region.vertex_color")
    assert "no vertex colours" in body["detail"]
    data = ply_with({"label": ("int", PAINTED)})
    body = await refused({"feature_id": {"attribute": "part", "values": [1]}}, data, "x.ply")
    assert "no attribute 'part'" in body["detail"] and "'label'" in body["detail"]
    body = await refused({"feature_id": {"attribute": "label", "values": [7]}}, data, "x.ply")
    assert "holds 0, 1" in body["detail"]
    for huge in (10**400, -(2**53) - 1):  # beyond what a double holds exactly
        region = {"feature_id": {"attribute": "label", "values": [0, huge]}}
        body = await refused(region, data, "x.ply", field="params.region.feature_id.values.1")
        assert "9007199254740992" in body["detail"]
    red = ply_with({"red": ("uchar", np.zeros(len(VERTICES), np.uint8))})
    body = await refused({"vertex_color": {"channel": "r", "min": 0.2}}, red, "x.ply")
    assert "runs from 0 to 0" in body["detail"]
    files = {"mask": ("mask.png", mask_png(np.ones((8, 8))))}
    body = await refused({"texture_mask": {}}, files=files)
    assert "no texture coordinates" in body["detail"]
    uv = np.full((len(VERTICES), 2), 0.5)
    body = await refused({"texture_mask": {}}, textured_obj(uv), "x.obj", field="mask")
    assert "needs the mask" in body["detail"]
    files = {"mask": ("mask.png", b"not a png")}
    body = await refused({"texture_mask": {}}, textured_obj(uv), "x.obj", files, "mask")
    assert "not a readable PNG" in body["detail"]
    unused = {"mask": ("mask.png", mask_png(np.ones((8, 8))))}
    cone = {"cone": {"axis": [0, 0, 1], "half_angle_deg": 60}}
    body = await refused(cone, files=unused, field="mask")
    assert "region.texture_mask only" in body["detail"]


def test_the_command_line_sends_the_mask_part(tmp_path):
    from service.cli import main

    uv = np.column_stack([VERTICES[:, 0], VERTICES[:, 1]]) / 260 + 0.5
    mesh, mask, out = tmp_path / "head.obj", tmp_path / "mask.png", tmp_path / "region.json"
    mesh.write_bytes(textured_obj(uv))
    left = np.zeros((64, 64))
    left[:, :32] = 1.0
    mask.write_bytes(mask_png(left))
    params = json.dumps({"region": {"texture_mask": {"min": 0.5}}, "center": "bbox_center"})
    assert (
        main(["flatten", str(mesh), "--params", params, "--mask", str(mask), "--out", str(out)])
        == 0
    )
    faces = json.loads(out.read_text())["faces"]["ids"]
    u = uv[FACES][:, :, 0]
    assert set(np.flatnonzero((u < 0.45).all(axis=1))) <= set(faces)
    assert not set(faces) & set(np.flatnonzero((u > 0.55).all(axis=1)))


async def test_texture_coordinates_that_are_not_numbers_leave_their_faces_out(client):
    uv = np.column_stack([VERTICES[:, 0], VERTICES[:, 1]]) / 260 + 0.5
    uv[:50] = np.nan  # a writer's NaN: those vertices' faces have no texture coordinates
    files = {"mask": ("mask.png", mask_png(np.ones((16, 16))))}
    got = await selected(client, textured_obj(uv), "head.obj", {"texture_mask": {}}, files)
    touched = set(np.flatnonzero((FACES < 50).any(axis=1)))
    assert got and not touched & set(got)


async def test_a_part_that_should_not_have_been_sent_is_refused_before_it_is_decoded(client):
    """Whether a PNG part is wanted is judged before its pixels are decoded or charged: a
    large mask beside a cone region, a mis-sized image beside values, a density map without
    its range get the refusal that says so, not a size or memory one."""
    huge = {"mask": ("mask.png", mask_png(np.zeros((8000, 8000))))}
    cone = json.dumps({"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 60}}})
    form = {"mesh": (NAME, SAMPLES[NAME].path.read_bytes())}
    answer = await client.post("/v1/flatten", files=form | huge, data={"params": cone})
    assert "region.texture_mask only" in problem(answer, 422, "mask")["detail"]
    small = {"image": ("map.png", mask_png(np.zeros((20, 10))))}
    values = json.dumps({"values": [0.0] * len(VERTICES)})
    answer = await client.post("/v1/transfer", files=form | small, data={"params": values})
    assert "not both" in problem(answer, 422, "image")["detail"]
    density = {"density_map": ("d.png", mask_png(np.zeros((20, 10))))}
    no_range = json.dumps({"density_per_cm2": 5, "units": "mm"})
    answer = await client.post("/v1/sites", files=form | density, data={"params": no_range})
    assert "needs params.density_range" in problem(answer, 422, "density_map")["detail"]
    no_units = json.dumps({"density_range": [0, 10]})
    answer = await client.post("/v1/sites", files=form | density, data={"params": no_units})
    assert "length unit" in problem(answer, 422, "params.units")["detail"]
