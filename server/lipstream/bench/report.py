"""Render the measurements in ``bench/*.json`` into the README and docs/reports.

Sketch: a Markdown file holds report blocks, each between ``<!-- report: NAME -->``
and ``<!-- /report -->``; ``BLOCKS[NAME]`` renders that block's body from the bench
directory, opening with where its figures come from: file, machine, date and command, each
from the file itself, else from ``bench/provenance.json`` (marked "recovered": what
the commit that added the file recorded), else "not recorded". ``render_text`` replaces every block
of a text; ``python -m lipstream.bench.report`` rewrites the README and every page
under docs/ in place, and ``--check`` only lists the files whose blocks differ from
a fresh rendering (exit 1), so committed figures cannot drift from the JSON.
Text outside the blocks is left alone: it explains, the blocks measure.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

BLOCK = re.compile(r"(<!-- report: ([\w-]+) -->\n)(.*?)(<!-- /report -->)", re.DOTALL)
NOT_RECORDED = "not recorded"
RECOVERED = "recovered"
PROVENANCE = "provenance.json"
ENGINE_ORDER = ("viseme-lerp", "anime-graph", "dam", "cohen-massaro", "hmm", "expressive-dp")
METHODS = {
    "viseme-lerp": "static viseme key poses, linear between phoneme centres: the baseline",
    "anime-graph": "recorded motion fragments joined with the fewest jumps (Cao et al. 2004)",
    "dam": "Dominated Animeme Models: per-phoneme modes under dominance curves (Lin et al.)",
    "cohen-massaro": "`dam` with constant targets: Cohen-Massaro coarticulation",
    "hmm": "voice puppetry (Brand 1999): an HMM driven by phonemes, voice or both",
    "expressive-dp": "constrained DP over captured motion nodes with emotion (Deng, Neumann 2008)",
}


@dataclass(frozen=True)
class Bench:
    """The results directory, read file by file."""

    directory: Path

    def load(self, name: str) -> Any:
        return json.loads((self.directory / name).read_text(encoding="utf-8"))

    def exists(self, name: str) -> bool:
        return (self.directory / name).is_file()

    def provenance(self, name: str) -> dict[str, Any]:
        """What ``provenance.json`` recovered for ``name``: machine, date, command, labels."""
        path = self.directory / PROVENANCE
        if not path.is_file():
            return {}
        files = json.loads(path.read_text(encoding="utf-8")).get("files", {})
        entry = files.get(name, {})
        return entry if isinstance(entry, dict) else {}

    def source(self, name: str, doc: Any) -> str:
        """``source`` of ``name``, with what provenance.json recovered for it."""
        return source(name, doc, self.provenance(name))


def number(value: float, digits: int = 1) -> str:
    """``value`` rounded to ``digits`` decimals, with a true minus sign kept as ``-``."""
    return f"{value:.{digits}f}"


def percent(share: float) -> str:
    return f"{100 * share:.1f}%"


def table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _machine(doc: Any, recovered: dict[str, Any]) -> str:
    machine = doc.get("machine") if isinstance(doc, dict) else None
    if isinstance(machine, dict):
        return ", ".join(f"{key} {value}" for key, value in machine.items())
    if recovered.get("machine"):
        return f"{recovered['machine']} ({RECOVERED})"
    return NOT_RECORDED


def _date(doc: Any, recovered: dict[str, Any]) -> str:
    date = doc.get("date") if isinstance(doc, dict) else None
    if date:
        return str(date)
    if recovered.get("date"):
        return f"{recovered['date']} ({RECOVERED})"
    return NOT_RECORDED


def _command(doc: Any, recovered: dict[str, Any]) -> str:
    if isinstance(doc, dict) and doc.get("command"):
        return f"`{doc['command']}`"
    if recovered.get("command"):
        return f"`{recovered['command']}` ({RECOVERED})"
    if isinstance(doc, dict) and doc.get("tool"):
        return f"{NOT_RECORDED} (tool `{doc['tool']}`; its options are the file's `config`)"
    return NOT_RECORDED


def _notes(doc: Any) -> list[str]:
    if not isinstance(doc, dict):
        return []
    return [f"{key}: {value}" for key, value in doc.items() if "note" in key and value]


def source(name: str, doc: Any, recovered: dict[str, Any] | None = None) -> str:
    """Where a block's figures come from: file, machine, date, command, recorded notes.
    ``recovered`` fills in what the file lacks (``Bench.provenance``)."""
    known = recovered or {}
    line = (
        f"Source: `bench/{name}`; machine: {_machine(doc, known)}; "
        f"date: {_date(doc, known)}; command: {_command(doc, known)}.\n"
    )
    notes = _notes(doc) + [f"{note} ({RECOVERED})" for note in _notes(known)]
    if notes:
        line += "Notes:\n\n" + "".join(f"- {note}\n" for note in notes)
    return line + "\n"


def rows_of(doc: Any) -> list[dict[str, Any]]:
    """A file's rows: its ``rows``, or the file itself when it is a list of rows (as those
    written before they recorded their machine, date and command are)."""
    rows: list[dict[str, Any]] = doc["rows"] if isinstance(doc, dict) else doc
    return rows


def _by_engine(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    known = {name: index for index, name in enumerate(ENGINE_ORDER)}
    return sorted(rows, key=lambda row: known.get(row["engine"], len(known)))


def _causal_call_us(calls: list[dict[str, Any]], engine: str) -> str:
    for row in calls:
        if row["engine"] == engine and row["rung"] == "causal":
            return f"{row['median_us']:.0f} µs"
    return "–"


def engines_summary(bench: Bench) -> str:
    """The README's table: one line per engine, quality and speed."""
    results = bench.load("results.json")
    calls = bench.load("stream_calls.json")
    rows = []
    for row in _by_engine(results["engines"]):
        rows.append(
            [
                f"`{row['engine']}`",
                METHODS.get(row["engine"], ""),
                f"{row['rms_error']:.4f} ({row['rms_ratio']:.2f})",
                percent(row["closure_rate"]),
                f"{row['ms_per_phoneme']:.4f} ({row['speed_ratio']:.1f}×)",
                _causal_call_us(rows_of(calls), row["engine"]),
            ]
        )
    header = [
        "engine",
        "method",
        "RMS to the recording (÷ baseline)",
        "/p b m/ closed",
        "offline ms / phoneme (× baseline)",
        "streamed call, causal rung",
    ]
    return (
        table(header, rows)
        + "\nQuality on the demo character's held-out lines (recorded lips close on "
        + f"{percent(results['recorded']['closure_rate'])} of /p b m/); speed ratios are to "
        + "`viseme-lerp` timed in the same run. Dates, machines and every rung: "
        + "[docs/reports/engines.md](docs/reports/engines.md).\n"
    )


def engines(bench: Bench) -> str:
    """Every engine's figures from ``lipstream bench``, each with the run it comes from."""
    results = bench.load("results.json")
    corpus = results["corpus"]
    text = bench.source("results.json", results)
    text += (
        f"Corpus `{corpus['name']}` (digest `{corpus['digest'][:12]}`, {corpus['fps']:g} fps): "
        f"{corpus['train_utterances']} training and {corpus['heldout_utterances']} held-out "
        "utterances.\n\n"
    )
    rows = []
    for row in _by_engine(results["engines"]):
        run = row.get("run_date") or results.get("date") or NOT_RECORDED
        speed_run = row.get("speed_run_date", run)
        rows.append(
            [
                f"`{row['engine']}`",
                f"{row['train_seconds']:.2f}",
                f"{row['ms_per_phoneme']:.4f} ({row['speed_ratio']:.1f}×)",
                f"{row['real_time_factor']:.5f}",
                f"{row['rms_error']:.4f} ({row['rms_ratio']:.2f})",
                f"{percent(row['closure_rate'])} ({row['closure_ratio']:.2f})",
                f"{row['closure_lag_ms']:.0f}" if "closure_lag_ms" in row else "–",
                f"{run}" + (f"; speed {speed_run}" if speed_run != run else ""),
            ]
        )
    text += table(
        [
            "engine",
            "train s",
            "ms / phoneme (× baseline)",
            "real-time factor",
            "RMS (÷ baseline)",
            "/p b m/ closed (÷ baseline)",
            "lip lag ms",
            "run",
        ],
        rows,
    )
    recorded = results["recorded"]
    text += (
        f"\nThe recordings close the lips on {percent(recorded['closure_rate'])} of /p b m/. "
        "Ratios are to `viseme-lerp` in the run of each row.\n"
    )
    emotions = [row for row in _by_engine(results["engines"]) if row.get("rms_by_emotion")]
    if emotions:
        names = sorted(emotions[0]["rms_by_emotion"])
        text += "\nRMS per emotion:\n\n" + table(
            ["engine", *names],
            (
                [f"`{row['engine']}`"] + [f"{row['rms_by_emotion'][name]:.4f}" for name in names]
                for row in emotions
            ),
        )
    text += "\nEach fidelity rung, best first (`lookahead_ms` at real-time input):\n\n"
    text += table(
        ["engine", "rung", "lookahead ms", "RMS", "/p b m/ closed", "RMS to the best rung"],
        (
            [
                f"`{rung['engine']}`",
                f"`{rung['rung']}`",
                f"{rung['lookahead_ms']:.0f}",
                f"{rung['rms_error']:.4f}",
                percent(rung["closure_rate"]),
                f"{rung['rms_vs_best']:.4f}",
            ]
            for rung in results["rungs"]
        ),
    )
    return text


def stream_calls(bench: Bench) -> str:
    calls = bench.load("stream_calls.json")
    return bench.source("stream_calls.json", calls) + table(
        ["engine", "rung", "calls", "median µs", "p90 µs", "mean µs"],
        (
            [
                f"`{row['engine']}`",
                f"`{row['rung']}`",
                str(row["calls"]),
                number(row["median_us"]),
                number(row["p90_us"]),
                number(row["mean_us"]),
            ]
            for row in _by_engine(rows_of(calls))
        ),
    )


def retarget_cost(bench: Bench) -> str:
    """CPU per frame of each rig preset's map: scipy's NNLS per frame and the compiled,
    warm-started one, side by side."""
    costs = bench.load("retarget_cost.json")
    return bench.source("retarget_cost.json", costs) + table(
        ["engine", "preset", "frames by NNLS", "scipy µs/frame", "compiled µs/frame", "ratio"],
        (
            [
                f"`{row['engine']}`",
                f"`{row['preset']}`",
                percent(row["nnls_share"]),
                number(row["scipy_us"]),
                number(row["compiled_us"]),
                f"{number(row['ratio'])}×",
            ]
            for row in _by_engine(rows_of(costs))
        ),
    )


CONNECTION_COST = "connection_cost.json"


def connection_cost(bench: Bench) -> str:
    """``python -m lipstream.bench.connection_cost``: server CPU per WebSocket opened and
    closed and per ``/healthz`` connection, each round and the median."""
    if not bench.exists(CONNECTION_COST):
        return (
            f"Not measured yet: no `bench/{CONNECTION_COST}` "
            "(`python -m lipstream.bench.connection_cost`).\n"
        )
    doc = bench.load(CONNECTION_COST)
    names = {"websocket": "WebSocket opened and closed", "healthz": "HTTP `GET /healthz`"}
    return bench.source(CONNECTION_COST, doc) + table(
        ["connection", "server CPU ms per connection, each round", "median"],
        (
            [
                names.get(leg, leg),
                ", ".join(number(value, 2) for value in figures["cpu_ms_per_connection"]),
                number(figures["median_ms"], 2),
            ]
            for leg, figures in doc["legs"].items()
        ),
    )


def _call_pairs(bench: Bench, name: str) -> str:
    doc = bench.load(name)
    header = (
        f"Before: `{doc['before']}`; after: `{doc['after']}`; "
        f"{doc['rows'][0]['rounds']} alternating rounds.\n\n"
    )
    return (
        bench.source(name, doc)
        + header
        + table(
            [
                "engine",
                "rung",
                "median µs before → after",
                "×",
                "mean µs before → after",
                "×",
                "rounds after lower",
            ],
            (
                [
                    f"`{row['engine']}`",
                    f"`{row['rung']}`",
                    f"{number(row['before_median_us'])} → {number(row['after_median_us'])}",
                    f"{row['median_ratio']:.3f}",
                    f"{number(row['before_mean_us'])} → {number(row['after_mean_us'])}",
                    f"{row['mean_ratio']:.3f}",
                    f"{row['rounds_after_lower']} of {row['rounds']}",
                ]
                for row in _by_engine(doc["rows"])
            ),
        )
    )


def call_pairs(name: str) -> Callable[[Bench], str]:
    """The block of one ``bench.call_pairs`` results file."""
    return lambda bench: _call_pairs(bench, name)


def lead0(bench: Bench) -> str:
    doc = bench.load("lead0_rungs.json")
    return bench.source("lead0_rungs.json", doc) + table(
        [
            "engine",
            "rung",
            "lookahead ms",
            "frames",
            "frame lag p50 / p99 ms",
            "first frame p50 / p99 ms",
        ],
        (
            [
                f"`{row['engine']}`",
                f"`{row['rung']}`",
                f"{row['lookahead_ms']:.0f}",
                str(row["frames"]),
                f"{number(row['lag_p50_ms'], 0)} / {number(row['lag_p99_ms'], 0)}",
                f"{number(row['first_frame_p50_ms'])} / {number(row['first_frame_p99_ms'])}",
            ]
            for row in _by_engine(rows_of(doc))
        ),
    )


def hmm_first_frame(bench: Bench) -> str:
    doc = bench.load("hmm_first_frame.json")
    text = bench.source("hmm_first_frame.json", doc)
    text += (
        f"Utterance `{doc['utterance']}` ({doc['audio_s']:.2f} s of audio) sent alone in "
        f"{doc['chunk_ms']:g} ms chunks at real time, {doc['fps']:g} fps:\n\n"
    )
    return text + table(
        ["rung", "requests", "lookahead ms", "first frame ms (median)", "audio sent by then ms"],
        (
            [
                f"`{rung}`",
                str(row["requests"]),
                f"{row['lookahead_ms']:.0f}",
                f"{row['first_frame_ms']:.0f}",
                f"{row['audio_sent_ms']:.0f}",
            ]
            for rung, row in doc["rungs"].items()
        ),
    )


