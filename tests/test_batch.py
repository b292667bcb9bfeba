"""``meshflat batch``: a manifest of scans answered as the API answers them, resumable, each
failure on its own, sharded over pods; a bad manifest line is named by its number."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import pytest

from service import batch as batch_module
from service.batch import DIGEST_FILE, ERROR_FILE, SCANS_FAILED, available_cpus, process
from service.capabilities import MESH_COMMANDS
from service.cli import main
from service.samples import SAMPLES

from .corpus import cases
from .test_api import flatten, problem
from .test_cli import NAME, PARAMS
from .test_privacy import watched_writes

#: The forms a flatten answers in (the manifest's outputs name them by extension).
FLATTEN = MESH_COMMANDS["flatten"]

pytestmark = pytest.mark.anyio

BAD_MESH = next(case for case in cases() if case.name == "OBJ face past the vertex list")


def write_manifest(folder: Path, lines: list) -> Path:
    """A manifest of ``lines`` (objects as JSON, strings as they are) in ``folder``."""
    path = folder / "manifest.jsonl"
    text = [line if isinstance(line, str) else json.dumps(line) for line in lines]
    path.write_text("\n".join(text) + "\n")
    return path


def scalp(outputs=("map.json",)) -> dict:
    """A manifest line for the bundled scalp (its folder: the file's name, unless named)."""
    return {"mesh": SAMPLES[NAME].path.as_posix(), "params": PARAMS, "outputs": list(outputs)}


#: The bundled scans' folder: the manifests of these tests name the scalp there.
SAMPLES_ROOT = SAMPLES[NAME].path.parent


def batch(manifest: Path, out: Path, *options) -> int:
    """``meshflat batch``, the bundled scans' folder allowed beside the manifest's."""
    allowed = ["--allow-root", str(SAMPLES_ROOT)]
    return main(["batch", str(manifest), "--out", str(out), *allowed, *map(str, options)])


def logged(capsys) -> list[dict]:
    """The JSON lines the last runs wrote on stderr (progress bars are off: not a terminal)."""
    return [json.loads(line) for line in capsys.readouterr().err.splitlines() if line]


def by_scan(lines: list[dict]) -> dict[str, str]:
    return {line["scan"]: line["message"].split(":")[0] for line in lines if "scan" in line}


async def test_outputs_are_the_api_answers_byte_for_byte(client, tmp_path):
    forms = [f"map.{output.value}" for output in FLATTEN.outputs]
    manifest = write_manifest(
        tmp_path,
        [
            {"mesh": str(SAMPLES[NAME].path), "params": PARAMS, "outputs": forms, "name": "s"},
            {"mesh": str(SAMPLES[NAME].path), "params": PARAMS, "outputs": ["v.json"],
             "command": "validate", "name": "v"},
        ],
    )  # fmt: skip
    assert batch(manifest, tmp_path / "out", "--processes", 1) == 0
    for name in forms:
        output = Path(name).suffix[1:]
        response = await flatten(client, NAME, {**PARAMS, "output": output})
        assert response.status_code == 200
        assert (tmp_path / "out" / "s" / name).read_bytes() == response.content, name
    response = await flatten(client, NAME, PARAMS, endpoint="/v1/validate")
    assert (tmp_path / "out" / "v" / "v.json").read_bytes() == response.content
    # Only the outputs asked for, and the digest: nothing partial is left behind.
    assert sorted(p.name for p in (tmp_path / "out" / "s").iterdir()) == sorted(
        [*forms, DIGEST_FILE]
    )


async def test_strands_in_a_batch_are_the_api_answers_byte_for_byte(client, tmp_path):
    mapped = (await flatten(client, NAME, PARAMS)).json()["vertices"]
    x, y = (np.array(mapped[axis]) for axis in "xy")
    whorl = {"x": float(x.mean()), "y": float(y.mean()), "turn": "clockwise"}
    params = {**PARAMS, "units": "mm", "density_per_cm2": 0.5, "seed": 3, "length_mm": 30,
              "growth": {"whorls": [whorl]}}  # fmt: skip
    forms = ["hair.usda", "hair.json", "hair.ply", "hair.glb"]
    line = {"mesh": str(SAMPLES[NAME].path), "command": "strands", "params": params}
    manifest = write_manifest(tmp_path, [{**line, "outputs": forms, "name": "s"}])
    assert batch(manifest, tmp_path / "out", "--processes", 1) == 0
    for name in forms:
        output = "usd" if name.endswith(".usda") else Path(name).suffix[1:]
        response = await flatten(client, NAME, {**params, "output": output},
                                 endpoint="/v1/strands")  # fmt: skip
        assert response.status_code == 200, response.text
        assert (tmp_path / "out" / "s" / name).read_bytes() == response.content, name


def test_a_rerun_skips_what_is_done_and_redoes_what_changed(tmp_path, capsys):
    scans = tmp_path / "scans"
    scans.mkdir()
    for name in ("a", "b", "c"):
        shutil.copy(SAMPLES[NAME].path, scans / f"{name}.ply")
    lines = [
        {"mesh": f"scans/{name}.ply", "params": PARAMS, "outputs": ["map.json", "map.png"]}
        for name in ("a", "b", "c")
    ]
    manifest = write_manifest(tmp_path, lines)
    out = tmp_path / "out"
    assert batch(manifest, out, "--processes", 1) == 0
    assert by_scan(logged(capsys)) == {"a": "scan done", "b": "scan done", "c": "scan done"}
    written = (out / "a" / "map.json").stat().st_mtime_ns

    assert batch(manifest, out, "--processes", 1) == 0
    assert set(by_scan(logged(capsys)).values()) == {"scan skipped"}
    assert (out / "a" / "map.json").stat().st_mtime_ns == written

    # A changed mesh (one more comment in its header), changed params, a lost output: each
    # of those scans alone is computed again.
    ply = (scans / "a.ply").read_bytes()
    (scans / "a.ply").write_bytes(ply.replace(b"\n", b"\ncomment touched\n", 1))
    lines[1]["params"] = {**PARAMS, "sigma": 0.25}
    manifest = write_manifest(tmp_path, lines)
    (out / "c" / "map.png").unlink()
    assert batch(manifest, out, "--processes", 1) == 0
    assert by_scan(logged(capsys)) == {"a": "scan done", "b": "scan done", "c": "scan done"}

    # An output altered after the run does not pass for done.
    (out / "b" / "map.json").write_bytes(b"{}")
    assert batch(manifest, out, "--processes", 1) == 0
    assert by_scan(logged(capsys)) == {"a": "scan skipped", "b": "scan done", "c": "scan skipped"}
    assert json.loads((out / "b" / "map.json").read_bytes())["params"]["sigma"] == 0.25


async def test_one_bad_scan_fails_alone_with_the_api_message(client, tmp_path, capsys):
    filename, data = BAD_MESH.mesh
    (tmp_path / filename).write_bytes(data)
    manifest = write_manifest(
        tmp_path,
        [
            {**scalp(), "name": "first"},
            {"mesh": filename, "outputs": ["map.json"], "name": "broken"},
            {**scalp(), "name": "last"},
        ],
    )
    out = tmp_path / "out"
    assert batch(manifest, out, "--processes", 2) == SCANS_FAILED
    lines = logged(capsys)
    assert by_scan(lines) == {"first": "scan done", "broken": "scan failed", "last": "scan done"}
    assert (out / "first" / DIGEST_FILE).exists() and (out / "last" / DIGEST_FILE).exists()

    answer = problem(await flatten(client, NAME, data=data, filename=filename), 422, "mesh")
    error = json.loads((out / "broken" / ERROR_FILE).read_bytes())
    # The API's problem, but for its detail: a reader's kind and position, never its words
    # (they may quote the file).
    assert {key: error[key] for key in answer if key != "detail"} == {
        key: answer[key] for key in answer if key != "detail"
    }
    assert error["detail"].startswith("mesh: not a readable mesh (MeshFormatError at line 7")
    assert (error["line"], error["scan"]) == (2, "broken")
    failed = next(line for line in lines if line.get("scan") == "broken")
    assert (failed["level"], failed["line"], failed["detail"]) == ("error", 2, error["detail"])
    summary = lines[-1]
    assert [summary[key] for key in ("message", "done", "skipped", "failed")] == [
        "batch finished",
        2,
        0,
        1,
    ]
    assert (
        not (out / "broken" / "map.json").exists() and not (out / "broken" / DIGEST_FILE).exists()
    )
    # Nothing of the mesh in the logs.
    stderr = "\n".join(json.dumps(line) for line in lines)
    assert not any(row in stderr for row in data.decode().splitlines() if row.strip())

    # A rerun retries the failure and skips the rest.
    assert batch(manifest, out, "--processes", 1) == SCANS_FAILED
    assert by_scan(logged(capsys)) == {
        "first": "scan skipped",
        "broken": "scan failed",
        "last": "scan skipped",
    }


async def test_only_the_outputs_asked_for_and_the_records_reach_the_disk(tmp_path):
    filename, data = BAD_MESH.mesh
    (tmp_path / filename).write_bytes(data)
    forms = [f"map.{output.value}" for output in FLATTEN.outputs]
    manifest = write_manifest(
        tmp_path, [{**scalp(forms), "name": "s"}, {"mesh": filename, "outputs": ["map.json"]}]
    )
    out = tmp_path / "out"

    async def run():
        assert batch(manifest, out, "--processes", 1) == SCANS_FAILED

    writes = await watched_writes(run)
    finals = [out / "s" / name for name in (*forms, DIGEST_FILE)] + [out / "a" / ERROR_FILE]
    allowed = {*finals, *(path.with_name(f".{path.name}.partial") for path in finals)}
    # A scan's files are opened by name in its folder (opened itself without following a
    # link); an opened descriptor's file object shows as its number.
    opened = {str(path) for event, path in writes if event == "open" and not isinstance(path, int)}
    assert opened and opened <= {path.name for path in allowed}, opened
    made = {str(path) for event, path in writes if event == "os.mkdir"}
    assert made <= {str(out), "s", "a"}


def test_an_unreadable_mesh_fails_its_scan_only(tmp_path, capsys):
    manifest = write_manifest(
        tmp_path, [{"mesh": "missing.obj", "outputs": ["m.json"]}, {**scalp(), "name": "ok"}]
    )
    assert batch(manifest, tmp_path / "out", "--processes", 1) == SCANS_FAILED
    lines = logged(capsys)
    assert by_scan(lines) == {"missing": "scan failed", "ok": "scan done"}
    error = json.loads((tmp_path / "out" / "missing" / ERROR_FILE).read_bytes())
    assert error["field"] == "mesh" and "cannot read" in error["detail"]


def test_a_folder_that_cannot_be_written_fails_its_scan_only(tmp_path, capsys):
    manifest = write_manifest(tmp_path, [{**scalp(), "name": name} for name in ("a", "b")])
    out = tmp_path / "out"
    out.mkdir()
    (out / "a").write_text("a file where the scan's folder would go")
    assert batch(manifest, out, "--processes", 1) == SCANS_FAILED
    lines = logged(capsys)
    assert by_scan(lines) == {"a": "scan failed", "b": "scan done"}
    failed = next(line for line in lines if line.get("scan") == "a")
    assert "cannot write in" in failed["detail"] and str(out / "a") in failed["detail"]

    assert batch(manifest, out / "a" / "below", "--processes", 1) == 2
    assert "--out" in capsys.readouterr().err


def test_shards_partition_the_scans(tmp_path, capsys, monkeypatch):
    names = [f"s{i}" for i in range(7)]
    line = {**scalp(), "command": "validate"}
    manifest = write_manifest(tmp_path, [{**line, "name": name} for name in names])
    seen = []
    for index in range(3):
        options = ["--shard-count", 3, "--shard-index", index, "--processes", 1]
        assert batch(manifest, tmp_path / "out", *options) == 0
        seen.append(set(by_scan(logged(capsys))))
    assert seen == [{"s0", "s3", "s6"}, {"s1", "s4"}, {"s2", "s5"}]
    assert {p.name for p in (tmp_path / "out").iterdir()} == set(names)

    # In an Indexed Job the index is Kubernetes's JOB_COMPLETION_INDEX.
    monkeypatch.setenv("JOB_COMPLETION_INDEX", "1")
    assert batch(manifest, tmp_path / "again", "--shard-count", 3, "--processes", 1) == 0
    assert set(by_scan(logged(capsys))) == {"s1", "s4"}


@pytest.mark.parametrize(
    ("options", "words"),
    [
        (["--shard-index", "0"], ["--shard-index", "--shard-count"]),
        (["--shard-count", "2"], ["JOB_COMPLETION_INDEX"]),
        (["--shard-count", "2", "--shard-index", "2"], ["2", "[0, 2)"]),
    ],
)
def test_shard_options_are_checked(tmp_path, capsys, monkeypatch, options, words):
    monkeypatch.delenv("JOB_COMPLETION_INDEX", raising=False)
    manifest = write_manifest(tmp_path, [scalp()])
    assert batch(manifest, tmp_path / "out", *options) == 2
    said = capsys.readouterr().err
    assert all(word in said for word in words), said


@pytest.mark.parametrize(
    ("cpu_max", "cpus"), [("max 100000", 4), ("150000 100000", 2), ("50000 100000", 1)]
)
def test_the_default_processes_keep_within_a_containers_cpu_limit(monkeypatch, cpu_max, cpus):
    # In a container the affinity counts the node's cores; the CPU limit is the cgroup's quota.
    real_read_text = Path.read_text

    def read_text(path, *args, **kwargs):
        if str(path) == "/sys/fs/cgroup/cpu.max":
            return cpu_max + "\n"
        return real_read_text(path, *args, **kwargs)

    monkeypatch.setattr(Path, "read_text", read_text)
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(4)))
    assert available_cpus() == cpus


