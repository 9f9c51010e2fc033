"""``lipstream bridge``: a request on a lipstream server, its frames sent where a rig listens.

The forwarding itself is the client SDK's (``lipstream_client.bridge``), so that a
program can run it too; this module reads the command line and the input files, builds
the sink the target names, and turns the SDK's coded errors into the CLI's one line.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import Settings
from ..errors import LipstreamError
from ..loadtest.command import default_url

if TYPE_CHECKING:
    from lipstream_client.bridge import BridgeInput, BridgeReport
    from lipstream_client.sinks import Sink, Target
    from lipstream_client.sinks.sound import SoundPlayer

    from .commands import Commands


OPTION_OF_FIELD = {
    "engine": "--engine",
    "character": "--character",
    "fps": "--fps",
    "output.retarget": "--preset",
    "output": "--preset",
    "text": "--text",
    "voice": "--voice",
    "rate": "--rate",
    "items": "--phones",
    "sample_rate": "--audio",
    "pcm16": "--audio",
}
"""The option behind a request field a server error (or the codec) names."""


def _bridge(args: argparse.Namespace, settings: Settings) -> None:
    from lipstream_client import EncodeError, LipstreamClientError, LipstreamServerError
    from lipstream_client.bridge import Bridge
    from lipstream_client.sinks import BridgeError, parse_target

    try:
        target = parse_target(args.to)
        _check_options(args, target)
        source = _source(args)
        player = _player() if args.play else None
        sink = _sink(args, target)
        bridge = Bridge(sink, wav=Path(args.wav) if args.wav else None, player=player)
        try:
            report = asyncio.run(
                bridge.run(
                    args.server or default_url(settings),
                    source,
                    engine=args.engine,
                    character=args.character,
                    preset=args.preset,
                    fps=args.fps,
                    token=args.token,
                )
            )
        finally:
            sink.close()
    except BridgeError as error:
        raise LipstreamError(error.message, where=error.where, code=error.code) from None
    except EncodeError as error:
        field = error.error.where or ""
        where = OPTION_OF_FIELD.get(field.split(".")[0].split("[")[0], "--server")
        message = f"{field}: {error.error.message}" if field else error.error.message
        raise LipstreamError(message, where=where, code=error.error.code) from None
    except LipstreamServerError as error:
        field = error.message.split(":", 1)[0] if ":" in error.message else ""
        where = OPTION_OF_FIELD.get(field.split("[")[0], "--server")
        raise LipstreamError(error.message, where=where, code=error.code) from None
    except LipstreamClientError as error:
        raise LipstreamError(str(error), where="--server", code="stream_failed") from None
    print(_summary(report, target), file=sys.stderr)
    if args.wav and report.speech_s > 0:
        print(f"wrote {report.speech_s:.2f} s of speech to {args.wav}", file=sys.stderr)


def _check_options(args: argparse.Namespace, target: Target) -> None:
    if args.text is not None and args.audio:
        raise LipstreamError(
            "--audio goes with --phones or alone; with --text the speech is the server's",
            where="--audio",
            code="invalid_request",
        )
    if args.text is None:
        for option, value in (("--voice", args.voice), ("--rate", args.rate)):
            if value is not None:
                raise LipstreamError(
                    f"{option} goes with --text", where=option, code="invalid_request"
                )
    if args.text is None and args.phones is None and args.audio is None:
        raise LipstreamError(
            "give --text, --phones or --audio", where="--text", code="invalid_request"
        )
    if target.kind != "livelink" and args.subject is not None:
        raise LipstreamError(
            "--subject names a Live Link subject", where="--subject", code="invalid_request"
        )
    if target.kind != "stdout" and args.format is not None:
        raise LipstreamError(
            "--format is the format of stdout", where="--format", code="invalid_request"
        )
    if target.kind == "stdout" and args.bind is not None:
        raise LipstreamError(
            "--bind is the local address of a UDP target", where="--bind", code="invalid_request"
        )


def _source(args: argparse.Namespace) -> BridgeInput:
    from lipstream_client.bridge import BridgeInput

    if args.text is not None:
        return BridgeInput(text=args.text, voice=args.voice, rate=args.rate)
    audio, rate = _read_audio(Path(args.audio)) if args.audio else (None, 16000)
    phonemes: list[tuple[str, float, float]] = []
    if args.phones is not None:
        from ..phones_io import read_phones

        spans = read_phones(Path(args.phones), args.tier)
        phonemes = [(span.phoneme, span.start, span.end) for span in spans]
    return BridgeInput.from_phonemes(phonemes, audio, rate)


def _read_audio(path: Path) -> tuple[bytes, int]:
    import numpy as np

    from ..audio import read_wav

    audio = read_wav(path)
    pcm = np.clip(np.round(audio.samples * 32767.0), -32768, 32767).astype("<i2")
    return pcm.tobytes(), audio.sample_rate


def _player() -> SoundPlayer:
    from lipstream_client.sinks.sound import SoundPlayer, player_command

    return SoundPlayer(player_command())


def _sink(args: argparse.Namespace, target: Target) -> Sink:
    from lipstream_client.sinks import (
        LinesSink,
        LiveLinkEncoder,
        LiveLinkSink,
        UdpSender,
        parse_local_address,
    )

    if target.kind == "stdout":
        return LinesSink(sys.stdout, args.format or "jsonl")
    bind = parse_local_address(args.bind) if args.bind else None
    if target.kind == "livelink":
        encoder = LiveLinkEncoder(args.subject or "lipstream")
        return LiveLinkSink(UdpSender(target.host, target.port, bind), encoder)
    from lipstream_client.sinks.vmc import VmcSink, require_python_osc

    require_python_osc("--to")  # before the socket opens
    return VmcSink(UdpSender(target.host, target.port, bind))


def _summary(report: BridgeReport, target: Target) -> str:
    line = (
        f"bridged {report.frames} frames ({len(report.channels)} channels at {report.fps:g} fps) "
        f"to {target}: {report.sent} on time, {report.dropped} dropped late"
    )
    delivery = report.delivery
    attempts = delivery.sent + delivery.refused + delivery.failed
    unit = "lines" if target.kind == "stdout" else "datagrams"
    if delivery.refused:
        line += (
            f"; {delivery.refused} of {attempts} {unit} refused (ICMP port unreachable: "
            f"nothing listened at {target})"
        )
    if delivery.failed:
        line += f"; {delivery.failed} of {attempts} {unit} failed"
    return line


def add_bridge_parser(commands: Commands) -> None:
    """Add ``bridge`` to the CLI's subcommands ``commands``."""
    from lipstream_client.sinks import LINE_FORMATS

    bridge = commands.add_parser(
        "bridge",
        help="stream a request's frames to Unreal Live Link, a VMC receiver or stdout",
        description="Open a request on a lipstream server (text, phonemes or audio) and "
        "forward every frame, on time, to Unreal's Live Link (the Live Link Face UDP packet), "
        "a VTuber app's VMC receiver (OSC) or stdout (JSON lines or CSV). Late frames are "
        "dropped, not queued; the count is shown at the end.",
    )
    bridge.add_argument(
        "--server",
        help="the server's stream URL, ws://HOST:PORT/v1/stream "
        "(default: $LIPSTREAM_HOST:$LIPSTREAM_PORT)",
    )
    bridge.add_argument(
        "--to",
        required=True,
        metavar="TARGET",
        help="livelink://HOST[:PORT] (default port 11111), vmc://HOST[:PORT] "
        "(default port 39539) or stdout",
    )
    bridge.add_argument(
        "--preset",
        metavar="NAME",
        help="rig preset, sent as output.retarget (e.g. arkit52; default: the character's)",
    )
    bridge.add_argument("--engine", help="default: the server's first character's first engine")
    bridge.add_argument("--character", help="default: the server's first character")
    given = bridge.add_mutually_exclusive_group()
    given.add_argument("--text", help="text for the server to speak (espeak-ng)")
    given.add_argument("--phones", metavar="FILE", help="phonemes: .TextGrid, .lab or .json")
    bridge.add_argument(
        "--audio", metavar="WAV", help="mono WAV of the speech: alone, or with --phones"
    )
    bridge.add_argument("--tier", help="with --phones: the TextGrid phone tier")
    bridge.add_argument("--voice", help="with --text: espeak-ng voice (default en-us)")
    bridge.add_argument("--rate", type=int, help="with --text: words per minute, 80-450")
    bridge.add_argument("--fps", type=float, default=60.0, help="frame rate (default 60)")
    bridge.add_argument(
        "--subject",
        help="livelink: the subject name Unreal lists the face under (default lipstream)",
    )
    bridge.add_argument("--format", choices=LINE_FORMATS, help="stdout: jsonl (default) or csv")
    bridge.add_argument(
        "--bind",
        metavar="HOST:PORT",
        help="UDP targets: the local address to send from (port 0: any)",
    )
    bridge.add_argument(
        "--wav", metavar="FILE", help="write the speech to this WAV, in step with the frames"
    )
    bridge.add_argument(
        "--play", action="store_true", help="play the speech through the sound device"
    )
    bridge.add_argument("--token", help="bearer token, if the server requires one")
    bridge.set_defaults(run=_bridge)
