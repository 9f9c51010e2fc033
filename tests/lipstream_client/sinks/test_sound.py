"""Speech laid on the frames' clock: chunks at their start sample, silence between; the
WAV written from it; the player fed the same bytes; no sound device a coded error."""

from __future__ import annotations

import asyncio
import sys
import wave
from pathlib import Path

import pytest

from lipstream_client.sinks import BridgeError, SoundPlayer, SpeechTrack, sound, write_wav


def test_chunks_land_at_their_start_sample_with_silence_between(tmp_path: Path) -> None:
    track = SpeechTrack(16000)
    track.place(b"\x01\x00" * 160, 0.5)  # 10 ms from 0.5 s
    track.place(b"\x02\x00" * 80, 0.1)
    pcm = track.pcm16()
    assert len(pcm) == 2 * (8000 + 160)
    assert pcm[2 * 1600 : 2 * 1680] == b"\x02\x00" * 80
    assert pcm[2 * 1680 : 2 * 8000] == bytes(2 * 6320) and pcm[: 2 * 1600] == bytes(3200)
    assert pcm[2 * 8000 :] == b"\x01\x00" * 160
    write_wav(tmp_path / "speech.wav", track)
    with wave.open(str(tmp_path / "speech.wav"), "rb") as written:
        assert (written.getnchannels(), written.getsampwidth(), written.getframerate()) == (
            1,
            2,
            16000,
        )
        assert written.readframes(written.getnframes()) == pcm


def test_the_player_gets_the_samples_in_order(tmp_path: Path) -> None:
    heard = tmp_path / "heard.raw"
    copy = f"import sys; open({str(heard)!r}, 'wb').write(sys.stdin.buffer.read())"
    player = SoundPlayer([sys.executable, "-c", copy, "{rate}"])

    async def play() -> int:
        await player.start(22050)
        await player.feed(b"\x01\x02" * 1000)
        await player.feed(b"\x03\x04" * 1000)
        return await player.finish()

    assert asyncio.run(play()) == 0
    assert heard.read_bytes() == b"\x01\x02" * 1000 + b"\x03\x04" * 1000


def test_no_sound_device_is_a_coded_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert not sound.has_sound_device(str(tmp_path), tmp_path / "snd")
    (tmp_path / "pulse").mkdir()
    (tmp_path / "pulse" / "native").touch()
    assert sound.has_sound_device(str(tmp_path), tmp_path / "snd")
    monkeypatch.setattr(sound, "has_sound_device", lambda: False)
    with pytest.raises(BridgeError) as caught:
        sound.player_command()
    assert caught.value.code == "no_sound_device" and caught.value.where == "--play"
