"""A chat-avatar backend: text reply -> TTS -> phonemes streamed as they are spoken -> face.

Method: for each reply the backend asks a TTS for speech with phoneme timing
(espeak-ng through ``lipstream.speech.espeak`` when it is installed, else a
canned line), then plays it: a feeder task sends each phoneme ``--lead-ms``
before the playback clock reaches its start, as a streaming TTS emits phoneme
events ahead of the audio it plays, and optionally the PCM16 audio in 100 ms
chunks, each as early (audio first at equal times); a consumer task reads the
frames as they come and measures how late each one is against its scheduled
time (playback start + i / fps; negative is early, ready to play).
``--interrupt-at`` cuts the first reply off there, as when the user talks over
the avatar: the face returns to rest and ``done`` reports reason ``interrupt``.

Why the defaults, ``viseme-lerp`` with a 400 ms lead: a frame is final only
once the input its engine looks ahead to has arrived. ``viseme-lerp`` waits for
the phoneme after the frame's own, so with each phoneme sent as it is spoken
(no lead) a frame is late by up to its phoneme's length; sending every phoneme
400 ms early, longer than the phonemes of ordinary speech (espeak-ng's longest
in the default replies lasts 0.30 s), means no frame waits.
``anime-graph``'s best rung waits for up to 10 phonemes (``ready.lookahead_ms``,
about 2.1 s on the demo), so streamed with no lead its frames arrive most of a
second late; use it with ``--lead-ms 2200``, or with ``--latency-budget-ms`` to
pick a faster rung (docs/reference/protocol.md, *Latency budgets*).

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
DEFAULT_ENGINE = "viseme-lerp"
DEFAULT_LEAD_MS = 400.0
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
        from lipstream.errors import LipstreamError
        from lipstream.speech.espeak import EspeakSynthesizer, speech_result
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
    stream: Stream,
    speech: Speech,
    origin: float,
    lead_s: float,
    with_audio: bool,
    stop_at: float | None,
) -> None:
    """Send the input ``lead_s`` before the playback clock reaches it; interrupt when
    playback reaches ``stop_at``."""
    for moment, _, payload in input_events(speech, with_audio):
        if stop_at is not None and moment - lead_s >= stop_at:
            await sleep_until(origin + stop_at)
            await stream.interrupt(stop_at)
            return
        await sleep_until(origin + moment - lead_s)
        if isinstance(payload, bytes):
            await stream.send_audio(payload, speech.sample_rate)
        else:
            await stream.send_phonemes([payload])
    await stream.end()


async def consume(stream: Stream, origin: float, fps: float) -> tuple[int, float]:
    """(frames received, largest lateness in ms against each frame's scheduled time;
    negative when every frame came early)."""
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
    lead_s = args.lead_ms / 1000.0
    origin = time.perf_counter() + lead_s  # playback starts one lead after the request
    stream = await client.start(
        engine,
        character,
        fps=args.fps,
        emotion=args.emotion,
        latency_budget_ms=args.latency_budget_ms,
    )
    _, (frames, worst) = await asyncio.gather(
        feed(stream, speech, origin, lead_s, args.send_audio, stop_at),
        consume(stream, origin, args.fps),
    )
    done = await stream.done()
    print(
        f"  {len(speech.spans)} phonemes over {speech.spans[-1][2]:.2f} s, {frames} frames, "
        f"latest frame {worst:+.0f} ms against its time; done: {done.reason}, "
        f"first frame after {done.stats.first_frame_latency_ms} ms (server)"
    )
    return done


async def run(args: argparse.Namespace) -> int:
    engine, character = await asyncio.to_thread(resolve_target, args)
    replies = args.text or list(DEFAULT_REPLIES)
    print(f"{engine}/{character}, each phoneme sent {args.lead_ms:g} ms before it is spoken")
    async with AsyncClient(args.url, token=args.token) as client:
        for number, text in enumerate(replies):
            speech = await asyncio.to_thread(speak, text, args.voice)
            print(f"reply {number + 1}: {speech.text!r}")
            stop_at = args.interrupt_at if number == 0 else None
            await reply(client, engine, character, speech, args, stop_at)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_server_arguments(parser, engine=DEFAULT_ENGINE)
    parser.add_argument(
        "--lead-ms",
        type=float,
        default=DEFAULT_LEAD_MS,
        help=f"send each phoneme this long before it is spoken (default {DEFAULT_LEAD_MS:g}: "
        f"{DEFAULT_ENGINE} then never waits for input; see the module docstring)",
    )
    parser.add_argument(
        "--latency-budget-ms",
        type=float,
        help="latency_budget_ms of each reply: the server picks the best rung that meets it",
    )
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