LINE = {"mesh": "head.ply", "outputs": ["map.json"]}


@pytest.mark.parametrize(
    ("line", "words"),
    [
        ("{not json", ["not JSON"]),
        ("[1, 2]", ["not a JSON object"]),
        ({"outputs": ["map.json"]}, ["mesh", "each line needs"]),
        ({"mesh": "head.ply"}, ["outputs", "list of file names"]),
        (
            {**LINE, "outputs": ["map.jpeg"]},
            ["outputs", "'map.jpeg'", ".json, .glb, .svg, .png or .arrow"],
        ),
        ({**LINE, "command": "locate", "params": {"theta": [1], "phi": [0]},
          "outputs": ["hits.png"]}, ["outputs", "use .json"]),
        ({**LINE, "outputs": ["../map.json"]}, ["outputs", "not a plain file name"]),
        ({**LINE, "outputs": ["digest.json"]}, ["outputs", "digest.json"]),
        ({**LINE, "outputs": ["a.json", "a.json"]}, ["outputs", "twice"]),
        ({**LINE, "name": "../up"}, ["name", "cannot name a folder"]),
        ({**LINE, "mesh": "head.fbx"}, ["mesh", "format"]),
        ({**LINE, "params": {"sigma": -1}}, ["params.sigma"]),
        ({**LINE, "params": {"output": "png"}}, ["params.output", "extensions"]),
        ({**LINE, "params": [1]}, ["params", "JSON object"]),
        ({**LINE, "command": "serve"}, ["command", "flatten, validate, fit, locate"]),
        ({**LINE, "command": "register", "params": {"units": "mm"}},
         ["command", "second mesh (follow_up)"]),
        ({**LINE, "outptus": []}, ["outptus", "not a key"]),
        ('{"mesh": "a.ply", "outputs": ["m.json"], "params": {"sigma": 0.3, "sigma": 0.5}}',
         ["params.sigma", "more than once"]),
    ],
)  # fmt: skip
def test_a_bad_line_is_named_by_its_number_and_nothing_runs(tmp_path, capsys, line, words):
    manifest = write_manifest(tmp_path, [{**LINE, "name": "first"}, "", line])
    assert batch(manifest, tmp_path / "out") == 2
    said = capsys.readouterr().err
    assert "manifest.jsonl: line 3: " in said, said
    assert all(word in said for word in words), said
    assert not (tmp_path / "out").exists()


