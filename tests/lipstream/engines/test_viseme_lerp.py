"""viseme-lerp against hand-computed key poses and interpolation."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.corpus import Corpus, Utterance
from lipstream.engines import load_model
from lipstream.engines.base import SynthesisRequest
from lipstream.engines.damped_fit import KAPPAS
from lipstream.engines.viseme_lerp import VisemeLerpEngine, VisemeLerpModel
from lipstream.errors import InvalidRequestError, ModelStoreError
from lipstream.store import save_model_dir
from lipstream.timeline import PhonemeSpan
from lipstream.visemes import get_scheme

FPS = 100.0


def _utterance(stem: str, plan: list[tuple[str, float, float, float]]) -> Utterance:
    """Frames hold a constant value per phoneme span: (phoneme, start, end, value)."""
    end = plan[-1][2]
    times = np.arange(round(end * FPS) + 1) / FPS
    frames = np.zeros((len(times), 2), dtype=np.float32)
    for _, start, stop, value in plan:
        inside = (times >= start - 1e-9) & (times < stop - 1e-9)
        frames[inside] = [value, 2 * value]
    frames[-1] = frames[-2]
    spans = [PhonemeSpan(p, s, e) for p, s, e, _ in plan]
    return Utterance(stem=stem, frames=frames, phones=spans, fps=FPS)


@pytest.fixture()
def corpus() -> Corpus:
    first = _utterance(
        "a",
        [
            ("sil", 0.0, 0.2, 0.0),
            ("AA", 0.2, 0.4, 0.8),
            ("P", 0.4, 0.5, 0.1),
            ("sil", 0.5, 0.7, 0.0),
        ],
    )
    second = _utterance(
        "b",
        [
            ("sil", 0.0, 0.1, 0.0),
            ("AA", 0.1, 0.2, 0.6),
            ("M", 0.2, 0.4, 0.3),
            ("sil", 0.4, 0.6, 0.0),
        ],
    )
    return Corpus(
        name="toy", fps=FPS, channels=("jawOpen", "mouthClose"), utterances=[first, second]
    )


def test_key_poses_are_frame_weighted_viseme_means(corpus: Corpus) -> None:
    model = VisemeLerpEngine(scheme="oculus15").fit(corpus)
    scheme = get_scheme("oculus15")
    aa = model.poses[scheme.classes.index("aa")]
    pp = model.poses[scheme.classes.index("PP")]
    np.testing.assert_allclose(
        aa, [(20 * 0.8 + 10 * 0.6) / 30, 2 * (20 * 0.8 + 10 * 0.6) / 30], rtol=1e-6
    )
    np.testing.assert_allclose(
        pp, [(10 * 0.1 + 20 * 0.3) / 30, 2 * (10 * 0.1 + 20 * 0.3) / 30], rtol=1e-6
    )
    unseen = model.poses[scheme.classes.index("SS")]
    np.testing.assert_allclose(unseen, model.poses[scheme.classes.index("sil")])


def test_frames_interpolate_linearly_between_phoneme_centres(corpus: Corpus) -> None:
    model = VisemeLerpEngine().fit(corpus)
    scheme = get_scheme("oculus15")
    aa = float(model.poses[scheme.classes.index("aa"), 0])
    pp = float(model.poses[scheme.classes.index("PP"), 0])
    rest = float(model.poses[scheme.classes.index("sil"), 0])
    spans = [("sil", 0.0, 0.2), ("AA", 0.2, 0.4), ("B", 0.4, 0.6)]
    frames = model.synthesize(spans, fps=20).frames[:, 0]
    expected = {
        0: rest,
        2: rest,
        4: rest + (aa - rest) * (0.2 - 0.1) / 0.2,
        6: aa,
        8: aa + (pp - aa) * (0.4 - 0.3) / 0.2,
        10: pp,
        12: pp,
    }
    for index, value in expected.items():
        assert frames[index] == pytest.approx(value, abs=1e-6), index


@pytest.mark.parametrize(
    ("corrupt", "named"),
    [
        (lambda poses, hyper: (poses * np.nan, hyper), "arrays.npz: poses"),
        (lambda poses, hyper: (poses[:, :1], hyper), "arrays.npz: poses"),
        (lambda poses, hyper: (poses[:-1], hyper), "arrays.npz: poses"),
        (lambda poses, hyper: (poses.astype(np.int32), hyper), "arrays.npz: poses"),
        (lambda poses, hyper: (poses, {"scheme": 7}), "model.json: hyperparameters.scheme"),
        (lambda poses, hyper: (poses, {"scheme": "nope"}), "model.json: hyperparameters.scheme"),
        (lambda poses, hyper: (poses, {}), "model.json: hyperparameters.scheme"),
    ],
)
def test_a_corrupt_stored_model_is_refused_naming_the_array_or_field(
    corpus: Corpus, tmp_path: Path, corrupt: Callable[..., Any], named: str
) -> None:
    model = VisemeLerpEngine().fit(corpus)
    model.save(tmp_path)
    loaded = load_model(tmp_path)
    assert isinstance(loaded, VisemeLerpModel) and np.array_equal(loaded.poses, model.poses)
    poses, hyperparameters = corrupt(model.poses, dict(model.manifest.hyperparameters))
    manifest = replace(model.manifest, hyperparameters=hyperparameters)
    save_model_dir(tmp_path, manifest, {**model.arrays(), "poses": poses})
    with pytest.raises(ModelStoreError) as caught:
        load_model(tmp_path)
    assert caught.value.code == "model_invalid"
    assert caught.value.where == f"{tmp_path}/{named}"


def test_a_scheme_alias_still_loads(corpus: Corpus, tmp_path: Path) -> None:
    model = VisemeLerpEngine(scheme="OVR").fit(corpus)
    model.save(tmp_path)
    loaded = load_model(tmp_path)
    assert isinstance(loaded, VisemeLerpModel) and loaded.scheme.name == "oculus15"


# The toy corpus's spans: sil 0.2, 0.2, 0.1, 0.2 s (4, enough for its own statistics); AA,
# P and M too few, so they borrow the median of all eight spans: five of 0.2 s, three of 0.1.
SIL_MEDIAN_S = 0.2**0.75 * 0.1**0.25
POOLED_MEDIAN_S = 0.2**0.625 * 0.1**0.375


def test_phoneme_medians_come_from_the_corpus_alignments(corpus: Corpus) -> None:
    model = VisemeLerpEngine().fit(corpus)
    assert model.durations.expected_s("sil") == pytest.approx(SIL_MEDIAN_S)
    assert model.durations.expected_s("AA") == pytest.approx(POOLED_MEDIAN_S)


@pytest.mark.parametrize("lead_ms", [0.0, 5.0, 120.0])
def test_damped_rungs_follow_the_closed_form_step_response(corpus: Corpus, lead_ms: float) -> None:
    model = VisemeLerpEngine().fit(corpus)
    aa = (20 * 0.8 + 10 * 0.6) / 30  # the aa key pose of jawOpen; the rest pose is 0
    kappa = model.kappa_for(lead_ms)
    assert kappa in KAPPAS
    omega = kappa / POOLED_MEDIAN_S
    # The filter's lag at the pooled median: 4 sil spans at their median, 4 at the pooled one.
    lag = 2.0 * (SIL_MEDIAN_S * POOLED_MEDIAN_S) ** 0.5 / kappa
    shift = min(lead_ms / 1000.0, lag)
    assert model.shift_s(lead_ms) == pytest.approx(shift)
    spans = [("sil", 0.0, 0.3), ("AA", 0.3, 1.0)]
    frames = model.synthesize(spans, fps=FPS, mode="damped", lead_ms=lead_ms).frames[:, 0]
    step = 0.3 - shift
    for index, value in enumerate(frames):
        t = index / FPS
        tau = max(0.0, t - step)
        expected = aa + (0.0 - aa) * (1.0 + omega * tau) * np.exp(-omega * tau)
        assert value == pytest.approx(expected, abs=1e-6), index


def test_damped_rungs_stream_each_frame_once_the_input_covers_it_plus_the_lead(
    corpus: Corpus,
) -> None:
    model = VisemeLerpEngine().fit(corpus)
    names = [rung.name for rung in model.fidelity_ladder()]
    assert names == ["lerp", "damped_lead", "causal"]
    synthesizer = model.start(fps=FPS, mode="damped", lead_ms=3)  # below the filter's lag
    synthesizer.feed([("sil", 0.0, 0.1)])
    assert len(synthesizer.frames()) == 10  # t = 0 .. 0.09 s: t + 0.003 <= 0.1
    synthesizer.feed([("AA", 0.1, 0.2)])
    assert len(synthesizer.frames()) == 10  # then t = 0.10 .. 0.19 s


@pytest.mark.parametrize(
    ("options", "where"),
    [
        ({"mode": "fast"}, "options.mode"),
        ({"mode": "damped", "lead_ms": -1}, "options.lead_ms"),
        ({"mode": "damped", "lead_ms": True}, "options.lead_ms"),
        ({"lead_ms": 30}, "options.lead_ms"),
    ],
)
def test_bad_damped_options_get_a_coded_error(
    corpus: Corpus, options: dict[str, object], where: str
) -> None:
    model = VisemeLerpEngine().fit(corpus)
    with pytest.raises(InvalidRequestError) as caught:
        model.start(SynthesisRequest(fps=FPS, options=options))
    assert caught.value.code == "invalid_request" and caught.value.where == where


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("lead_ms", np.array([120.0, -5.0])),
        ("kappa", np.array([2.0, 0.0])),
        ("kappa", np.array([2.0])),
        ("duration_log_mean", np.array([0.1])),
    ],
)
def test_bad_damped_rung_arrays_are_refused_naming_the_array(
    corpus: Corpus, tmp_path: Path, name: str, value: np.ndarray
) -> None:
    model = VisemeLerpEngine().fit(corpus)
    save_model_dir(tmp_path, model.manifest, {**model.arrays(), name: value})
    with pytest.raises(ModelStoreError) as caught:
        load_model(tmp_path)
    assert caught.value.code == "model_invalid"
    assert caught.value.where == f"{tmp_path}/arrays.npz: {name}"
