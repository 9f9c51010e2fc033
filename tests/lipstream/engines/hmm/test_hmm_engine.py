"""The hmm engine on the demo character: three driving modes, audio rules, the server."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest

from lipstream.audio import Audio
from lipstream.bench.hmm_first_frame import pcm16_of
from lipstream.corpus import Corpus
from lipstream.engines.base import Model, frame_count
from lipstream.engines.hmm import HmmEngine, HmmModel
from lipstream.engines.hmm.model import RUNGS
from lipstream.errors import InvalidRequestError
from lipstream_client import AsyncClient, Frames, LipstreamServerError, StreamResult
from tests.helpers import return_frames
from tests.live_server import LiveServer, live_server, save_models

FPS = 60.0


@pytest.fixture(scope="module")
def model(trained_models: dict[str, Model]) -> HmmModel:
    hmm = trained_models["hmm"]
    assert isinstance(hmm, HmmModel)
    return hmm


@pytest.fixture(scope="module")
def heldout(small_demo_corpus: Corpus) -> Corpus:
    return small_demo_corpus.split()[1]


def _rms(frames: np.ndarray, recorded: np.ndarray) -> float:
    n = min(len(frames), len(recorded))
    return float(np.sqrt(np.mean((frames[:n] - recorded[:n]) ** 2)))


def test_every_mode_beats_the_mean_pose_on_held_out_lines(
    model: HmmModel, heldout: Corpus, small_demo_corpus: Corpus
) -> None:
    train = small_demo_corpus.split()[0]
    mean = np.concatenate([u.frames for u in train.utterances]).mean(axis=0)
    errors: dict[str, list[float]] = {"phonemes": [], "audio": [], "both": [], "mean": []}
    for u in heldout.utterances:
        fps, emotion = u.fps, u.emotion
        errors["phonemes"].append(
            _rms(model.synthesize(u.phones, fps, emotion=emotion).frames, u.frames)
        )
        errors["audio"].append(_rms(model.synthesize([], fps, u.audio, emotion).frames, u.frames))
        errors["both"].append(
            _rms(model.synthesize(u.phones, fps, u.audio, emotion).frames, u.frames)
        )
        errors["mean"].append(_rms(np.broadcast_to(mean, u.frames.shape), u.frames))
    baseline = np.mean(errors["mean"])
    for mode in ("phonemes", "audio", "both"):
        assert np.mean(errors[mode]) < baseline, (mode, errors)


def test_audio_alone_gives_frames_for_its_whole_duration_in_any_chunking(
    model: HmmModel, heldout: Corpus
) -> None:
    audio = heldout.utterances[0].audio
    assert audio is not None
    offline = model.synthesize([], FPS, audio).frames
    assert len(offline) == frame_count(audio.duration, FPS)
    synthesizer = model.start(fps=FPS)
    pieces = []
    for first in range(0, len(audio.samples), 3000):
        synthesizer.feed([], Audio(audio.samples[first : first + 3000], audio.sample_rate))
        pieces.append(synthesizer.frames())
    assert sum(len(piece) for piece in pieces) > len(offline) // 2  # streamed, not held back
    pieces.append(synthesizer.finish())
    np.testing.assert_array_equal(np.concatenate(pieces), offline)


def test_a_streamed_request_is_driven_by_what_its_first_input_was(
    model: HmmModel, heldout: Corpus
) -> None:
    line = heldout.utterances[0]
    listening = model.start(fps=FPS)
    listening.feed([], line.audio)
    with pytest.raises(InvalidRequestError, match="options.drive = both"):
        listening.feed(line.phones)
    both = model.start(fps=FPS, drive="both")
    both.feed([], line.audio)
    assert len(both.frames()) == 0  # waits for the phonemes too
    both.feed(line.phones)
    streamed = np.concatenate([both.frames(), both.finish()])
    np.testing.assert_array_equal(streamed, model.synthesize(line.phones, FPS, line.audio).frames)


def test_trajectory_windows_join_without_a_jump_in_pose_or_velocity(
    model: HmmModel, heldout: Corpus
) -> None:
    """Blocks of 250 ms at the synthesis rate (one output frame per trajectory frame): the
    acceleration at each join is no larger than the motion's own elsewhere."""
    rate = model.synthesis_fps
    block = round(0.25 * rate)
    for line in heldout.utterances:
        frames = model.synthesize(line.phones, rate, lag_ms=None, window_ms=250).frames
        acceleration = np.abs(np.diff(frames.astype(np.float64), 2, axis=0)).max(axis=1)
        joins = np.arange(block, len(frames) - 1, block) - 1  # second difference centred on a join
        elsewhere = np.delete(acceleration, joins)
        assert acceleration[joins].max() <= 0.5 * elsewhere.max()


