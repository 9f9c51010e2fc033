"""A chat-avatar backend: text reply -> TTS -> phonemes streamed as they are spoken -> face.

Method: for each reply the backend asks a TTS for speech with phoneme timing
(espeak-ng through ``lipstream.demo.espeak`` when it is installed, else a
canned line), then plays it: a feeder task sends each phoneme when the
playback clock reaches its start, as a streaming TTS emits phoneme events,
and optionally the PCM16 audio in 100 ms chunks, each at its start time
(audio first at equal times); a consumer task reads the
frames as they come and measures how late each one is against its
scheduled time (start sent + i / fps). ``--interrupt-at`` cuts the first
reply off there, as when the user talks over the avatar: the face returns to
rest and ``done`` reports reason ``interrupt``.

    python client_sdk/examples/chat_avatar.py --url ws://127.0.0.1:8000/v1/stream
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from dataclasses import dataclass

from _shared import CANNED_LINE, add_server_arguments, resolve_target

from lipstream_client import AsyncClient, Done, LipstreamClientError, Stream

AUDIO_CHUNK_S = 0.1
PCM16_BYTES = 2
DEFAULT_REPLIES = ("Hello there, how are you today?", "I can help you with that.")


Span = tuple[str, float, float]


@dataclass(frozen=True)
class Speech:
    """A TTS result: contiguous (phoneme, start s, end s) spans and optional PCM16 audio."""

    text: str
    spans: list[Span]
    pcm16: bytes = b""
    sample_rate: int = 0


def speak(text: str, voice: str) -> Speech:
    """espeak-ng's speech and phoneme timing for ``text``; the canned line when espeak-ng
    (or lipstream, which drives it) is not there."""
    try:
        from lipstream.demo.espeak import EspeakSynthesizer, speech_result
        from lipstream.errors import LipstreamError
    except ImportError:
        return Speech("(canned) " + text, list(CANNED_LINE))
    try:
        pcm, rate, events = EspeakSynthesizer(voice=voice).raw_speech(text)
        _, spans = speech_result(text, pcm, rate, events)
    except (LipstreamError, OSError) as error:
        print(f"espeak-ng failed ({error}); speaking the canned line", file=sys.stderr)
        return Speech("(canned) " + text, list(CANNED_LINE))
    return Speech(text, [(span.phoneme, span.start, span.end) for span in spans], pcm, rate)


async def sleep_until(moment: float) -> None:
    delay = moment - time.perf_counter()
    if delay > 0:
        await asyncio.sleep(delay)


def input_events(speech: Speech, with_audio: bool) -> list[tuple[float, int, bytes | Span]]:
    """(time s, order, payload) in sending order: each PCM16 chunk at its start time and
    each phoneme at its start; at equal times audio goes first, since a request that
    uses audio must have it from its first input on."""
    events: list[tuple[float, int, bytes | Span]] = [(span[1], 1, span) for span in speech.spans]
    if with_audio and speech.pcm16:
        chunk_bytes = round(AUDIO_CHUNK_S * speech.sample_rate) * PCM16_BYTES
        events += [
            (
                offset / PCM16_BYTES / speech.sample_rate,
                0,
                speech.pcm16[offset : offset + chunk_bytes],
            )
            for offset in range(0, len(speech.pcm16), chunk_bytes)
        ]
    return sorted(events, key=lambda event: event[:2])


async def feed(
    stream: Stream, speech: Speech, origin: float, with_audio: bool, stop_at: float | None
) -> None:
    """Send the input as the playback clock reaches it; interrupt at ``stop_at``."""
    for moment, _, payload in input_events(speech, with_audio):
        if stop_at is not None and moment >= stop_at:
            await sleep_until(origin + stop_at)
            await stream.interrupt(stop_at)
            return
        await sleep_until(origin + moment)
        if isinstance(payload, bytes):
            await stream.send_audio(payload, speech.sample_rate)
        else:
            await stream.send_phonemes([payload])
    await stream.end()


async def consume(stream: Stream, origin: float, fps: float) -> tuple[int, float]:
    """(frames received, largest lateness in ms against each frame's scheduled time)."""
    frames, worst = 0, float("-inf")
    async for block in stream.frames():
        arrived = time.perf_counter()
        frames += block.n_frames
        worst = max(worst, (arrived - origin - block.first_frame / fps) * 1000.0)
    return frames, worst


async def reply(
    client: AsyncClient,
    engine: str,
    character: str,
    speech: Speech,
    args: argparse.Namespace,
    stop_at: float | None,
) -> Done:
    origin = time.perf_counter()
    stream = await client.start(engine, character, fps=args.fps, emotion=args.emotion)
    _, (frames, worst) = await asyncio.gather(
        feed(stream, speech, origin, args.send_audio, stop_at), consume(stream, origin, args.fps)
    )
    done = await stream.done()
    print(
        f"  {len(speech.spans)} phonemes over {speech.spans[-1][2]:.2f} s, {frames} frames, "
        f"latest frame {worst:.0f} ms after its time; done: {done.reason}, "
        f"first frame after {done.stats.first_frame_latency_ms} ms (server)"
    )
    return done


async def run(args: argparse.Namespace) -> int:
    engine, character = await asyncio.to_thread(resolve_target, args)
    replies = args.text or list(DEFAULT_REPLIES)
    async with AsyncClient(args.url, token=args.token) as client:
        for number, text in enumerate(replies):
            speech = await asyncio.to_thread(speak, text, args.voice)
            print(f"reply {number + 1}: {speech.text!r}")
            stop_at = args.interrupt_at if number == 0 else None
            await reply(client, engine, character, speech, args, stop_at)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_server_arguments(parser)
    parser.add_argument("--text", action="append", help="a reply to speak (repeatable)")
    parser.add_argument("--voice", default="en-us", help="espeak-ng voice")
    parser.add_argument("--fps", type=float, default=60.0)
    parser.add_argument("--emotion", choices=["neutral", "happy", "angry", "sad"])
    parser.add_argument(
        "--send-audio",
        action="store_true",
        help="also stream the PCM16 audio (for engines that use it)",
    )
    parser.add_argument(
        "--interrupt-at", type=float, help="cut the first reply off at this many seconds"
    )
    args = parser.parse_args()
    try:
        return asyncio.run(run(args))
    except (LipstreamClientError, OSError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