def test_every_bad_line_is_listed_and_names_are_unique(tmp_path, capsys):
    manifest = write_manifest(tmp_path, [LINE, "{", LINE, {"mesh": "x.obj"}])
    assert batch(manifest, tmp_path / "out") == 2
    said = capsys.readouterr().err
    assert "line 2: not JSON" in said and "line 4: outputs" in said
    assert "line 3: name: 'head' is also line 1's folder" in said


def test_an_empty_or_missing_manifest_is_refused(tmp_path, capsys):
    assert batch(write_manifest(tmp_path, [""]), tmp_path / "out") == 2
    assert "no scans" in capsys.readouterr().err
    assert batch(tmp_path / "nothing.jsonl", tmp_path / "out") == 2
    assert "cannot read" in capsys.readouterr().err


@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_the_installed_command_runs_scans_in_processes(tmp_path):
    manifest = write_manifest(
        tmp_path,
        [{**scalp(["map.svg"]), "name": name} for name in ("one", "two", "three")],
    )
    command = Path(sys.executable).parent / "meshflat"
    options = ["--processes", "2", "--progress", "--allow-root", SAMPLES_ROOT]
    run = subprocess.run(
        [command, "batch", manifest, "--out", tmp_path / "out", *options],
        capture_output=True,
        text=True,
        timeout=300,
        # The tree under test (a worktree's, when the editable install is another's).
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])},
    )
    assert run.returncode == 0, run.stderr
    assert "3/3 done" in run.stderr  # the progress bar
    for name in ("one", "two", "three"):
        assert (tmp_path / "out" / name / "map.svg").read_bytes().startswith(b"<svg")
    summary = json.loads(run.stderr.rsplit("\n", 2)[-2].rpartition("\r")[2])
    assert summary["message"] == "batch finished" and summary["done"] == 3


