"""The ``meshflat`` command: the API's answers and messages, from a shell."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from service.cli import main
from service.samples import SAMPLES

from .test_api import flatten, problem

pytestmark = pytest.mark.anyio

NAME = "fsaverage-head.ply"
ARGS = ["--region-cone", "0,0,1:70", "--pole", "0,0,-1", "--up", "0,1,0", "--sigma", "0.3"]
PARAMS = {
    "region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}},
    "rotation": {"pole": [0, 0, -1], "up": [0, 1, 0]},
    "sigma": 0.3,
}


def cli(*args: str) -> int:
    return main([str(a) for a in args])


@pytest.mark.parametrize("suffix", ["json", "glb", "svg", "png", "arrow"])
async def test_flatten_writes_what_the_api_answers(client, tmp_path, suffix):
    out = tmp_path / f"region.{suffix}"
    assert cli("flatten", SAMPLES[NAME].path, *ARGS, "--out", out) == 0
    response = await flatten(client, NAME, {**PARAMS, "output": suffix})
    assert response.status_code == 200
    if suffix == "json":
        assert json.loads(out.read_bytes()) == response.json()
    else:
        assert out.read_bytes() == response.content


@pytest.mark.parametrize("command", ["validate", "fit"])
async def test_validate_and_fit_print_the_api_json(client, capsys, command):
    assert cli(command, SAMPLES[NAME].path, "--region-cone", "0,0,1:70") == 0
    printed = json.loads(capsys.readouterr().out)
    params = {"region": PARAMS["region"]}
    response = await flatten(client, NAME, params, endpoint=f"/v1/{command}")
    assert printed == response.json()
    assert ("explain" in printed) == (command == "fit")


async def test_facing_on_the_command_line_is_the_api_facing(client, capsys):
    assert cli("fit", SAMPLES[NAME].path, "--region-cone", "0,0,1:70", "--facing", "0,1,0") == 0
    printed = json.loads(capsys.readouterr().out)
    params = {"region": PARAMS["region"], "facing": [0, 1, 0]}
    assert printed == (await flatten(client, NAME, params, endpoint="/v1/fit")).json()
    assert printed["params"]["facing"] == [0.0, 1.0, 0.0]


async def test_errors_are_the_api_messages_with_exit_status_2(client, capsys):
    assert cli("flatten", SAMPLES[NAME].path, "--region-cone", "0,0,1:70", "--sigma", "-1") == 2
    said = capsys.readouterr().err
    answer = problem(await flatten(client, NAME, {**PARAMS, "sigma": -1}), 422)
    assert answer["detail"] in said
    assert cli("flatten", SAMPLES[NAME].path, "--region-cone", "up:70") == 2
    assert "--region-cone" in capsys.readouterr().err
    assert cli("flatten", SAMPLES[NAME].path, "--out", "map.jpeg") == 2
    assert ".png" in capsys.readouterr().err
    assert cli("validate", Path("no-such-file.obj")) == 2
    assert "cannot read" in capsys.readouterr().err


@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_the_installed_command_runs(tmp_path):
    command = Path(sys.executable).parent / "meshflat"
    out = tmp_path / "map.svg"
    run = subprocess.run(
        [command, "flatten", SAMPLES[NAME].path, *ARGS, "--out", out, "--progress"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stderr
    assert "3/3 done" in run.stderr  # the progress bar
    assert out.read_bytes().startswith(b"<svg")
