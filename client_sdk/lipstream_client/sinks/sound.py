"""The speech that goes with the frames: placed on the frames' clock, written or played.

Sketch: the speech arrives as PCM16 chunks, each with its start on the utterance clock
(the server's speech for a ``text`` request), or is the WAV the request was driven by
(start 0). ``SpeechTrack`` lays them on one timeline from t = 0, silence in the gaps,
so that sample ``k`` sounds at ``k / sample_rate`` seconds, exactly where frame
``floor(k * fps / sample_rate)`` is shown: written to a WAV (``write_wav``) it lines up
with the frames from its first sample. ``SoundPlayer`` plays the track through a
command-line player (PipeWire's ``pw-play``, PulseAudio's ``paplay`` or ALSA's
``aplay``), started when the first frame goes out (or, when the speech comes later, at
the point of the track the frames have reached) and fed as the speech arrives; a
machine with no sound device or no player is ``no_sound_device``.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil
import wave
from collections.abc import Sequence
from pathlib import Path

from ..messages import PCM16_BYTES
from .errors import NO_SOUND_DEVICE, BridgeError


class SpeechTrack:
    """Mono PCM16 at ``sample_rate`` from t = 0: chunks placed at their start times."""

    def __init__(self, sample_rate: int) -> None:
        if sample_rate <= 0:
            raise ValueError(f"sample rate must be positive, got {sample_rate}")
        self.sample_rate = sample_rate
        self._pcm = bytearray()

    def place(self, pcm16: bytes, start_s: float) -> tuple[int, int]:
        """Lay ``pcm16`` from ``start_s`` seconds (later chunks overwrite where they
        overlap); the byte range it now fills."""
        offset = round(start_s * self.sample_rate) * PCM16_BYTES
        data = pcm16[: len(pcm16) - len(pcm16) % PCM16_BYTES]
        end = offset + len(data)
        if end > len(self._pcm):
            self._pcm.extend(bytes(end - len(self._pcm)))
        self._pcm[offset:end] = data
        return offset, end

    def pcm16(self, from_byte: int = 0) -> bytes:
        """The track's bytes from ``from_byte`` on."""
        return bytes(self._pcm[from_byte:])

    @property
    def n_bytes(self) -> int:
        return len(self._pcm)

    @property
    def duration(self) -> float:
        return len(self._pcm) // PCM16_BYTES / self.sample_rate


def write_wav(path: Path, track: SpeechTrack) -> None:
    """The track as a 16-bit mono WAV."""
    with wave.open(str(path), "wb") as output:
        output.setnchannels(1)
        output.setsampwidth(PCM16_BYTES)
        output.setframerate(track.sample_rate)
        output.writeframes(track.pcm16())


PLAYERS: tuple[tuple[str, ...], ...] = (
    ("pw-play", "--format", "s16", "--channels", "1", "--rate", "{rate}", "-"),
    ("paplay", "--raw", "--format=s16le", "--channels=1", "--rate={rate}"),
    ("aplay", "-q", "-t", "raw", "-f", "S16_LE", "-c", "1", "-r", "{rate}"),
)
"""Players tried in order, each reading raw PCM16 on its standard input."""


def has_sound_device(runtime_dir: str | None = None, dev: Path = Path("/dev/snd")) -> bool:
    """An ALSA playback device, or a PipeWire or PulseAudio server socket for this user."""
    if any(dev.glob("pcmC*D*p")):
        return True
    runtime = Path(runtime_dir or os.environ.get("XDG_RUNTIME_DIR") or f"/run/user/{os.getuid()}")
    return (runtime / "pipewire-0").exists() or (runtime / "pulse" / "native").exists()


def player_command() -> tuple[str, ...]:
    """The argv template (``{rate}`` for the sample rate) of the first player found for a
    sound device; ``no_sound_device`` when there is no device or no player."""
    if not has_sound_device():
        raise BridgeError(
            NO_SOUND_DEVICE,
            "this machine has no sound device (no ALSA playback device in /dev/snd, no "
            "PipeWire or PulseAudio server); write the speech with --wav instead",
            "--play",
        )
    for template in PLAYERS:
        if shutil.which(template[0]) is not None:
            return template
    names = ", ".join(template[0] for template in PLAYERS)
    raise BridgeError(NO_SOUND_DEVICE, f"no player found on PATH (tried {names})", "--play")


class SoundPlayer:
    """Plays PCM16 through ``command`` (an argv template, ``{rate}`` standing for the
    sample rate, of a player reading raw samples on stdin), fed as the speech arrives."""

    def __init__(self, command: Sequence[str]) -> None:
        self.command = list(command)
        self._process: asyncio.subprocess.Process | None = None

    @property
    def started(self) -> bool:
        return self._process is not None

    async def start(self, sample_rate: int) -> None:
        argv = [part.format(rate=sample_rate) for part in self.command]
        try:
            self._process = await asyncio.create_subprocess_exec(
                *argv,
                stdin=asyncio.subprocess.PIPE,
                stdout=asyncio.subprocess.DEVNULL,
                stderr=asyncio.subprocess.DEVNULL,
            )
        except OSError as error:
            raise BridgeError(
                NO_SOUND_DEVICE, f"cannot start {argv[0]}: {error.strerror}", "--play"
            ) from None

    async def feed(self, pcm16: bytes) -> None:
        """Play ``pcm16`` after what was fed before."""
        process = self._process
        if process is None:
            raise RuntimeError("start() the player first")
        assert process.stdin is not None
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):
            process.stdin.write(pcm16)
            await process.stdin.drain()

    async def finish(self) -> int:
        """Close the player's input and wait until it has played everything."""
        process = self._process
        if process is None:
            return 0
        assert process.stdin is not None
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):
            process.stdin.close()
            await process.stdin.wait_closed()
        return await process.wait()