def test_meshes_are_read_only_as_regular_files_inside_the_manifests_folder(
    tmp_path, capsys, monkeypatch
):
    monkeypatch.setenv("MESHFLAT_MAX_UPLOAD_BYTES", "100000")
    here, secret = tmp_path / "here", tmp_path / "secret"
    here.mkdir()
    secret.mkdir()
    (secret / "hidden.obj").write_bytes(b"v 0 0 0\n")
    (here / "link.obj").symlink_to(secret / "hidden.obj")
    os.mkfifo(here / "pipe.obj")  # read in the main process, it would hang the batch
    (here / "huge.obj").write_bytes(b"v 0 0 0\n" * 20_000)  # 160 kB, beyond the limit
    refused = {
        "shadow": ("/etc/shadow", "outside"),
        "passwd": ("../../../../../../etc/passwd", "outside"),
        "hidden": ("../secret/hidden.obj", "outside"),
        "link": ("link.obj", "outside"),
        "pipe": ("pipe.obj", "not a regular file"),
        "zero": ("/dev/zero", "not a regular file"),
        "huge": ("huge.obj", "larger than 100000 bytes"),
    }
    lines = [
        {"mesh": mesh, "params": {"format": "obj"}, "outputs": ["m.json"], "name": name}
        for name, (mesh, _) in refused.items()
    ]
    manifest = write_manifest(here, [*lines, {**scalp(), "name": "ok"}])
    out = tmp_path / "out"
    assert batch(manifest, out, "--processes", 1, "--allow-root", "/dev") == SCANS_FAILED
    assert by_scan(logged(capsys)) == {**dict.fromkeys(refused, "scan failed"), "ok": "scan done"}
    for name, (_, words) in refused.items():
        error = json.loads((out / name / ERROR_FILE).read_bytes())
        assert error["field"] == "mesh" and words in error["detail"], (name, error)
    assert json.loads((out / "huge" / ERROR_FILE).read_bytes())["status"] == 413


