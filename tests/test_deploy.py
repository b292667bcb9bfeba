"""The Dockerfile and the Kubernetes manifests: linted, validated against the Kubernetes
schemas offline (KEDA's ScaledObject against its CRD's), and consistent with the image and the
service (user, port, probes, settings, the metric and the command they name). The image itself
is built and run by deploy/container-smoke-test.sh (CI runs it)."""

from __future__ import annotations

import copy
import json
import math
import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import fields
from pathlib import Path

import jsonschema
import kubernetes_validate
import pytest
import yaml

from service.app import create_app
from service.batch import JOB_INDEX_VARIABLE, SCANS_FAILED
from service.cli import parser
from service.observability import JOBS_IN_FLIGHT
from service.settings import Settings, container_memory_for, memory_budget_of

ROOT = Path(__file__).parent.parent
DOCKERFILE = ROOT / "Dockerfile"
#: The service's manifests, and in folders of their own (applied on their own) KEDA's
#: ScaledObject and the batch's Indexed Job.
MANIFESTS = sorted((ROOT / "deploy" / "kubernetes").rglob("*.yaml"))
#: API groups of custom resources: no Kubernetes schema has them (their CRDs' schemas below).
CUSTOM_GROUPS = {"keda.sh"}
KEDA_SCHEMA = Path(__file__).parent / "schemas" / "keda-scaledobject.schema.json"
SMOKE_TEST = ROOT / "deploy" / "container-smoke-test.sh"
#: The oldest and the newest Kubernetes the manifests are checked against.
KUBERNETES = ("1.30.0", kubernetes_validate.latest_version())
#: Where running in production is documented: the names and commands the manifests and the
#: smoke test use must be the ones it gives.
OPERATIONS_DOC = ROOT / "docs" / "operations.md"


def operations_doc() -> str:
    return OPERATIONS_DOC.read_text()


def documents() -> list[dict]:
    return [doc for path in MANIFESTS for doc in yaml.safe_load_all(path.read_text()) if doc]


def document(kind: str) -> dict:
    return next(doc for doc in documents() if doc["kind"] == kind)


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
        if doc["apiVersion"].split("/")[0] in CUSTOM_GROUPS:
            continue
        kubernetes_validate.validate(doc, version, strict=True)
        kinds.add(doc["kind"])
    assert {"Deployment", "Service", "HorizontalPodAutoscaler", "Job"} <= kinds


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


def test_the_smoke_test_is_a_valid_script_named_in_the_docs_and_run_by_ci():
    subprocess.run(["bash", "-n", str(SMOKE_TEST)], check=True)
    name = "deploy/container-smoke-test.sh"
    assert name in operations_doc()
    assert name in (ROOT / ".ci" / "run").read_text()


# -- KEDA's ScaledObject ---------------------------------------------------------------------


def scaled_object_schema() -> dict:
    """KEDA's ScaledObject (keda.sh/v1alpha1) as JSON schema, from its CRD (where it comes
    from: the file's ``$comment``), made strict as kubernetes-validate's strict mode is: no
    field the CRD does not have."""
    schema = json.loads(KEDA_SCHEMA.read_text())
    for node in (schema, *schema["$defs"].values()):
        if "properties" in node:
            node.setdefault("additionalProperties", False)
    return schema


def test_the_scaled_object_matches_kedas_schema():
    scaled = document("ScaledObject")
    assert (scaled["apiVersion"], scaled["kind"]) == ("keda.sh/v1alpha1", "ScaledObject")
    jsonschema.Draft202012Validator(scaled_object_schema()).validate(scaled)


def test_the_keda_schema_refuses_a_wrong_scaled_object():
    validator = jsonschema.Draft202012Validator(scaled_object_schema())
    typo = copy.deepcopy(document("ScaledObject"))
    typo["spec"]["minReplicas"] = 2  # the HPA's name for minReplicaCount
    assert not validator.is_valid(typo)
    number = copy.deepcopy(document("ScaledObject"))
    number["spec"]["triggers"][0]["metadata"]["threshold"] = 2  # trigger metadata are strings
    assert not validator.is_valid(number)