def word_timings(bench: Bench) -> str:
    """Phoneme onset error per TTS timing format (``lipstream.bench.word_timings``)."""
    doc = bench.load("word_timings.json")
    text = bench.source("word_timings.json", doc)
    text += (
        f"{doc['heldout_sentences']} held-out demo sentences spoken by espeak-ng at "
        f"{', '.join(str(rate) for rate in doc['rates_wpm'])} words per minute "
        f"({doc['heldout_speech_s']:.0f} s of speech); the duration model trained on "
        f"{doc['training_sentences']} other sentences at the same rates. Onset error of every "
        "phoneme matched with espeak-ng's own, and of those after each word's first:\n\n"
    )
    rows = []
    for name, row in doc["formats"].items():
        rtf = row.get("real_time_factor")
        rows.append(
            [
                name,
                f"{row['median_ms']:.1f} / {row['p90_ms']:.1f}",
                f"{row['inner_median_ms']:.1f} / {row['inner_p90_ms']:.1f}",
                str(row["pairs"]),
                "" if rtf is None else f"{rtf:.4f}",
            ]
        )
    text += table(
        [
            "input",
            "onset error median / p90 ms",
            "after a word's first: median / p90 ms",
            "phonemes matched",
            "real-time factor",
        ],
        rows,
    )
    frames = doc.get("frames")
    if not frames:
        return text
    text += (
        f"\nFrames of the derived spans against the frames of espeak-ng's own spans, by "
        f"{frames['model']} at {frames['fps']:g} fps, the held-out sentences at "
        f"{frames['rate_wpm']} words per minute:\n\n"
    )
    return text + table(
        ["input", "RMS", "/p b m/ closures", "closure lag, abs. median / p90 ms"],
        (
            [
                name,
                f"{row['rms']:.4f}",
                str(row["closures"]),
                f"{row['closure_lag_median_abs_ms']:.1f} / {row['closure_lag_p90_abs_ms']:.1f}",
            ]
            for name, row in frames["formats"].items()
        ),
    )


ALIGNER_REAL = "aligner_real.json"
ALIGNER_CLIPS_LISTED = 6
GRID_POSITIONS = ("command", "colour", "preposition", "letter", "digit", "adverb")


def _position(index: int, count: int) -> str:
    """Word ``index`` (from 0) of ``count``, named by GRID's grammar when six."""
    return (
        f"{index + 1} ({GRID_POSITIONS[index]})" if count == len(GRID_POSITIONS) else str(index + 1)
    )


def _errors(summary: dict[str, Any]) -> str:
    return (
        f"{number(summary['median_ms'])} / {number(summary['p90_ms'])} / "
        f"{number(summary['max_ms'])} ({summary['mean_signed_ms']:+.1f})"
    )