def test_outputs_are_never_written_through_a_symbolic_link(tmp_path, capsys):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "victim").write_text("untouched")
    out = tmp_path / "out"
    out.mkdir()
    (out / "linked").symlink_to(elsewhere)  # a scan's folder that is a link out of DIR
    (out / "planted").mkdir()
    (out / "planted" / f".{ERROR_FILE}.partial").symlink_to(elsewhere / "victim")
    manifest = write_manifest(
        tmp_path,
        [
            {"mesh": "missing.obj", "outputs": ["m.json"], "name": "linked"},
            {"mesh": "missing.obj", "outputs": ["m.json"], "name": "planted"},
            {**scalp(), "name": "ok"},
        ],
    )
    assert batch(manifest, out, "--processes", 1) == SCANS_FAILED
    lines = logged(capsys)
    assert by_scan(lines) == {"linked": "scan failed", "planted": "scan failed", "ok": "scan done"}
    linked = next(line for line in lines if line.get("scan") == "linked")
    assert "symbolic link" in linked["detail"]
    assert sorted(p.name for p in elsewhere.iterdir()) == ["victim"]
    assert (elsewhere / "victim").read_text() == "untouched"
    written = out / "planted" / ERROR_FILE
    assert not written.is_symlink() and json.loads(written.read_bytes())["scan"] == "planted"


