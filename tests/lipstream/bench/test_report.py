"""``lipstream.bench.report``: the committed README and reports match bench/*.json, and
the renderer writes what a results file holds, saying what it lacks."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import pytest

from lipstream.bench.report import (
    BLOCKS,
    NOT_RECORDED,
    Bench,
    UnknownBlock,
    UnreadableResults,
    main,
    render_text,
    report_files,
    stale,
)
from tests.helpers import REPO

README_LIMIT_BYTES = 10_000


def engine_row(engine: str, rms: float, ms: float, closure: float) -> dict[str, object]:
    return {
        "engine": engine,
        "train_seconds": 1.0,
        "ms_per_phoneme": ms,
        "real_time_factor": ms / 100,
        "rms_error": rms,
        "closure_rate": closure,
        "train_ratio": 1.0,
        "speed_ratio": ms / 0.01,
        "rms_ratio": rms / 0.2,
        "closure_ratio": closure,
    }


@pytest.fixture
def bench(tmp_path: Path) -> Bench:
    """A results file with hand-picked figures, and streamed-call timings without
    machine, date or command."""
    results = {
        "date": "2030-01-02T03:04:05+00:00",
        "machine": {"python": "3.11.7", "system": "Linux"},
        "corpus": {
            "name": "toy",
            "digest": "0123456789abcdef",
            "fps": 60.0,
            "train_utterances": 9,
            "heldout_utterances": 1,
        },
        "recorded": {"closure_rate": 0.75},
        "engines": [
            engine_row("anime-graph", 0.1, 0.05, 0.5),
            engine_row("viseme-lerp", 0.2, 0.01, 1.0),
        ],
        "rungs": [
            {
                "engine": "viseme-lerp",
                "rung": "causal",
                "lookahead_ms": 0.0,
                "rms_error": 0.25,
                "closure_rate": 1.0,
                "rms_vs_best": 0.03,
            }
        ],
    }
    calls = [
        {
            "engine": "viseme-lerp",
            "rung": "causal",
            "calls": 5,
            "median_us": 12.4,
            "p90_us": 20.0,
            "mean_us": 13.0,
        }
    ]
    (tmp_path / "results.json").write_text(json.dumps(results))
    (tmp_path / "stream_calls.json").write_text(json.dumps(calls))
    return Bench(tmp_path)


def test_summary_rows_hold_the_results_figures(bench: Bench) -> None:
    rendered = BLOCKS["engines-summary"](bench)
    rows = [line for line in rendered.splitlines() if line.startswith("| `")]
    # the baseline first, whatever the file's order; streamed call only where measured
    assert rows[0].startswith("| `viseme-lerp` |")
    assert "| 0.2000 (1.00) | 100.0% | 0.0100 (1.0×) | 12 µs |" in rows[0]
    assert rows[1].startswith("| `anime-graph` |")
    assert "| 0.1000 (0.50) | 50.0% | 0.0500 (5.0×) | – |" in rows[1]
    assert "close on 75.0% of /p b m/" in rendered


def test_source_line_names_what_the_file_lacks(bench: Bench) -> None:
    engines = BLOCKS["engines"](bench)
    assert engines.startswith(
        "Source: `bench/results.json`; machine: python 3.11.7, system Linux; "
        f"date: 2030-01-02T03:04:05+00:00; command: {NOT_RECORDED}."
    )
    calls = BLOCKS["stream-calls"](bench)
    assert calls.startswith(
        f"Source: `bench/stream_calls.json`; machine: {NOT_RECORDED}; date: {NOT_RECORDED}; "
        f"command: {NOT_RECORDED}."
    )


def test_render_replaces_only_block_bodies(bench: Bench) -> None:
    text = "intro 1.5 ms\n<!-- report: stream-calls -->\nold figures\n<!-- /report -->\noutro\n"
    rendered = render_text(text, bench)
    assert rendered.startswith("intro 1.5 ms\n<!-- report: stream-calls -->\n")
    assert rendered.endswith("\n<!-- /report -->\noutro\n")
    assert "old figures" not in rendered and "| `viseme-lerp` | `causal` | 5 | 12.4 |" in rendered
    assert render_text(rendered, bench) == rendered


def test_an_unknown_block_is_an_error(bench: Bench) -> None:
    with pytest.raises(UnknownBlock, match="nope"):
        render_text("<!-- report: nope -->\n<!-- /report -->\n", bench, "page.md")


def test_check_finds_a_figure_edited_by_hand(tmp_path: Path) -> None:
    shutil.copytree(REPO / "bench", tmp_path / "bench")
    (tmp_path / "docs").mkdir()
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    (tmp_path / "README.md").write_text(readme, encoding="utf-8")
    assert stale(tmp_path) == []
    block = readme[readme.index("<!-- report: engines-summary -->") :]
    figure = re.search(r"\| (0\.\d{4}) \(", block)
    assert figure
    edited = readme.replace(figure.group(0), "| 0.0001 (", 1)
    (tmp_path / "README.md").write_text(edited, encoding="utf-8")
    assert stale(tmp_path) == [tmp_path / "README.md"]
    assert main(["--repo", str(tmp_path), "--check"]) == 1
    assert main(["--repo", str(tmp_path)]) == 0
    assert (tmp_path / "README.md").read_text(encoding="utf-8") == readme


def test_committed_readme_and_reports_match_the_bench_files() -> None:
    """Re-rendering bench/*.json changes nothing: run ``python -m lipstream.bench.report``
    after changing a results file."""
    assert stale(REPO) == []


def test_readme_figures_are_rendered() -> None:
    files = report_files(REPO)
    assert REPO / "README.md" in files
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert "<!-- report: engines-summary -->" in readme


def test_readme_is_a_front_page() -> None:
    readme = (REPO / "README.md").read_bytes()
    assert len(readme) <= README_LIMIT_BYTES, len(readme)
    assert re.search(rb"20\d\d-\d\d-\d\d", readme) is None, "a dated figure belongs in a report"


def test_provenance_fills_in_only_what_a_file_lacks(bench: Bench) -> None:
    recovered = {
        "results.json": {"date": "1999-01-01", "command": "lipstream bench --results x.json"},
        "stream_calls.json": {"machine": "a 2-core box", "date": "2030-02-03"},
    }
    (bench.directory / "provenance.json").write_text(json.dumps({"files": recovered}))
    engines = BLOCKS["engines"](bench)
    # the file's own date wins; the command it lacks is recovered, and says so
    assert engines.startswith(
        "Source: `bench/results.json`; machine: python 3.11.7, system Linux; "
        "date: 2030-01-02T03:04:05+00:00; "
        "command: `lipstream bench --results x.json` (recovered)."
    )
    calls = BLOCKS["stream-calls"](bench)
    assert calls.startswith(
        "Source: `bench/stream_calls.json`; machine: a 2-core box (recovered); "
        f"date: 2030-02-03 (recovered); command: {NOT_RECORDED}."
    )


def test_first_start_renders_each_phase(bench: Bench) -> None:
    assert "Not measured yet" in BLOCKS["first-start"](bench)
    doc = {
        "date": "2030-03-04",
        "command": "lipstream serve",
        "starts": [
            {"start": "first", "total_s": 48.25, "phases": {"speech": 9.04, "train": 30.0}},
            {"start": "later", "total_s": 3.5, "phases": {"load": 3.5}},
        ],
    }
    (bench.directory / "first_start.json").write_text(json.dumps(doc))
    assert BLOCKS["first-start-summary"](bench).startswith(
        "Measured with `lipstream serve`: first start 48.2 s; later start 3.5 s ("
    )
    rendered = BLOCKS["first-start"](bench)
    assert "First start, 48.2 s in all:" in rendered and "Later start, 3.5 s in all:" in rendered
    assert "| `speech` | 9.0 |" in rendered and "| `train` | 30.0 |" in rendered


def test_the_first_start_summary_groups_the_phases(bench: Bench) -> None:
    phases = {
        "importing the server": 0.8,
        "generating the demo corpus": 3.6,
        "training hmm and compiling its kernels": 25.8,  # inside the parallel step
        "training 6 engines on 2 processes": 48.5,
        "loading the models": 0.8,
        "warming up dam (demo)": 0.25,
        "calibrating dam (demo): timing 5 fidelity rung(s)": 0.5,
    }
    doc = {
        "machine": {"cores": 2},
        "starts": [{"start": "first", "total_s": 54.5, "phases": phases}],
    }
    (bench.directory / "first_start.json").write_text(json.dumps(doc))
    assert BLOCKS["first-start-summary"](bench).startswith(
        "Measured with `lipstream serve` on 2 cores: first start 54.5 s (imports 0.8 s, "
        "corpus 3.6 s, training 48.5 s, loading 0.8 s, calibration 0.8 s) ("
    )


def test_every_results_file_is_rendered() -> None:
    """A results file added to bench/ needs a report block: its figures are otherwise
    unread data or, worse, hand-copied into prose."""
    rendered = "".join(path.read_text(encoding="utf-8") for path in report_files(REPO))
    shown = set(re.findall(r"Source: `bench/([\w.-]+\.json)`", rendered))
    results = {path.name for path in (REPO / "bench").glob("*.json")} - {"provenance.json"}
    assert results - shown == set()


def test_streamed_calls_in_either_shape(tmp_path: Path) -> None:
    """Rows alone (as first written) and rows beside their machine, date and command render
    the same table; only the second names its own machine."""
    rows = [
        {
            "engine": "dam",
            "rung": "causal",
            "calls": 6,
            "median_us": 7.26,
            "p90_us": 9.0,
            "mean_us": 8.0,
        },
        {
            "engine": "viseme-lerp",
            "rung": "causal",
            "calls": 6,
            "median_us": 1.5,
            "p90_us": 2.0,
            "mean_us": 1.74,
        },
    ]
    stamped = {
        "command": "python -m lipstream.bench.floor_calls --models M",
        "date": "2030-05-06T07:08:09+00:00",
        "machine": {"cores": 2},
        "rows": rows,
    }
    rendered = []
    for doc in (rows, stamped):
        (tmp_path / "stream_calls.json").write_text(json.dumps(doc))
        rendered.append(BLOCKS["stream-calls"](Bench(tmp_path)))
    tables = [[line for line in text.splitlines() if line.startswith("| `")] for text in rendered]
    assert (
        tables[0]
        == tables[1]
        == [
            "| `viseme-lerp` | `causal` | 6 | 1.5 | 2.0 | 1.7 |",
            "| `dam` | `causal` | 6 | 7.3 | 9.0 | 8.0 |",
        ]
    )
    assert rendered[0].startswith(f"Source: `bench/stream_calls.json`; machine: {NOT_RECORDED};")
    assert rendered[1].startswith(
        "Source: `bench/stream_calls.json`; machine: cores 2; date: 2030-05-06T07:08:09+00:00; "
        "command: `python -m lipstream.bench.floor_calls --models M`."
    )


def test_workers_memory_in_either_shape(tmp_path: Path) -> None:
    """The file as first written (worker counts at the top) and with its machine, date,
    command and models beside ``workers`` render the same table."""
    processes = {
        "1": [{"pid": 1, "role": "worker", "rss_mib": 300.4, "pss_mib": 280.2}],
        "2": [
            {"pid": 2, "role": "supervisor", "rss_mib": 265.0, "pss_mib": 181.0},
            {"pid": 3, "role": "worker", "rss_mib": 297.0, "pss_mib": 202.0},
            {"pid": 4, "role": "worker", "rss_mib": 298.0, "pss_mib": 203.0},
        ],
    }
    stamped = {
        "date": "2030-04-05T06:07:08+00:00",
        "command": "python -m lipstream.bench.workers_memory --models M --workers 1 2",
        "machine": {"cpus": 2},
        "models": [{"name": "a", "engine": "dam", "bytes": 3_000_000}],
        "workers": processes,
    }
    tables = []
    for doc in (processes, stamped):
        (tmp_path / "workers_memory.json").write_text(json.dumps(doc))
        (tmp_path / "resume_time.json").write_text(
            json.dumps(
                {
                    "utterances": 2,
                    "resume_ms_p50": 1.0,
                    "resume_ms_max": 2.0,
                    "frames_lost": 0,
                    "frames_duplicated": 0,
                }
            )
        )
        (tmp_path / "proxy_latency.json").write_text(json.dumps({}))
        rendered = BLOCKS["scale-out"](Bench(tmp_path))
        memory_table = rendered[: rendered.index("bench/resume_time.json")]
        tables.append([line for line in memory_table.splitlines() if re.match(r"\| \d", line)])
    assert tables[0] == tables[1] == ["| 1 | 300 | 280 | 280 |", "| 2 | 298 | 203 | 586 |"]
    assert "date: 2030-04-05T06:07:08+00:00" in rendered
    assert "Models loaded: `dam` (3 MB of model files)." in rendered


def test_a_results_file_it_cannot_read_changes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    shutil.copytree(REPO / "bench", tmp_path / "bench")
    reports = tmp_path / "docs" / "reports"
    reports.mkdir(parents=True)
    (tmp_path / "README.md").write_text("no blocks\n", encoding="utf-8")
    # a.md renders (and is out of date); b.md's results file lacks what its block reads
    stale_page = "<!-- report: storm -->\nold\n<!-- /report -->\n"
    (reports / "a.md").write_text(stale_page, encoding="utf-8")
    (reports / "b.md").write_text("<!-- report: soak -->\n<!-- /report -->\n", encoding="utf-8")
    (tmp_path / "bench" / "soak.json").write_text('{"config": {}}')
    assert main(["--repo", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert "b.md: report block 'soak' (soak in" in error and "KeyError" in error
    assert (reports / "a.md").read_text(encoding="utf-8") == stale_page


def _real_row(engine: str, r: float, closed: float, lag: float) -> dict[str, object]:
    return {
        "engine": engine,
        "aperture_r": r,
        "closure_rate": closed,
        "closure_lag_ms": lag,
        "closure_lag_sd_ms": 40.0,
        "closure_lag_se_ms": 40.0 / 14**0.5,
        "closures_timed": 14,
        "clips_mapped_on_themselves": 11,
        "aperture_r_by_clip": {},
    }


def test_real_faces_render_every_engine_and_the_readme_line(tmp_path: Path) -> None:
    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "machine": {"python": "3.11.7"},
        "command": "lipstream bench --real",
        "corpus": {
            "name": "grid",
            "digest": "0123456789abcdef",
            "fps": 25.0,
            "clips": 11,
            "speakers": 11,
        },
        "recorded": {"closure_threshold": 0.0441, "closure_rate": 1.0, "bilabials": 14},
        "engines": [
            _real_row("dam", 0.566, 0.714, 15.7),
            _real_row("viseme-lerp", 0.496, 0.929, 17.1),
            _real_row("hmm", 0.433, 0.786, 28.6),
        ],
    }
    (tmp_path / "real_faces.json").write_text(json.dumps(doc))
    bench = Bench(tmp_path)
    rendered = BLOCKS["real-faces"](bench)
    rows = [line for line in rendered.splitlines() if line.startswith("| `")]
    # the standard error 40 / sqrt(14) = 10.69
    assert rows[0] == "| `viseme-lerp` | 0.496 | 92.9% | +17.1 ± 10.7 | 40.0 | 14 | 11 |"
    assert rows[1] == "| `dam` | 0.566 | 71.4% | +15.7 ± 10.7 | 40.0 | 14 | 11 |"
    assert "close on 100.0% of their 14 /p b m/ (threshold 0.044)" in rendered
    summary = BLOCKS["real-faces-summary"](bench)
    assert "aperture r up to 0.57 (`dam`; `viseme-lerp` 0.50)" in summary
    assert "closure lag +16 to +29 ms (`viseme-lerp` +17;" in summary
    assert "Not measured yet" in BLOCKS["real-faces"](Bench(tmp_path / "empty"))


def _aligner_summary(median: float, p90: float, largest: float, bias: float) -> dict[str, float]:
    return {"median_ms": median, "p90_ms": p90, "max_ms": largest, "mean_signed_ms": bias}


def test_the_aligner_against_grid_renders_each_clip_and_all(tmp_path: Path) -> None:
    clip = {
        "clip": "swwp2s",
        "audio_s": 2.995,
        "confidence": 0.574,
        "real_time_factor": 0.845,
        "words": [{"word": "set"}, {"word": "white"}],
        "onset": _aligner_summary(25.0, 40.0, 50.0, 15.0),
        "offset": _aligner_summary(25.0, 35.0, 40.0, -3.3),
    }
    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "machine": {"python": "3.11.7"},
        "command": "python -m lipstream.bench.aligner_real",
        "clips": [clip, {**clip, "clip": "other"}],
        "all": {
            "clips": 2,
            "words": 4,
            "onset": _aligner_summary(20.0, 30.0, 50.0, 5.0),
            "offset": _aligner_summary(10.0, 20.0, 40.0, 0.0),
        },
    }
    (tmp_path / "aligner_real.json").write_text(json.dumps(doc))
    rendered = BLOCKS["aligner-real"](Bench(tmp_path))
    rows = [line for line in rendered.splitlines() if line.startswith("| `") or "| all" in line]
    assert rows == [
        "| `swwp2s` (3.00 s) | 2 | 25.0 / 40.0 / 50.0 (+15.0) | 25.0 / 35.0 / 40.0 (-3.3) "
        "| 0.57 | 0.84 |",
        "| `other` (3.00 s) | 2 | 25.0 / 40.0 / 50.0 (+15.0) | 25.0 / 35.0 / 40.0 (-3.3) "
        "| 0.57 | 0.84 |",
        "| all 2 clips | 4 | 20.0 / 30.0 / 50.0 (+5.0) | 10.0 / 20.0 / 40.0 (+0.0) "
        "| 0.57 (0.57–0.57) | 0.84 |",
    ]
    assert "2 clip(s) with GRID's word times, 4 words" in rendered
    assert "Not measured yet" in BLOCKS["aligner-real"](Bench(tmp_path / "empty"))


def test_many_aligned_clips_render_pooled_with_grids_word_positions(tmp_path: Path) -> None:
    """Past six clips only the pooled row is a table row; the confidence column gives the
    clips' median and range, the positions are named by GRID's grammar, and a refused
    clip is named with its code."""
    clips = [
        {
            "clip": f"c{index}",
            "audio_s": 3.0,
            "confidence": confidence,
            "real_time_factor": factor,
            "words": [{"word": "w"}] * 6,
            "onset": _aligner_summary(10.0, 20.0, 30.0, 1.0),
            "offset": _aligner_summary(10.0, 20.0, 30.0, 1.0),
        }
        for index, (confidence, factor) in enumerate(
            zip([0.5, 0.3, 0.7, 0.4, 0.6, 0.35, 0.45], [0.2, 0.1, 0.3, 0.25, 0.15, 0.22, 0.18])
        )
    ]
    positions = [_aligner_summary(10.0 * i, 20.0, 30.0, 0.0) for i in range(1, 7)]
    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "machine": {"python": "3.11.7"},
        "command": "python -m lipstream.bench.aligner_real",
        "clips": clips,
        "refused": [{"clip": "lriyzn", "code": "transcript_mismatch", "error": "no path"}],
        "all": {
            "clips": 7,
            "refused": 1,
            "words": 42,
            "onset": _aligner_summary(20.0, 30.0, 50.0, 5.0),
            "offset": _aligner_summary(10.0, 20.0, 40.0, 0.0),
            "onset_by_position": positions,
        },
    }
    (tmp_path / "aligner_real.json").write_text(json.dumps(doc))
    rendered = BLOCKS["aligner-real"](Bench(tmp_path))
    assert not [line for line in rendered.splitlines() if line.startswith("| `c")]
    # confidences sorted: 0.3 0.35 0.4 0.45 0.5 0.6 0.7, the median the fourth
    assert (
        "| all 7 clips | 42 | 20.0 / 30.0 / 50.0 (+5.0) | 10.0 / 20.0 / 40.0 (+0.0) "
        "| 0.45 (0.30–0.70) | 0.20 |"
    ) in rendered
    assert "| 1 (command) | 10.0 / 20.0 / 30.0 (+0.0) |" in rendered
    assert "| 6 (adverb) | 60.0 / 20.0 / 30.0 (+0.0) |" in rendered
    assert "`lriyzn` refused by the aligner (`transcript_mismatch`)" in rendered


def test_real_faces_before_and_after_side_by_side(tmp_path: Path) -> None:
    def doc(rows: list[dict[str, object]]) -> dict[str, object]:
        return {
            "date": "2030-01-02T03:04:05+00:00",
            "command": "lipstream bench --real",
            "engines": rows,
        }

    before = doc([_real_row("dam", 0.566, 0.714, 15.7), _real_row("viseme-lerp", 0.496, 0.9, 17.1)])
    after = doc([_real_row("dam", 0.6, 0.8, -4.0), _real_row("viseme-lerp", 0.51, 0.9, -2.5)])
    (tmp_path / "real_faces_before.json").write_text(json.dumps(before))
    bench = Bench(tmp_path)
    assert "Not measured yet" in BLOCKS["real-faces-before-after"](bench)
    (tmp_path / "real_faces.json").write_text(json.dumps(after))
    rendered = BLOCKS["real-faces-before-after"](bench)
    rows = [line for line in rendered.splitlines() if line.startswith("| `")]
    assert rows == [
        "| `viseme-lerp` | 0.496 | 0.510 | +17.1 | -2.5 |",
        "| `dam` | 0.566 | 0.600 | +15.7 | -4.0 |",
    ]
    assert "`bench/real_faces_before.json`" in rendered and "`bench/real_faces.json`" in rendered


def test_demo_calibration_renders_each_corpus_beside_the_real_one(tmp_path: Path) -> None:
    def measures(closure: float, opening: float, rounding: float) -> dict[str, Any]:
        def summary(mean: float, sd: float, count: int) -> dict[str, Any]:
            return {"mean": mean, "sd": sd, "count": count}

        return {
            "closure_from_onset_ms": summary(closure, 30.0, 14),
            "closure_share": summary(0.05, 0.3, 14),
            "opening_speed": summary(opening, 2.0, 11),
            "closing_speed": summary(14.0, 2.0, 11),
            "opening_speed_median": opening,
            "closing_speed_median": 14.25,
            "rounding_half_rise_ms": summary(rounding, 90.0, 10),
        }

    corpora = {
        "real": {"name": "grid", "utterances": 11, "measures": measures(3.6, 13.8, 0.2)},
        "after": {"name": "demo", "utterances": 332, "measures": measures(11.6, 13.1, 3.8)},
    }
    doc = {"date": "2030-01-02T03:04:05+00:00", "measure_fps": 25.0, "corpora": corpora}
    (tmp_path / "demo_calibration.json").write_text(json.dumps(doc))
    rendered = BLOCKS["demo-calibration"](Bench(tmp_path))
    assert "| measure | real (`grid`, 11 utt.) | after (`demo`, 332 utt.) |" in rendered
    assert "| +3.6 ± 30.0 (n 14)" not in rendered  # ms are shown whole
    assert (
        "| /p b m/ closure centre less the acoustic onset, ms | +4 ± 30 (n 14) | +12 ± 30 (n 14) |"
        in rendered
    )
    assert "| peak opening speed, aperture ranges per s (median) | 13.80 | 13.10 |" in rendered
    assert (
        "| rounding halfway up, less the rounded vowel's onset, ms | +0 ± 90 (n 10) | +4 ± 90 (n 10) |"
        in rendered
    )
    assert "Not measured yet" in BLOCKS["demo-calibration"](Bench(tmp_path / "empty"))


def test_the_connection_cost_renders_each_round_and_the_median(tmp_path: Path) -> None:
    legs = {
        "websocket": {"cpu_ms_per_connection": [1.575, 1.775], "median_ms": 1.675},
        "healthz": {"cpu_ms_per_connection": [0.65, 0.675], "median_ms": 0.6625},
    }
    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "machine": {"python": "3.11.7"},
        "command": "python -m lipstream.bench.connection_cost",
        "legs": legs,
    }
    (tmp_path / "connection_cost.json").write_text(json.dumps(doc))
    rendered = BLOCKS["connection-cost"](Bench(tmp_path))
    assert "| WebSocket opened and closed | 1.57, 1.77 | 1.68 |" in rendered
    assert "| HTTP `GET /healthz` | 0.65, 0.68 | 0.66 |" in rendered
    assert "Not measured yet" in BLOCKS["connection-cost"](Bench(tmp_path / "empty"))


def _with_emotions(engine: str, rms: float, emotions: dict[str, float]) -> dict[str, object]:
    return {**engine_row(engine, rms, 0.01, 0.9), "rms_by_emotion": emotions}


def _rung(engine: str, rung: str, lookahead: float, rms: float, closed: float) -> dict[str, object]:
    return {
        "engine": engine,
        "rung": rung,
        "lookahead_ms": lookahead,
        "rms_error": rms,
        "closure_rate": closed,
        "rms_vs_best": 0.01,
    }


def _results(tmp_path: Path, **fields: object) -> Bench:
    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "command": "lipstream bench --results bench/results.json",
        "corpus": {"name": "toy", "digest": "0123456789abcdef"},
        "recorded": {"closure_rate": 1.0},
        "engines": [],
        "rungs": [],
        **fields,
    }
    (tmp_path / "results.json").write_text(json.dumps(doc))
    return Bench(tmp_path)


def test_an_engine_page_quality_block_compares_emotion_by_emotion(tmp_path: Path) -> None:
    bench = _results(
        tmp_path,
        engines=[
            _with_emotions("viseme-lerp", 0.2, {"happy": 0.25, "sad": 0.15}),
            _with_emotions("cohen-massaro", 0.06, {"happy": 0.07, "sad": 0.04}),
            _with_emotions("dam", 0.05, {"happy": 0.06, "sad": 0.045}),
            _with_emotions("anime-graph", 0.04, {"happy": 0.07, "sad": 0.05}),
        ],
    )
    rendered = BLOCKS["dam-quality"](bench)
    assert rendered.startswith("Source: `bench/results.json`;")
    rows = [line for line in rendered.splitlines() if line.startswith("| `")]
    # the page's order, not the file's
    assert [row.split(" | ")[0] for row in rows] == [
        "| `dam`",
        "| `cohen-massaro`",
        "| `anime-graph`",
        "| `viseme-lerp`",
    ]
    assert rows[0] == "| `dam` | 0.0500 (0.25) | 0.0600 | 0.0450 | 90.0% | – |"
    assert (
        "- `dam` against `cohen-massaro`: RMS 0.0500 against 0.0600 (lower), "
        "lower in 1 of 2 emotions (not sad).\n" in rendered
    )
    assert (
        "- `dam` against `anime-graph`: RMS 0.0500 against 0.0400 (not lower), "
        "lower in every emotion.\n" in rendered
    )
    assert "`viseme-lerp`: RMS 0.0500 against 0.2000 (lower), lower in every emotion." in rendered


def test_quality_blocks_name_what_the_results_lack(tmp_path: Path) -> None:
    bench = _results(tmp_path, engines=[_with_emotions("dam", 0.05, {"sad": 0.04})])
    with pytest.raises(UnreadableResults, match="dam-quality"):
        render_text("<!-- report: dam-quality -->\n<!-- /report -->\n", bench, "dam.md")


def test_the_rung_block_says_what_the_causal_rung_gives_up(tmp_path: Path) -> None:
    bench = _results(
        tmp_path,
        rungs=[
            _rung("viseme-lerp", "causal", 0.0, 0.125, 1.0),
            _rung("dam", "full", 1600.0, 0.05, 0.8),
            _rung("dam", "causal_lead", 6.749, 0.052, 0.95),
            _rung("dam", "causal", 0.0, 0.055, 0.95),
            _rung("cohen-massaro", "full", 1400.0, 0.06, 0.7),
            _rung("cohen-massaro", "causal", 0.0, 0.045, 0.75),
            _rung("anime-graph", "causal", 0.0, 0.07, 0.8),
        ],
    )
    rendered = BLOCKS["dam-rungs"](bench)
    assert "| `dam` | `full` | 1600 | 0.0500 | 80.0% | 0.0100 |" in rendered
    assert "| `dam` | `causal_lead` | 6.7 | 0.0520 | 95.0% | 0.0100 |" in rendered
    assert "viseme-lerp` | `causal`" not in rendered  # a rival is ranked, not tabled
    assert (
        "`dam` on `causal`: RMS 0.0550 against 0.0500 on `full` (+10.0%), "
        "/p b m/ closed 95.0% against 80.0%." in rendered
    )
    assert "`cohen-massaro` on `causal`: RMS 0.0450 against 0.0600 on `full` (-25.0%)" in rendered
    assert rendered.endswith(
        "lowest first: `cohen-massaro` 0.0450, `dam` 0.0550, `anime-graph` 0.0700, "
        "`viseme-lerp` 0.1250.\n"
    )


def _dam_fit(modes: int, tail: int) -> dict[str, object]:
    search = [
        {"name": f"s{n}", "lookahead_phonemes": tail + n, "truncation_error": 0.0066}
        for n in (2, 1, 0)
    ]
    return {
        "fit_s": 7.85,
        "modes": modes,
        "basis_components": 17,
        "fit_rms": 0.03959,
        "tail": tail,
        "rungs": [*search, {"name": "causal", "lookahead_phonemes": 0, "truncation_error": None}],
        "cut_tail_errors": {"tail_ahead=0": 1.0047, "tail_ahead=1": 0.4748},
        "synthesis": {
            "phonemes": 40,
            "fps": 60.0,
            "repeats": 200,
            "cpu_ms_per_phoneme": 0.00612,
            "paper_ms_per_phoneme": 0.8,
        },
        "causal_calls": [
            {"rung": "causal_lead", "cpu_ms_median": 0.01057},
            {"rung": "causal", "cpu_ms_median": 0.01079},
        ],
    }


def test_the_dam_fit_block(tmp_path: Path) -> None:
    bench = _results(tmp_path, engine_benches={"dam": {"dam": _dam_fit(428, 6)}})
    rendered = BLOCKS["dam-fit"](bench)
    assert (
        "| `dam` | 428 | 17 | 7.8 | 0.0396 | 6 (0.7%) | 8, 7, 6 | 47.5%, 100.5% | 0.0061 "
        "| 0.0106 / 0.0108 |" in rendered
    )
    assert (
        "a 40-phoneme sentence at 60 fps, 200 repeats (the paper: 0.8 ms per phoneme)" in rendered
    )


def _pq(ms: float, jumps: int, speedup: float, over_unclustered: float) -> dict[str, object]:
    return {
        "search_ms": ms,
        "jumps": jumps,
        "timed_out": False,
        "speedup": speedup,
        "speedup_over_unclustered_greedy": over_unclustered,
    }


def _anime_graph_benches() -> dict[str, object]:
    def row(graph: str, greedy_ms: float, jumps: int, pq4: dict[str, object]) -> dict[str, Any]:
        greedy = {"search_ms": greedy_ms, "jumps": jumps, "search_ms_in_synthesis": 0.122}
        return {
            "phonemes": 27,
            "graph": graph,
            "greedy": greedy,
            "pq": {"3": _pq(8.45, 0, 1.0, 1.0), "4": pq4, "5": {"timed_out": True}},
        }

    return {
        "model": {
            "fit_s": 6.23,
            "metrics": {
                "animes": 11245,
                "pca_components": 13,
                "clusters": 1000,
                "cluster_degree_mean": 6.913,
                "cluster_degree_max": 30,
            },
        },
        "table": {
            "rows": [
                row("unclustered", 0.0117, 9, _pq(254.3, 11, 21805.4, 21805.4)),
                row("clustered", 0.0682, 0, _pq(12.69, 0, 186.0, 1088.4)),
                row("clustered", 0.0727, 2, _pq(20.68, 2, 284.6, 1255.5)),
            ],
            "pq_advance": 1,
            "pq_budget_s": 60.0,
            "greedy_never_more_jumps": True,
            "min_speedup_over_pq4": 1088.4,
            "min_speedup_over_pq4_in_synthesis": 340.8,
        },
        "scaling": [
            {
                "factor": 4,
                "animes": 44980,
                "fit_s": 4.16,
                "search_ms_per_sentence": 0.01639,
                "search_us_per_phoneme": 0.4362,
                "warm_search_ms_per_sentence": 0.01318,
            }
        ],
        "speed": {
            "phonemes": 40,
            "greedy_search_ms": 0.01304,
            "greedy_search_ms_with_audio": 0.05489,
            "synthesis_ms_per_sentence": 0.5317,
            "synthesis_ms_per_sentence_with_audio": 2.82,
            "mean_phonemes_per_sentence": 37.576,
        },
        "quality": {
            "viseme-lerp": {"rms": 0.12212, "closure_rate": 1.0},
            "anime-graph clustered": {"rms": 0.06037, "closure_rate": 0.92222},
            "recorded_closure_rate": 1.0,
        },
    }


def test_the_anime_graph_blocks(tmp_path: Path) -> None:
    bench = _results(tmp_path, engine_benches={"anime-graph": _anime_graph_benches()})
    found = BLOCKS["anime-graph-table"](bench)
    assert "mean out-degree 6.9 (at most 30). PQ with h_q = 1, at most 60 s a search." in found
    assert (
        "| 27 | unclustered | 0.012 (0.122) | 9 | 8 / 0 | 254 / 11 | timed out | 21,805× "
        "| 21,805× |" in found
    )
    assert "at least 1,088× faster than PQ(4) on either graph, or 341× timed inside" in found
    assert (
        "On the clustered graph PQ(4) takes 12.7–20.7 ms, greedy on that graph is 186–285× "
        "faster than it, and greedy takes 0–2 jumps per sentence there." in found
    )
    scaling = BLOCKS["anime-graph-scaling"](bench)
    assert "| 4 | 44,980 | 4.2 | 0.013 | 0.016 | 0.44 |" in scaling
    quality = BLOCKS["anime-graph-quality"](bench)
    assert "40-phoneme sentence 0.013 ms (0.055 ms ranking by audio)" in quality
    assert "(37.6 phonemes on average) 0.5 ms without audio and 2.8 ms with audio" in quality
    assert "| `anime-graph`, clustered | 0.0604 | 92.2% |" in quality
    assert "| recorded | — | 100.0% |" in quality


def _table_v(fast_ms: float, nodes: int) -> dict[str, object]:
    row = {
        "phonemes": 63,
        "paper_cpu_s": 942.609,
        "exact_dp_cpu_s": 894.81,
        "fast_cpu_ms": fast_ms,
        "fast_cpu_ms_least": 4.2104,
        "fast_priced_nodes": 5705,
    }
    table_v = {
        "rows": [row],
        "exact_dp_cpu_s_per_transition": 14.43,
        "same_optimum_on_exact_layers": True,
    }
    return {
        "expressive-dp": {
            "fit_s": 5.06,
            "nodes": nodes,
            "basis_components": 14,
            "table_v": table_v,
        }
    }


def test_table_v_says_whether_the_target_is_met(tmp_path: Path) -> None:
    rendered = BLOCKS["expressive-dp-table-v"](
        _results(tmp_path, engine_benches=_table_v(4.6972, 10527))
    )
    assert "| 63 | 942.6 | 894.8 | 4.70 / 4.21 | 5,705 |" in rendered
    assert "14.4 CPU s per transition" in rendered and "the same optimum there" in rendered
    assert rendered.endswith("4.7 ms median for 63 phonemes on 10,527 nodes, met.\n")
    slow = BLOCKS["expressive-dp-table-v"](_results(tmp_path, engine_benches=_table_v(20.5, 10527)))
    assert slow.endswith("20.5 ms median for 63 phonemes on 10,527 nodes, not met.\n")
    small = BLOCKS["expressive-dp-table-v"](_results(tmp_path, engine_benches=_table_v(4.7, 4000)))
    assert small.endswith("on 4,000 nodes, not met.\n")


def test_the_hmm_bench_block(tmp_path: Path) -> None:
    estimators = {
        "entropic": {
            "fit_s": 2.86,
            "states": 38,
            "states_initial": 40,
            "transitions": 336,
            "perplexity": 2.13768,
            "heldout_entropy_rate_bits": 0.029595,
        }
    }
    errors = {"heldout": {"phonemes": {"err": 0.08228, "rms": 0.06448}}}
    hmm = {
        "estimators": estimators,
        "errors": errors,
        "real_time_factor": {"offline": 1943.5, "causal": 2833.9},
        "first_frame": {"causal": {"audio_needed_ms": 9.977, "call_ms": 0.036614}},
    }
    rendered = BLOCKS["hmm-benches"](_results(tmp_path, engine_benches={"hmm": hmm}))
    assert "| `entropic` | 38 (40) | 336 | 2.138 | 0.0296 | 2.9 |" in rendered
    assert "| lines | phonemes |" in rendered and "| heldout | 0.082 / 0.0645 |" in rendered
    assert "| `offline` | 1,944 | – | – |" in rendered
    assert "| `causal` | 2,834 | 10 | 0.037 |" in rendered


def test_the_expressive_dp_bench_block(tmp_path: Path) -> None:
    lag = {
        "lag": 4,
        "lines_differing": 0.42424,
        "nodes_differing": 0.041935,
        "mean_cost_gap": 0.0029979,
        "max_cost_gap": 0.022141,
        "lookahead_ms": 485.92,
        "ms_per_phoneme": 0.22211,
    }
    figures = {
        "cv_error": 0.049409,
        "cv_error_defaults": 0.050851,
        "pick_ms": 0.047947,
        "lags": [lag],
        "rms_by_emotion": {
            "correct_modifiers": {"sad": 0.058169, "angry": 0.082834},
            "viseme-lerp": {"sad": 0.099755, "angry": 0.157178},
        },
    }
    rendered = BLOCKS["expressive-dp-benches"](
        _results(tmp_path, engine_benches={"expressive-dp": figures})
    )
    assert (
        "searched weights 0.0494, with the defaults 0.0509; a phoneme-map pick 0.048 ms" in rendered
    )
    assert "| 4 | 42.4% | 4.2% | 0.30% / 2.21% | 486 | 0.222 |" in rendered
    assert "| synthesis | angry | sad |" in rendered
    assert "| correct modifiers | 0.0828 | 0.0582 |" in rendered
    assert "| `viseme-lerp` | 0.1572 | 0.0998 |" in rendered


def test_closure_sources_renders_the_character_and_each_engine_by_context(tmp_path: Path) -> None:
    def summary(mean: float | None, se: float | None, count: int) -> dict[str, Any]:
        return {"mean_ms": mean, "se_ms": se, "count": count}

    def contexts(all_: float, quiet: float | None, speech: float) -> dict[str, Any]:
        return {
            "all": summary(all_, 2.5, 9),
            "after_silence": summary(quiet, None, 1 if quiet is not None else 0),
            "after_speech": summary(speech, 3.0, 8),
        }

    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "corpus": {"name": "grid", "fps": 25.0},
        "clips": 4,
        "character_behind_real": contexts(4.75, -20.0, 8.0),
        "engines": {
            "hmm": {
                "behind_character": contexts(30.0, None, 24.25),
                "behind_real": contexts(34.0, 18.0, 43.0),
            },
            "viseme-lerp": {
                "behind_character": contexts(2.0, -19.0, 14.0),
                "behind_real": contexts(7.0, -40.0, 33.0),
            },
        },
    }
    (tmp_path / "closure_sources.json").write_text(json.dumps(doc))
    rendered = BLOCKS["closure-sources"](Bench(tmp_path))
    assert "4 clips of `grid`, 25 fps" in rendered
    assert "| lag | all /p b m/ | after silence | after speech |" in rendered
    assert (
        "| the character behind the real lips | +4.8 ± 2.5 (n 9) | -20.0 (n 1) | +8.0 ± 3.0 (n 8) |"
        in rendered
    )
    assert "| `hmm` behind the character | +30.0 ± 2.5 (n 9) | – | +24.2 ± 3.0 (n 8) |" in rendered
    # the engines in the report's usual order: viseme-lerp before hmm
    assert rendered.index("`viseme-lerp` behind") < rendered.index("`hmm` behind")
    assert "Not measured yet" in BLOCKS["closure-sources"](Bench(tmp_path / "empty"))


def test_aligner_bilabial_onsets_takes_each_b_p_word_of_grid(tmp_path: Path) -> None:
    def word(name: str, grid: float, aligned: float) -> dict[str, Any]:
        return {"word": name, "grid_s": [grid, grid + 0.2], "aligned_s": [aligned, grid + 0.2]}

    clips = [
        {"words": [word("bin", 0.5, 0.52), word("blue", 0.8, 0.77), word("at", 1.0, 1.1)]},
        {"words": [word("bin", 0.4, 0.44), word("by", 1.2, 1.2)]},
    ]
    doc = {"date": "2030-01-02T03:04:05+00:00", "clips": clips}
    (tmp_path / "aligner_real.json").write_text(json.dumps(doc))
    rendered = BLOCKS["aligner-bilabial-onsets"](Bench(tmp_path))
    assert "| `bin` | 2 | +30.0 | +30.0 |" in rendered
    assert "| `blue` | 1 | -30.0 | -30.0 |" in rendered
    assert "| `by` | 1 | +0.0 | +0.0 |" in rendered
    assert "`at`" not in rendered and "`place`" not in rendered  # not /b p/-initial, or absent
    assert "Not measured yet" in BLOCKS["aligner-bilabial-onsets"](Bench(tmp_path / "empty"))


def test_closure_timing_renders_each_engine_part_and_group(tmp_path: Path) -> None:
    def group(label: str, count: int, recorded: float | None, lag: float | None) -> dict[str, Any]:
        return {
            "group": label,
            "count": count,
            "recorded_ms": recorded,
            "predicted_ms": None if lag is None or recorded is None else recorded + lag,
            "lag_ms": lag,
        }

    def timed(
        lag: float, closing: float, release: float, lags: list[float | None]
    ) -> dict[str, Any]:
        return {
            "closures": 5,
            "lag_ms": lag,
            "closing_lag_ms": closing,
            "release_lag_ms": release,
            "recorded_closing_ms": -47.25,
            "recorded_release_ms": 68.0,
            "rms": 0.05,
            "groups": [
                group("< -20", 2, -28.0, lags[0]),
                group("-20 .. 0", 3, -10.0, lags[1]),
                group("0 .. 20", 0, None, None),
            ],
        }

    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "corpus": {"name": "demo", "fps": 120.0},
        "engines": {
            "dam": {
                "train": timed(14.25, 62.0, -33.5, [27.5, 18.9]),
                "heldout": timed(11.0, 52.0, -30.0, [24.0, 22.0]),
                "fit": timed(4.5, 53.75, -44.75, [20.25, 11.0]),
                "leads": [
                    {
                        "lead_ms": 0.0,
                        "lag_ms": 11.0,
                        "closing_lag_ms": 52.0,
                        "release_lag_ms": -30.0,
                        "rms": 0.0558,
                    },
                    {
                        "lead_ms": 20.0,
                        "lag_ms": 2.875,
                        "closing_lag_ms": 39.0,
                        "release_lag_ms": -33.25,
                        "rms": 0.05561,
                        "causal": {"lag_ms": 9.25, "rms": 0.0601},
                        "real_phones_lag_ms": -3.25,
                        "real": {"mean_ms": -2.75, "se_ms": 4.5, "count": 79},
                    },
                ],
                "chosen_lead_ms": 20.0,
                "best_lead_ms": 20.0,
            }
        },
        "after_silence": {
            "silence": {"closures": 4, "closing_ms": -94.0, "release_ms": 57.0, "centre_ms": -18.5},
            "phoneme": {"closures": 9, "closing_ms": -42.0, "release_ms": 68.0, "centre_ms": 13.0},
        },
    }
    (tmp_path / "closure_timing.json").write_text(json.dumps(doc))
    rendered = BLOCKS["closure-timing"](Bench(tmp_path))
    assert "The `demo` corpus at 120 fps; 5 /p b m/ closures" in rendered
    assert "runs from -47 to +68 ms" in rendered
    assert "trained here without it (`bilabial_lead_s` = 0)" in rendered
    fit_row = (
        "| `dam` | training lines, EM fit with each occurrence's own mode | 5 | +4.5 | +53.8 "
        "| -44.8 | 0.0500 |"
    )
    assert fit_row in rendered
    # the fit's row comes between the synthesized training lines and the held-out lines
    assert rendered.index("training lines, synthesized") < rendered.index(fit_row)
    assert rendered.index(fit_row) < rendered.index("held-out lines, synthesized")
    assert "| < -20 | 2 | -28.0 | +20.2 | +27.5 |" in rendered
    assert "| 0 .. 20 | 0 | – | – | – |" in rendered
    assert (
        "| `dam` | **20** | +2.9 | +39.0 | -33.2 | 0.0556 | +9.2 | 0.0601 | -3.2 | -2.8 |"
        in rendered
    )
    assert "| `dam` | 0 | +11.0 | +52.0 | -30.0 | 0.0558 | – | – | – | – |" in rendered
    assert rendered.index("| `dam` | 0 | +11.0 |") < rendered.index("| `dam` | **20** |")
    assert "after silence (or first in a line, 4 closures) closes at -94.0" in rendered
    assert "behind the character on the real phones: `dam` 20 ms (default 20 ms)." in rendered
    assert (
        "centres at -18.5 ms" in rendered and "after a phoneme (9) at -42.0 and +13.0" in rendered
    )
    assert "Not measured yet" in BLOCKS["closure-timing"](Bench(tmp_path / "empty"))


def test_throughput_targets_put_each_figure_beside_its_target(tmp_path: Path) -> None:
    def cpu_run(engine: str, fidelity: str, ratio: float) -> dict[str, Any]:
        return {"engine": engine, "fidelity": fidelity, "cpu_ratio": ratio}

    cpu = {
        "runs": [
            cpu_run("viseme-lerp", "causal", 1.2),
            cpu_run("dam", "causal_lead", 1.5),
            cpu_run("viseme-lerp", "lerp", 1.4),
            cpu_run("dam", "full", 1.45),
        ]
    }
    calls = {"rows": [{"engine": "expressive-dp", "rung": "lag-4", "after_median_us": 183.25}]}
    first = {
        "streams": 500,
        "target_p99_ms": 50.0,
        "rows": [
            {"engine": "dam", "side": "before", "first_frame_ms": {"p99": 46.0}},
            {"engine": "dam", "side": "after", "first_frame_ms": {"p99": 180.0}},
        ],
    }
    floor = {"searches": [{"engine": "dam", "capacity_ratio": 0.5}, {"engine": "hmm"}]}
    best = {"searches": [{"engine": "dam", "capacity_ratio": 0.75}]}
    for name, doc in (
        ("cpu_per_session_session15.json", cpu),
        ("call_pairs_lag_window.json", calls),
        ("first_frame_priority.json", first),
        ("capacity_floor.json", floor),
        ("capacity_best.json", best),
    ):
        (tmp_path / name).write_text(json.dumps(doc))
    rendered = BLOCKS["throughput-targets"](Bench(tmp_path))
    assert "at most 1.25 | 1.20–1.50 over 2 engines" in rendered
    assert "missed by 1 of 2, by 1.20×" in rendered  # 1.5 / 1.25
    assert "at most 1.5 | 1.40–1.45 over 2 engines" in rendered
    assert "met by all 2" in rendered
    assert "183.2 µs, median" in rendered and "missed by 33 µs" in rendered
    # the served code's rounds only: the variant's 180 ms is not the server's
    assert "worst round of any engine 46 ms" in rendered and "| met |" in rendered
    # a search without a reference has no ratio and is left out
    assert "at least 0.8 | 0.50 over 1 engine " in rendered
    assert "missed by 1 of 1, by 1.60×" in rendered
    assert (
        "at least 0.6 | 0.75 over 1 engine (`bench/capacity_best.json`) | met by all 1 |"
        in rendered
    )
