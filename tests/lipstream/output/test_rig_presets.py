"""Rig presets driven by the demo character: vowel rigs close on /p b m/ and round on /uw/,
viseme rigs show viseme_PP and viseme_U there, blendshape rigs pass each ARKit channel to the
published counterparts, emotions follow the requested emotion, and unknown names are coded."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pytest

from lipstream.engines.base import SynthesisRequest
from lipstream.errors import LipstreamError
from lipstream.output.probes import probe_rig
from lipstream.output.retarget import fit_map
from lipstream.output.rig_presets import PRESETS, model_maps, offered_presets, preset_pairs
from lipstream.timeline import PhonemeSpan
from lipstream_client.channels import RETARGET_PRESETS

if TYPE_CHECKING:
    from lipstream.engines.base import Model
    from lipstream.output.retarget import RetargetMap

FPS = 60.0
# Engines of the demo character that coarticulate differently: key poses, damped targets,
# dominance functions, and an expressive search; each must close and round on every rig.
ENGINES = ("viseme-lerp", "dam", "cohen-massaro", "expressive-dp")
SPOKEN = (
    ("sil", 0.3),
    ("AA", 0.2),
    ("M", 0.12),
    ("AA", 0.2),
    ("B", 0.1),
    ("UW", 0.25),
    ("P", 0.1),
    ("IY", 0.2),
    ("M", 0.12),
    ("IY", 0.2),
    ("sil", 0.3),
    ("W", 0.1),
    ("UW", 0.25),
    ("B", 0.1),
    ("UW", 0.25),
    ("M", 0.12),
    ("AA", 0.2),
    ("sil", 0.3),
)
VOWEL_RIGS = {
    "vrm1": (("aa", "ih", "ou", "ee", "oh"), "ou"),
    "vrm0": (("A", "I", "U", "E", "O"), "U"),
    "vroid": (("Fcl_MTH_A", "Fcl_MTH_I", "Fcl_MTH_U", "Fcl_MTH_E", "Fcl_MTH_O"), "Fcl_MTH_U"),
}
"""Each vowel rig's mouth shapes (from the VRM 1.0 and 0.x specifications and VRoid's
morphs) and its rounded one."""
CLOSED_AT_MOST = 0.15
ROUNDED_AT_LEAST = 0.5
"""The rounded shape's least weight at a /uw/ centre: the second /uw/ sits between two
lip closures (/b uw m/), which the engines that lead a bilabial start closing inside it."""


def timeline() -> list[tuple[str, float, float]]:
    spans, start = [], 0.0
    for phoneme, duration in SPOKEN:
        spans.append((phoneme, start, start + duration))
        start += duration
    return spans


def span_frames(*phonemes: str) -> list[slice]:
    """The frames of each span of ``phonemes`` in ``SPOKEN``."""
    return [
        slice(math.ceil(start * FPS), math.ceil(end * FPS))
        for p, start, end in timeline()
        if p in phonemes
    ]


def centres(*phonemes: str) -> list[int]:
    """Frame index at the centre of each span of ``phonemes`` in ``SPOKEN``."""
    return [round((start + end) / 2 * FPS) for p, start, end in timeline() if p in phonemes]


@pytest.fixture(scope="module")
def served(
    trained_models: dict[str, Model],
) -> dict[str, tuple[np.ndarray, dict[str, RetargetMap]]]:
    """Per engine: its frames of ``SPOKEN`` and its maps, probed as the server probes (phoneme
    poses from the character's viseme-lerp model, rest and closures from the engine's)."""
    lerp = trained_models["viseme-lerp"]
    out = {}
    for engine in ENGINES:
        model = trained_models[engine]
        frames = np.asarray(model.synthesize(timeline(), fps=FPS).frames, dtype=np.float64)
        maps = model_maps(model, None, probe=probe_rig(model, phoneme_source=lerp))
        out[engine] = (frames, maps)
    return out


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("preset", sorted(VOWEL_RIGS))
def test_a_vowel_rig_closes_the_mouth_on_bilabials_and_rounds_on_uw(
    served: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]], engine: str, preset: str
) -> None:
    frames, maps = served[engine]
    retarget = maps[preset]
    shapes, rounded = VOWEL_RIGS[preset]
    columns = [retarget.controls.index(name) for name in shapes]
    mouth = retarget.apply(frames)[:, columns]
    # closed within each bilabial, wherever the engine times its closure (dam's and
    # cohen-massaro's start before the acoustic span)
    for frames_of in span_frames("P", "B", "M"):
        closest = mouth[frames_of].max(axis=1).min()
        assert closest <= CLOSED_AT_MOST, (frames_of, mouth[frames_of])
    for frame in centres("UW"):
        assert shapes[int(mouth[frame].argmax())] == rounded, (frame, mouth[frame])
        assert mouth[frame, shapes.index(rounded)] >= ROUNDED_AT_LEAST


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("preset", ["oculus15", "rpm"])
def test_a_viseme_rig_shows_pp_on_bilabials_and_u_on_uw(
    served: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]], engine: str, preset: str
) -> None:
    frames, maps = served[engine]
    retarget = maps[preset]
    visemes = retarget.apply(frames)[:, :15]
    names = retarget.controls[:15]
    assert names[0] == "viseme_sil" and names[-1] == "viseme_U"
    for frame in centres("P", "B", "M"):
        assert names[int(visemes[frame].argmax())] == "viseme_PP", (frame, visemes[frame])
    for frame in centres("UW"):
        assert names[int(visemes[frame].argmax())] == "viseme_U", (frame, visemes[frame])


def test_rpm_passes_the_face_off_the_mouth_and_holds_the_arkit_mouth_at_rest(
    served: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]], trained_models: dict[str, Model]
) -> None:
    frames, maps = served["dam"]
    controls = maps["rpm"].apply(frames)
    names = maps["rpm"].controls
    channels = trained_models["dam"].channels
    assert len(names) == 15 + 52
    for face in ("eyeBlinkLeft", "eyeBlinkRight", "browInnerUp", "browDownLeft"):
        expected = np.clip(frames[:, channels.index(face)], 0.0, 1.0)
        np.testing.assert_allclose(controls[:, names.index(face)], expected, atol=1e-9)
    for mouth in ("jawOpen", "mouthClose", "mouthFunnel", "mouthPucker", "mouthSmileLeft"):
        assert not controls[:, names.index(mouth)].any()


def arkit_frames(model: Model, count: int = 40) -> np.ndarray:
    return np.random.default_rng(6).uniform(-0.2, 1.2, (count, len(model.channels)))


def test_metahuman_and_a2f68_name_the_arkit_curves_in_pascal_case_with_the_tongue_at_rest(
    trained_models: dict[str, Model],
) -> None:
    model = trained_models["viseme-lerp"]
    maps = model_maps(model, None)
    frames = arkit_frames(model)
    tongue = (
        "TongueTipUp",
        "TongueTipDown",
        "TongueTipLeft",
        "TongueTipRight",
        "TongueRollUp",
        "TongueRollDown",
        "TongueRollLeft",
        "TongueRollRight",
        "TongueUp",
        "TongueDown",
        "TongueLeft",
        "TongueRight",
        "TongueIn",
        "TongueStretch",
        "TongueWide",
        "TongueNarrow",
    )
    a2f = maps["a2f68"]
    assert len(a2f.controls) == 68 and a2f.controls[52:] == tongue
    assert a2f.controls[14:18] == ("JawForward", "JawLeft", "JawRight", "JawOpen")
    assert maps["metahuman"].controls[14:18] == ("JawForward", "JawRight", "JawLeft", "JawOpen")
    for name in ("metahuman", "a2f68"):
        controls = maps[name].apply(frames)
        names = maps[name].controls
        for column, channel in enumerate(model.channels):
            pascal = channel[0].upper() + channel[1:]
            expected = np.clip(frames[:, column], 0.0, 1.0)
            np.testing.assert_allclose(controls[:, names.index(pascal)], expected, atol=1e-9)
        driven = {channel[0].upper() + channel[1:] for channel in model.channels}
        for column, control in enumerate(names):
            if control not in driven:
                assert not controls[:, column].any(), control


def test_a2f68_passes_a_models_own_tongue_shapes_through() -> None:
    channels = ("jawOpen", "tongueTipUp", "tongueIn", "lipsWide")
    pairs = PRESETS["a2f68"].build(channels, lambda: pytest.fail("a2f68 needs no probe"))
    frames = np.random.default_rng(2).uniform(-0.2, 1.2, (20, len(channels)))
    controls = fit_map("a2f68", pairs).apply(frames)
    for channel, control in (
        ("jawOpen", "JawOpen"),
        ("tongueTipUp", "TongueTipUp"),
        ("tongueIn", "TongueIn"),
    ):
        np.testing.assert_allclose(
            controls[:, pairs.controls.index(control)],
            np.clip(frames[:, channels.index(channel)], 0.0, 1.0),
            atol=1e-9,
        )
    driven = {"JawOpen", "TongueTipUp", "TongueIn"}
    assert not controls[:, [i for i, c in enumerate(pairs.controls) if c not in driven]].any()


def test_unified_drives_each_part_of_an_arkit_mouth_shape(trained_models: dict[str, Model]) -> None:
    model = trained_models["viseme-lerp"]
    retarget = model_maps(model, None, only="unified")["unified"]
    frames = arkit_frames(model)
    controls = retarget.apply(frames)
    # VRCFaceTracking's ARKit transform, written out here from its documentation.
    parts = {
        "jawOpen": ["JawOpen"],
        "mouthClose": ["MouthClosed"],
        "mouthFunnel": [
            f"LipFunnel{part}" for part in ("UpperRight", "UpperLeft", "LowerRight", "LowerLeft")
        ],
        "mouthPucker": [
            f"LipPucker{part}" for part in ("UpperRight", "UpperLeft", "LowerRight", "LowerLeft")
        ],
        "mouthRollUpper": ["LipSuckUpperRight", "LipSuckUpperLeft"],
        "mouthRollLower": ["LipSuckLowerRight", "LipSuckLowerLeft"],
        "mouthSmileLeft": ["MouthCornerPullLeft", "MouthCornerSlantLeft"],
        "mouthShrugLower": ["MouthRaiserLower"],
        "mouthPressRight": ["MouthPressRight"],
        "mouthLowerDownLeft": ["MouthLowerDownLeft"],
    }
    for channel, shapes in parts.items():
        expected = np.clip(frames[:, model.channels.index(channel)], 0.0, 1.0)
        for shape in shapes:
            np.testing.assert_allclose(
                controls[:, retarget.controls.index(shape)], expected, atol=1e-9
            )
    for idle in ("MouthTightenerLeft", "MouthTightenerRight", "JawLeft", "MouthFrownLeft"):
        assert not controls[:, retarget.controls.index(idle)].any()
    assert "eyeBlinkLeft" not in retarget.controls and "EyeClosedLeft" not in retarget.controls


def test_the_demo_rounds_and_presses_through_the_blendshape_rigs(
    served: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]],
) -> None:
    frames, maps = served["dam"]
    for preset, pucker, press in (
        ("arkit52", "mouthPucker", "mouthPressLeft"),
        ("metahuman", "MouthPucker", "MouthPressLeft"),
        ("a2f68", "MouthPucker", "MouthPressLeft"),
        ("unified", "LipPuckerUpperLeft", "MouthPressLeft"),
    ):
        controls = maps[preset].apply(frames)
        names = maps[preset].controls
        rounding = controls[:, names.index(pucker)]
        pressing = controls[:, names.index(press)]
        assert rounding[centres("UW")].min() > 2 * rounding[centres("AA")].max(), preset
        # each bilabial presses (at its peak) more than any /aa/ at its centre, and twice as
        # much on average: the /aa/ before a led /b/ already anticipates its closure
        peaks = np.array([pressing[frames_of].max() for frames_of in span_frames("P", "B", "M")])
        open_vowels = pressing[centres("AA")]
        assert peaks.min() > open_vowels.max(), preset
        assert peaks.mean() > 2 * open_vowels.mean(), preset


def emotional_controls(model: Model, retarget: RetargetMap, emotion: str | None) -> np.ndarray:
    synthesizer = model.start(SynthesisRequest(fps=FPS, emotion=emotion))
    synthesizer.feed([PhonemeSpan(*span) for span in timeline()])
    return retarget.apply(np.asarray(synthesizer.finish(), dtype=np.float64))


@pytest.mark.parametrize("preset", sorted(VOWEL_RIGS))
def test_vowel_rig_emotions_follow_the_requested_emotion_and_not_speech(
    served: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]],
    trained_models: dict[str, Model],
    preset: str,
) -> None:
    retarget = served["dam"][1][preset]
    emotions = {
        "vrm1": {"happy": "happy", "angry": "angry", "sad": "sad"},
        "vrm0": {"happy": "Joy", "angry": "Angry", "sad": "Sorrow"},
        "vroid": {"happy": "Fcl_ALL_Joy", "angry": "Fcl_ALL_Angry", "sad": "Fcl_ALL_Sorrow"},
    }[preset]
    unmatched = {
        "vrm1": ("relaxed", "surprised"),
        "vrm0": ("Fun",),
        "vroid": ("Fcl_ALL_Fun", "Fcl_ALL_Surprised"),
    }[preset]
    columns = {name: retarget.controls.index(control) for name, control in emotions.items()}
    neutral = emotional_controls(trained_models["dam"], retarget, None)
    assert all(neutral[:, column].mean() <= 0.05 for column in columns.values())
    for emotion, column in columns.items():
        controls = emotional_controls(trained_models["dam"], retarget, emotion)
        others = [controls[:, other].mean() for name, other in columns.items() if name != emotion]
        assert controls[:, column].mean() > 2 * max(others) + 0.05, emotion
        for idle in unmatched:
            assert not controls[:, retarget.controls.index(idle)].any()


def test_a_blink_closes_the_rigs_eyes_and_nothing_else(
    served: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]], trained_models: dict[str, Model]
) -> None:
    frames, maps = served["viseme-lerp"]
    channels = trained_models["viseme-lerp"].channels
    closed = frames[centres("sil")[0]].copy()
    closed[[channels.index("eyeBlinkLeft"), channels.index("eyeBlinkRight")]] = 1.0
    for preset, blink, neutral in (
        ("vrm1", "blink", "neutral"),
        ("vrm0", "Blink", "Neutral"),
        ("vroid", "Fcl_EYE_Close", "Fcl_ALL_Neutral"),
    ):
        controls = maps[preset].apply(closed[None])[0]
        names = maps[preset].controls
        assert controls[names.index(blink)] == pytest.approx(1.0, abs=0.02)
        assert controls[names.index(neutral)] == pytest.approx(1.0, abs=0.02)
        others = [value for name, value in zip(names, controls) if name not in (blink, neutral)]
        assert max(others) <= 0.02, preset


def test_the_presets_are_named_as_clients_name_them() -> None:
    assert RETARGET_PRESETS == (
        "oculus15",
        "arkit52",
        "vrm1",
        "vrm0",
        "vroid",
        "rpm",
        "unified",
        "metahuman",
        "a2f68",
    )
    assert tuple(PRESETS) == RETARGET_PRESETS
    without_arkit = offered_presets(("lipsOpen", "lipsRound"))
    assert without_arkit == ("oculus15", "vrm1", "vrm0", "vroid", "rpm")


def test_an_unknown_preset_is_a_coded_error_listing_the_presets(
    trained_models: dict[str, Model],
) -> None:
    with pytest.raises(LipstreamError) as caught:
        preset_pairs(trained_models["viseme-lerp"], "vrm2")
    assert caught.value.code == "unknown_retarget"
    assert caught.value.where == "target"
    assert caught.value.message == (
        "no rig preset 'vrm2'; the presets: "
        "oculus15, arkit52, vrm1, vrm0, vroid, rpm, unified, metahuman, a2f68"
    )
