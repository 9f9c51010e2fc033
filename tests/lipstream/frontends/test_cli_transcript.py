"""``lipstream synth --audio WAV --transcript TEXT|FILE``: a recording's phones by forced
alignment drive a model; its frames stay as close to those of espeak-ng's own phoneme
events as the aligner's measured onset error allows; every aligner error is one coded
line naming the audio file."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from lipstream.audio import Audio, write_wav
from lipstream.cli import main
from lipstream.engines import load_model
from lipstream.speech.text_frontend import speak_text
from tests.helpers import delayed_spans

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

TEXT = "Please call Stella and ask her to bring these things with her from the store."
FPS = 50.0
# test_align.py holds the aligner's phone onsets to a p90 error of 50 ms against
# espeak-ng's events; frames of the aligned phones must then be closer to the true
# frames than the true frames delayed by that much are.
P90_ONSET_ERROR_S = 0.05


def frames_of(path: Path) -> np.ndarray:
    document = json.loads(path.read_text(encoding="utf-8"))
    return np.array(document["frames"], dtype=np.float64)


def rms(a: np.ndarray, b: np.ndarray) -> float:
    rows = min(len(a), len(b))
    return float(np.sqrt(np.mean((a[:rows] - b[:rows]) ** 2)))


def test_aligned_frames_are_within_the_aligners_error_of_espeak_ngs_own(
    lerp_model_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spoken = speak_text(TEXT)
    wav = tmp_path / "stella.wav"
    write_wav(wav, spoken.audio)
    transcript = tmp_path / "stella.txt"
    transcript.write_text(TEXT, encoding="utf-8")
    out = tmp_path / "frames.json"
    status = main(
        [
            "synth",
            "--model",
            str(lerp_model_dir),
            "--audio",
            str(wav),
            "--transcript",
            str(transcript),
            "--out",
            str(out),
            "--fps",
            str(FPS),
        ]
    )
    assert status in (0, None)
    err = capsys.readouterr().err
    confidence = float(err.split("alignment confidence ")[1].split()[0])
    assert 0.25 <= confidence <= 1.0
    model = load_model(lerp_model_dir)
    truth = np.asarray(model.synthesize(spoken.spans, fps=FPS, audio=spoken.audio).frames)
    late = np.asarray(
        model.synthesize(delayed_spans(spoken.spans, P90_ONSET_ERROR_S), fps=FPS).frames
    )
    aligned = frames_of(out)
    assert abs(len(aligned) - len(truth)) <= 1
    assert rms(aligned, truth) < rms(late, truth)
    assert rms(late, truth) > 0.0  # the bound means something: a delay does change frames


@pytest.mark.parametrize(
    ("transcript", "audio", "code"),
    [
        ("", "speech", "empty_transcript"),
        ("Seven green apples sat in a wooden bowl all day.", "speech", "transcript_mismatch"),
        ("hello there", "silence", "not_speech"),
    ],
)
def test_each_aligner_error_is_one_coded_line_naming_the_audio(
    lerp_model_dir: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    transcript: str,
    audio: str,
    code: str,
) -> None:
    wav = tmp_path / f"{audio}.wav"
    if audio == "speech":
        write_wav(wav, speak_text("The quick brown fox jumps over the lazy dog.").audio)
    else:
        write_wav(wav, Audio(np.zeros(16000, np.float32), 16000))
    out = tmp_path / "f.json"
    status = main(
        [
            "synth",
            "--model",
            str(lerp_model_dir),
            "--audio",
            str(wav),
            "--transcript",
            transcript,
            "--out",
            str(out),
        ]
    )
    assert status == 2
    assert capsys.readouterr().err.startswith(f"error [{code}]: {wav}:")
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "where"),
    [([], "--transcript"), (["--audio", "a.wav", "--voice", "m1"], "--voice")],
)
def test_a_transcript_without_audio_or_with_text_options_is_refused(
    lerp_model_dir: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    where: str,
) -> None:
    status = main(
        [
            "synth",
            "--model",
            str(lerp_model_dir),
            "--transcript",
            "hello",
            *extra,
            "--out",
            str(tmp_path / "f.json"),
        ]
    )
    assert status == 2
    assert capsys.readouterr().err.startswith(f"error [invalid_request]: {where}:")


def test_the_audio_reaches_an_engine_that_hears_it(all_models_dir: Path, tmp_path: Path) -> None:
    """``hmm`` listens: the transcript's frames are those of ``lipstream align``'s TextGrid
    played with the same WAV through ``--phones``, and differ from them without the WAV."""
    spoken = speak_text(TEXT)
    wav = tmp_path / "stella.wav"
    write_wav(wav, spoken.audio)
    grid = tmp_path / "stella.TextGrid"
    assert main(["align", str(wav), "--transcript", TEXT, "--out", str(grid)]) in (0, None)
    model = ["--model", str(all_models_dir / "hmm"), "--fps", str(FPS)]
    runs = {
        "transcript": ["--audio", str(wav), "--transcript", TEXT],
        "phones": ["--phones", str(grid), "--audio", str(wav)],
        "deaf": ["--phones", str(grid)],
    }
    frames = {}
    for name, given in runs.items():
        out = tmp_path / f"{name}.json"
        assert main(["synth", *model, *given, "--out", str(out)]) in (0, None)
        frames[name] = frames_of(out)
    np.testing.assert_allclose(frames["transcript"], frames["phones"], atol=1e-3)
    assert rms(frames["deaf"], frames["phones"]) > 1e-3