def test_a_readers_refusal_is_told_by_kind_and_position_never_by_the_files_words(tmp_path, capsys):
    meshes = {
        "count.ply": b"ply\nformat ascii 1.0\nelement vertex SECRETCOUNT\nend_header\n",
        "element.ply": b"ply\nformat ascii 1.0\nelement MRN_12345678 1\nproperty float x\n"
        b"end_header\n1\n",
    }
    for filename, data in meshes.items():
        (tmp_path / filename).write_bytes(data)
    manifest = write_manifest(
        tmp_path, [{"mesh": filename, "outputs": ["m.json"]} for filename in meshes]
    )
    out = tmp_path / "out"
    assert batch(manifest, out, "--processes", 1) == SCANS_FAILED
    said = capsys.readouterr().err
    errors = {name: (out / name / ERROR_FILE).read_text() for name in ("count", "element")}
    for text in (said, *errors.values()):
        assert "SECRETCOUNT" not in text and "MRN_12345678" not in text, text
    count = json.loads(errors["count"])
    assert (count["status"], count["field"]) == (422, "mesh")
    assert "MeshFormatError at line 3" in count["detail"], count
    assert "not a readable mesh" in json.loads(errors["element"])["detail"]


def _killed_while_computing(scan, out, settings):
    """The batch's ``process`` in a worker that is killed (SIGKILL, as the kernel's OOM
    killer does) while computing ``dies-*`` scans: ``dies-once`` on its first attempt only."""
    died = scan.mesh.parent / f"{scan.name}.died"
    if scan.name == "dies-always" or (scan.name == "dies-once" and not died.exists()):
        died.write_text("")
        os.kill(os.getpid(), signal.SIGKILL)
    return process(scan, out, settings)


