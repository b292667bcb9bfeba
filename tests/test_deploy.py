"""The Dockerfile and the Kubernetes manifests: linted, validated against the Kubernetes
schemas offline, and consistent with the image and the service (user, port, probes, settings).
The image itself is built and run by deploy/container-smoke-test.sh (CI runs it)."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import kubernetes_validate
import pytest
import yaml

from service.app import create_app
from service.settings import Settings, container_memory_for, memory_budget_of

ROOT = Path(__file__).parent.parent
DOCKERFILE = ROOT / "Dockerfile"
MANIFESTS = sorted((ROOT / "deploy" / "kubernetes").glob("*.yaml"))
SMOKE_TEST = ROOT / "deploy" / "container-smoke-test.sh"
#: The oldest and the newest Kubernetes the manifests are checked against.
KUBERNETES = ("1.30.0", kubernetes_validate.latest_version())


def documents() -> list[dict]:
    return [doc for path in MANIFESTS for doc in yaml.safe_load_all(path.read_text()) if doc]


def deployment_container() -> tuple[dict, dict]:
    deployment = next(doc for doc in documents() if doc["kind"] == "Deployment")
    pod = deployment["spec"]["template"]["spec"]
    return pod, pod["containers"][0]


def test_dockerfile_is_hadolint_clean():
    hadolint = Path(sys.executable).parent / "hadolint"
    result = subprocess.run(
        [str(hadolint), "--failure-threshold", "info", str(DOCKERFILE)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_hadolint_does_find_faults(tmp_path):
    # The check above can fail: an unpinned base image and a root user are reported.
    bad = tmp_path / "Dockerfile"
    bad.write_text("FROM python\nRUN cd /tmp && pip install numpy\n")
    hadolint = Path(sys.executable).parent / "hadolint"
    result = subprocess.run([str(hadolint), str(bad)], capture_output=True, text=True)
    assert result.returncode != 0 and "DL3006" in result.stdout


@pytest.mark.parametrize("version", KUBERNETES)
def test_manifests_match_the_kubernetes_schemas(version):
    kinds = set()
    for doc in documents():
        kubernetes_validate.validate(doc, version, strict=True)
        kinds.add(doc["kind"])
    assert {"Deployment", "Service", "HorizontalPodAutoscaler"} <= kinds


def test_the_validator_refuses_a_wrong_manifest():
    deployment = next(doc for doc in documents() if doc["kind"] == "Deployment")
    container = deployment["spec"]["template"]["spec"]["containers"][0]
    container["readinessProbe"]["httpGet"]["paht"] = "/readyz"  # a typo: strict refuses it
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(deployment, KUBERNETES[1], strict=True)
    del container["readinessProbe"]["httpGet"]["paht"]
    container["resources"]["limits"]["memory"] = ["4Gi"]
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(deployment, KUBERNETES[1], strict=True)


def test_the_deployment_matches_the_image_and_the_service():
    dockerfile = DOCKERFILE.read_text()
    user = re.search(r"^USER (\d+):(\d+)$", dockerfile, re.M)
    port = re.search(r"MESHFLAT_PORT=(\d+)", dockerfile)
    assert user and port and re.search(rf"^EXPOSE {port[1]}$", dockerfile, re.M)
    assert int(user[1]) != 0

    pod, container = deployment_container()
    security = container["securityContext"]
    assert pod["securityContext"]["runAsUser"] == security["runAsUser"] == int(user[1])
    assert pod["securityContext"]["runAsGroup"] == security["runAsGroup"] == int(user[2])
    assert security["readOnlyRootFilesystem"] and security["runAsNonRoot"]
    assert not security["allowPrivilegeEscalation"]
    assert security["capabilities"]["drop"] == ["ALL"]
    assert container["ports"][0]["containerPort"] == int(port[1])
    assert {"/tmp"} <= {mount["mountPath"] for mount in container["volumeMounts"]}

    # Probes on routes the app has, which stay open when keys are configured.
    paths = set(create_app(Settings()).openapi()["paths"])
    assert container["livenessProbe"]["httpGet"]["path"] == "/healthz"
    assert container["readinessProbe"]["httpGet"]["path"] == "/readyz"
    assert container["startupProbe"]["httpGet"]["path"] in paths
    assert {"/healthz", "/readyz", "/metrics"} <= paths

    # Only settings the service reads; the keys come from the Secret mounted as a file.
    known = {f"MESHFLAT_{field.name.upper()}" for field in fields(Settings)}
    env = {item["name"]: item["value"] for item in container["env"]}
    assert set(env) <= known, set(env) - known
    Settings.from_env({k: v for k, v in env.items() if k != "MESHFLAT_API_KEYS_FILE"})
    secret = next(v for v in pod["volumes"] if "secret" in v)
    mount = next(m for m in container["volumeMounts"] if m["name"] == secret["name"])
    item = secret["secret"]["items"][0]
    assert env["MESHFLAT_API_KEYS_FILE"] == f"{mount['mountPath']}/{item['path']}"

    # The memory limit is the one at which the worker gets its budget (service.settings).
    workers, budget = int(env["MESHFLAT_WORKERS"]), int(env["MESHFLAT_MEMORY_BUDGET"])
    limit = container["resources"]["limits"]["memory"]
    assert limit == f"{math.ceil(container_memory_for(budget, workers) / 2**20)}Mi"
    assert memory_budget_of(int(limit.removesuffix("Mi")) * 2**20, workers) >= budget

    # Requests in progress get their time limit and the server's grace before the kill.
    grace = float(env["MESHFLAT_REQUEST_TIMEOUT"]) + 5
    assert pod["terminationGracePeriodSeconds"] > grace


def test_the_smoke_test_is_a_valid_script_named_in_the_readme_and_run_by_ci():
    subprocess.run(["bash", "-n", str(SMOKE_TEST)], check=True)
    name = "deploy/container-smoke-test.sh"
    assert name in (ROOT / "README.md").read_text()
    assert name in (ROOT / ".ci" / "run").read_text()
