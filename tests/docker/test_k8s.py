"""docker/k8s/: valid Kubernetes objects, wired as the deployment guide says.

Every manifest is validated offline against the Kubernetes 1.37 schemas that
``kubernetes-validate`` bundles, strictly (unknown fields fail); a copy with
a mistyped field must fail the same check. Then the wiring: readiness on
``/readyz`` and liveness on ``/healthz`` of the health port, a preStop that
starts the drain and waits for it, a grace period above the drain and the
drain above the longest utterance, the models on a read-only volume claimed
ReadOnlyMany, the container running the image's own command with workers, and
the HPA scaling on the custom metric that the Prometheus adapter's rule
serves, which is a metric the server exports.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import kubernetes_validate
import pytest
import yaml

from lipstream.server.metrics import Metrics
from tests.helpers import REPO
from tests.test_docker import DOCKERFILE, dockerfile_instructions

K8S = REPO / "docker" / "k8s"
VERSION = "1.37.0"


def documents(path: Path) -> list[dict[str, Any]]:
    return [doc for doc in yaml.safe_load_all(path.read_text(encoding="utf-8")) if doc]


def by_kind() -> dict[str, dict[str, Any]]:
    found = {doc["kind"]: doc for path in sorted(K8S.glob("*.yaml")) for doc in documents(path)}
    return found


@pytest.mark.parametrize("path", sorted(K8S.glob("*.yaml")), ids=lambda p: p.name)
def test_every_manifest_is_a_valid_kubernetes_object(path: Path) -> None:
    for document in documents(path):
        kubernetes_validate.validate(document, VERSION, strict=True)


def test_a_mistyped_field_fails_validation() -> None:
    [deployment] = documents(K8S / "deployment.yaml")
    deployment["spec"]["template"]["spec"]["terminationGracePeriod"] = 180
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(deployment, VERSION, strict=True)


def container() -> dict[str, Any]:
    containers: list[dict[str, Any]] = by_kind()["Deployment"]["spec"]["template"]["spec"][
        "containers"
    ]
    [only] = containers
    return only


def env() -> dict[str, str]:
    return {item["name"]: item["value"] for item in container()["env"]}


def test_probes_drain_and_grace_period_fit_the_longest_utterance() -> None:
    spec = by_kind()["Deployment"]["spec"]["template"]["spec"]
    served = container()
    ports = {port["name"]: port["containerPort"] for port in served["ports"]}
    assert served["readinessProbe"]["httpGet"] == {"path": "/readyz", "port": "http"}
    assert served["livenessProbe"]["httpGet"] == {"path": "/healthz", "port": "health"}
    assert ports["health"] == int(env()["LIPSTREAM_HEALTH_PORT"]) != ports["http"]
    longest = float(env()["LIPSTREAM_MAX_REQUEST_S"])
    drain = float(env()["LIPSTREAM_DRAIN_TIMEOUT_S"])
    assert spec["terminationGracePeriodSeconds"] > drain > longest
    assert served["lifecycle"]["preStop"]["exec"]["command"] == [
        "/bin/sh",
        "-c",
        "kill -TERM 1; while kill -0 1 2>/dev/null; do sleep 1; done",
    ]


def test_the_container_runs_the_images_command_as_pid_1_with_workers() -> None:
    instructions = dockerfile_instructions(DOCKERFILE.read_text(encoding="utf-8"))
    [cmd] = [arguments for keyword, arguments in instructions if keyword == "CMD"]
    image_command = json.loads(cmd)  # exec form: lipstream is PID 1, which preStop signals
    command = container()["command"]
    assert command[: len(image_command)] == image_command
    assert command[len(image_command) :] == ["--workers", "2"]


def test_models_come_from_a_read_only_volume_every_pod_shares() -> None:
    kinds = by_kind()
    spec = kinds["Deployment"]["spec"]["template"]["spec"]
    [mount] = container()["volumeMounts"]
    [volume] = spec["volumes"]
    assert mount == {
        "name": volume["name"],
        "mountPath": env()["LIPSTREAM_MODELS"],
        "readOnly": True,
    }
    claim = kinds["PersistentVolumeClaim"]
    assert volume["persistentVolumeClaim"] == {
        "claimName": claim["metadata"]["name"],
        "readOnly": True,
    }
    assert claim["spec"]["accessModes"] == ["ReadOnlyMany"]


def test_the_autoscaler_uses_the_sessions_metric_the_adapter_serves() -> None:
    kinds = by_kind()
    hpa = kinds["HorizontalPodAutoscaler"]
    assert hpa["spec"]["scaleTargetRef"]["name"] == kinds["Deployment"]["metadata"]["name"]
    [metric] = hpa["spec"]["metrics"]
    name = metric["pods"]["metric"]["name"]
    [rule] = yaml.safe_load(kinds["ConfigMap"]["data"]["config.yaml"])["rules"]
    assert rule["name"]["as"] == name
    assert rule["seriesQuery"].startswith(f"{name}{{")
    exported = {metric.name for metric in Metrics().registry.collect()}
    assert name in exported
    assert int(metric["pods"]["target"]["averageValue"]) < int(env()["LIPSTREAM_MAX_SESSIONS"])
