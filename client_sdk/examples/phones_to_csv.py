"""Batch-convert phones files (.TextGrid, .lab, .json) to frame CSVs through the server.

Method: every file becomes one request on a single WebSocket connection;
``--concurrency`` requests run at once, multiplexed by id. Each sends its
phonemes in messages of at most ``CHUNK`` items (to stay far below the
server's message-size limit), then ``end``, and collects the frames. The CSV
has the corpus format that ``lipstream synth`` writes: a ``time`` column
(frame i at i / fps s) and one column per channel, values printed with
``%.6f``; its rows are those of ``lipstream synth``, then the frames of the
server's return to rest after the last phoneme. Files are read with
``lipstream.phones_io`` when lipstream is installed (all three formats,
validated with file and line); with the client package alone, JSON lists of
``{"phoneme", "start", "end"}`` are read.
A file that fails is reported on one line and the others still convert.

    python client_sdk/examples/phones_to_csv.py --url ws://127.0.0.1:8000/v1/stream \\
        --out-dir frames/ alignments/*.TextGrid
"""

from __future__ import annotations

import argparse
import asyncio
import csv
import json
import sys
from pathlib import Path

from _shared import add_server_arguments, resolve_target

from lipstream_client import AsyncClient, EncodeError, LipstreamClientError, StreamResult

CHUNK = 256
VALUE_FORMAT = "%.6f"

Span = tuple[str, float, float]


class PhonesError(Exception):
    """A phones file that cannot be read; the message names the file."""


def read_phones(path: Path) -> list[Span]:
    """(phoneme, start s, end s) spans of a .TextGrid, .lab or .json phones file."""
    try:
        from lipstream.errors import LipstreamError
        from lipstream.phones_io import read_phones as read_validated
    except ImportError:
        return _read_json_phones(path)
    try:
        return [(span.phoneme, span.start, span.end) for span in read_validated(path)]
    except LipstreamError as error:
        raise PhonesError(str(error)) from None


def _read_json_phones(path: Path) -> list[Span]:
    if path.suffix.lower() != ".json":
        raise PhonesError(
            f"{path}: reading {path.suffix} files needs the lipstream package; "
            f"without it only .json phones are read"
        )
    try:
        items = json.loads(path.read_text(encoding="utf-8"))
        return [(str(item["phoneme"]), float(item["start"]), float(item["end"])) for item in items]
    except (OSError, ValueError, TypeError, KeyError) as error:
        raise PhonesError(
            f"{path}: not a JSON list of phoneme/start/end objects ({error})"
        ) from None


def write_csv(path: Path, result: StreamResult) -> None:
    """``time`` plus one column per channel; frame i at i / fps seconds."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(("time", *result.channels))
        for index, row in enumerate(result.rows()):
            writer.writerow(
                [
                    VALUE_FORMAT % (index / result.ready.fps),
                    *(VALUE_FORMAT % value for value in row),
                ]
            )


async def convert(
    client: AsyncClient,
    target: tuple[str, str],
    source: Path,
    out: Path,
    fps: float,
    limit: asyncio.Semaphore,
) -> bool:
    async with limit:
        try:
            spans = await asyncio.to_thread(read_phones, source)
            stream = await client.start(*target, fps=fps)
            for first in range(0, len(spans), CHUNK):
                await stream.send_phonemes(spans[first : first + CHUNK])
            await stream.end()
            result = await stream.collect()
            await asyncio.to_thread(write_csv, out, result)
        except PhonesError as error:  # its message names the file
            print(error, file=sys.stderr)
            return False
        except (EncodeError, LipstreamClientError, OSError) as error:
            print(f"{source}: {error}", file=sys.stderr)
            return False
    print(f"{source} -> {out}: {len(result.rows())} frames x {len(result.channels)} channels")
    return True


def output_path(source: Path, out_dir: Path | None) -> Path:
    return (out_dir / source.name if out_dir else source).with_suffix(".csv")


async def run(args: argparse.Namespace) -> int:
    target = await asyncio.to_thread(resolve_target, args)
    sources = [Path(name) for name in args.phones]
    out_dir = Path(args.out_dir) if args.out_dir else None
    limit = asyncio.Semaphore(args.concurrency)
    async with AsyncClient(args.url, token=args.token) as client:
        converted = await asyncio.gather(
            *(
                convert(client, target, source, output_path(source, out_dir), args.fps, limit)
                for source in sources
            )
        )
    failed = converted.count(False)
    print(f"converted {len(sources) - failed} of {len(sources)} files")
    return 1 if failed else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_server_arguments(parser)
    parser.add_argument("phones", nargs="+", help=".TextGrid, .lab or .json phones files")
    parser.add_argument("--out-dir", help="where to write the CSVs (default: beside each input)")
    parser.add_argument("--fps", type=float, default=60.0)
    parser.add_argument(
        "--concurrency", type=int, default=4, help="requests in flight at once on the connection"
    )
    args = parser.parse_args()
    if args.concurrency < 1:
        parser.error("--concurrency must be at least 1")
    try:
        return asyncio.run(run(args))
    except (LipstreamClientError, OSError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
