"""The workers' memory bench: it records how and where it measured, its table is rendered
from the results file, and the deploy guide shows the committed results of every engine."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from lipstream.bench.workers_memory import main, render_markdown, smaps_rollup
from lipstream.engines import engine_names
from tests.helpers import REPO

if TYPE_CHECKING:
    from lipstream.corpus import Corpus

RESULTS = REPO / "bench" / "workers_memory.json"
DEPLOY = REPO / "docs" / "how-to" / "deploy.md"


def _process(role: str, rss: float, pss: float, uss: float = 0.0) -> dict[str, Any]:
    return {"pid": 1, "role": role, "rss_mib": rss, "pss_mib": pss, "uss_mib": uss}


HAND_MADE: dict[str, Any] = {
    "command": "python -m lipstream.bench.workers_memory --models M --workers 1 2 4",
    "date": "2026-12-04T02:00:00+00:00",
    "models": [
        {"name": "a", "engine": "viseme-lerp", "bytes": 2_000_000},
        {"name": "b", "engine": "dam", "bytes": 9_000_000},
    ],
    "workers": {
        "1": [_process("worker", 300.0, 280.0, 250.0)],
        "2": [
            _process("supervisor", 260.0, 180.0),
            _process("helper", 12.0, 6.0),
            _process("worker", 300.0, 200.0, 150.0),
            _process("worker", 302.0, 202.0, 153.0),
        ],
        "4": [
            _process("supervisor", 260.0, 170.0),
            _process("helper", 12.0, 6.0),
            *[_process("worker", 300.0, 180.0, 140.0) for _ in range(4)],
        ],
    },
}


def test_the_table_is_rendered_from_the_results() -> None:
    rendered = render_markdown(HAND_MADE)
    assert rendered.startswith(
        "Memory with every engine of the demo character loaded (`viseme-lerp`, `dam`; "
        "11 MB of model files), measured with "
        "`python -m lipstream.bench.workers_memory --models M --workers 1 2 4` on 2026-12-04 "
    )
    # Totals by hand: 280; 180 + 6 + 200 + 202 = 588; 170 + 6 + 4 x 180 = 896.
    assert (
        "| 1 | 300 MiB | 280 MiB | 250 MiB | (none: the process is the worker) | 280 MiB |\n"
        "| 2 | 301 MiB | 201 MiB | 152 MiB | 260 / 180 MiB | 588 MiB |\n"
        "| 4 | 300 MiB | 180 MiB | 140 MiB | 260 / 170 MiB | 896 MiB |\n"
    ) in rendered
    assert "resource tracker adds 12 MiB RSS, 6 MiB PSS" in rendered
    # Shared: 301 - 201 and 300 - 180; the line through (2, 588) and (4, 896).
    assert "A worker's RSS less its PSS, 100–120 MiB, is what it shares" in rendered
    assert "about 280 MiB + 154 MiB × N" in rendered and "against 280 MiB for one" in rendered


def test_the_deploy_guide_shows_the_committed_results_of_every_engine() -> None:
    results = json.loads(RESULTS.read_text())
    assert {"command", "date", "machine"} <= set(results)
    assert results["command"].startswith("python -m lipstream.bench.workers_memory ")
    assert sorted(model["engine"] for model in results["models"]) == sorted(engine_names())
    assert render_markdown(results) in DEPLOY.read_text()


def test_smaps_rollup_reads_this_process() -> None:
    fields = smaps_rollup(os.getpid())
    assert fields["Rss"] >= fields["Pss"] >= fields["Private_Clean"] + fields["Private_Dirty"] > 0


@pytest.mark.slow
def test_a_run_records_the_command_machine_models_and_each_process(
    small_demo_corpus: Corpus, tmp_path: Path
) -> None:
    from lipstream.training import train_engine

    train, _ = small_demo_corpus.split()
    models = tmp_path / "models"
    train_engine(train, "viseme-lerp").save(models / "lerp")
    out = tmp_path / "memory.json"
    argv = ["--models", str(models), "--workers", "1", "--json", str(out)]
    assert main(argv) == 0
    results = json.loads(out.read_text())
    assert results["command"] == "python -m lipstream.bench.workers_memory " + " ".join(argv)
    assert results["machine"]["cpus"] == os.cpu_count()
    on_disk = sum(path.stat().st_size for path in (models / "lerp").rglob("*") if path.is_file())
    assert results["models"] == [{"name": "lerp", "engine": "viseme-lerp", "bytes": on_disk}]
    [worker] = results["workers"]["1"]
    assert worker["role"] == "worker" and worker["rss_mib"] >= worker["pss_mib"] > 10
    assert worker["pss_mib"] >= worker["uss_mib"] > 0
