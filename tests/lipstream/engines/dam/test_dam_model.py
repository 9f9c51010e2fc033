"""The trained dam and cohen-massaro models: M = 0 is Cohen-Massaro, rungs stream as offline,
truncation within the bound, emotion, options and load-time checks."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from lipstream.corpus import Corpus
from lipstream.engines import load_model
from lipstream.engines.base import Model, SynthesisRequest, frame_count, frames_before
from lipstream.engines.dam import CohenMassaroEngine, DamEngine, DamModel
from lipstream.engines.dam.modes import PHONEME_INDEX
from lipstream.errors import InvalidRequestError, ModelStoreError
from lipstream.phonemes import PHONEMES as PHONEMES_BY_INDEX
from lipstream.store import read_manifest, save_model_dir
from lipstream.timeline import PhonemeSpan
from tests.helpers import REMOVED, edit_hyperparameters
from tests.lipstream.engines.dam.reference import led_by_hand, path_cost, select_mode


def _spans(corpus: Corpus) -> list[PhonemeSpan]:
    return corpus.split()[1].utterances[0].phones


def _dam(models: dict[str, Model], name: str = "dam") -> DamModel:
    model = models[name]
    assert isinstance(model, DamModel)
    return model


def _by_loops(model: DamModel, spans: list[PhonemeSpan], fps: float) -> np.ndarray:
    """Eq. 2 with constant targets, frame by frame: sum over phonemes k with
    owner - tail <= k <= owner + tail of D_k(t) * T_k where D_k >= tol."""
    request = SynthesisRequest(fps=fps)
    modes = [select_mode(model, spans, k, model.search_ahead, request) for k in range(len(spans))]
    tol = float(model.manifest.hyperparameters["tol"])
    eps = float(model.manifest.hyperparameters["eps"])
    out = np.zeros((frame_count(spans[-1].end, fps), model.coefficients.shape[2]))
    for i in range(len(out)):
        t = i / fps
        owner = next((k for k, s in enumerate(spans) if s.end > t), len(spans) - 1)
        for k in range(max(0, owner - model.tail), min(len(spans), owner + model.tail + 1)):
            span, mode = spans[k], modes[k]
            u = (t - span.start) / (span.end - span.start)
            gap = u if u < 0 else (u - 1 if u > 1 else 0.0)
            weight = math.exp(-gap * gap / (2 * model.sigma[mode] ** 2 + eps))
            if weight >= tol:
                out[i] += weight * model.coefficients[mode, 0]
    return np.asarray(out @ model.basis.components + model.basis.mean)


def test_cohen_massaro_is_the_dam_with_m_zero(
    trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    cohen = _dam(trained_models, "cohen-massaro")
    assert cohen.coefficients.shape[1] == 1
    train = small_demo_corpus.split()[0]
    lead = cohen.bilabial_lead_s
    assert lead == CohenMassaroEngine().bilabial_lead_s > 0.0
    zero = DamEngine(degree=0, bilabial_lead_s=lead).fit(train)
    for name, array in cohen.arrays().items():
        np.testing.assert_array_equal(zero.arrays()[name], array, err_msg=name)
    spans = _spans(small_demo_corpus)
    frames = cohen.synthesize(spans, fps=60).frames
    np.testing.assert_array_equal(zero.synthesize(spans, fps=60).frames, frames)
    # the loops run on the bilabials' articulatory spans, led by hand here
    np.testing.assert_allclose(frames, _by_loops(cohen, led_by_hand(spans, lead), 60.0), atol=1e-5)
    assert CohenMassaroEngine().hyperparameters()["sigma_init"] == DamEngine().sigma_init


def _without_lead(model: DamModel) -> DamModel:
    """``model`` as an artifact saved before the lead existed would load it: no
    ``bilabial_lead_s``."""
    hyper = {k: v for k, v in model.manifest.hyperparameters.items() if k != "bilabial_lead_s"}
    manifest = dataclasses.replace(model.manifest, hyperparameters=hyper)
    return type(model)(manifest, model.arrays())


@pytest.mark.parametrize("name", ["dam", "cohen-massaro"])
def test_the_lead_is_the_same_in_training_and_synthesis(
    name: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = _dam(trained_models, name)
    lead = model.bilabial_lead_s
    assert lead > 0.0
    train = small_demo_corpus.split()[0]
    led_lines = dataclasses.replace(
        train,
        utterances=[
            dataclasses.replace(u, phones=led_by_hand(u.phones, lead)) for u in train.utterances
        ],
    )
    engine = {"dam": DamEngine, "cohen-massaro": CohenMassaroEngine}[name]
    on_led = engine(bilabial_lead_s=0.0).fit(led_lines)
    # what the EM fitted is what a model without a lead fits on spans led by hand; the
    # durations and κ (the causal rungs', which keep the acoustic spans) are not
    for array in ("sigma", "coefficients", "mode_phoneme", "count_previous", "count_emotion"):
        np.testing.assert_array_equal(on_led.arrays()[array], model.arrays()[array], err_msg=array)
    # synthesis: the model's frames are those of the same model without the lead on the
    # spans led by hand
    spans = _spans(small_demo_corpus)
    np.testing.assert_array_equal(
        model.synthesize(spans, fps=60).frames,
        _without_lead(model).synthesize(led_by_hand(spans, lead), fps=60).frames,
    )
    # and a bilabial's closure moves earlier than without the lead
    assert not np.array_equal(
        model.synthesize(spans, fps=60).frames,
        _without_lead(model).synthesize(spans, fps=60).frames,
    )


@pytest.mark.parametrize("name", ["dam", "cohen-massaro"])
def test_an_artifact_without_the_lead_loads_as_no_lead_with_the_frames_of_before(
    name: str, small_demo_corpus: Corpus, tmp_path: Path
) -> None:
    train = small_demo_corpus.split()[0]
    engine = {"dam": DamEngine, "cohen-massaro": CohenMassaroEngine}[name]
    model = engine(bilabial_lead_s=0.0).fit(train)
    assert isinstance(model, DamModel)
    model.save(tmp_path / name)
    edit_hyperparameters(tmp_path / name, bilabial_lead_s=REMOVED)
    old = load_model(tmp_path / name)
    assert isinstance(old, DamModel) and old.bilabial_lead_s == 0.0
    spans = _spans(small_demo_corpus)
    for rung in old.fidelity_ladder():
        assert rung.lookahead == model.rung_for(rung.options).lookahead  # type: ignore[union-attr]
        if "causal" not in rung.options:
            assert rung.lookahead.seconds == 0.0
        np.testing.assert_array_equal(
            old.synthesize(spans, fps=60, **rung.options).frames,
            model.synthesize(spans, fps=60, **rung.options).frames,
        )
    if name == "cohen-massaro":  # the frames of before: Eq. 2 on the acoustic spans
        frames = old.synthesize(spans, fps=60).frames
        np.testing.assert_allclose(frames, _by_loops(old, spans, 60.0), atol=1e-5)


def test_dam_fits_better_than_cohen_massaro_on_its_training_data(
    trained_models: dict[str, Model],
) -> None:
    dam, cohen = _dam(trained_models), _dam(trained_models, "cohen-massaro")
    assert dam.manifest.metrics["fit_rms"] < cohen.manifest.metrics["fit_rms"]
    for model in (dam, cohen):
        history = model.manifest.metrics["em_objective"]
        assert all(b <= a for a, b in itertools.pairwise(history))


@pytest.mark.parametrize("name", ["dam", "cohen-massaro"])
def test_every_rung_streams_its_offline_frames_as_soon_as_its_lookahead_allows(
    name: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = _dam(trained_models, name)
    spans = _spans(small_demo_corpus)
    ladder = model.fidelity_ladder()
    assert [rung.lookahead.phonemes for rung in ladder] == sorted(
        (rung.lookahead.phonemes for rung in ladder), reverse=True
    )
    assert ladder[0].lookahead == model.lookahead
    searches = [rung for rung in ladder if "causal" not in rung.options]
    # a bilabial lead waits one phoneme more and the lead on every search rung
    assert model.bilabial_lead_s > 0.0
    assert searches[-1].lookahead.phonemes == model.tail + 1
    assert all(rung.lookahead.seconds == model.bilabial_lead_s for rung in searches)
    assert [rung.name for rung in ladder[len(searches) :]] == ["causal_lead", "causal"]
    for rung in ladder:
        assert model.rung_for(rung.options) == rung
        offline = model.synthesize(spans, fps=60, **rung.options).frames
        synthesizer = model.start(fps=60, **rung.options)
        pieces = []
        for index, span in enumerate(spans):
            synthesizer.feed([span])
            pieces.append(synthesizer.frames())
            back = index - rung.lookahead.phonemes
            promised = spans[back].end - rung.lookahead.seconds if back >= 0 else 0.0
            assert sum(map(len, pieces)) >= frames_before(promised, 60.0)
        pieces.append(synthesizer.finish())
        np.testing.assert_array_equal(np.concatenate(pieces), offline)


@pytest.mark.parametrize("name", ["dam", "cohen-massaro"])
def test_tail_cut_stays_within_the_declared_bound(
    name: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = _dam(trained_models, name)
    bound = float(model.manifest.hyperparameters["truncation_bound"])
    errors = model.manifest.metrics["truncation_error"]
    assert errors["tail"] < bound < errors["tail_ahead=0"]  # no tail at all would break it
    manifest = dataclasses.replace(model.manifest, extra={**model.manifest.extra, "tail": 16})
    uncut = type(model)(manifest, model.arrays())
    train = small_demo_corpus.split()[0]
    frames = np.concatenate([u.frames for u in train.utterances])
    span = frames.max(axis=0) - frames.min(axis=0)
    for utterance in train.utterances[:4]:
        spans = utterance.phones
        cut = model.synthesize(spans, fps=train.fps).frames
        full = uncut.synthesize(spans, fps=train.fps, tail_ahead=16).frames
        assert np.all(np.abs(cut - full).max(axis=0) <= bound * span + 1e-6)


def test_mode_choice_on_short_inputs_is_the_exhaustive_optimum(
    trained_models: dict[str, Model],
) -> None:
    model = _dam(trained_models)
    request = SynthesisRequest()
    for phonemes in (["HH", "AH"], ["M", "AA", "P"], ["S", "IY", "T"]):
        spans = [PhonemeSpan(p, 0.1 * i, 0.1 * i + 0.1) for i, p in enumerate(phonemes)]
        layers = [model.layer(spans, k, len(spans) - 1, request) for k in range(len(spans))]
        every = itertools.product(*(range(len(layer.candidates)) for layer in layers))
        best = min(every, key=lambda path: path_cost(model.costs, layers, path))
        for k in range(len(spans)):
            if k + model.search_ahead >= len(spans) - 1 and k - model.search_behind <= 0:
                chosen = select_mode(model, spans, k, model.search_ahead, request)
                assert chosen == layers[k].candidates[best[k]]


def test_emotion_selects_that_emotions_modes_and_falls_back(
    trained_models: dict[str, Model],
) -> None:
    model = _dam(trained_models)
    counts = model.count_emotion
    for emotion, column in (("happy", 1), ("sad", 3), (None, 0)):
        request = SynthesisRequest(emotion=emotion)
        for phoneme in ("AA", "M", "S", "IY"):
            spans = [PhonemeSpan(phoneme, 0.0, 0.1)]
            layer = model.layer(spans, 0, 0, request)
            own = np.arange(
                model.offsets[PHONEME_INDEX[phoneme]], model.offsets[PHONEME_INDEX[phoneme] + 1]
            )
            said = own[counts[own, column] > 0]
            expected = said if len(said) else own
            np.testing.assert_array_equal(layer.candidates, expected)
    per_span = [PhonemeSpan("AA", 0.0, 0.1, "angry")]
    np.testing.assert_array_equal(
        model.layer(per_span, 0, 0, SynthesisRequest(emotion="happy")).candidates,
        model.layer(per_span, 0, 0, SynthesisRequest(emotion="angry")).candidates,
    )


@pytest.mark.parametrize("value", [-1, 17, 1.5, True, "2"])
def test_bad_option_values_are_coded_errors(
    trained_models: dict[str, Model], value: object
) -> None:
    model = _dam(trained_models)
    for name in ("search_ahead", "tail_ahead"):
        with pytest.raises(InvalidRequestError) as caught:
            model.start(SynthesisRequest(fps=60, options={name: value}))
        assert caught.value.where == f"options.{name}"
    searching = model.lookahead_for({"search_ahead": 0, "tail_ahead": 1})
    # one phoneme more than the options ask for, and the lead: the bilabial lead's wait
    assert searching is not None and searching.phonemes == 2
    assert searching.seconds == model.bilabial_lead_s > 0.0


def _damped_by_hand(raw: np.ndarray, omegas: np.ndarray, dt: float) -> np.ndarray:
    """x'' = -2ω x' - ω²(x - u) from rest on raw[0], u = raw[i] held over each step, by the
    exact solution written out: e = x - u, c = v + ω e, x(dt) = u + (e + c dt) e^{-ω dt}."""
    x, v = raw[0].copy(), np.zeros_like(raw[0])
    out = [x.copy()]
    for target, w in zip(raw[1:], omegas[1:], strict=True):
        error = x - target
        pull = v + w * error
        decay = math.exp(-w * dt)
        x = target + (error + pull * dt) * decay
        v = (v - w * pull * dt) * decay
        out.append(x.copy())
    return np.array(out)


@pytest.mark.parametrize("name", ["dam", "cohen-massaro"])
def test_the_causal_rung_commits_modes_on_arrival_and_sums_only_begun_spans(
    name: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = _dam(trained_models, name)
    spans = _spans(small_demo_corpus)
    fps = 60.0
    request = SynthesisRequest(fps=fps)
    # Modes: each span's choice minimizes E over the prefix cut at it, earlier choices fixed.
    chosen: list[int] = []
    modes = []
    for k in range(len(spans)):
        layers = [model.layer(spans, j, k, request) for j in range(k + 1)]
        best = min(
            range(len(layers[k].candidates)),
            key=lambda c: path_cost(model.costs, layers, [*chosen, c]),
        )
        chosen.append(best)
        modes.append(int(layers[k].candidates[best]))
    tol = float(model.manifest.hyperparameters["tol"])
    eps = float(model.manifest.hyperparameters["eps"])
    degree = model.coefficients.shape[1] - 1
    n = frame_count(spans[-1].end, fps)
    raw = np.zeros((n, model.coefficients.shape[2]))
    omegas = np.zeros(n)
    for i in range(n):
        t = i / fps
        begun = max([k for k, s in enumerate(spans) if s.start < t - 1e-9], default=0)
        omegas[i] = model.causal_kappa / model.durations.expected_s(spans[begun].phoneme)
        for k in range(max(0, begun - model.tail), begun + 1):
            span, mode = spans[k], modes[k]
            u = (t - span.start) / (span.end - span.start)
            gap = u if u < 0 else (u - 1 if u > 1 else 0.0)
            weight = math.exp(-gap * gap / (2 * model.sigma[mode] ** 2 + eps))
            if weight >= tol:
                clamped = min(max(u, 0.0), 1.0)
                animeme = sum(clamped**m * model.coefficients[mode, m] for m in range(degree + 1))
                raw[i] += weight * animeme
    expected = _damped_by_hand(raw, omegas, 1.0 / fps) @ model.basis.components
    expected += model.basis.mean
    frames = model.synthesize(spans, fps=fps, causal=True, lead_ms=0).frames
    np.testing.assert_allclose(frames, expected, atol=1e-5)
    # The raw sum jumps at span starts; the filter's output is continuous in time, so at a
    # high frame rate its steps shrink well below those jumps.
    raw_steps = np.abs(np.diff(raw @ model.basis.components, axis=0)).max()
    fine = model.synthesize(spans, fps=1000.0, causal=True).frames
    assert np.abs(np.diff(fine, axis=0)).max() < 0.25 * raw_steps
    # A span never changes a frame before it starts: cut the input, the frames are the same.
    for cut in (3, len(spans) // 2):
        prefix = model.synthesize(spans[:cut], fps=fps, causal=True).frames
        np.testing.assert_array_equal(prefix, frames[: len(prefix)])


def test_causal_options_are_checked_and_select_the_causal_rungs(
    trained_models: dict[str, Model],
) -> None:
    model = _dam(trained_models)
    for options, where in (
        ({"causal": 1}, "options.causal"),
        ({"causal": True, "lead_ms": -1}, "options.lead_ms"),
        ({"causal": True, "lead_ms": "5"}, "options.lead_ms"),
        ({"lead_ms": 50}, "options.lead_ms"),
    ):
        with pytest.raises(InvalidRequestError) as caught:
            model.start(fps=60, **options)
        assert caught.value.where == where
    causal = model.rung_for({"causal": True, "search_ahead": 2, "tail_ahead": 3})
    assert causal is not None and causal.name == "causal"
    lead = model.rung_for({"causal": True, "lead_ms": 120})
    assert lead is not None and lead.name == "causal_lead"
    median = model.durations.pooled_median_s()
    assert lead.lookahead.seconds == min(0.12, 2.0 * median / model.causal_kappa)
    assert model.rung_for({"causal": True, "lead_ms": 50}) is None
    shifted = model.lookahead_for({"causal": True, "lead_ms": 50})
    assert shifted is not None and shifted.seconds > 0.0


def _corrupt(directory: Path, name: str, change: object) -> None:
    arrays = dict(np.load(directory / "arrays.npz"))
    if callable(change):
        arrays[name] = change(arrays[name])
    else:
        del arrays[name]
    save_model_dir(directory, read_manifest(directory), arrays)


@pytest.mark.parametrize(
    ("name", "change"),
    [
        ("sigma", lambda a: np.where(np.arange(len(a)) == 0, np.nan, a)),
        ("sigma", lambda a: a * 0.0),
        ("coefficients", lambda a: a[:, :-1]),
        ("mode_offsets", lambda a: a[::-1].copy()),
        ("mode_phoneme", lambda a: (a + 1) % 40),
        ("stand_in", lambda a: a + 100),
        ("count_previous", lambda a: a - 5),
        ("count_emotion", lambda a: a.astype(np.float64)),
        ("count_following", None),
        ("basis_components", lambda a: 2.0 * a),
        ("basis_mean", lambda a: a[:-1]),
        ("causal_kappa", lambda a: -a),
        ("causal_kappa", None),
        ("duration_log_std", lambda a: a - 10.0),
        ("duration_count", None),
    ],
)
def test_corrupt_arrays_are_refused_naming_the_array(
    trained_models: dict[str, Model], tmp_path: Path, name: str, change: object
) -> None:
    _dam(trained_models).save(tmp_path / "dam")
    _corrupt(tmp_path / "dam", name, change)
    with pytest.raises(ModelStoreError) as caught:
        load_model(tmp_path / "dam")
    assert caught.value.code == "model_invalid"
    assert caught.value.where is not None and caught.value.where.endswith(f"arrays.npz: {name}")


@pytest.mark.parametrize(
    ("section", "field", "value"),
    [
        ("hyperparameters", "degree", -1),
        ("hyperparameters", "tol", 0.0),
        ("hyperparameters", "search_behind", "two"),
        ("hyperparameters", "bilabial_lead_s", -0.01),
        ("hyperparameters", "bilabial_lead_s", "20 ms"),
        ("extra", "tail", 99),
        ("extra", "reference_duration", None),
    ],
)
def test_bad_manifest_fields_are_refused_naming_the_field(
    trained_models: dict[str, Model], tmp_path: Path, section: str, field: str, value: object
) -> None:
    _dam(trained_models).save(tmp_path / "dam")
    path = tmp_path / "dam" / "model.json"
    manifest = json.loads(path.read_text())
    manifest[section][field] = value
    path.write_text(json.dumps(manifest))
    with pytest.raises(ModelStoreError) as caught:
        load_model(tmp_path / "dam")
    assert caught.value.where == f"{path}: {section}.{field}"


def test_a_phoneme_never_trained_is_spoken_by_its_stand_in(small_demo_corpus: Corpus) -> None:
    few = small_demo_corpus.split()[0]
    few = dataclasses.replace(few, utterances=few.utterances[:2], heldout=())
    model = DamEngine(n_iter=1).fit(few)
    offsets = model.offsets
    unseen = [p for p, k in PHONEME_INDEX.items() if offsets[k + 1] == offsets[k]]
    assert unseen
    for phoneme in unseen[:4]:
        stand_in = PHONEMES_BY_INDEX[int(model.stand_in[PHONEME_INDEX[phoneme]])]
        assert stand_in != phoneme
        frames = model.synthesize([(phoneme, 0.0, 0.2)]).frames
        np.testing.assert_array_equal(frames, model.synthesize([(stand_in, 0.0, 0.2)]).frames)


def test_cohen_massaro_takes_dams_hyperparameters_but_degree() -> None:
    from lipstream.engines.dam.engine import CohenMassaroEngine, DamEngine

    assert set(DamEngine.hyperparameter_names()) - set(
        CohenMassaroEngine.hyperparameter_names()
    ) == {"degree"}
    engine = CohenMassaroEngine(points=6, w_smooth=2.0)
    assert engine.polynomial_degree() == 0
    assert (engine.points, engine.w_smooth) == (6, 2.0)
    assert CohenMassaroEngine(**engine.hyperparameters()).hyperparameters() == (
        engine.hyperparameters()
    )
    with pytest.raises(TypeError):
        CohenMassaroEngine(degree=3)