def test_the_trajectory_is_solved_at_the_output_rate_below_the_synthesis_rate(
    model: HmmModel,
) -> None:
    """The smallest whole multiple of fps at or above hmm_fps (60 Hz), at most R_s (120)."""
    assert (model.hmm_fps, model.synthesis_fps) == (60.0, 120.0)
    expected = {
        240.0: 120.0,
        120.0: 120.0,
        100.0: 100.0,
        60.0: 60.0,
        50.0: 100.0,
        30.0: 60.0,
        25.0: 75.0,
        24.0: 72.0,
        10.0: 60.0,
        7.0: 63.0,
    }
    assert {fps: model.solve_fps(fps) for fps in expected} == expected
    for name, lag_ms, window_ms in RUNGS:
        options = {"lag_ms": lag_ms, "window_ms": window_ms}
        at_synthesis_rate = model.plan(options)
        if window_ms:  # blocks of window_ms at R_s with half a block of future, as before
            block = round(window_ms / 1000.0 * 120.0)
            assert (at_synthesis_rate.block, at_synthesis_rate.future) == (block, block // 2)
        lookahead = model.lookahead_for(options)
        assert lookahead is not None
        for fps in (*expected, 33.0, 90.0, 119.0):
            plan = model.plan(options, fps)
            assert plan == at_synthesis_rate if fps >= 120.0 else plan.lag == at_synthesis_rate.lag
            assert plan.rate == (120.0 if window_ms == 0.0 else model.solve_fps(fps)), name
            wait = plan.wait_s(model.hmm_fps)
            assert wait is not None and wait <= lookahead.seconds + 1e-12, (name, fps)


def test_below_the_synthesis_rate_the_frames_stay_close_to_the_synthesis_rate_ones(
    model: HmmModel, heldout: Corpus
) -> None:
    """At R_s / 2 the trajectory is solved at 60 Hz, the HMM's own rate: the same quadratic
    (Eq. 5) on a grid half as fine, so it differs from the 120 Hz solution at the 60 Hz
    frames only where the motion changes within a frame. Bounds: over the lines the RMS
    difference is under a tenth of the synthesis error against the recording, and on each
    line the coarse frames are as near the recording as the 120 Hz ones (within 5%)."""
    changes, errors = [], []
    for line in heldout.utterances[:6]:
        for spans, audio in ((line.phones, None), ([], line.audio)):
            fine = model.synthesize(spans, 120.0, audio, line.emotion, lag_ms=None, window_ms=None)
            coarse = model.synthesize(spans, 60.0, audio, line.emotion, lag_ms=None, window_ms=None)
            sampled = fine.frames[::2][: len(coarse.frames)]
            assert len(coarse.frames) == frame_count(line.duration, 60.0) == len(sampled)
            recorded = line.frames[::2]
            change, error = _rms(coarse.frames, sampled), _rms(sampled, recorded)
            assert 0.0 < change and _rms(coarse.frames, recorded) < 1.05 * error, (change, error)
            changes.append(change)
            errors.append(error)
    assert np.mean(changes) < 0.1 * np.mean(errors), (changes, errors)


def test_the_model_stores_its_training_figures(model: HmmModel) -> None:
    metrics = model.manifest.metrics
    assert 1 <= metrics["states"] <= metrics["states_initial"] == 40
    assert 1.0 <= metrics["perplexity"] < metrics["states"]
    assert metrics["heldout_entropy_rate_bits"] >= 0.0
    history = metrics["log_posterior"]
    assert all(b >= a - 1e-6 * abs(a) for a, b in zip(history, history[1:]))


def test_audio_alone_needs_a_model_trained_with_audio(
    small_demo_corpus: Corpus, trained_models: dict[str, Model], heldout: Corpus
) -> None:
    train = small_demo_corpus.split()[0]
    silent = replace(train, utterances=[replace(u, audio=None) for u in train.utterances[:8]])
    mute = HmmEngine(n_states=8, n_iter=3).fit(silent)
    assert not mute.accepts_audio_only and not mute.uses_audio
    line = heldout.utterances[0]
    for other in (mute, trained_models["viseme-lerp"]):
        with pytest.raises(InvalidRequestError) as raised:
            other.synthesize([], FPS, line.audio)
        assert raised.value.code == "audio_only_unsupported"
    with pytest.raises(InvalidRequestError) as raised:
        mute.synthesize(line.phones, FPS, line.audio, drive="both")
    assert raised.value.where == "options.drive"
    np.testing.assert_array_equal(  # audio beside phonemes is ignored, not refused
        mute.synthesize(line.phones, FPS, line.audio).frames,
        mute.synthesize(line.phones, FPS).frames,
    )


@pytest.fixture(scope="module")
def served(
    trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory
) -> Iterator[LiveServer]:
    chosen = {name: trained_models[name] for name in ("hmm", "viseme-lerp")}
    with live_server(save_models(chosen, tmp_path_factory.mktemp("hmm-models"))) as server:
        yield server


async def _stream(
    url: str, engine: str, spans: list[tuple[str, float, float]], pcm16: bytes, rate: int
) -> StreamResult:
    options = {"drive": "both"} if spans and pcm16 else None
    async with AsyncClient(url) as client:
        stream = await client.start(engine, "demo", fps=FPS, options=options)
        step = 2 * rate // 10  # 100 ms of samples per message
        for first in range(0, len(pcm16), step):
            await stream.send_audio(pcm16[first : first + step], rate)
        if spans:
            await stream.send_phonemes(spans)
        await stream.end()
        return await asyncio.wait_for(stream.collect(), 60)


def test_three_modes_stream_through_the_server(
    served: LiveServer, model: HmmModel, heldout: Corpus
) -> None:
    line = heldout.utterances[1]
    assert line.audio is not None
    pcm16 = (np.clip(line.audio.samples, -1, 1) * 32767).astype("<i2").tobytes()
    audio = Audio.from_pcm16(pcm16, line.audio.sample_rate)
    spans = [(s.phoneme, s.start, s.end) for s in line.phones]
    for sent_spans, sent_audio in ((spans, None), ([], audio), (spans, audio)):
        result = asyncio.run(
            _stream(served.ws, "hmm", sent_spans, pcm16 if sent_audio else b"", audio.sample_rate)
        )
        offline = model.synthesize(sent_spans, FPS, sent_audio, "neutral").frames
        rows = np.asarray(result.rows(), np.float32)
        assert len(rows) == len(offline) + return_frames(FPS) and len(offline) > 0
        np.testing.assert_allclose(rows[: len(offline)], offline, atol=1e-5)
    with pytest.raises(LipstreamServerError) as raised:
        asyncio.run(_stream(served.ws, "viseme-lerp", [], pcm16, audio.sample_rate))
    assert raised.value.code == "audio_only_unsupported"


async def _first_block_before_the_end(
    url: str, character: str, pcm16: bytes, rate: int, options: dict[str, float]
) -> Frames | None:
    """The first frames block of an audio-only request sent ``pcm16`` and no ``end``: it can
    only answer from the audio so far, however long that takes."""
    async with AsyncClient(url) as client:
        stream = await client.start(
            "hmm", character, fps=FPS, options={**options, "drive": "audio"}
        )
        step = 2 * (rate // 100)  # 10 ms of samples per message
        for first in range(0, len(pcm16), step):
            await stream.send_audio(pcm16[first : first + step], rate)
        block = await asyncio.wait_for(stream.next_block(), 60)  # a bound, not a speed
        await stream.cancel()
        return block


def test_an_audio_only_request_gets_frames_before_its_end_on_the_causal_rung(
    served: LiveServer, model: HmmModel, heldout: Corpus
) -> None:
    line = heldout.utterances[0]
    assert line.audio is not None
    rate = line.audio.sample_rate
    pcm16 = pcm16_of(line.audio.samples)
    half = pcm16[: len(pcm16) // 4 * 2]  # the first half of the samples; no end follows
    causal = {"lag_ms": 0.0, "window_ms": 0.0}
    block = asyncio.run(_first_block_before_the_end(served.ws, model.name, half, rate, causal))
    assert block is not None and block.first_frame == 0
    audio = Audio.from_pcm16(pcm16, rate)
    offline = model.synthesize([], FPS, audio, "neutral", drive="audio", **causal).frames
    rows = np.frombuffer(block.data, "<f4").reshape(block.n_frames, -1)
    assert 0 < len(rows) <= frame_count(len(half) / 2 / rate, FPS)
    np.testing.assert_allclose(rows, offline[: len(rows)], atol=1e-5)