def test_the_scaled_object_scales_the_deployment_on_its_jobs_in_flight():
    scaled, hpa = document("ScaledObject"), document("HorizontalPodAutoscaler")
    deployment = document("Deployment")
    assert scaled["spec"]["scaleTargetRef"] == hpa["spec"]["scaleTargetRef"]
    assert scaled["spec"]["scaleTargetRef"]["name"] == deployment["metadata"]["name"]
    assert scaled["spec"]["minReplicaCount"] == hpa["spec"]["minReplicas"]
    assert scaled["spec"]["maxReplicaCount"] == hpa["spec"]["maxReplicas"]
    triggers = {trigger["type"]: trigger for trigger in scaled["spec"]["triggers"]}

    # The gauge the service exports, summed over the pods the Deployment labels (as the pod
    # scrape job maps labels: app.kubernetes.io/name becomes app_kubernetes_io_name), one
    # pod's compute slots each.
    prometheus = triggers["prometheus"]
    query = re.fullmatch(r'sum\((\w+)\{(\w+)="([^"]+)"\}\)', prometheus["metadata"]["query"])
    assert query, prometheus["metadata"]["query"]
    assert query[1] == JOBS_IN_FLIGHT.describe()[0].name
    labels = deployment["spec"]["template"]["metadata"]["labels"]
    assert {re.sub(r"\W", "_", key): value for key, value in labels.items()}[query[2]] == query[3]
    _, container = deployment_container()
    env = {item["name"]: item["value"] for item in container["env"]}
    assert prometheus["metricType"] == "AverageValue"
    assert prometheus["metadata"]["threshold"] == env["MESHFLAT_MAX_JOBS"]

    # CPU as the HorizontalPodAutoscaler has it.
    target = hpa["spec"]["metrics"][0]["resource"]["target"]
    assert triggers["cpu"]["metricType"] == target["type"]
    assert triggers["cpu"]["metadata"]["value"] == str(target["averageUtilization"])


def test_the_keda_and_batch_manifests_are_not_applied_with_the_service():
    # `kubectl apply -f deploy/kubernetes/` (no -R) must neither start a batch nor put a
    # second autoscaler on the Deployment: they live in folders of their own.
    top = ROOT / "deploy" / "kubernetes"
    for path in MANIFESTS:
        kinds = {doc["kind"] for doc in yaml.safe_load_all(path.read_text()) if doc}
        apart = bool(kinds & {"ScaledObject", "Job"})
        assert (path.parent != top) == apart, path
    documented = operations_doc()
    assert "kubectl apply -f deploy/kubernetes/keda/" in documented
    assert "kubectl apply -f deploy/kubernetes/batch/" in documented


# -- the batch's Indexed Job -----------------------------------------------------------------


def test_the_indexed_job_shards_one_manifest_over_its_pods():
    job = document("Job")
    spec, pod = job["spec"], job["spec"]["template"]["spec"]
    container = pod["containers"][0]
    command = container["command"]
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert command[0] in scripts
    args = parser().parse_args(command[1:])  # options the command has
    assert args.command == "batch" and args.shard_index is None  # from JOB_COMPLETION_INDEX
    assert spec["completionMode"] == "Indexed"
    assert args.shard_count == spec["completions"] == spec["parallelism"]
    assert args.processes == int(container["resources"]["limits"]["cpu"])
    assert JOB_INDEX_VARIABLE == "JOB_COMPLETION_INDEX"  # the variable Kubernetes sets

    # The manifest and the outputs are on the data volume, a claim named in the docs.
    data = next(volume for volume in pod["volumes"] if "persistentVolumeClaim" in volume)
    mount = next(m for m in container["volumeMounts"] if m["name"] == data["name"])
    assert Path(args.manifest).is_relative_to(mount["mountPath"])
    assert Path(args.out).is_relative_to(mount["mountPath"])
    claim = data["persistentVolumeClaim"]["claimName"]
    assert claim in operations_doc()

    # Failed scans (exit status 1) are not retried: they would fail again.
    rule = spec["podFailurePolicy"]["rules"][0]
    assert rule["action"] == "FailIndex" and rule["onExitCodes"]["values"] == [SCANS_FAILED]
    assert rule["onExitCodes"]["containerName"] == container["name"]
    assert pod["restartPolicy"] == "Never"


def test_the_indexed_job_runs_as_the_deployment_does():
    job_pod = document("Job")["spec"]["template"]["spec"]
    job_container = job_pod["containers"][0]
    pod, container = deployment_container()
    assert job_container["image"] == container["image"]
    assert job_pod["securityContext"] == pod["securityContext"]
    assert job_container["securityContext"] == container["securityContext"]
    assert job_pod["automountServiceAccountToken"] is False
    tmp = next(v for v in job_pod["volumes"] if v["name"] == "tmp")
    assert tmp == next(v for v in pod["volumes"] if v["name"] == "tmp")

    # The Service and the PodDisruptionBudget select the service's pods, not the batch's.
    labels = document("Job")["spec"]["template"]["metadata"]["labels"]
    for kind in ("Service", "PodDisruptionBudget"):
        selector = document(kind)["spec"]["selector"]
        selector = selector.get("matchLabels", selector)
        assert not selector.items() <= labels.items(), kind


def test_the_job_command_is_the_documented_one():
    job = document("Job")
    command = shlex.join(job["spec"]["template"]["spec"]["containers"][0]["command"][:5])
    assert command in operations_doc()
