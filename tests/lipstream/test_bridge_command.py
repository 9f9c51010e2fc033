"""``lipstream bridge`` end to end against a real server on loopback (text in, UDP and
stdout out, on the real clock), and its coded one-line errors for bad input."""

from __future__ import annotations

import asyncio
import json
import re
import socket
import struct
import sys
import wave
from collections.abc import Iterator
from pathlib import Path

import pytest

from lipstream.cli import main
from lipstream.corpus import Corpus
from lipstream_client import AsyncClient
from lipstream_client.sinks.sound import has_sound_device
from tests.bridge_server import TEXT, bridge_server, served
from tests.helpers import run_cli
from tests.lipstream_client.sinks.livelink_decoder import app_slot, decode
from tests.live_server import LiveServer


def float32(value: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", value))[0])


SUMMARY = re.compile(
    r"bridged (\d+) frames \((\d+) channels at 60 fps\) to (\S+): (\d+) on time, (\d+) dropped late"
)


@pytest.fixture(scope="module")
def server(
    small_demo_corpus: Corpus, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[LiveServer]:
    with bridge_server(small_demo_corpus, tmp_path_factory.mktemp("bridge-cli-models")) as live:
        yield live


def summary(stderr: str) -> tuple[int, int, int]:
    found = SUMMARY.search(stderr)
    assert found is not None, stderr
    return int(found[1]), int(found[4]), int(found[5])


def test_bridge_to_live_link_with_the_speech_written(server: LiveServer, tmp_path: Path) -> None:
    result = served(server.ws, "arkit52")
    expected = result.rows()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(0.5)
        port = receiver.getsockname()[1]
        wav = tmp_path / "speech.wav"
        done = run_cli(
            "bridge",
            "--server",
            server.ws,
            "--to",
            f"livelink://127.0.0.1:{port}",
            "--preset",
            "arkit52",
            "--text",
            TEXT,
            "--subject",
            "Ada",
            "--wav",
            str(wav),
        )
        assert done.returncode == 0, done.stderr
        frames, sent, dropped = summary(done.stderr)
        packets = [decode(receiver.recv(4096)) for _ in range(sent)]
    assert frames == len(expected) and sent + dropped == frames
    numbers = [packet.frame_number for packet in packets]
    assert numbers == sorted(set(numbers))  # in order, each once; late ones left out
    for packet in packets:
        row = expected[packet.frame_number - numbers[0]]  # frame 0 is never late
        curves = [0.0] * 61
        for name, value in zip(result.channels, row):
            curves[app_slot(name)] = value
        assert packet.subject == "Ada" and list(packet.curves) == curves
    with wave.open(str(wav), "rb") as written:
        assert written.getnframes() > 0 and written.getnchannels() == 1
    assert f"to {wav}" in done.stderr


def test_bridge_to_stdout_json_lines(server: LiveServer) -> None:
    result = served(server.ws, None)
    expected, channels = result.rows(), result.channels
    done = run_cli("bridge", "--server", server.ws, "--to", "stdout", "--text", TEXT)
    assert done.returncode == 0, done.stderr
    frames, sent, dropped = summary(done.stderr)
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert frames == len(expected) and len(lines) == sent and sent + dropped == frames
    indices = [line["frame"] for line in lines]
    assert indices == sorted(set(indices))
    for line in lines:
        assert list(line["values"]) == list(channels)
        row = expected[line["frame"]]
        assert [float32(value) for value in line["values"].values()] == row


def served_phonemes(
    url: str, phones: list[tuple[str, float, float]], pcm16: bytes, rate: int
) -> list[list[float]]:
    async def request() -> list[list[float]]:
        async with AsyncClient(url) as client:
            stream = await client.start("viseme-lerp", "demo", fps=60.0)
            await stream.send_phonemes(phones)
            await stream.send_audio(pcm16, rate)
            await stream.end()
            return (await asyncio.wait_for(stream.collect(), 60)).rows()

    return asyncio.run(request())


def error_line(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(["bridge", *argv]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_an_unknown_preset_surfaces_the_server_s_error(
    server: LiveServer, capsys: pytest.CaptureFixture[str]
) -> None:
    line = error_line(
        capsys, "--server", server.ws, "--to", "stdout", "--text", "hi", "--preset", "no-such-rig"
    )
    assert re.match(
        r"error \[(invalid_request|unknown_retarget)\]: --preset: output.retarget: ", line
    )
    assert "'no-such-rig'" in line and "arkit52" in line


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (["--fps", "-5"], "error [invalid_message]: --fps: fps: must be >= 1, got -5.0"),
        (["--engine", "nope"], "error [unknown_engine]: --engine: engine: no engine 'nope'"),
        (["--voice", "xx-nope"], "error [invalid_request]: --voice: voice: espeak-ng has no voice"),
    ],
)
def test_request_errors_name_the_option(
    server: LiveServer, capsys: pytest.CaptureFixture[str], argv: list[str], line: str
) -> None:
    said = error_line(capsys, "--server", server.ws, "--to", "stdout", "--text", "hi", *argv)
    assert said.startswith(line)


@pytest.mark.parametrize(
    ("to", "code"),
    [
        ("livelink://127.0.0.1:99999", "invalid_target"),
        ("tcp://127.0.0.1:1", "invalid_target"),
        ("vmc://", "invalid_target"),
        ("livelink://no-such-host.invalid", "target_unreachable"),
    ],
)
def test_bad_targets(
    server: LiveServer, capsys: pytest.CaptureFixture[str], to: str, code: str
) -> None:
    line = error_line(capsys, "--server", server.ws, "--to", to, "--text", "hi")
    assert line.startswith(f"error [{code}]: --to: ")


def test_a_local_port_in_use(server: LiveServer, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        line = error_line(
            capsys,
            "--server",
            server.ws,
            "--to",
            "vmc://127.0.0.1",
            "--bind",
            f"127.0.0.1:{port}",
            "--text",
            "hi",
        )
    assert line.startswith("error [port_in_use]: --bind: ") and str(port) in line


def test_a_server_that_is_not_there(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    line = error_line(
        capsys, "--server", f"ws://127.0.0.1:{port}/v1/stream", "--to", "stdout", "--text", "hi"
    )
    assert line.startswith("error [server_unreachable]: --server: ")
    line = error_line(
        capsys, "--server", "http://127.0.0.1:1/v1/stream", "--to", "stdout", "--text", "hi"
    )
    assert line.startswith("error [server_unreachable]: --server: ")


@pytest.mark.parametrize(
    ("argv", "where"),
    [
        (["--to", "stdout", "--phones", "x.lab", "--voice", "en-us"], "--voice"),
        (["--to", "stdout", "--text", "hi", "--audio", "x.wav"], "--audio"),
        (["--to", "vmc://127.0.0.1", "--text", "hi", "--subject", "Ada"], "--subject"),
        (["--to", "stdout"], "--text"),
        (["--to", "vmc://127.0.0.1", "--text", "hi", "--format", "csv"], "--format"),
        (["--to", "stdout", "--text", "hi", "--bind", "127.0.0.1:0"], "--bind"),
    ],
)
def test_options_that_do_not_go_together(
    capsys: pytest.CaptureFixture[str], argv: list[str], where: str
) -> None:
    line = error_line(capsys, "--server", "ws://127.0.0.1:1/v1/stream", *argv)
    assert line.startswith(f"error [invalid_request]: {where}: ")


def test_a_vmc_target_without_python_osc(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "pythonosc", None)  # any import of python-osc now fails
    line = error_line(
        capsys, "--server", "ws://127.0.0.1:1/v1/stream", "--to", "vmc://127.0.0.1", "--text", "hi"
    )
    assert line.startswith("error [missing_dependency]: --to: ")
    assert 'pip install "lipstream-client[vmc]"' in line


@pytest.mark.skipif(has_sound_device(), reason="this machine has a sound device")
def test_play_without_a_sound_device(capsys: pytest.CaptureFixture[str]) -> None:
    line = error_line(
        capsys, "--server", "ws://127.0.0.1:1/v1/stream", "--to", "stdout", "--text", "hi", "--play"
    )
    assert line.startswith("error [no_sound_device]: --play: ")


def test_bridge_phonemes_with_their_recording_written_back_in_step(
    server: LiveServer, tmp_path: Path
) -> None:
    phones = [
        ("sil", 0.0, 0.1),
        ("M", 0.1, 0.2),
        ("AA", 0.2, 0.45),
        ("P", 0.45, 0.55),
        ("sil", 0.55, 0.7),
    ]
    (tmp_path / "line.json").write_text(
        json.dumps([{"phoneme": p, "start": s, "end": e} for p, s, e in phones])
    )
    rate = 16000
    samples = [round(8000 * ((i * 7919) % 200 - 100) / 100) for i in range(int(0.7 * rate))]
    recording = struct.pack(f"<{len(samples)}h", *samples)
    with wave.open(str(tmp_path / "line.wav"), "wb") as output:
        output.setnchannels(1)
        output.setsampwidth(2)
        output.setframerate(rate)
        output.writeframes(recording)
    done = run_cli(
        "bridge",
        "--server",
        server.ws,
        "--to",
        "stdout",
        "--format",
        "csv",
        "--phones",
        str(tmp_path / "line.json"),
        "--audio",
        str(tmp_path / "line.wav"),
        "--wav",
        str(tmp_path / "back.wav"),
    )
    assert done.returncode == 0, done.stderr
    frames, sent, dropped = summary(done.stderr)
    assert frames == len(served_phonemes(server.ws, phones, recording, rate))
    rows = done.stdout.splitlines()
    assert rows[0].startswith("frame,time,") and len(rows) == 1 + sent
    with wave.open(str(tmp_path / "back.wav"), "rb") as written:
        assert written.getframerate() == rate
        assert written.readframes(written.getnframes()) == recording
