"""A game loop that pulls lip-sync frames at a fixed 60 Hz tick.

Method: a game knows a dialogue line's phoneme alignment before it plays, so
it sends the whole line at once and then runs its usual fixed-timestep loop.
Every tick it takes the blocks that have arrived (``poll``, never blocking
the frame), files them by index in a ``FrameTimeline``, and applies the frame
due at the tick's time: ``floor(t * fps)``, or the newest frame received when
the stream has not caught up (counted as a late tick). The loop ends when the
request is done and the last frame has played, or after ``--seconds``.

    python client_sdk/examples/game_loop.py --url ws://127.0.0.1:8000/v1/stream
"""

from __future__ import annotations

import argparse
import sys
import time

from _shared import CANNED_LINE, add_server_arguments, milliseconds, resolve_target

from lipstream_client import LipstreamClientError, Ready
from lipstream_client.frame_timeline import FrameTimeline
from lipstream_client.sync import Client

TICK_HZ = 60.0
BAR_WIDTH = 30


def jaw_channel(ready: Ready) -> int:
    """The column of the jaw-open channel in any naming style, else column 0."""
    names = [name.lower() for name in ready.channels]
    return names.index("jawopen") if "jawopen" in names else 0


def bar(value: float) -> str:
    filled = round(min(max(value, 0.0), 1.0) * BAR_WIDTH)
    return "#" * filled + "." * (BAR_WIDTH - filled)


def play(args: argparse.Namespace) -> int:
    engine, character = resolve_target(args)
    with Client(args.url, token=args.token, timeout=10.0) as client:
        stream = client.start(engine, character, fps=args.fps)
        stream.send_phonemes(CANNED_LINE)
        stream.end()
        ready = stream.ready()
        jaw = jaw_channel(ready)
        timeline = FrameTimeline(ready.fps)
        print(
            f"{engine}/{character}: {len(ready.channels)} channels at {ready.fps:g} fps, "
            f"fidelity {ready.fidelity}, showing {ready.channels[jaw]}"
        )
        tick, late, report_every = 0, 0, max(1, round(args.report_every * TICK_HZ))
        started = time.perf_counter()
        while True:
            delay = started + tick / TICK_HZ - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            for block in stream.poll():
                timeline.add(block)
            now = tick / TICK_HZ
            shown = timeline.at(now)
            if shown is None or shown[0] < min(timeline.index_at(now), len(timeline) - 1):
                late += 1
            if shown is not None and tick % report_every == 0:
                index, row = shown
                print(f"t={now:6.3f}s frame {index:4d} {bar(row[jaw])} {row[jaw]:.3f}")
            if stream.is_over and shown is not None and now >= (len(timeline) - 1) / ready.fps:
                break
            if now >= args.seconds:
                print(f"stopping after {args.seconds:g} s", file=sys.stderr)
                stream.cancel()
                break
            tick += 1
        done = stream.done()
    print(
        f"played {tick + 1} ticks at {TICK_HZ:g} Hz; {len(timeline)} frames received; "
        f"{late} late ticks; done: {done.reason}, {done.stats.frames} frames, "
        f"server max lag {milliseconds(done.stats.max_lag_ms)}"
    )
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_server_arguments(parser)
    parser.add_argument("--fps", type=float, default=60.0, help="frame rate to request")
    parser.add_argument("--seconds", type=float, default=10.0, help="longest run time")
    parser.add_argument(
        "--report-every", type=float, default=0.1, help="print the shown frame this often (seconds)"
    )
    args = parser.parse_args()
    try:
        return play(args)
    except (LipstreamClientError, OSError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