def aligner_real(bench: Bench) -> str:
    """The forced aligner's word times against GRID's (``lipstream.bench.aligner_real``):
    each clip's row when there are a few, else the pooled row and the clips' spread."""
    if not bench.exists(ALIGNER_REAL):
        return (
            f"Not measured yet: no `bench/{ALIGNER_REAL}` "
            "(`python -m lipstream.bench.aligner_real`).\n"
        )
    doc = bench.load(ALIGNER_REAL)
    every, clips = doc["all"], doc["clips"]
    refused = doc.get("refused", [])
    text = bench.source(ALIGNER_REAL, doc)
    text += (
        f"{every['clips']} clip(s) with GRID's word times, {every['words']} words"
        + "".join(f"; `{row['clip']}` refused by the aligner (`{row['code']}`)" for row in refused)
        + ". Errors are |aligned − GRID's| in ms, median / p90 / max, with the mean signed "
        "error (aligned minus GRID's) in brackets"
        + (
            "; the pooled row's confidence is the clips' median (range), its real-time "
            "factor their median"
            if len(clips) > 1
            else ""
        )
        + ":\n\n"
    )
    shown = clips if len(clips) <= ALIGNER_CLIPS_LISTED else []
    rows = [
        [
            f"`{clip['clip']}` ({clip['audio_s']:.2f} s)",
            str(len(clip["words"])),
            _errors(clip["onset"]),
            _errors(clip["offset"]),
            number(clip["confidence"], 2),
            number(clip["real_time_factor"], 2),
        ]
        for clip in shown
    ]
    if len(clips) > 1:
        confidences = sorted(clip["confidence"] for clip in clips)
        factors = sorted(clip["real_time_factor"] for clip in clips)
        rows.append(
            [
                f"all {len(clips)} clips",
                str(every["words"]),
                _errors(every["onset"]),
                _errors(every["offset"]),
                f"{number(confidences[len(clips) // 2], 2)} "
                f"({number(confidences[0], 2)}–{number(confidences[-1], 2)})",
                number(factors[len(clips) // 2], 2),
            ]
        )
    header = ["clip", "words", "word onsets", "word offsets", "confidence", "real-time factor"]
    text += table(header, rows)
    positions = every.get("onset_by_position") or []
    if len(clips) > 1 and positions:
        text += "\nWord onsets by position in the sentence, over the clips:\n\n"
        text += table(
            ["word", "onset error ms"],
            [
                [_position(index, len(positions)), _errors(summary)]
                for index, summary in enumerate(positions)
            ],
        )
    return text


def _pair(stats: dict[str, Any] | None, key: str, digits: int = 0) -> str:
    values = stats.get(key) if stats else None
    if not values:
        return "–"
    return f"{number(values['p50'], digits)} / {number(values['p99'], digits)}"


def _failed(search: dict[str, Any]) -> dict[str, Any] | None:
    failed = [probe for probe in search["probes"] if not probe["passed"]]
    above = [probe for probe in failed if probe["streams"] > search["capacity_streams"]]
    return min(above, key=lambda probe: probe["streams"]) if above else None


def _capacity_rows(searches: list[dict[str, Any]]) -> list[list[str]]:
    rows = []
    for search in _by_engine(searches):
        held = search.get("at_capacity")
        failed = _failed(search)
        reference = search.get("reference") or {}
        failed_text = "–"
        if failed:
            refused = failed["requests"] - failed["successful_requests"]
            failed_text = (
                f"{failed['streams']} (p99 lag {failed['frame_lag_ms']['p99']:.0f} ms; "
                f"{refused} of {failed['requests']} requests failed)"
            )
        ratio = search.get("capacity_ratio")
        rows.append(
            [
                f"`{search['engine']}`",
                str(max(1, search["server_processes"] - 1)),
                str(search["capacity_streams"]),
                failed_text,
                str(reference.get("capacity_streams", "–")),
                f"{ratio:.2f}" if ratio is not None else "–",
                _pair(held, "frame_lag_ms"),
                _pair(held, "probe_first_frame_latency_ms"),
                (
                    f"{held['server_cores']:.2f} / {held['client_cores']:.2f}"
                    if held and "server_cores" in held
                    else "–"
                ),
            ]
        )
    return rows


CAPACITY_HEADER = [
    "engine",
    "workers",
    "sessions held",
    "first count failed",
    "reference held",
    "ratio",
    "frame lag p50 / p99 ms, at the count held",
    "first frame of a whole request p50 / p99 ms",
    "cores: server / load generator",
]


def _capacity(name: str, key: str = "searches") -> Callable[[Bench], str]:
    def render(bench: Bench) -> str:
        doc = bench.load(name)
        searches = doc[key]
        first = searches[0]
        budget = first.get("latency_budget_ms")
        text = bench.source(name, doc)
        text += (
            f"{first['fps']:g} fps, {first['clip_s']:g} s clips, phonemes sent "
            f"{first['lead_ms']:g} ms early, "
            + (f"a {budget:g} ms latency budget" if budget else "no latency budget")
            + f", {first['encoding']}. Criterion: {first['criterion']}.\n\n"
        )
        return text + table(CAPACITY_HEADER, _capacity_rows(searches))

    return render


def _cost(side: dict[str, Any]) -> str:
    value = side.get("cpu_ms_per_session_s")
    return "–" if value is None else number(value, 3)


def _rung(run: dict[str, Any]) -> str:
    budget = run.get("latency_budget_ms")
    conditions = f"lead {run['lead_ms']:g} ms, " + (
        f"budget {budget:g} ms" if budget is not None else "no budget"
    )
    return f"`{run['fidelity']}` ({conditions})"


CAUSAL_CPU_RATIO_TARGET = 1.25
BEST_CPU_RATIO_TARGET = 1.5


def _against_target(fidelity: str, ratio: float | None) -> str:
    """Whether ``ratio`` meets the target for its rung (causal rungs 1.25, best
    rungs 1.5), and if not by what factor it misses."""
    target = CAUSAL_CPU_RATIO_TARGET if "causal" in fidelity else BEST_CPU_RATIO_TARGET
    if ratio is None:
        return f"≤ {target:g}: not measured"
    if ratio <= target:
        return f"≤ {target:g}: met"
    return f"≤ {target:g}: missed by {number(ratio / target, 2)}×"


def cpu_per_session(bench: Bench, name: str = "cpu_per_session.json") -> str:
    doc = bench.load(name)
    rows = []
    for run in _by_engine(doc["runs"]):
        server, reference, ratio = run["server"], run["reference"], run.get("cpu_ratio")
        per_round = ", ".join(
            "–" if value is None else number(value, 2) for value in run["cpu_ratio_per_round"]
        )
        rows.append(
            [
                f"`{run['engine']}`",
                _rung(run),
                f"{run['streams']}, {run['rounds']} × {run['duration_s']:g} s",
                _cost(server),
                _cost(reference),
                "–" if ratio is None else f"**{number(ratio, 2)}** ({per_round})",
                " / ".join(
                    "–" if side["frame_lag_ms_p99"] is None else number(side["frame_lag_ms_p99"])
                    for side in (server, reference)
                ),
                " / ".join("yes" if side["held"] else "no" for side in (server, reference)),
                _against_target(run["fidelity"], ratio),
            ]
        )
    header = [
        "engine",
        "rung",
        "sessions, rounds × leg",
        "server CPU ms per session-second",
        "reference",
        "ratio (per round)",
        "p99 frame lag ms: server / reference",
        "count held: server / reference",
        "target",
    ]
    text = bench.source(name, doc) + (
        "Each round is one leg against the server, then one against the reference; every "
        "session streams one clip as long as the leg, at the fps of its command.\n\n"
    )
    commands = sorted({run["command"] for run in doc["runs"]})
    return (
        text
        + table(header, rows)
        + "\nEach run's command:\n\n"
        + "".join(f"- `{command}`\n" for command in commands)
    )


def message_cost(
    bench: Bench, name: str = "message_cost_cuts.json", change: str = "the cuts"
) -> str:
    doc = bench.load(name)
    rows = []
    for engine in [run["engine"] for run in _by_engine(doc["summary"])]:
        legs = [run for run in doc["runs"] if run["engine"] == engine]
        for tree in ("before", "after"):
            mine = [run for run in legs if run["tree"] == tree]
            if not mine:
                continue
            server = statistics.median(run["server_median_us"] for run in mine)
            reference = statistics.median(run["reference_median_us"] for run in mine)
            ratios = ", ".join(number(run["ratio"], 2) for run in mine)
            rows.append(
                [
                    f"`{engine}`",
                    f"`{mine[0]['fidelity']}`",
                    f"{tree} (`{mine[0]['revision']}`)",
                    f"{len(mine)} × {mine[0]['rounds']}",
                    number(server),
                    number(reference),
                    f"**{number(server / reference, 2)}** ({ratios})",
                ]
            )
    header = [
        "engine",
        "rung",
        "code",
        "runs × rounds",
        "server µs per phonemes message",
        "reference",
        "ratio (per run)",
    ]
    text = bench.source(name, doc) + (
        "Each run is one process (`python -m lipstream.bench.message_cost`, the code before "
        f"and after {change} in alternate runs) that streams the same requests to the "
        "server's app and to the reference app in alternate legs, with no sockets; a run's "
        "figure is its legs' median, the table's the median over its runs.\n\n"
    )
    return text + table(header, rows)


def websocket_layers(bench: Bench) -> str:
    name = "websocket_layers.json"
    doc = bench.load(name)
    text = bench.source(name, doc) + (
        f"Each layer carried {doc['messages']} binary messages of {doc['payload']} bytes "
        f"per round, {doc['rounds']} rounds, the layers in turn "
        "(`python -m lipstream.bench.websocket_layers`); the figure is the median round's "
        "process CPU per message, and the saving beside `starlette` (Starlette's "
        "`WebSocket`, what the endpoint uses) what it would save by speaking to that "
        "layer instead.\n\n"
    )
    rows = []
    above: dict[str, float] = {}
    for row in doc["layers"]:
        direction, median = row["direction"], row["median_us"]
        saved = "–" if direction not in above else number(above[direction] - median, 2)
        above.setdefault(direction, median)
        rows.append(
            [
                direction,
                f"`{row['layer']}`",
                number(median, 2),
                saved,
                ", ".join(number(value, 2) for value in row["us"]),
            ]
        )
    header = ["message", "layer", "µs per message", "saved beside `starlette`", "per round"]
    return text + table(header, rows)


def server_profile(bench: Bench) -> str:
    name = "server_profile.json"
    doc = bench.load(name)
    text = bench.source(name, doc) + (
        f"{doc['samples']} samples of the serving process, each counted in the first layer "
        "its stack passes through (`lipstream.bench.server_profile`); "
        f"{doc['event_loop_samples']} of them in the event loop's thread.\n\n"
    )
    layers = table(
        ["layer", "samples", "share of all", "share of the event loop's thread"],
        (
            [
                row["layer"],
                str(row["samples"]),
                percent(row["share"]),
                "–" if row["share_of_event_loop"] is None else percent(row["share_of_event_loop"]),
            ]
            for row in doc["layers"]
        ),
    )
    functions = table(
        ["innermost function", "samples", "share of the event loop's thread"],
        (
            [f"`{row['function']}`", str(row["samples"]), percent(row["share_of_event_loop"])]
            for row in doc["top_functions"]
        ),
    )
    return text + layers + "\nThe innermost functions that took the most samples:\n\n" + functions


def capacity_workers(bench: Bench) -> str:
    doc = bench.load("capacity_workers.json")
    text = bench.source("capacity_workers.json", doc)
    for key in ("two_workers", "ray_serve_two_replicas"):
        if doc.get(key):
            text += f"`{key}`:\n\n" + table(CAPACITY_HEADER, _capacity_rows(doc[key])) + "\n"
    return text


def loadtest(bench: Bench) -> str:
    doc = bench.load("loadtest.json")
    config = doc["config"]
    text = bench.source("loadtest.json", doc)
    text += (
        f"{config['streams']} sessions, {config['requests']} requests per clip, "
        f"`{config['engine']}` at {config['fps']:g} fps, phonemes sent {config['lead_ms']:g} ms "
        "early.\n\n"
    )
    return text + table(
        [
            "clip s",
            "requests (ok)",
            "first frame p50 / p99 ms",
            "stream fps p1",
            "frame lag p50 / p99 ms",
            "frames / s",
        ],
        (
            [
                f"{clip['clip_s']:g}",
                f"{clip['requests']} ({clip['successful_requests']})",
                _pair(clip, "first_frame_latency_ms", 1),
                f"{clip['fps']['p1']:.1f}",
                _pair(clip, "frame_lag_ms"),
                f"{clip['throughput_frames_per_s']:.0f}",
            ]
            for clip in doc["clips"]
        ),
    )


def _measured(doc: dict[str, Any], kind: type) -> list[tuple[str, Any]]:
    """The entries of a file keyed by what was measured (worker counts, URLs, runs),
    without its machine, date, command or notes."""
    skip = {"machine", "date", "command", "tool"}
    return [
        (key, value)
        for key, value in doc.items()
        if isinstance(value, kind) and key not in skip and "note" not in key
    ]


def scale_out(bench: Bench) -> str:
    memory = bench.load("workers_memory.json")
    text = bench.source("workers_memory.json", memory)
    models = memory.get("models")
    if isinstance(models, list) and models:
        engines = ", ".join(f"`{model['engine']}`" for model in models)
        megabytes = sum(model["bytes"] for model in models) / 1e6
        text += f"Models loaded: {engines} ({megabytes:.0f} MB of model files).\n\n"
    measured = _measured(memory.get("workers", memory), list)
    # USS (private pages): files written before it was recorded lack it.
    with_uss = all("uss_mib" in p for _, processes in measured for p in processes)
    rows = []
    for workers, processes in measured:
        served = [process for process in processes if process["role"] == "worker"]
        uss = [f"{max(p['uss_mib'] for p in served):.0f}"] if with_uss else []
        rows.append(
            [
                workers,
                f"{max(p['rss_mib'] for p in served):.0f}",
                f"{max(p['pss_mib'] for p in served):.0f}",
                *uss,
                f"{sum(p['pss_mib'] for p in processes):.0f}",
            ]
        )
    header = ["workers", "RSS per worker MiB", "PSS per worker MiB"]
    header += ["USS per worker MiB"] if with_uss else []
    text += table([*header, "PSS of all processes MiB"], rows)
    resume = bench.load("resume_time.json")
    text += "\n" + bench.source("resume_time.json", resume)
    text += table(
        ["utterances", "resume p50 ms", "resume max ms", "frames lost", "frames duplicated"],
        [
            [
                str(resume["utterances"]),
                f"{resume['resume_ms_p50']:.0f}",
                f"{resume['resume_ms_max']:.0f}",
                str(resume["frames_lost"]),
                str(resume["frames_duplicated"]),
            ]
        ],
    )
    proxy = bench.load("proxy_latency.json")
    text += "\n" + bench.source("proxy_latency.json", proxy)
    labels = bench.provenance("proxy_latency.json").get("labels", {})
    return text + table(
        ["URL", "what serves it", "blocks", "round trip p50 ms", "p99 ms"],
        (
            [
                f"`{url}`",
                labels.get(url, NOT_RECORDED),
                str(row["blocks"]),
                number(row["p50_ms"]),
                number(row["p99_ms"]),
            ]
            for url, row in _measured(proxy, dict)
        ),
    )


def soak(bench: Bench, name: str = "soak.json") -> str:
    doc = bench.load(name)
    config = doc["config"]
    valid = doc["valid"]
    healthz = doc["healthz"]
    text = bench.source(name, doc)
    text += (
        f"{config['duration_s']:g} s; {config['valid_sessions']} valid `{config['engine']}` "
        f"sessions at a time ({config['clip_s']:g} s clips, {config['fps']:g} fps, phonemes "
        f"sent {config['lead_ms']:g} ms early) among {config['hostile_per_kind']} clients of "
        "each hostile kind.\n\n"
    )
    text += table(
        ["figure", "value"],
        [
            [
                "valid requests that succeeded",
                f"{valid['successful_requests']} of {valid['requests']}",
            ],
            ["valid frame lag p99", f"{valid['frame_lag_ms']['p99']:.0f} ms"],
            [
                f"`/healthz` latency ({healthz['polls']} polls, "
                f"{sum(healthz['failures'].values())} failed)",
                f"p50 {healthz['latency_ms']['p50']:.0f} ms, p99 "
                f"{healthz['latency_ms']['p99']:.0f} ms, max {healthz['latency_ms']['max']:.0f} ms",
            ],
            ["peak server RSS", _peak_of_ceiling(doc["server_memory"])],
            ["undocumented errors", str(len(doc["undocumented_errors"]))],
        ],
    )
    return (
        text
        + "\n"
        + table(
            ["hostile kind", "attempts", "error codes", "closes"],
            (
                [
                    f"`{kind}`",
                    str(row["attempts"]),
                    ", ".join(f"`{c}` {n}" for c, n in row["error_codes"].items()) or "–",
                    ", ".join(f"{c} {n}" for c, n in row["closes"].items()) or "–",
                ]
                for kind, row in doc["hostile"].items()
            ),
        )
    )


def _peak_of_ceiling(memory: dict[str, Any]) -> str:
    peak = f"{memory['peak_rss_bytes'] / 2**20:.0f} MiB"
    ceiling = memory.get("ceiling_bytes")
    return f"{peak} of a {ceiling / 2**20:.0f} MiB ceiling" if ceiling else peak


def storm(bench: Bench) -> str:
    """One row per run of ``lipstream loadtest storm``: lags on the client's clock, each run
    with its own machine, date and command."""
    doc = bench.load("storm.json")
    text = (
        "Source: `bench/storm.json`, one entry per run, each with its machine, date and "
        "command.\n\n"
    )
    rows, runs = [], []
    for name, run in _measured(doc, dict):
        report = run["report"]
        health = report["healthz"]
        rows.append(
            [
                f"`{name}`",
                f"{report['connections']} {report['kind']} + {report['baseline']} baseline",
                ", ".join(f"{outcome} {n}" for outcome, n in report["outcomes"].items()),
                _lag(report.get("lag_ms")),
                _lag(report.get("baseline_lag_ms")),
                " / ".join(
                    f"{number(health[port]['latency_ms']['p99'], 0)} ({health[port]['failed']} "
                    "failed)"
                    if port in health
                    else "–"
                    for port in ("serving", "health_port")
                ),
                f"{number(report['peak_rss_mb'], 0)} of {number(report['memory_ceiling_mb'], 0)}",
                number(report["client_loop_lag_ms"]["p99"], 1),
            ]
        )
        machine = ", ".join(f"{key} {value}" for key, value in run["machine"].items())
        runs.append(f"- `{name}`: {run['date']}; {machine}; `{run['command']}`\n")
    text += table(
        [
            "run",
            "sessions opened",
            "outcomes",
            "admitted sessions' lag p50 / p99 ms",
            "baseline sessions' lag p50 / p99 ms",
            "`/healthz` p99 ms: serving port / liveness port",
            "peak RSS of ceiling MiB",
            "load generator's loop lag p99 ms",
        ],
        rows,
    )
    return text + "\nRuns:\n\n" + "".join(runs)


def _lag(lag: dict[str, float] | None) -> str:
    if not lag:
        return "–"
    return f"{number(lag['p50'], 1)} / {number(lag['p99'], 1)}"


FIRST_START = "first_start.json"


def _seconds(value: float) -> str:
    return f"{value:.1f} s"


def first_start_summary(bench: Bench) -> str:
    """The README's line on start-up time, from ``first_start.json`` when it exists."""
    link = "[docs/reports/first-start.md](docs/reports/first-start.md)"
    if not bench.exists(FIRST_START):
        return f"Phase times of a first and a later start: {link}.\n"
    doc = bench.load(FIRST_START)
    told = "; ".join(
        f"{start['start']} start {_seconds(start['total_s'])}{_phase_groups(start['phases'])}"
        for start in doc["starts"]
    )
    cores = doc.get("machine", {}).get("cores")
    machine = f" on {cores} cores" if cores else ""
    return (
        f"Measured with `lipstream serve`{machine}: {told} "
        f"(each phase, machine and date: {link}).\n"
    )


PHASE_GROUPS = (
    ("importing", "imports"),
    ("generating", "corpus"),
    ("training ", "training"),
    ("checking", "loading"),
    ("loading", "loading"),
    ("warming up", "calibration"),
    ("calibrating", "calibration"),
)


def _phase_groups(phases: dict[str, float]) -> str:
    """A start's phases summed into a few groups, in order. Each engine's own training step
    runs inside the parallel step (``training N engines on P processes``), so only that
    one counts toward training."""
    groups: dict[str, float] = {}
    for name, seconds in phases.items():
        if name.startswith("training ") and " engines on " not in name:
            continue
        group = next((label for prefix, label in PHASE_GROUPS if name.startswith(prefix)), None)
        if group is not None:
            groups[group] = groups.get(group, 0.0) + seconds
    told = ", ".join(f"{label} {_seconds(seconds)}" for label, seconds in groups.items())
    return f" ({told})" if told else ""


def first_start(bench: Bench) -> str:
    """Each phase of a first start (empty ``$LIPSTREAM_HOME``) and of a later one."""
    if not bench.exists(FIRST_START):
        return (
            f"Not measured yet: no `bench/{FIRST_START}`. Its shape: `machine`, `date`, "
            "`command`, and `starts`, a list of `{start, total_s, phases: {name: seconds}}`.\n"
        )
    doc = bench.load(FIRST_START)
    text = bench.source(FIRST_START, doc)
    for start in doc["starts"]:
        text += f"{start['start'].capitalize()} start, {_seconds(start['total_s'])} in all:\n\n"
        text += table(
            ["phase", "seconds"],
            ([f"`{name}`", f"{seconds:.1f}"] for name, seconds in start["phases"].items()),
        )
        text += "\n"
    return text


LANGUAGES = "languages.json"


def _languages_doc(bench: Bench) -> Any | None:
    return bench.load(LANGUAGES) if bench.exists(LANGUAGES) else None


def languages(bench: Bench) -> str:
    """Each espeak-ng language: its voice, the phonemes its sample holds, whether all map."""
    doc = _languages_doc(bench)
    if doc is None:
        return (
            f"Not measured yet: no `bench/{LANGUAGES}` (`python -m lipstream.bench.languages`).\n"
        )
    served = set(doc.get("served", []))
    rows = []
    for row in doc["languages"]:
        if "error" in row:
            rows.append(
                [f"`{row['code']}`", row["title"], "", "", f"not spoken: {row['error']}", ""]
            )
            continue
        unmapped = ", ".join(f"`{name}`" for name in row["unmapped"])
        rows.append(
            [
                f"`{row['code']}`",
                row["title"] + (" (sentence)" if row["sample"] else ""),
                f"`{row['file']}`",
                str(len(row["phonemes"]) + len(row["unmapped"])),
                "yes" if row["maps_fully"] else f"no: {unmapped}",
                "tested" if row["code"] in served else "",
            ]
        )
    fully = sum(1 for row in doc["languages"] if row.get("maps_fully"))
    header = (
        f"{doc.get('espeak_ng', 'espeak-ng')}: {fully} of {len(doc['languages'])} languages "
        f"map fully. Sample: the numbers `{doc['numbers']}`, plus a sentence where marked.\n\n"
    )
    return (
        bench.source(LANGUAGES, doc)
        + header
        + table(
            ["lang", "language", "espeak-ng voice", "phonemes", "maps fully", "end to end"], rows
        )
    )


def _code(text: str) -> str:
    return f"`` {text} ``" if "`" in text else f"`{text}`"


def language_phonemes(bench: Bench) -> str:
    """Every phoneme name the survey met, its IPA, the phonemes it maps to, its languages."""
    doc = _languages_doc(bench)
    if doc is None:
        return f"Not measured yet: no `bench/{LANGUAGES}`.\n"
    speakers: dict[tuple[str, str], list[str]] = {}
    for row in doc["languages"]:
        for name in row.get("phonemes", []):
            speakers.setdefault((row["names"], name), []).append(row["code"])
    rows = []
    for (names, name), codes in sorted(speakers.items()):
        entry = doc["phonemes"][names][name]
        ipa, mapped = entry["ipa"], " ".join(entry["maps_to"]) or "(lengthens the phoneme before)"
        shown = ", ".join(codes[:8]) + (f" and {len(codes) - 8} more" if len(codes) > 8 else "")
        rows.append([_code(name), names, _code(ipa), mapped, shown])
    return table(["espeak-ng name", "names", "as IPA", "phonemes", "languages"], rows)


CAPTURE = "capture.json"


def capture(bench: Bench) -> str:
    """``lipstream capture`` on one core: decode, tracking, the whole step, alignment."""
    if not bench.exists(CAPTURE):
        return f"Not measured yet: no `bench/{CAPTURE}` (`python -m lipstream.bench.capture`).\n"
    doc = bench.load(CAPTURE)
    load = doc.get("load_average_1min", {})
    text = bench.source(CAPTURE, doc)
    if load:
        text += (
            f"Load average (1 min) {number(load['before'], 1)} before, "
            f"{number(load['after'], 1)} after.\n\n"
        )
    rows = []
    for run in doc["runs"]:
        cpu = run["per_cpu_second"]
        for label, key in (
            ("decoding (PyAV, to RGB), frames/s", "decode_fps"),
            ("tracking (FaceMesh), frames/s", "tracking_fps"),
            ("whole capture step, frames/s", "capture_fps"),
            ("alignment, s per s of audio", "alignment_real_time_factor"),
        ):
            rows.append(
                [
                    f"`{run['video']}` ({run['frames']} frames)",
                    label,
                    number(run[key], 2 if "factor" in key else 0),
                    number(cpu[key], 2 if "factor" in key else 0),
                ]
            )
    return text + table(["video", "step", "per wall-clock second", "per CPU second"], rows)


REAL_FACES = "real_faces.json"


def _signed(value: float | None, digits: int = 0) -> str:
    return "–" if value is None else f"{value:+.{digits}f}"


def real_faces_summary(bench: Bench) -> str:
    """The README's line: aperture r and closure lag on real lips, engines against the
    baseline."""
    doc = bench.load(REAL_FACES)
    rows = _by_engine(doc["engines"])
    learned = [row for row in rows if row["engine"] != "viseme-lerp"]
    base = next(row for row in rows if row["engine"] == "viseme-lerp")
    best = max(learned, key=lambda row: row["aperture_r"] or -1.0)
    lags = [row["closure_lag_ms"] for row in learned if row["closure_lag_ms"] is not None]
    return (
        "Real lips (GRID): aperture r up to "
        f"{best['aperture_r']:.2f} (`{best['engine']}`; `viseme-lerp` {base['aperture_r']:.2f}), "
        f"closure lag {_signed(min(lags, default=None))} to "
        f"{_signed(max(lags, default=None))} ms "
        f"(`viseme-lerp` {_signed(base['closure_lag_ms'])}; "
        f"[more](docs/reports/engines.md#real-faces)).\n"
    )


def _trained_on(doc: dict[str, Any]) -> str:
    models = doc.get("models", {}).values()
    pairs = sorted(
        {(m["character"], m["corpus_digest"][:12]) for m in models if isinstance(m, dict)}
    )
    return "".join(f" Models of `{name}` (corpus digest `{digest}`)." for name, digest in pairs)


def real_faces(bench: Bench) -> str:
    """``lipstream bench --real``: every engine of the demo character against real lips."""
    if not bench.exists(REAL_FACES):
        return f"Not measured yet: no `bench/{REAL_FACES}` (`lipstream bench --real`).\n"
    doc = bench.load(REAL_FACES)
    corpus, recorded = doc["corpus"], doc["recorded"]
    text = bench.source(REAL_FACES, doc)
    text += (
        f"Corpus `{corpus['name']}` (digest `{corpus['digest'][:12]}`, {corpus['fps']:g} fps): "
        f"{corpus['clips']} clips, {corpus['speakers']} speakers; the real lips close on "
        f"{percent(recorded['closure_rate'])} of their {recorded['bilabials']} /p b m/ "
        f"(threshold {recorded['closure_threshold']:.3f}).{_trained_on(doc)}\n\n"
    )
    rows = []
    for row in _by_engine(doc["engines"]):
        rate = row["closure_rate"]
        rows.append(
            [
                f"`{row['engine']}`",
                "–" if row["aperture_r"] is None else number(row["aperture_r"], 3),
                "–" if rate is None else percent(rate),
                _signed(row["closure_lag_ms"], 1)
                + (
                    ""
                    if row.get("closure_lag_se_ms") is None
                    else f" ± {row['closure_lag_se_ms']:.1f}"
                ),
                "–" if row["closure_lag_sd_ms"] is None else number(row["closure_lag_sd_ms"], 1),
                str(row["closures_timed"]),
                str(row["clips_mapped_on_themselves"]),
            ]
        )
    header = [
        "engine",
        "aperture r",
        "/p b m/ closed",
        "closure lag ms (mean ± se)",
        "lag sd ms",
        "closures timed",
        "clips mapped on themselves",
    ]
    return text + table(header, rows)


SENTENCES_CURVE = "sentences_curve.json"


def _median_range(cell: dict[str, float] | None, digits: int, scale: float = 1.0) -> str:
    if cell is None:
        return "–"
    low, mid, high = (round(scale * cell[key], digits) + 0.0 for key in ("min", "median", "max"))
    return f"{mid:.{digits}f} ({low:.{digits}f}–{high:.{digits}f})"


def _smallest_size_below(
    rows: Sequence[dict[str, Any]], engine: str, figure: str, bound: float
) -> str:
    """The smallest N at which ``engine``'s median ``figure`` falls below ``bound``."""
    sizes = [
        row["n"]
        for row in rows
        if row["engine"] == engine and row[figure] is not None and row[figure]["median"] < bound
    ]
    return str(min(sizes)) if sizes else "none measured"


def sentences_curve(bench: Bench) -> str:
    """``python -m lipstream.bench.sentences``: held-out quality against the number of
    sentences a person records, every engine beside ``viseme-lerp`` and the demo models."""
    if not bench.exists(SENTENCES_CURVE):
        return (
            f"Not measured yet: no `bench/{SENTENCES_CURVE}` "
            "(`python -m lipstream.bench.sentences`).\n"
        )
    doc = bench.load(SENTENCES_CURVE)
    held = doc["heldout"]
    text = bench.source(SENTENCES_CURVE, doc)
    text += (
        f"Speaker `{doc['speaker']['name']}` (not one of the demo character's), "
        f"{doc['emotion']}, {doc['fps']:g} fps; {doc['draws']} seeded draws (seed {doc['seed']}) "
        f"of N sentences from a pool of {len(doc['pool_stems'])}; held-out set of "
        f"{len(held['stems'])} sentences (digest `{held['digest'][:12]}`), whose recorded lips "
        f"close on {percent(held['recorded_closure_rate'])} of /p b m/. Each cell: median "
        "(lowest–highest) over the draws; RMS ÷ base is against `viseme-lerp` trained on "
        "the same draw.\n\n"
    )
    rows = []
    curve = sorted(doc["curve"], key=lambda row: (ENGINE_ORDER.index(row["engine"]), row["n"]))
    for row in curve:
        rows.append(
            [
                f"`{row['engine']}`",
                str(row["n"]),
                _median_range(row["rms_error"], 4),
                _median_range(row["rms_ratio"], 3),
                _median_range(row["aperture_r"], 3),
                _median_range(row["closure_rate"], 0, 100.0),
                _median_range(row["closure_lag_ms"], 0),
                _median_range(row["train_cpu_s"], 2),
                f"{row['failed']} of {row['draws']}" if row["failed"] else "–",
            ]
        )
    header = ["engine", "N", "RMS", "RMS ÷ base", "aperture r", "/p b m/ closed %"]
    header += ["closure lag ms", "train CPU s", "failed"]
    text += table(header, rows)
    demo = {row["engine"]: row for row in doc["demo"]}
    if demo:
        text += (
            "\nThe demo character's shipped models, trained on "
            f"{next(iter(demo.values()))['train_utterances']} utterances of three other "
            "speakers, on the same held-out set, and the smallest N whose median beats them:\n\n"
        )
        demo_rows = []
        for engine in ENGINE_ORDER:
            if engine not in demo:
                continue
            row = demo[engine]
            demo_rows.append(
                [
                    f"`{engine}`",
                    number(row["rms_error"], 4),
                    "–" if row["aperture_r"] is None else number(row["aperture_r"], 3),
                    "–" if row["closure_rate"] is None else percent(row["closure_rate"]),
                    _signed(row["closure_lag_ms"]),
                    _smallest_size_below(curve, engine, "rms_error", row["rms_error"]),
                    "(the base)"
                    if engine == "viseme-lerp"
                    else _smallest_size_below(curve, engine, "rms_ratio", 1.0),
                ]
            )
        demo_header = ["engine", "demo RMS", "demo aperture r", "demo /p b m/ closed"]
        demo_header += ["demo closure lag ms", "N beating its demo model (RMS)"]
        demo_header += ["N beating personal `viseme-lerp` (RMS)"]
        text += table(demo_header, demo_rows)
    real = doc.get("real_faces")
    if real:
        text += (
            f"\nReal faces: `{real['corpus']}` holds {real['clips']} clips under "
            f"{real['speakers']} speaker labels, at most {real['most_clips_of_one_speaker']} "
            "under one, so "
            + (
                "a curve can be drawn from it.\n"
                if real["curve_possible"]
                else "no speaker's curve can be drawn from it.\n"
            )
        )
    return text


def sentences_curve_summary(bench: Bench) -> str:
    """One line: where the curve is and how many draws and sizes it spans."""
    if not bench.exists(SENTENCES_CURVE):
        return f"Not measured yet: no `bench/{SENTENCES_CURVE}`.\n"
    doc = bench.load(SENTENCES_CURVE)
    sizes = ", ".join(str(n) for n in doc["sizes"])
    return (
        f"`bench/{SENTENCES_CURVE}` ({doc['date']}): {len(doc['engines'])} engines trained on "
        f"N = {sizes} sentences of one generated speaker, {doc['draws']} draws each, scored on "
        f"{len(doc['heldout']['stems'])} held-out sentences; "
        "[how-to/record-your-face.md](../how-to/record-your-face.md#how-much-speech-is-enough).\n"
    )


REAL_FACES_BEFORE = "real_faces_before.json"
DEMO_CALIBRATION = "demo_calibration.json"


def _mean_sd(summary: dict[str, Any], digits: int = 0, signed: bool = True) -> str:
    if summary["mean"] is None:
        return "–"
    mean = f"{summary['mean']:+.{digits}f}" if signed else f"{summary['mean']:.{digits}f}"
    spread = "" if summary["sd"] is None else f" ± {summary['sd']:.{digits}f}"
    return f"{mean}{spread} (n {summary['count']})"


def demo_calibration(bench: Bench) -> str:
    """The demo character's motion against the real faces, corpus by corpus, on the three
    measures it is calibrated to (``lipstream.bench.demo_calibration``)."""
    if not bench.exists(DEMO_CALIBRATION):
        return f"Not measured yet: no `bench/{DEMO_CALIBRATION}`.\n"
    doc = bench.load(DEMO_CALIBRATION)
    corpora = doc["corpora"]
    names = list(corpora)
    text = bench.source(DEMO_CALIBRATION, doc)
    text += f"All read on a {doc['measure_fps']:g} fps grid; mean ± sd (count) or median.\n\n"
    header = [
        "measure",
        *(
            f"{name} (`{corpora[name]['name']}`, {corpora[name]['utterances']} utt.)"
            for name in names
        ),
    ]
    rows = [
        ["/p b m/ closure centre less the acoustic onset, ms"]
        + [_mean_sd(corpora[n]["measures"]["closure_from_onset_ms"]) for n in names],
        ["the same, as a share of the /p b m/ span"]
        + [_mean_sd(corpora[n]["measures"]["closure_share"], 2) for n in names],
        ["peak opening speed, aperture ranges per s (median)"]
        + [_median(corpora[n]["measures"]["opening_speed_median"]) for n in names],
        ["peak closing speed, aperture ranges per s (median)"]
        + [_median(corpora[n]["measures"]["closing_speed_median"]) for n in names],
        ["rounding halfway up, less the rounded vowel's onset, ms"]
        + [_mean_sd(corpora[n]["measures"]["rounding_half_rise_ms"]) for n in names],
    ]
    return text + table(header, rows) + _phone_aperture_table(corpora, names)


PHONE_APERTURE_MIN_REAL = 10


def _phone_aperture_table(corpora: dict[str, Any], names: Sequence[str]) -> str:
    """Mean lip aperture over each phoneme's spans, as a share of its utterance's speech
    range, for the phonemes the real set holds at least ``PHONE_APERTURE_MIN_REAL`` times;
    empty for results measured before the measure existed."""
    measures = [corpora[n]["measures"].get("phone_apertures") for n in names]
    if any(m is None for m in measures):
        return ""
    real = measures[0]
    phonemes = sorted(
        (p for p, s in real.items() if s["count"] >= PHONE_APERTURE_MIN_REAL),
        key=lambda p: -real[p]["count"],
    )
    rows = [
        [f"`{p}`"] + [_mean_sd(m[p], 2, signed=False) if p in m else "–" for m in measures]
        for p in phonemes
    ]
    header = ["lip aperture over the phoneme, share of the speech range", *names]
    return (
        "\nLip aperture by phoneme (mean ± sd (count); the phonemes the first corpus holds "
        f"at least {PHONE_APERTURE_MIN_REAL} times):\n\n" + table(header, rows)
    )


CLOSURE_SOURCES = "closure_sources.json"
CLOSURE_CONTEXTS = ("all", "after_silence", "after_speech")


def _lag_cell(summary: dict[str, Any]) -> str:
    if summary["mean_ms"] is None:
        return "–"
    se = "" if summary["se_ms"] is None else f" ± {summary['se_ms']:.1f}"
    return f"{summary['mean_ms']:+.1f}{se} (n {summary['count']})"


HMM_CLOSURE_LAG = "hmm_closure_lag.json"
HMM_CONVENTIONS = {
    "floor": "⌊k R / f⌋, held over [j / R, (j + 1) / R) (the engine's)",
    "nearest": "⌊k R / f + ½⌋, the nearest instant",
    "ceil": "⌈k R / f⌉, the first backward difference covering the frame's",
}
HMM_SAMPLINGS = {
    "instant": "at j / R (the engine's default)",
    "centre": "at (j + ½) / R",
}
HMM_SHIFTS = {  # the others are the rungs, by name
    "offline": "demo held-out, offline",
    "real_behind_character": "real clips, behind the character (offline)",
}


def hmm_closure_lag(bench: Bench) -> str:
    """Phoneme-driven `hmm`'s closure lag trained on the face at each HMM frame's instant
    and at the centre of its hold interval, with each convention for the state of a
    trajectory frame, on the demo's held-out lines and the real-face set, on each served
    rung, and over EM seeds (``lipstream.bench.hmm_closure_lag``)."""
    if not bench.exists(HMM_CLOSURE_LAG):
        return f"Not measured yet: no `bench/{HMM_CLOSURE_LAG}`.\n"
    doc = bench.load(HMM_CLOSURE_LAG)
    samplings = doc["samplings"]
    first = samplings["centre"]
    demo, real = first["demo"], first["real"]
    worst = max(samplings[name]["demo"]["floor_max_abs_diff"] for name in HMM_SAMPLINGS)
    text = bench.source(HMM_CLOSURE_LAG, doc)
    text += (
        f"`hmm` {doc['model']} of `{doc['corpus']['name']}` (seed {doc['seed']}), trained on the "
        f"face at the instants j / R (`sample_offset` {samplings['instant']['sample_offset']:g}) "
        f"and at the hold intervals' centres (`sample_offset` {first['sample_offset']:g}), "
        "driven by phonemes, offline rung; "
        f"{demo['lines']} held-out lines at {doc['corpus']['fps']:g} fps and {real['clips']} "
        f"real clips at {real['fps']:g} fps. Closure lag in ms, mean ± standard error (count); "
        f"the `floor` rows reproduce the engines' frames to {worst:.0e}.\n\n"
    )
    header = [
        "face sampled",
        "state of trajectory frame k",
        "demo held-out, behind the recordings",
        "shift from `floor` (paired)",
        "demo RMS",
        "real clips, behind the character",
        "real clips, behind the real lips",
    ]
    rows = []
    for sampling, said in HMM_SAMPLINGS.items():
        found = samplings[sampling]
        for name, meaning in HMM_CONVENTIONS.items():
            row, grid = found["demo"]["conventions"][name], found["real"]["conventions"][name]
            rows.append(
                [
                    f"{said}: `sample_offset` {found['sample_offset']:g}",
                    f"`{name}`: {meaning}",
                    _lag_cell(row["lag"]),
                    _lag_cell(row["shift_from_floor"]),
                    f"{row['rms']:.5f}",
                    _lag_cell(grid["behind_character"]["all"]),
                    _lag_cell(grid["behind_real"]["all"]),
                ]
            )
    text += table(header, rows)
    text += (
        "\nThe engines' own frames (`floor`) by context: the demo's held-out lines behind the "
        "recordings, the real clips behind the character:\n\n"
    )
    contexts = [
        [said, where] + [_lag_cell(by[c]) for c in CLOSURE_CONTEXTS]
        for name, said in HMM_SAMPLINGS.items()
        for where, by in (
            ("demo held-out", samplings[name]["demo"]["conventions"]["floor"]["by_context"]),
            ("real clips", samplings[name]["real"]["conventions"]["floor"]["behind_character"]),
        )
    ]
    header = ["face sampled", "lines", "all /p b m/", "after silence", "after speech"]
    text += table(header, contexts)
    text += (
        "\nThe served rungs (`floor`), driven by phonemes, on the demo's held-out lines, and "
        "the hold-centre model's shift from the instant-sampled one, span by span:\n\n"
    )
    before, after = samplings["instant"]["demo"]["rungs"], demo["rungs"]
    shifts = first["shift_from_instant"]
    rungs = [
        [
            f"`{rung}`",
            _lag_cell(before[rung]["lag"]),
            f"{before[rung]['rms']:.5f}",
            _lag_cell(after[rung]["lag"]),
            f"{after[rung]['rms']:.5f}",
            _lag_cell(shifts[rung]),
        ]
        for rung in after
    ]
    header = [
        "rung",
        "lag, instants",
        "RMS, instants",
        "lag, hold centres",
        "RMS, hold centres",
        "shift (paired)",
    ]
    text += table(header, rungs)
    seeds = [doc["seed"]] + [row["seed"] for row in doc["seeds"]]
    text += (
        "\nEM from other seeds (both samplings trained again from each): the hold-centre shift "
        "from the instant-sampled model, paired span by span, per seed, and its mean over "
        f"the {len(seeds)} seeds ± the standard error across them:\n\n"
    )
    per_seed = [shifts] + [row["shift"] for row in doc["seeds"]]
    header = ["shift of the closures", *(f"seed {seed}" for seed in seeds), "mean over seeds"]
    sweep = [
        [
            said,
            *(_lag_cell(shift[name]) for shift in per_seed),
            _lag_cell(doc["seed_mean_shift"][name]),
        ]
        for name, said in (
            (name, HMM_SHIFTS.get(name, f"demo held-out, `{name}`"))
            for name in doc["seed_mean_shift"]
        )
    ]
    text += table(header, sweep)
    own = [
        (
            doc["seed"],
            samplings["instant"]["demo"]["conventions"]["floor"]["rms"],
            demo["conventions"]["floor"]["rms"],
        )
    ]
    own += [(row["seed"], row["instant"]["rms"], row["centre"]["rms"]) for row in doc["seeds"]]
    rms = [[f"seed {seed}", f"{before:.5f}", f"{after:.5f}"] for seed, before, after in own]
    text += "\nThe demo held-out RMS (offline rung, the engines' frames) per seed:\n\n"
    return text + table(["seed", "instants", "hold centres"], rms)


def closure_sources(bench: Bench) -> str:
    """Each engine's closure lag on the real lips split into its lag behind the demo
    character on the same phones and the character's behind the real lips
    (``lipstream.bench.closure_sources``)."""
    if not bench.exists(CLOSURE_SOURCES):
        return f"Not measured yet: no `bench/{CLOSURE_SOURCES}`.\n"
    doc = bench.load(CLOSURE_SOURCES)
    text = bench.source(CLOSURE_SOURCES, doc)
    text += (
        f"{doc['clips']} clips of `{doc['corpus']['name']}`, {doc['corpus']['fps']:g} fps; "
        "closure lag in ms, mean ± standard error (count)."
    )
    if "character_aperture_r" in doc:
        text += (
            " The character's lip aperture against the real lips, on the speech frames: "
            f"r {doc['character_aperture_r']:.3f} (mean over the clips)"
        )
        if "phoneme_mean_aperture_r" in doc:
            text += (
                "; a context-free predictor (each phoneme's mean real aperture over the "
                f"other clips, smoothed over 40 ms): r {doc['phoneme_mean_aperture_r']:.3f}"
            )
        text += "."
    text += "\n\n"
    header = ["lag", "all /p b m/", "after silence", "after speech"]
    rows = [
        ["the character behind the real lips"]
        + [_lag_cell(doc["character_behind_real"][c]) for c in CLOSURE_CONTEXTS]
    ]
    order = _by_engine({"engine": name} for name in doc["engines"])
    for engine in (row["engine"] for row in order):
        parts = doc["engines"][engine]
        rows.append(
            [f"`{engine}` behind the character"]
            + [_lag_cell(parts["behind_character"][c]) for c in CLOSURE_CONTEXTS]
        )
        rows.append(
            [f"`{engine}` behind the real lips"]
            + [_lag_cell(parts["behind_real"][c]) for c in CLOSURE_CONTEXTS]
        )
    return text + table(header, rows)


CLOSURE_TIMING = "closure_timing.json"
CLOSURE_TIMING_PARTS = {
    "train": "training lines, synthesized",
    "fit": "training lines, EM fit with each occurrence's own mode",
    "heldout": "held-out lines, synthesized",
}


def closure_timing(bench: Bench) -> str:
    """Where the demo models' /p b m/ closures sit against their own recordings: lag of the
    plateau's centre, closing and release, on the training lines, the EM fit and the
    held-out lines, and by the recording's closure centre (``lipstream.bench.closure_timing``)."""
    if not bench.exists(CLOSURE_TIMING):
        return f"Not measured yet: no `bench/{CLOSURE_TIMING}`.\n"
    doc = bench.load(CLOSURE_TIMING)
    text = bench.source(CLOSURE_TIMING, doc)
    engines = doc["engines"]
    train = next(iter(engines.values()))["train"]
    text += (
        f"The `{doc['corpus']['name']}` corpus at {doc['corpus']['fps']:g} fps; "
        f"{train['closures']} /p b m/ closures on the training lines. The recorded plateau "
        f"runs from {_signed(train['recorded_closing_ms'])} to "
        f"{_signed(train['recorded_release_ms'])} ms of the acoustic onset (means). "
        "Lags in ms, mean over closures; the centre's lag is the mean of the closing's "
        "and the release's."
    )
    if any("leads" in parts for parts in engines.values()):
        text += (
            " The engines with a bilabial lead are trained here without it "
            "(`bilabial_lead_s` = 0), as they were before it; the last table sweeps it."
        )
    text += "\n\n"
    header = ["engine", "lines", "closures", "centre lag", "closing lag", "release lag", "RMS"]
    rows = []
    for engine, parts in engines.items():
        for part, label in CLOSURE_TIMING_PARTS.items():
            if part not in parts:
                continue
            timed = parts[part]
            rows.append(
                [
                    f"`{engine}`",
                    label,
                    str(timed["closures"]),
                    _signed(timed["lag_ms"], 1),
                    _signed(timed["closing_lag_ms"], 1),
                    _signed(timed["release_lag_ms"], 1),
                    number(timed["rms"], 4),
                ]
            )
    text += table(header, rows) + "\n"
    columns = [
        (engine, part)
        for engine, parts in engines.items()
        for part in ("fit", "train")
        if part in parts
    ]
    groups = [
        [row["group"], str(row["count"]), _signed(row["recorded_ms"], 1)] for row in train["groups"]
    ]
    for engine, part in columns:
        for cells, row in zip(groups, engines[engine][part]["groups"], strict=True):
            cells.append("–" if row["lag_ms"] is None else _signed(row["lag_ms"], 1))
    text += (
        "By the recorded closure centre less the acoustic onset (training lines): the lag of "
        "each group.\n\n"
    )
    header = ["recorded centre, ms", "closures", "recorded mean"] + [
        f"`{engine}`" + (" fit" if part == "fit" else "") for engine, part in columns
    ]
    text += table(header, groups)
    text += _after_silence(doc.get("after_silence"))
    leads = [
        _lead_row(engine, row, parts.get("chosen_lead_ms"))
        for engine, parts in engines.items()
        for row in parts.get("leads", [])
    ]
    if not leads:
        return text
    text += (
        "\nThe sweep of `bilabial_lead_s`: trained and run with every bilabial's span started "
        "the lead earlier than its acoustic one (the preceding span shortened, by at most "
        "half), held-out lines timed against the recordings on the acoustic spans, offline "
        "(the search rungs) and on the `causal` rung (which keeps the acoustic spans); then "
        "offline on the real set's force-aligned phones, behind the character rendered on "
        "them and, for information, behind the real lips; **bold**: the engine's default."
        "\n\n"
    )
    header = [
        "engine",
        "lead, ms",
        "centre lag",
        "closing lag",
        "release lag",
        "RMS",
        "`causal` centre lag",
        "`causal` RMS",
        *REAL_PHONES_HEADER,
    ]
    text += table(header, leads)
    picks = [
        f"`{engine}` {parts['best_lead_ms']:g} ms (default {parts['chosen_lead_ms']:g} ms)"
        for engine, parts in engines.items()
        if "best_lead_ms" in parts and "chosen_lead_ms" in parts
    ]
    if picks:
        text += f"\n{LEAD_CRITERION}: " + ", ".join(picks) + ".\n"
    return text


BILABIAL_LEAD_SWEEP = "bilabial_lead_sweep.json"
REAL_PHONES_HEADER = ("behind the character, real phones", "behind the real lips")
LEAD_CRITERION = (
    "The sweep's pick (`closure_timing.best_lead_ms`), among the leads whose held-out RMS is "
    "not above the unled one, the least of the larger of the held-out centre lag and the lag "
    "behind the character on the real phones"
)


def bilabial_lead_hmm(bench: Bench) -> str:
    """``hmm`` trained and run at each bilabial lead: held-out closure lag and RMS per rung,
    averaged over the EM seeds, and the lag behind the real lips
    (``lipstream.bench.bilabial_lead_sweep``)."""
    if not bench.exists(BILABIAL_LEAD_SWEEP):
        return f"Not measured yet: no `bench/{BILABIAL_LEAD_SWEEP}`.\n"
    doc = bench.load(BILABIAL_LEAD_SWEEP)
    found = doc["engines"]["hmm"]
    rungs = doc["rungs"]
    chosen = found.get("chosen_lead_ms")
    text = bench.source(BILABIAL_LEAD_SWEEP, doc) + (
        f"`hmm` trained on the `{doc['corpus']['name']}` train split with each lead, from EM "
        f"seeds {', '.join(str(seed) for seed in found['seeds'])}, driven by phonemes; the "
        f"held-out lines' closures timed against the recordings (centre lag, ms, and RMS, "
        f"means over the seeds), on `{rungs[0]}` (centre, closing and release) and every "
        f"other rung; then `{rungs[0]}` on the force-aligned phones of the "
        f"{doc['real_set']['clips']} clips of `{doc['real_set']['name']}`, behind the "
        "character rendered on them and, for information, behind the real lips. "
        "**Bold**: the engine's default.\n\n"
    )
    header = ["lead, ms", "centre lag", "closing lag", "release lag", "RMS"]
    header += [f"`{rung}` lag / RMS" for rung in rungs[1:]] + list(REAL_PHONES_HEADER)
    rows = []
    for row in found["leads"]:
        lead = f"{row['lead_ms']:g}"
        rows.append(
            [
                f"**{lead}**" if row["lead_ms"] == chosen else lead,
                _signed(row["lag_ms"], 1),
                _signed(row["closing_lag_ms"], 1),
                _signed(row["release_lag_ms"], 1),
                number(row["rms"], 5),
                *(
                    f"{_signed(row['rungs'][rung]['lag_ms'], 1)} / "
                    f"{number(row['rungs'][rung]['rms'], 4)}"
                    for rung in rungs[1:]
                ),
                *_real_phones_cells(row),
            ]
        )
    text += table(header, rows)
    return text + (
        f"\n{LEAD_CRITERION} (`{rungs[0]}`, means over the seeds): "
        f"{found['best_lead_ms']:g} ms (default {chosen:g} ms).\n"
    )


HMM_RATE = "hmm_rate.json"


def hmm_rate(bench: Bench) -> str:
    """``hmm`` trained at each HMM frame rate: its closures on the real set's phones, its
    quality on the demo and its cost (``lipstream.bench.hmm_rate``)."""
    if not bench.exists(HMM_RATE):
        return f"Not measured yet: no `bench/{HMM_RATE}`.\n"
    doc = bench.load(HMM_RATE)
    rungs, rates = doc["rungs"], doc["rates"]
    first = rates[0]
    text = bench.source(HMM_RATE, doc) + (
        f"`hmm` trained on the `{doc['corpus']['name']}` train split at each HMM frame rate "
        f"(`hmm_fps`), from EM seeds {', '.join(str(seed) for seed in doc['seeds'])}, the "
        "training frames and the speaker prior scaled to the same seconds; means over the "
        f"seeds. On the force-aligned phones of the {doc['real_set']['clips']} clips of "
        f"`{doc['real_set']['name']}` (`{rungs[0]}` rung): the closure lag behind the real "
        "lips (the seeds' least and most in brackets) and behind the character rendered on "
        "them, and the lip-aperture r against the real lips. On the demo's held-out lines, "
        "driven by phonemes: closure lag and RMS per rung; driven by their audio alone: RMS "
        "as a share of `viseme-lerp`'s. CPU to fit, and to synthesize from audio, as a "
        f"ratio to {first['hmm_fps']:g} Hz's in the same run. **Bold**: the engine's "
        "default.\n\n"
    )
    header = ["HMM rate, Hz", "behind the real lips", "behind the character", "aperture r"]
    header += [f"`{rung}` lag / RMS" for rung in rungs]
    header += ["from audio, share of `viseme-lerp`", "fit CPU", "synthesis CPU"]
    rows = []
    for row in rates:
        rate = f"{row['hmm_fps']:g}"
        rows.append(
            [
                f"**{rate}**" if row["hmm_fps"] == doc["default_hmm_fps"] else rate,
                f"{_signed(row['real_lag_ms'], 1)} ({_signed(row['real_lag_min_ms'], 1)} .. "
                f"{_signed(row['real_lag_max_ms'], 1)})",
                _signed(row["real_phones_lag_ms"], 1),
                number(row["aperture_r"], 3),
                *(
                    f"{_signed(row['rungs'][rung]['lag_ms'], 1)} / "
                    f"{number(row['rungs'][rung]['rms'], 4)}"
                    for rung in rungs
                ),
                number(row["voice_rms_ratio"], 3),
                f"×{row['fit_cpu_s'] / first['fit_cpu_s']:.2f}",
                f"×{row['voice_cpu_per_speech_s'] / first['voice_cpu_per_speech_s']:.2f}",
            ]
        )
    return text + table(header, rows)


def bilabial_lead_evaluated(engine: str) -> Callable[[Bench], str]:
    """``engine`` trained and run on spans led by each lead (it has no lead of its own):
    held-out closure lag and RMS, and the lag behind the real lips."""

    def render(bench: Bench) -> str:
        if not bench.exists(BILABIAL_LEAD_SWEEP):
            return f"Not measured yet: no `bench/{BILABIAL_LEAD_SWEEP}`.\n"
        doc = bench.load(BILABIAL_LEAD_SWEEP)
        found = doc["engines"][engine]
        text = bench.source(BILABIAL_LEAD_SWEEP, doc) + (
            f"`{engine}` trained on the `{doc['corpus']['name']}` train split (the demo "
            "model's hyperparameters) with every bilabial's span started the lead earlier, "
            "and run on the held-out lines' spans so led (its default rung); closures timed "
            "against the recordings (centre lag, ms; RMS), then on the force-aligned phones "
            f"of the {doc['real_set']['clips']} clips of `{doc['real_set']['name']}`, behind "
            "the character rendered on them and, for information, behind the real lips.\n\n"
        )
        rows = [
            [
                f"{row['lead_ms']:g}",
                _signed(row["lag_ms"], 1),
                _signed(row["closing_lag_ms"], 1),
                _signed(row["release_lag_ms"], 1),
                number(row["rms"], 5),
                *_real_phones_cells(row),
            ]
            for row in found["leads"]
        ]
        header = ["lead, ms", "centre lag", "closing lag", "release lag", "RMS"]
        header += list(REAL_PHONES_HEADER)
        return text + table(header, rows) + f"\n{LEAD_CRITERION}: {found['best_lead_ms']:g} ms.\n"

    render.__name__ = f"bilabial_lead_{engine.replace('-', '_')}"
    return render


def _after_silence(groups: dict[str, Any] | None) -> str:
    if not groups or not all(groups[g]["closures"] for g in ("silence", "phoneme")):
        return ""
    paused, spoken = groups["silence"], groups["phoneme"]
    return (
        f"\nThe recording after silence (or first in a line, {paused['closures']} closures) "
        f"closes at {_signed(paused['closing_ms'], 1)} ms and centres at "
        f"{_signed(paused['centre_ms'], 1)} ms of the onset; after a phoneme "
        f"({spoken['closures']}) at {_signed(spoken['closing_ms'], 1)} and "
        f"{_signed(spoken['centre_ms'], 1)} ms (training lines).\n"
    )


def _lead_row(engine: str, row: dict[str, Any], chosen_ms: float | None) -> list[str]:
    lead = f"{row['lead_ms']:g}"
    causal = row.get("causal")
    return [
        f"`{engine}`",
        f"**{lead}**" if chosen_ms is not None and row["lead_ms"] == chosen_ms else lead,
        _signed(row["lag_ms"], 1),
        _signed(row["closing_lag_ms"], 1),
        _signed(row["release_lag_ms"], 1),
        number(row["rms"], 4),
        _signed(causal["lag_ms"], 1) if causal else "–",
        number(causal["rms"], 4) if causal else "–",
        *_real_phones_cells(row),
    ]


def _real_phones_cells(row: dict[str, Any]) -> list[str]:
    """A sweep row's lag behind the character and behind the real lips, on the real set's
    phones (``–`` for a row measured before them)."""
    phones = row.get("real_phones_lag_ms")
    real = row.get("real_lag_ms", (row.get("real") or {}).get("mean_ms"))
    return [
        "–" if phones is None else _signed(phones, 1),
        "–" if real is None else _signed(real, 1),
    ]


GRID_BILABIAL_WORDS = ("bin", "place", "blue", "by", "please")
"""GRID's words that open with /b/ or /p/ (none opens with /m/: its letter m is "em"); bin
and place open the sentence, blue, by and please follow speech."""


def aligner_bilabial_onsets(bench: Bench) -> str:
    """The forced aligner's onsets of GRID's /b p/-initial words less GRID's, word by word
    (from ``bench/aligner_real.json``)."""
    if not bench.exists(ALIGNER_REAL):
        return f"Not measured yet: no `bench/{ALIGNER_REAL}`.\n"
    doc = bench.load(ALIGNER_REAL)
    errors: dict[str, list[float]] = {word: [] for word in GRID_BILABIAL_WORDS}
    for clip in doc["clips"]:
        for word in clip["words"]:
            if word["word"] in errors:
                errors[word["word"]].append(1000.0 * (word["aligned_s"][0] - word["grid_s"][0]))
    text = bench.source(ALIGNER_REAL, doc)
    text += "The aligner's word onset less GRID's, ms (positive: the aligner's is later).\n\n"
    rows = [
        [
            f"`{word}`",
            str(len(values)),
            f"{statistics.mean(values):+.1f}",
            f"{statistics.median(values):+.1f}",
        ]
        for word, values in errors.items()
        if values
    ]
    return text + table(["word", "count", "mean", "median"], rows)


def _median(value: float | None) -> str:
    return "–" if value is None else number(value, 2)


def real_faces_before_after(bench: Bench) -> str:
    """``lipstream bench --real`` on the models of the demo character before its
    calibration and after, engine by engine."""
    if not (bench.exists(REAL_FACES_BEFORE) and bench.exists(REAL_FACES)):
        return f"Not measured yet: needs `bench/{REAL_FACES_BEFORE}` and `bench/{REAL_FACES}`.\n"
    before_doc, after_doc = bench.load(REAL_FACES_BEFORE), bench.load(REAL_FACES)
    text = bench.source(REAL_FACES_BEFORE, before_doc) + bench.source(REAL_FACES, after_doc)
    before = {row["engine"]: row for row in before_doc["engines"]}
    rows = []
    for row in _by_engine(after_doc["engines"]):
        old = before.get(row["engine"])
        rows.append(
            [
                f"`{row['engine']}`",
                "–" if old is None or old["aperture_r"] is None else number(old["aperture_r"], 3),
                "–" if row["aperture_r"] is None else number(row["aperture_r"], 3),
                "–" if old is None else _signed(old["closure_lag_ms"], 1),
                _signed(row["closure_lag_ms"], 1),
            ]
        )
    header = [
        "engine",
        "aperture r before",
        "aperture r after",
        "closure lag ms before",
        "closure lag ms after",
    ]
    return text + table(header, rows)


RESULTS = "results.json"
BASELINE = "viseme-lerp"


def _results_rows(results: dict[str, Any], names: Sequence[str]) -> list[dict[str, Any]]:
    rows = {row["engine"]: row for row in results["engines"]}
    return [rows[name] for name in names]


def _against(first: dict[str, Any], other: dict[str, Any]) -> str:
    """``first``'s RMS against ``other``'s, overall and emotion by emotion."""
    mine, theirs = first.get("rms_by_emotion", {}), other.get("rms_by_emotion", {})
    emotions = sorted(set(mine) & set(theirs))
    lower = [name for name in emotions if mine[name] < theirs[name]]
    overall = "lower" if first["rms_error"] < other["rms_error"] else "not lower"
    if len(lower) == len(emotions):
        by_emotion = "lower in every emotion"
    elif not lower:
        by_emotion = "lower in no emotion"
    else:
        others = ", ".join(name for name in emotions if name not in lower)
        by_emotion = f"lower in {len(lower)} of {len(emotions)} emotions (not {others})"
    return (
        f"`{first['engine']}` against `{other['engine']}`: RMS {first['rms_error']:.4f} "
        f"against {other['rms_error']:.4f} ({overall}), {by_emotion}"
    )


def _lookahead(ms: float) -> str:
    """Whole milliseconds, but a lead rung's few milliseconds to a tenth."""
    return f"{ms:.1f}" if 0 < ms < 100 else f"{ms:.0f}"


def engine_quality(names: Sequence[str]) -> Callable[[Bench], str]:
    """An engine page's quality table: held-out RMS (overall and per emotion), /p b m/
    closure and lip lag of ``names`` from ``lipstream bench``, and how the first
    compares with each of the others."""

    def render(bench: Bench) -> str:
        results = bench.load(RESULTS)
        rows = _results_rows(results, names)
        emotions = sorted(rows[0].get("rms_by_emotion", {}))
        header = ["engine", f"RMS (÷ `{BASELINE}`)", *(f"RMS {name}" for name in emotions)]
        header += ["/p b m/ closed", "lip lag ms"]
        body = [
            [
                f"`{row['engine']}`",
                f"{row['rms_error']:.4f} ({row['rms_ratio']:.2f})",
                *(f"{row['rms_by_emotion'][name]:.4f}" for name in emotions),
                percent(row["closure_rate"]),
                f"{row['closure_lag_ms']:.0f}" if "closure_lag_ms" in row else "–",
            ]
            for row in rows
        ]
        comparisons = "".join(f"- {_against(rows[0], other)}.\n" for other in rows[1:])
        return (
            bench.source(RESULTS, results)
            + f"Held-out lines of corpus `{results['corpus']['name']}` "
            + f"(`{results['corpus']['digest'][:12]}`), recorded lips closed on "
            + f"{percent(results['recorded']['closure_rate'])} of /p b m/:\n\n"
            + table(header, body)
            + (f"\n{comparisons}" if comparisons else "")
        )

    render.__name__ = "engine_quality"
    return render


def _causal_rms(rungs: list[dict[str, Any]], engine: str) -> dict[str, Any] | None:
    return next((r for r in rungs if r["engine"] == engine and r["rung"] == "causal"), None)


def engine_rungs(names: Sequence[str], rivals: Sequence[str] = ()) -> Callable[[Bench], str]:
    """An engine page's rung table from ``lipstream bench``: each rung of ``names`` with
    its lookahead, RMS, closure and RMS to the best rung; what the ``causal`` rung gives
    up against the best, and the ``causal`` rungs of ``names`` and ``rivals`` by RMS."""

    def render(bench: Bench) -> str:
        results = bench.load(RESULTS)
        rungs = [rung for rung in results["rungs"] if rung["engine"] in names]
        text = bench.source(RESULTS, results) + table(
            ["engine", "rung", "lookahead ms", "RMS", "/p b m/ closed", "RMS to the best rung"],
            (
                [
                    f"`{rung['engine']}`",
                    f"`{rung['rung']}`",
                    _lookahead(rung["lookahead_ms"]),
                    f"{rung['rms_error']:.4f}",
                    percent(rung["closure_rate"]),
                    f"{rung['rms_vs_best']:.4f}",
                ]
                for rung in rungs
            ),
        )
        for name in names:
            own = [rung for rung in rungs if rung["engine"] == name]
            best, causal = own[0], _causal_rms(own, name)
            if causal is None:
                continue
            change = causal["rms_error"] / best["rms_error"] - 1
            text += (
                f"\n`{name}` on `causal`: RMS {causal['rms_error']:.4f} against "
                f"{best['rms_error']:.4f} on `{best['rung']}` ({100 * change:+.1f}%), "
                f"/p b m/ closed {percent(causal['closure_rate'])} against "
                f"{percent(best['closure_rate'])}.\n"
            )
        causal_rows = [
            row
            for name in (*names, *rivals)
            if (row := _causal_rms(results["rungs"], name)) is not None
        ]
        if len(causal_rows) > 1:
            ranked = sorted(causal_rows, key=lambda row: row["rms_error"])
            text += "\nThe `causal` rungs by RMS, lowest first: " + ", ".join(
                f"`{row['engine']}` {row['rms_error']:.4f}" for row in ranked
            )
            text += ".\n"
        return text

    render.__name__ = "engine_rungs"
    return render


def dam_fit(bench: Bench) -> str:
    """``lipstream.bench.dam`` within ``lipstream bench``: each engine's fit, its tails'
    truncation error, offline synthesis and streamed-call CPU."""
    results = bench.load(RESULTS)
    figures = results["engine_benches"]["dam"]
    rows = []
    for name, fit in figures.items():
        cut = fit["cut_tail_errors"]
        calls = {call["rung"]: call["cpu_ms_median"] for call in fit.get("causal_calls", [])}
        search = [rung for rung in fit["rungs"] if rung["truncation_error"] is not None]
        rows.append(
            [
                f"`{name}`",
                str(fit["modes"]),
                str(fit["basis_components"]),
                number(fit["fit_s"]),
                f"{fit['fit_rms']:.4f}",
                f"{fit['tail']} ({percent(fit['rungs'][0]['truncation_error'])})",
                ", ".join(str(rung["lookahead_phonemes"]) for rung in search),
                f"{percent(cut['tail_ahead=1'])}, {percent(cut['tail_ahead=0'])}",
                f"{fit['synthesis']['cpu_ms_per_phoneme']:.4f}",
                " / ".join(
                    f"{calls[rung]:.4f}" for rung in ("causal_lead", "causal") if rung in calls
                )
                or "–",
            ]
        )
    header = ["engine", "modes", "components", "fit s", "fit RMS", "tail, phonemes (error)"]
    header += ["search rungs' lookahead, phonemes", "tail cut to 1, 0 ahead"]
    header += ["synthesis CPU ms / phoneme", "streamed call CPU ms, `causal_lead` / `causal`"]
    synthesis = next(iter(figures.values()))["synthesis"]
    return (
        bench.source(RESULTS, results)
        + table(header, rows)
        + f"\nSynthesis: a {synthesis['phonemes']}-phoneme sentence at {synthesis['fps']:g} fps, "
        + f"{synthesis['repeats']} repeats (the paper: {synthesis['paper_ms_per_phoneme']:g} ms "
        + "per phoneme). Errors are shares of a channel's recorded range.\n"
    )


def _pq_cell(cell: dict[str, Any]) -> str:
    if cell.get("timed_out"):
        return "timed out"
    return f"{cell['search_ms']:,.0f} / {cell['jumps']}"


def _span(values: Sequence[float], digits: int = 0) -> str:
    low, high = min(values), max(values)
    return f"{low:,.{digits}f}–{high:,.{digits}f}"


def anime_graph_table(bench: Bench) -> str:
    """Cao et al.'s Tables 1–2 on the demo model (``lipstream.bench.anime_graph``): greedy
    against PQ-Matching on both graphs, and what the figures say."""
    results = bench.load(RESULTS)
    figures = results["engine_benches"]["anime-graph"]
    metrics, found = figures["model"]["metrics"], figures["table"]
    rows = [
        [
            str(row["phonemes"]),
            row["graph"],
            f"{row['greedy']['search_ms']:.3f} ({row['greedy']['search_ms_in_synthesis']:.3f})",
            str(row["greedy"]["jumps"]),
            *(_pq_cell(row["pq"][h]) for h in ("3", "4", "5")),
            f"{row['pq']['4']['speedup']:,.0f}×",
            f"{row['pq']['4']['speedup_over_unclustered_greedy']:,.0f}×",
        ]
        for row in found["rows"]
    ]
    header = ["phonemes", "graph", "greedy ms", "greedy jumps", "PQ(3) ms / jumps"]
    header += ["PQ(4) ms / jumps", "PQ(5) ms / jumps", "PQ(4) ÷ greedy, same graph"]
    header += ["PQ(4) ÷ unclustered greedy"]
    clustered = [row for row in found["rows"] if row["graph"] == "clustered"]
    text = bench.source(RESULTS, results)
    text += (
        f"Model: {metrics['animes']:,} animes, {metrics['pca_components']} PCA components, "
        f"fit {figures['model']['fit_s']:.1f} s; clustered graph k = {metrics['clusters']}, "
        f"mean out-degree {metrics['cluster_degree_mean']:.1f} (at most "
        f"{metrics['cluster_degree_max']}). PQ with h_q = {found['pq_advance']}, "
        f"at most {found['pq_budget_s']:g} s a search.\n\n"
    )
    text += table(header, rows)
    jumps = "never uses" if found["greedy_never_more_jumps"] else "sometimes uses"
    text += (
        f"\nGreedy {jumps} more jumps than a PQ(h). Greedy on the unclustered graph is at "
        f"least {found['min_speedup_over_pq4']:,.0f}× faster than PQ(4) on either graph, "
        f"or {found['min_speedup_over_pq4_in_synthesis']:,.0f}× timed inside a synthesis."
    )
    if clustered:
        text += (
            f" On the clustered graph PQ(4) takes "
            f"{_span([row['pq']['4']['search_ms'] for row in clustered], 1)} ms, greedy on "
            f"that graph is {_span([row['pq']['4']['speedup'] for row in clustered])}× faster "
            f"than it, and greedy takes "
            f"{_span([row['greedy']['jumps'] for row in clustered])} jumps per sentence there."
        )
    return text + "\n"


def anime_graph_scaling(bench: Bench) -> str:
    """Greedy search time against database size (``lipstream.bench.anime_graph``)."""
    results = bench.load(RESULTS)
    figures = results["engine_benches"]["anime-graph"]
    return bench.source(RESULTS, results) + table(
        ["copies", "animes", "fit s", "search ms / sentence"]
        + ["inside a synthesis: ms / sentence", "µs / phoneme"],
        (
            [
                str(row["factor"]),
                f"{row['animes']:,}",
                number(row["fit_s"]),
                f"{row['warm_search_ms_per_sentence']:.3f}",
                f"{row['search_ms_per_sentence']:.3f}",
                number(row["search_us_per_phoneme"], 2),
            ]
            for row in figures["scaling"]
        ),
    )


def anime_graph_quality(bench: Bench) -> str:
    """Speed and held-out quality of both graphs (``lipstream.bench.anime_graph``)."""
    results = bench.load(RESULTS)
    figures = results["engine_benches"]["anime-graph"]
    speed, quality = figures["speed"], figures["quality"]
    text = bench.source(RESULTS, results)
    text += (
        f"Speed (served defaults, 60 fps): greedy search for a {speed['phonemes']}-phoneme "
        f"sentence {speed['greedy_search_ms']:.3f} ms "
        f"({speed['greedy_search_ms_with_audio']:.3f} ms ranking by audio), timed inside a "
        f"synthesis; whole synthesis per held-out sentence "
        f"({speed['mean_phonemes_per_sentence']:.1f} phonemes on average) "
        f"{speed['synthesis_ms_per_sentence']:.1f} ms without audio and "
        f"{speed['synthesis_ms_per_sentence_with_audio']:.1f} ms with audio.\n\n"
        "Quality on the held-out split (each utterance's own emotion and audio):\n\n"
    )
    rows = [
        [f"`{name}`" if " " not in name else f"`{name.split()[0]}`, {name.split()[1]}"]
        + [f"{value['rms']:.4f}", percent(value["closure_rate"])]
        for name, value in quality.items()
        if isinstance(value, dict)
    ]
    rows.append(["recorded", "—", percent(quality["recorded_closure_rate"])])
    return text + table(["engine", "RMS", "/p b m/ closure"], rows)


TARGET_PHONEMES, TARGET_MS, TARGET_NODES = 60, 20.0, 5000


def expressive_dp_table_v(bench: Bench) -> str:
    """Deng & Neumann's Table V lengths (``lipstream.bench.expressive_dp``): the paper's
    CPU time, exact DP's and the fast search's, and the issue's target."""
    results = bench.load(RESULTS)
    figures = results["engine_benches"]["expressive-dp"]
    found = figures["table_v"]
    text = bench.source(RESULTS, results)
    text += (
        f"Database: {figures['nodes']:,} motion nodes, {figures['basis_components']} basis "
        f"components, fit {figures['fit_s']:.1f} s. Exact DP (every pair priced) is timed "
        f"over a few layers, {found['exact_dp_cpu_s_per_transition']:.1f} CPU s per "
        "transition, and scaled to each length; it and the fast search reach "
        + (
            "the same optimum there"
            if found["same_optimum_on_exact_layers"]
            else "different optima there (!)"
        )
        + ".\n\n"
    )
    text += table(
        ["phonemes", "paper CPU s", "exact DP CPU s", "fast search CPU ms, median / least"]
        + ["nodes priced"],
        (
            [
                str(row["phonemes"]),
                number(row["paper_cpu_s"]),
                number(row["exact_dp_cpu_s"]),
                f"{number(row['fast_cpu_ms'], 2)} / {number(row['fast_cpu_ms_least'], 2)}",
                f"{row['fast_priced_nodes']:,}",
            ]
            for row in found["rows"]
        ),
    )
    longest = max(found["rows"], key=lambda row: row["phonemes"])
    met = (
        longest["phonemes"] >= TARGET_PHONEMES
        and figures["nodes"] >= TARGET_NODES
        and longest["fast_cpu_ms"] <= TARGET_MS
    )
    text += (
        f"\nThe issue's target, {TARGET_MS:g} ms of CPU for a {TARGET_PHONEMES}-phoneme "
        f"sentence on at least {TARGET_NODES:,} nodes: {longest['fast_cpu_ms']:.1f} ms median "
        f"for {longest['phonemes']} phonemes on {figures['nodes']:,} nodes, "
        + ("met" if met else "not met")
        + ".\n"
    )
    return text


def hmm_benches(bench: Bench) -> str:
    """``lipstream.bench.hmm`` within ``lipstream bench``: the two estimators, Brand's Err
    and RMS by what drives the model, and voice-driven speed and first frame per rung."""
    results = bench.load(RESULTS)
    figures = results["engine_benches"]["hmm"]
    text = bench.source(RESULTS, results) + "Estimators, trained from the same start:\n\n"
    text += table(
        ["estimator", "states (of)", "transitions", "perplexity", "held-out entropy rate, bits"]
        + ["fit s"],
        (
            [
                f"`{name}`",
                f"{fit['states']} ({fit['states_initial']})",
                str(fit["transitions"]),
                number(fit["perplexity"], 3),
                number(fit["heldout_entropy_rate_bits"], 4),
                number(fit["fit_s"]),
            ]
            for name, fit in figures["estimators"].items()
        ),
    )
    errors = figures["errors"]
    drivers = list(errors["heldout"])
    text += "\nBrand's Err / RMS against the recorded curves, by what drives the model:\n\n"
    text += table(
        ["lines", *drivers],
        (
            [split] + [f"{by[name]['err']:.3f} / {by[name]['rms']:.4f}" for name in drivers]
            for split, by in errors.items()
        ),
    )
    speeds, first = figures["real_time_factor"], figures["first_frame"]
    text += (
        "\nVoice-driven synthesis at 60 fps, audio seconds per CPU second (real-time factor), "
        "and a request fed audio alone: the audio heard before its first frame, and that "
        "call's time:\n\n"
    )
    return text + table(
        ["rung", "real-time factor", "audio before the first frame ms", "first call ms"],
        (
            [
                f"`{name}`",
                f"{factor:,.0f}",
                f"{first[name]['audio_needed_ms']:.0f}" if name in first else "–",
                f"{first[name]['call_ms']:.3f}" if name in first else "–",
            ]
            for name, factor in speeds.items()
        ),
    )


def expressive_dp_benches(bench: Bench) -> str:
    """``lipstream.bench.expressive_dp``'s other figures: the weights' cross-validated
    error, fixed lag against the full search, and RMS per emotion by modifiers."""
    results = bench.load(RESULTS)
    figures = results["engine_benches"]["expressive-dp"]
    text = bench.source(RESULTS, results)
    text += (
        f"Cross-validated error with the searched weights {figures['cv_error']:.4f}, with the "
        f"defaults {figures['cv_error_defaults']:.4f}; a phoneme-map pick "
        f"{figures['pick_ms']:.3f} ms.\n\nFixed lag against the full search on the held-out "
        "lines:\n\n"
    )
    text += table(
        ["lag", "lines differing", "nodes differing", "cost above the optimum, mean / largest"]
        + ["wait ms (lag + 2 median phonemes)", "ms / phoneme"],
        (
            [
                str(row["lag"]),
                percent(row["lines_differing"]),
                percent(row["nodes_differing"]),
                f"{100 * row['mean_cost_gap']:.2f}% / {100 * row['max_cost_gap']:.2f}%",
                f"{row['lookahead_ms']:.0f}",
                f"{row['ms_per_phoneme']:.3f}",
            ]
            for row in figures["lags"]
        ),
    )
    by_emotion = figures["rms_by_emotion"]
    emotions = sorted(next(iter(by_emotion.values())))
    labels = {"correct_modifiers": "correct modifiers", "neutral_modifiers": "all neutral"}
    text += "\nHeld-out RMS per emotion:\n\n"
    return text + table(
        ["synthesis", *emotions],
        (
            [labels.get(name, f"`{name}`")] + [f"{rms[emotion]:.4f}" for emotion in emotions]
            for name, rms in by_emotion.items()
        ),
    )


HMM_VOICES = "hmm_voices.json"
HMM_VOICE_SETS = (
    ("demo", "demo held-out"),
    ("second_character", "second character"),
    ("second_character_self_trained", "second character, self-trained"),
    ("heldout_voice", "held-out voice"),
)


def _ratio(sets: dict[str, Any], key: str) -> str:
    figures = sets.get(key)
    if figures is None:
        return "–"
    return f"{figures['audio_ratio']:.3f} ({figures['phonemes_ratio']:.3f})"


def _causal(sets: dict[str, Any], key: str) -> str:
    figures = sets.get(key)
    if figures is None or "audio_causal_ratio" not in figures:
        return "–"
    return (
        f"{figures['audio_causal_lead_ratio']:.3f} / {figures['audio_causal_ratio']:.3f} "
        f"({figures['phonemes_causal_ratio']:.3f})"
    )


def _r(value: float | None) -> str:
    return "–" if value is None else f"{value:+.3f}"


def hmm_voices(bench: Bench) -> str:
    """``python -m lipstream.bench.hmm_voices``: voice-driven ``hmm`` on unseen voices and
    characters, and on the GRID clip that has sound."""
    if not bench.exists(HMM_VOICES):
        return f"Not measured yet: no `bench/{HMM_VOICES}`.\n"
    doc = bench.load(HMM_VOICES)
    second, held = doc["second_character"], doc["heldout_voice"]
    text = bench.source(HMM_VOICES, doc)
    text += (
        f"Demo corpus `{doc['corpus']['digest'][:12]}` ({doc['corpus']['lines']} lines). "
        f"Second character: voice `{second['voice']}`, pitch {second['pitch']}, rate "
        f"×{second['rate_factor']:g}, jaw ×{second['jaw_scale']:g}, lips "
        f"×{second['lips_scale']:g}, rounding ×{second['rounding_scale']:g}, stiffness "
        f"×{second['stiffness_scale']:g}; {second['lines']} lines. Held-out voice: "
        f"`+{held['variant']}`, pitch {held['pitch_shift']:+d}, on the demo's held-out lines. "
        f"GRID clips with sound: {len(doc['grid']['clips_with_sound'])} of "
        f"{doc['grid']['clips']}.\n\n"
        "Voice-driven RMS over `viseme-lerp`'s, `full` rung (phoneme-driven `hmm` in "
        "brackets):\n\n"
    )
    rows = []
    for name, configuration in doc["configurations"].items():
        sets = configuration["sets"]
        rows.append(
            [name, str(configuration["training_lines"])]
            + [_ratio(sets, key) for key, _ in HMM_VOICE_SETS]
        )
    text += table(
        ["configuration", "training lines"] + [label for _, label in HMM_VOICE_SETS], rows
    )
    text += (
        "\nThe same on the frame-at-a-time rungs: voice-driven on `causal_lead` / on "
        "`causal` (phoneme-driven on `causal` in brackets):\n\n"
    )
    rows = [
        [name] + [_causal(configuration["sets"], key) for key, _ in HMM_VOICE_SETS]
        for name, configuration in doc["configurations"].items()
    ]
    text += table(["configuration"] + [label for _, label in HMM_VOICE_SETS], rows)
    text += (
        "\nGRID aperture r, the mean over the clips with sound (`hmm` by audio alone, `hmm` "
        "by phonemes, `viseme-lerp` fed the aligned phones; each clip's in the JSON):\n\n"
    )
    rows = []
    for name, configuration in doc["configurations"].items():
        figures = configuration["grid_mean"]
        rows.append(
            [
                name,
                str(figures["clips"]),
                _r(figures.get("hmm_audio_r")),
                _r(figures.get("hmm_phonemes_r")),
                _r(figures.get("viseme_lerp_r")),
            ]
        )
    text += table(
        ["configuration", "clips", "hmm by audio", "hmm by phonemes", "viseme-lerp"], rows
    )
    warps = doc.get("warps")
    if warps:
        last = list(doc["configurations"])[-1]
        text += (
            f"\nVocal-tract-length warp, `{last}`: voice-driven ratio at each fixed warp and "
            "with each line at its most likely warp (chosen from the whole line):\n\n"
        )
        header = ["set"] + [f"warp {w:g}" for w in warps["warps"]] + ["most likely (warps chosen)"]
        rows = []
        for key, label in HMM_VOICE_SETS:
            if key not in warps["fixed"]:
                continue
            chosen = warps["most_likely"][key]
            picks = ", ".join(f"{w}: {n}" for w, n in chosen["warps_chosen"].items())
            rows.append(
                [label]
                + [f"{warps['fixed'][key][f'{w:g}']:.3f}" for w in warps["warps"]]
                + [f"{chosen['audio_ratio']:.3f} ({picks})"]
            )
        text += table(header, rows)
        if warps.get("grid_mean"):
            mean = warps["grid_mean"]
            text += (
                f"\nGRID, each of the {mean['clips']} clips with sound at its most likely warp: "
                f"audio-driven aperture r {_r(mean.get('hmm_audio_r'))} (mean).\n"
            )
    return text


def _ms_cell(figures: dict[str, Any], keys: Sequence[str]) -> str:
    return " / ".join("–" if figures[key] is None else number(figures[key], 0) for key in keys)


def first_frame_priority(bench: Bench, name: str = "first_frame_priority.json") -> str:
    """``python -m lipstream.bench.first_frame_priority``: a whole request's first frame beside
    causal sessions, on two servers side by side (the served code, ``before``, and a variant,
    ``after``), run by run, and for each side whether the target holds in its worst round."""
    doc = bench.load(name)
    target = doc["target_p99_ms"]
    rows = []
    verdicts = []
    for engine in dict.fromkeys(row["engine"] for row in _by_engine(doc["rows"])):
        runs = [row for row in doc["rows"] if row["engine"] == engine]
        for row in sorted(runs, key=lambda row: (row["side"] != "before", row["round"])):
            rows.append(
                [
                    f"`{engine}`",
                    row["side"],
                    str(row["round"] + 1),
                    f"{_ms_cell(row['first_frame_ms'], ('p50', 'p99', 'max'))} "
                    f"({row['probe_requests']})",
                    _ms_cell(row["frame_lag_ms"], ("p50", "p99")),
                    f"{row['peak_sessions']} of {row['requests']}",
                    ", ".join(f"{code} {count}" for code, count in sorted(row["errors"].items()))
                    or "none",
                ]
            )
        parts = []
        for side in ("before", "after"):
            p99 = [row["first_frame_ms"]["p99"] for row in runs if row["side"] == side]
            worst = max(p99)
            verdict = "met" if worst < target else f"missed by {number(worst - target, 0)} ms"
            listed = ", ".join(number(value, 0) for value in p99)
            parts.append(f"{side} {listed} ms ({verdict})")
        verdicts.append(f"`{engine}`: first frame p99 by round, " + "; ".join(parts))
    header = [
        "engine",
        "server",
        "round",
        "first frame p50 / p99 / max ms (probe requests)",
        "frame lag p50 / p99 ms",
        "sessions held at once",
        "errors",
    ]
    text = bench.source(name, doc) + (
        f"{doc['streams']} causal sessions (lead {doc['lead_ms']:g} ms, latency budget "
        f"{doc['latency_budget_ms']:g} ms), one {doc['clip_s']:g} s clip each, beside one "
        f"connection sending {doc['probe_phonemes']}-phoneme requests whole; the two servers "
        "alternate within each round. Target: first frame p99 under "
        f"{target:g} ms in every round.\n\n"
    )
    return text + table(header, rows) + "\n" + "".join(f"- {line}\n" for line in verdicts)


THROUGHPUT_CPU = "cpu_per_session_session15.json"
THROUGHPUT_LAG_WINDOW = "call_pairs_lag_window.json"
THROUGHPUT_FIRST_FRAME = "first_frame_priority.json"
FLOOR_CAPACITY_TARGET = 0.8
BEST_CAPACITY_TARGET = 0.6
LAG4_CALL_TARGET_US = 150.0


def _spread(values: Sequence[float], digits: int = 2) -> str:
    low, high = min(values), max(values)
    return number(low, digits) if low == high else f"{number(low, digits)}–{number(high, digits)}"


def _engines(count: int) -> str:
    return f"{count} engine" + ("" if count == 1 else "s")


def _ratio_verdict(values: Sequence[float], target: float, at_most: bool) -> str:
    """Met when every value is on the right side of ``target``; else how many miss it and
    by what factors."""
    factors = [value / target if at_most else target / value for value in values]
    missed = [factor for factor in factors if factor > 1.0]
    if not missed:
        return f"met by all {len(values)}"
    return f"missed by {len(missed)} of {len(values)}, by {_spread(missed)}×"


def throughput_targets(bench: Bench) -> str:
    """Issue 27's targets, each beside the figure that measures it and whether it is met,
    read from the results files of the sections below."""
    rows = []
    cpu = bench.load(THROUGHPUT_CPU)
    for label, target, causal in (
        ("the causal rung", CAUSAL_CPU_RATIO_TARGET, True),
        ("the best rung", BEST_CPU_RATIO_TARGET, False),
    ):
        ratios = [
            run["cpu_ratio"]
            for run in cpu["runs"]
            if ("causal" in run["fidelity"]) == causal and run.get("cpu_ratio") is not None
        ]
        rows.append(
            [
                f"server CPU per session-second at {label}, over the reference's: at most "
                f"{target:g}",
                f"{_spread(ratios)} over {_engines(len(ratios))} (`bench/{THROUGHPUT_CPU}`)",
                _ratio_verdict(ratios, target, at_most=True),
            ]
        )
    calls = bench.load(THROUGHPUT_LAG_WINDOW)
    lag4 = next(row for row in calls["rows"] if row["rung"] == "lag-4")
    call_us = lag4["after_median_us"]
    rows.append(
        [
            f"`expressive-dp` `lag-4` streamed call: at most {LAG4_CALL_TARGET_US:g} µs",
            f"{number(call_us)} µs, median (`bench/{THROUGHPUT_LAG_WINDOW}`)",
            "met"
            if call_us <= LAG4_CALL_TARGET_US
            else f"missed by {number(call_us - LAG4_CALL_TARGET_US, 0)} µs",
        ]
    )
    first = bench.load(THROUGHPUT_FIRST_FRAME)
    worst = max(row["first_frame_ms"]["p99"] for row in first["rows"] if row["side"] == "before")
    rows.append(
        [
            f"first frame of a whole request beside {first['streams']} causal sessions: p99 "
            f"under {first['target_p99_ms']:g} ms for every engine",
            f"worst round of any engine {number(worst, 0)} ms (`bench/{THROUGHPUT_FIRST_FRAME}`)",
            "met"
            if worst < first["target_p99_ms"]
            else f"missed by {number(worst - first['target_p99_ms'], 0)} ms",
        ]
    )
    for label, name, target in (
        ("at the latency floor", "capacity_floor.json", FLOOR_CAPACITY_TARGET),
        ("at the best rungs", "capacity_best.json", BEST_CAPACITY_TARGET),
    ):
        ratios = [
            search["capacity_ratio"]
            for search in bench.load(name)["searches"]
            if search.get("capacity_ratio") is not None
        ]
        rows.append(
            [
                f"sessions held {label}, over the reference's: at least {target:g}",
                f"{_spread(ratios)} over {_engines(len(ratios))} (`bench/{name}`)",
                _ratio_verdict(ratios, target, at_most=False),
            ]
        )
    return table(["target", "measured", "verdict"], rows)


BLOCKS: dict[str, Callable[[Bench], str]] = {
    "throughput-targets": throughput_targets,
    "sentences-curve": sentences_curve,
    "sentences-curve-summary": sentences_curve_summary,
    "hmm-voices": hmm_voices,
    "real-faces-summary": real_faces_summary,
    "real-faces": real_faces,
    "real-faces-before-after": real_faces_before_after,
    "demo-calibration": demo_calibration,
    "closure-sources": closure_sources,
    "hmm-closure-lag": hmm_closure_lag,
    "closure-timing": closure_timing,
    "bilabial-lead-hmm": bilabial_lead_hmm,
    "hmm-rate": hmm_rate,
    "bilabial-lead-anime-graph": bilabial_lead_evaluated("anime-graph"),
    "bilabial-lead-expressive-dp": bilabial_lead_evaluated("expressive-dp"),
    "aligner-bilabial-onsets": aligner_bilabial_onsets,
    "languages": languages,
    "language-phonemes": language_phonemes,
    "capture": capture,
    "first-start-summary": first_start_summary,
    "first-start": first_start,
    "engines-summary": engines_summary,
    "engines": engines,
    "dam-quality": engine_quality(("dam", "cohen-massaro", "anime-graph", "viseme-lerp")),
    "dam-rungs": engine_rungs(("dam", "cohen-massaro"), ("anime-graph", "viseme-lerp")),
    "dam-fit": dam_fit,
    "anime-graph-rungs": engine_rungs(("anime-graph",)),
    "hmm-rungs": engine_rungs(("hmm",), ("viseme-lerp",)),
    "expressive-dp-rungs": engine_rungs(("expressive-dp",), ("viseme-lerp",)),
    "anime-graph-table": anime_graph_table,
    "anime-graph-scaling": anime_graph_scaling,
    "anime-graph-quality": anime_graph_quality,
    "expressive-dp-table-v": expressive_dp_table_v,
    "expressive-dp-benches": expressive_dp_benches,
    "hmm-benches": hmm_benches,
    "stream-calls": stream_calls,
    "retarget-cost": retarget_cost,
    "call-pairs": call_pairs("call_pairs.json"),
    "call-pairs-expressive-dp": call_pairs("call_pairs_expressive_dp.json"),
    "call-pairs-search": call_pairs("call_pairs_search.json"),
    "call-pairs-numerics": call_pairs("call_pairs_numerics.json"),
    "call-pairs-lag-window": call_pairs("call_pairs_lag_window.json"),
    "lead0": lead0,
    "hmm-first-frame": hmm_first_frame,
    "word-timings": word_timings,
    "aligner-real": aligner_real,
    "capacity-floor": _capacity("capacity_floor.json"),
    "capacity-best": _capacity("capacity_best.json"),
    "capacity-best-two-workers": _capacity("capacity_best_two_workers.json"),
    "capacity-workers": capacity_workers,
    "cpu-per-session": cpu_per_session,
    "cpu-per-session-cuts": lambda bench: cpu_per_session(bench, "cpu_per_session_cuts.json"),
    "cpu-per-session-cuts-before": lambda bench: cpu_per_session(
        bench, "cpu_per_session_cuts_before.json"
    ),
    "cpu-per-session-session14": lambda bench: cpu_per_session(
        bench, "cpu_per_session_session14.json"
    ),
    "cpu-per-session-session14-before": lambda bench: cpu_per_session(
        bench, "cpu_per_session_session14_before.json"
    ),
    "cpu-per-session-session15": lambda bench: cpu_per_session(
        bench, "cpu_per_session_session15.json"
    ),
    "cpu-per-session-hmm40": lambda bench: cpu_per_session(bench, "cpu_per_session_hmm40.json"),
    "first-frame-priority": first_frame_priority,
    "server-profile": server_profile,
    "message-cost-cuts": message_cost,
    "message-cost-cuts2": lambda bench: message_cost(bench, "message_cost_cuts2.json"),
    "message-cost-asgi": lambda bench: message_cost(
        bench, "message_cost_asgi.json", "taking Starlette's WebSocket out"
    ),
    "websocket-layers": websocket_layers,
    "capacity-earlier": _capacity("capacity.json"),
    "loadtest": loadtest,
    "scale-out": scale_out,
    "soak": soak,
    "soak-before": lambda bench: soak(bench, "soak_before.json"),
    "storm": storm,
    "connection-cost": connection_cost,
}


class UnknownBlock(ValueError):
    """A ``<!-- report: NAME -->`` marker whose NAME no renderer has."""


class UnreadableResults(ValueError):
    """A results file that lacks what its block's renderer reads, or is not JSON."""


def render_block(name: str, bench: Bench, where: str) -> str:
    try:
        return BLOCKS[name](bench)
    except (KeyError, TypeError, ValueError, OSError) as error:
        raise UnreadableResults(
            f"{where}: report block {name!r} ({BLOCKS[name].__name__} in "
            f"lipstream/bench/report.py) cannot read {bench.directory}: "
            f"{type(error).__name__}: {error}"
        ) from error


def render_text(text: str, bench: Bench, where: str = "text") -> str:
    """``text`` with the body of every report block rendered afresh."""

    def replace(match: re.Match[str]) -> str:
        name = match.group(2)
        if name not in BLOCKS:
            raise UnknownBlock(f"{where}: no report block named {name!r}; known: {sorted(BLOCKS)}")
        rendered = render_block(name, bench, where)
        return match.group(1) + "\n" + rendered.strip("\n") + "\n\n" + match.group(4)

    return BLOCK.sub(replace, text)


def report_files(repo: Path) -> list[Path]:
    """The README and every docs page that holds a report block."""
    candidates = [repo / "README.md", *sorted((repo / "docs").rglob("*.md"))]
    return [path for path in candidates if BLOCK.search(path.read_text(encoding="utf-8"))]


def stale(repo: Path, bench_dir: Path | None = None) -> list[Path]:
    """The files whose blocks differ from a fresh rendering of ``bench/*.json``."""
    bench = Bench(bench_dir or repo / "bench")
    return [
        path
        for path in report_files(repo)
        if render_text(text := path.read_text(encoding="utf-8"), bench, str(path)) != text
    ]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m lipstream.bench.report",
        description="Render bench/*.json into the report blocks of README.md and docs/.",
    )
    parser.add_argument("--repo", type=Path, default=Path.cwd(), help="checkout (default: .)")
    parser.add_argument(
        "--check", action="store_true", help="change nothing; exit 1 if a block is out of date"
    )
    args = parser.parse_args(argv)
    try:
        return _run(args.repo, args.check)
    except (UnknownBlock, UnreadableResults) as error:
        print(error, file=sys.stderr)
        return 2


def _run(repo: Path, check: bool) -> int:
    if check:
        out_of_date = stale(repo)
        for path in out_of_date:
            print(f"{path}: report blocks differ from bench/*.json", file=sys.stderr)
        return 1 if out_of_date else 0
    bench = Bench(repo / "bench")
    pages = {path: path.read_text(encoding="utf-8") for path in report_files(repo)}
    # every page rendered before any is written: a file that cannot be read changes nothing
    rendered = {path: render_text(text, bench, str(path)) for path, text in pages.items()}
    for path, text in rendered.items():
        if text != pages[path]:
            path.write_text(text, encoding="utf-8")
            print(f"rendered {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
