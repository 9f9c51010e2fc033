"""The workers' memory bench: it records how and where it measured and each process's RSS,
PSS and USS; the committed results hold every engine and are rendered into the report."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from lipstream.bench.report import BLOCKS, Bench
from lipstream.bench.workers_memory import main, smaps_rollup
from lipstream.engines import engine_names
from tests.helpers import REPO

if TYPE_CHECKING:
    from lipstream.corpus import Corpus

RESULTS = REPO / "bench" / "workers_memory.json"
SCALE_OUT = REPO / "docs" / "reports" / "scale-out.md"


def _process(role: str, rss: float, pss: float, uss: float) -> dict[str, Any]:
    return {"pid": 1, "role": role, "rss_mib": rss, "pss_mib": pss, "uss_mib": uss}


def test_the_report_shows_uss_when_the_file_records_it(tmp_path: Path) -> None:
    memory = {
        "date": "2030-04-05T06:07:08+00:00",
        "command": "python -m lipstream.bench.workers_memory --models M --workers 1 2",
        "machine": {"cpus": 2},
        "models": [{"name": "a", "engine": "dam", "bytes": 3_000_000}],
        "workers": {
            "1": [_process("worker", 300.0, 280.0, 250.0)],
            "2": [
                _process("supervisor", 260.0, 180.0, 150.0),
                _process("helper", 12.0, 6.0, 5.0),
                _process("worker", 300.0, 200.0, 150.0),
                _process("worker", 302.0, 202.0, 153.0),
            ],
        },
    }
    (tmp_path / "workers_memory.json").write_text(json.dumps(memory))
    (tmp_path / "resume_time.json").write_text(
        json.dumps(
            {"utterances": 1, "resume_ms_p50": 1.0, "resume_ms_max": 1.0}
            | {"frames_lost": 0, "frames_duplicated": 0}
        )
    )
    (tmp_path / "proxy_latency.json").write_text("{}")
    rendered = BLOCKS["scale-out"](Bench(tmp_path))
    # the largest worker's figures; all processes: 180 + 6 + 200 + 202 = 588
    assert (
        "| workers | RSS per worker MiB | PSS per worker MiB | USS per worker MiB "
        "| PSS of all processes MiB |\n|---|---|---|---|---|\n"
        "| 1 | 300 | 280 | 250 | 280 |\n"
        "| 2 | 302 | 202 | 153 | 588 |\n"
    ) in rendered


def test_the_committed_results_hold_every_engine_and_how_they_were_measured() -> None:
    results = json.loads(RESULTS.read_text())
    assert results["command"].startswith("python -m lipstream.bench.workers_memory ")
    assert results["date"] and results["machine"]["cpus"]
    assert sorted(model["engine"] for model in results["models"]) == sorted(engine_names())
    assert sorted(results["workers"], key=int) == ["1", "2", "4"]
    shown = SCALE_OUT.read_text()
    assert all(f"`{engine}`" in shown for engine in engine_names())
    assert "(recovered)" not in shown.split("bench/workers_memory.json")[1].split("\n")[0]


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
    assert results["machine"]["cores"] == len(os.sched_getaffinity(0))
    on_disk = sum(path.stat().st_size for path in (models / "lerp").rglob("*") if path.is_file())
    assert results["models"] == [{"name": "lerp", "engine": "viseme-lerp", "bytes": on_disk}]
    [worker] = results["workers"]["1"]
    assert worker["role"] == "worker" and worker["rss_mib"] >= worker["pss_mib"] > 10
    assert worker["pss_mib"] >= worker["uss_mib"] > 0