def test_a_worker_that_dies_fails_its_own_scan_alone_after_one_retry(tmp_path, capsys, monkeypatch):
    shutil.copy(SAMPLES[NAME].path, tmp_path / "scalp.ply")
    line = {"mesh": "scalp.ply", "params": PARAMS, "outputs": ["v.json"], "command": "validate"}
    names = ["a", "dies-once", "b", "dies-always", "c", "d"]
    manifest = write_manifest(tmp_path, [{**line, "name": name} for name in names])
    # The workers are forked from this process, so that they run the function above: the
    # test's own code kills them; the batch knows nothing of it.
    monkeypatch.setattr(batch_module, "_fresh_processes", lambda: get_context("fork"))
    monkeypatch.setattr(batch_module, "process", _killed_while_computing)
    out = tmp_path / "out"
    assert batch(manifest, out, "--processes", 2) == SCANS_FAILED
    lines = logged(capsys)
    assert by_scan(lines) == {
        **dict.fromkeys(names, "scan done"),
        "dies-once": "scan done",
        "dies-always": "scan failed",
    }
    again = [line["scan"] for line in lines if line["message"].startswith("scan's process died")]
    assert sorted(again) == ["dies-always", "dies-once"]
    error = json.loads((out / "dies-always" / ERROR_FILE).read_bytes())
    assert error["status"] == 500 and "died 2 times" in error["detail"]
    assert error["line"] == 4
    assert lines[-1]["done"] == 5 and lines[-1]["failed"] == 1


@pytest.mark.parametrize(
    ("line", "words"),
    [
        ({**LINE, "params": {"region": {"texture_mask": {}}}},
         ["params.region.texture_mask", "mask", "--mask"]),
        ({**LINE, "command": "measure", "params": {"region": {"texture_mask": {}}}},
         ["params.region.texture_mask", "measure"]),
        ({**LINE, "command": "sites", "params": {"density_range": [10, 40]}},
         ["params.density_range", "density_map", "--density-map"]),
        ({**LINE, "command": "strands", "params": {"density_per_cm2": 1, "length_range": [10, 40]}},
         ["params.length_range", "length_map", "--length-map"]),
        ({**LINE, "command": "transfer"}, ["params.values", "image", "--image"]),
        ({**LINE, "command": "transfer", "params": {"values": "x"}, "outputs": ["ids.face_ids"]},
         ["outputs", "'ids.face_ids'", "look-up"]),
    ],
)  # fmt: skip
def test_a_line_that_needs_a_part_the_batch_cannot_give_is_refused(tmp_path, capsys, line, words):
    manifest = write_manifest(tmp_path, [{**LINE, "name": "first"}, line])
    assert batch(manifest, tmp_path / "out") == 2
    said = capsys.readouterr().err
    assert "manifest.jsonl: line 2: " in said, said
    assert all(word in said for word in words), said
    assert not (tmp_path / "out").exists()


def test_a_refusal_that_names_what_the_file_has_keeps_those_names_out(tmp_path, capsys):
    ply = (
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        b"property float z\nproperty int MRN_12345678\nelement face 1\n"
        b"property list uchar int vertex_indices\nend_header\n"
        b"0 0 0 1\n1 0 0 1\n0 1 0 1\n3 0 1 2\n"
    )
    (tmp_path / "props.ply").write_bytes(ply)
    (tmp_path / "groups.obj").write_bytes(b"g patient-7f3a9c\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    feature = {"feature_id": {"attribute": "quality", "values": [1]}}
    manifest = write_manifest(
        tmp_path,
        [
            {"mesh": "props.ply", "params": {"region": feature}, "outputs": ["m.json"]},
            {
                "mesh": "groups.obj",
                "params": {"region": {"groups": ["nope"]}},
                "outputs": ["m.json"],
            },
        ],
    )
    out = tmp_path / "out"
    assert batch(manifest, out, "--processes", 1) == SCANS_FAILED
    said = capsys.readouterr().err
    errors = {name: (out / name / ERROR_FILE).read_text() for name in ("props", "groups")}
    for text in (said, *errors.values()):
        assert "MRN_12345678" not in text and "patient-7f3a9c" not in text, text
    # What the line said is still named; what the file has is shown as '…'.
    assert "'quality'" in json.loads(errors["props"])["detail"]
    assert "'nope'" in json.loads(errors["groups"])["detail"]
    assert "'…'" in json.loads(errors["groups"])["detail"]
