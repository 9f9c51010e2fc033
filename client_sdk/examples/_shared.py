"""What the examples share: server flags, the default engine and character, a canned line.

The canned line is "Hello there, how are you today?" in ARPAbet with the
timing of a forced alignment of ordinary speech, for machines without a TTS.
"""

from __future__ import annotations

import argparse

from lipstream_client.rest import RestClient

DEFAULT_URL = "ws://127.0.0.1:8000/v1/stream"

# (phoneme, start s, end s), contiguous from 0.
CANNED_LINE: list[tuple[str, float, float]] = [
    ("sil", 0.00, 0.12),
    ("HH", 0.12, 0.19),
    ("AH", 0.19, 0.25),
    ("L", 0.25, 0.32),
    ("OW", 0.32, 0.47),
    ("DH", 0.47, 0.52),
    ("EH", 0.52, 0.63),
    ("R", 0.63, 0.72),
    ("sil", 0.72, 0.86),
    ("HH", 0.86, 0.92),
    ("AW", 0.92, 1.08),
    ("AA", 1.08, 1.16),
    ("R", 1.16, 1.22),
    ("Y", 1.22, 1.27),
    ("UW", 1.27, 1.38),
    ("T", 1.38, 1.44),
    ("AH", 1.44, 1.49),
    ("D", 1.49, 1.54),
    ("EY", 1.54, 1.78),
    ("sil", 1.78, 1.95),
]


def add_server_arguments(parser: argparse.ArgumentParser, engine: str | None = None) -> None:
    """--url, --engine (default ``engine``, else the server's first), --character, --token."""
    parser.add_argument(
        "--url", default=DEFAULT_URL, help=f"/v1/stream URL (default {DEFAULT_URL})"
    )
    parser.add_argument(
        "--engine",
        default=engine,
        help=f"default: {engine}" if engine else "default: the first engine of the first character",
    )
    parser.add_argument("--character", help="default: the server's first character")
    parser.add_argument("--token", help="bearer token, if the server requires one")


def resolve_target(args: argparse.Namespace) -> tuple[str, str]:
    """(engine, character) from the flags, asking the server for what is missing."""
    if args.engine and args.character:
        return args.engine, args.character
    engine, character = RestClient(args.url, args.token).default_target()
    return args.engine or engine, args.character or character


def milliseconds(value: float | None) -> str:
    """A server's timing for a reader: ``12.3 ms``, or ``n/a`` when it sent none."""
    return "n/a" if value is None else f"{value:.1f} ms"
