"""Output profiles: naming, subsets, transforms, Oculus and Preston Blair visemes, with exact
values."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from lipstream.engines.viseme_lerp import VisemeLerpModel
from lipstream.errors import LipstreamError
from lipstream.output.probes import mouth_channels, probe_key_poses
from lipstream.output.profiles import (
    ProfileError,
    ProfileRequest,
    ResolvedProfile,
    load_presets,
    parse_profile,
    requested_profile,
    resolve_profile,
)
from lipstream.output.viseme_projection import VisemeProjector
from lipstream.visemes import OCULUS15, PRESTON_BLAIR
from lipstream_client import ChannelTransform, OutputProfile, Start
from lipstream_client.channels import OCULUS15_VISEMES, PRESTON_BLAIR_SHAPES
from lipstream_client.messages import Naming

if TYPE_CHECKING:
    from lipstream.engines.base import Model

RIG = ("jawOpen", "mouthClose", "eyeBlinkLeft", "eyeBlinkRight")
FRAMES = np.array(
    [[0.1, 0.2, 0.3, 0.4], [0.5, 0.6, 0.7, 0.8], [0.7, 0.0, 1.0, 0.25]], dtype=np.float32
)


def no_projector(visemes: str) -> VisemeProjector:
    raise AssertionError("a blendshape profile must not build the viseme projector")


def resolved(profile: OutputProfile | None, field: str = "output") -> ResolvedProfile:
    return resolve_profile(RIG, ProfileRequest(profile, field), no_projector)


def test_default_profile_is_every_channel_in_arkit_names_unchanged() -> None:
    profile = resolved(None)
    assert profile.channels == RIG
    assert profile.apply(FRAMES).tobytes() == FRAMES.tobytes()


@pytest.mark.parametrize(
    ("naming", "expected"),
    [
        ("arkit", RIG),
        ("livelink", ("JawOpen", "MouthClose", "EyeBlinkLeft", "EyeBlinkRight")),
        ("suffix_lr", ("jawOpen", "mouthClose", "eyeBlink_L", "eyeBlink_R")),
    ],
)
def test_naming_styles(naming: Naming, expected: tuple[str, ...]) -> None:
    assert resolved(OutputProfile(naming=naming)).channels == expected


def test_subset_picks_and_orders_columns_in_the_output_naming() -> None:
    profile = resolved(OutputProfile(naming="suffix_lr", channels=("eyeBlink_R", "jawOpen")))
    assert profile.channels == ("eyeBlink_R", "jawOpen")
    expected = np.array([[0.4, 0.1], [0.8, 0.5], [0.25, 0.7]], dtype=np.float32)
    assert profile.apply(FRAMES).tobytes() == expected.tobytes()


def test_transform_is_multiply_add_then_clamp_after_the_subset() -> None:
    profile = resolved(
        OutputProfile(
            naming="livelink",
            channels=("JawOpen", "MouthClose"),
            transforms={
                "JawOpen": ChannelTransform(2.0, -0.5, (0.0, 0.6)),
                "MouthClose": ChannelTransform(offset=0.25),
            },
        )
    )
    out = profile.apply(FRAMES)
    # JawOpen: 0.1*2-0.5 = -0.3 -> 0; 0.5*2-0.5 = 0.5; 0.7*2-0.5 = 0.9 -> 0.6.
    # MouthClose: 0.2+0.25, 0.6+0.25, 0.0+0.25.
    expected = np.array(
        [
            [0.0, np.float32(0.2) + 0.25],
            [np.float32(0.5) * 2 - 0.5, np.float32(0.6) + 0.25],
            [0.6, 0.25],
        ]
    )
    assert out.dtype == np.float32 and out.shape == (3, 2)
    np.testing.assert_array_equal(out, expected.astype(np.float32))


def test_unknown_channels_name_the_field_that_holds_them() -> None:
    with pytest.raises(ProfileError) as error:
        resolved(OutputProfile(channels=("jawOpen", "JawOpen")))
    assert (error.value.code, error.value.where) == ("unknown_channel", "output.channels[1]")
    with pytest.raises(ProfileError) as error:
        resolved(OutputProfile(channels=("nose",)), field="")
    assert (error.value.code, error.value.where) == ("unknown_channel", "channels[0]")
    with pytest.raises(ProfileError) as error:
        resolved(
            OutputProfile(channels=("jawOpen",), transforms={"mouthClose": ChannelTransform(2.0)})
        )
    assert (error.value.code, error.value.where) == (
        "unknown_channel",
        "output.transforms.mouthClose",
    )


def test_names_that_collide_after_renaming_are_invalid() -> None:
    with pytest.raises(ProfileError) as error:
        resolve_profile(
            ("fooLeft", "foo_L"), ProfileRequest(OutputProfile(naming="suffix_lr")), no_projector
        )
    assert (error.value.code, error.value.where) == ("invalid_request", "output.naming")


def test_a_transform_beyond_float32_is_refused_and_engine_nan_is_a_fault() -> None:
    huge = resolved(OutputProfile(transforms={"jawOpen": ChannelTransform(1e39)}))
    with pytest.raises(ProfileError) as error:
        huge.apply(FRAMES)
    assert error.value.code == "invalid_request"
    with pytest.raises(ValueError, match="non-finite"):
        resolved(None).apply(np.full((1, 4), np.nan, dtype=np.float32))


@pytest.mark.parametrize("bad", [np.inf, -np.inf, np.nan])
def test_an_identity_profile_passes_the_largest_finite_frames_and_refuses_non_finite(
    bad: float,
) -> None:
    identity = resolved(None)
    big = np.full((3, 4), np.finfo(np.float32).max, dtype=np.float32)
    assert np.array_equal(identity.apply(big), big)
    cancelling = np.array([[np.inf, -np.inf, 0.0, 0.0]], dtype=np.float32)  # sums to NaN
    for frames in (cancelling, np.where(np.eye(3, 4, dtype=bool), bad, big)):
        with pytest.raises(ValueError, match="non-finite"):
            identity.apply(frames.astype(np.float32))


# ---- Oculus visemes ----------------------------------------------------------------------

MOUTH = tuple(f"mouthShape{index:02d}" for index in range(16))
VISEME_RIG = (*MOUTH, "eyeBlinkLeft")


def synthetic_projector(visemes: str = "oculus15") -> VisemeProjector:
    poses = np.random.default_rng(7).random((15, len(VISEME_RIG)))
    return VisemeProjector(poses, mouth_channels(VISEME_RIG))


def test_mouth_channels_mask_and_its_fallback() -> None:
    assert mouth_channels(RIG).tolist() == [True, True, False, False]
    assert mouth_channels(("browUp", "eyeWide")).tolist() == [True, True]


def test_projection_recovers_known_convex_weights_ignoring_non_mouth_channels() -> None:
    projector = synthetic_projector()
    weights = np.zeros((3, 15))
    weights[0, 0] = 1.0
    weights[1, [0, 10]] = (0.75, 0.25)
    weights[2, [1, 12, 14]] = (0.2, 0.3, 0.5)
    frames = weights @ projector.poses
    frames[:, -1] = [0.0, 1.0, 0.5]  # blinks must not change the visemes
    recovered = projector.weights(frames)
    np.testing.assert_allclose(recovered, weights, atol=1e-6)
    np.testing.assert_allclose(recovered.sum(axis=1), 1.0, atol=1e-12)


def test_viseme_profile_uses_oculus_order_and_accepts_ovr_spellings() -> None:
    projector = synthetic_projector()
    full = resolve_profile(
        VISEME_RIG, ProfileRequest(OutputProfile(visemes="oculus15")), lambda visemes: projector
    )
    assert full.channels == OCULUS15_VISEMES
    subset = resolve_profile(
        VISEME_RIG,
        ProfileRequest(
            OutputProfile(
                visemes="oculus15",
                channels=("ih", "PP", "viseme_aa"),
                transforms={"I": ChannelTransform(2.0)},
            )
        ),
        lambda visemes: projector,
    )
    assert subset.channels == ("viseme_I", "viseme_PP", "viseme_aa")
    frame = (0.5 * projector.poses[12] + 0.5 * projector.poses[10])[None]
    np.testing.assert_allclose(subset.apply(frame), [[1.0, 0.0, 0.5]], atol=1e-5)


def test_viseme_aliases_naming_one_viseme_twice_are_invalid() -> None:
    with pytest.raises(ProfileError) as error:
        resolve_profile(
            VISEME_RIG,
            ProfileRequest(OutputProfile(visemes="oculus15", channels=("I", "ih"))),
            synthetic_projector,
        )
    assert (error.value.code, error.value.where) == ("invalid_request", "output.channels[1]")
    with pytest.raises(ProfileError) as error:
        resolve_profile(
            VISEME_RIG,
            ProfileRequest(OutputProfile(visemes="oculus15", channels=("jawOpen",))),
            synthetic_projector,
        )
    assert error.value.code == "unknown_channel"


def test_probing_viseme_lerp_returns_its_trained_key_poses(
    trained_models: dict[str, Model],
) -> None:
    model = trained_models["viseme-lerp"]
    assert isinstance(model, VisemeLerpModel)
    assert model.manifest.hyperparameters["scheme"] == "oculus15"
    np.testing.assert_allclose(
        probe_key_poses(model),
        model.poses,
        atol=1e-6,
    )


# ---- Preston Blair mouth shapes ----------------------------------------------------------


def test_preston_blair_profile_has_the_nine_shapes_in_any_case() -> None:
    poses = np.random.default_rng(11).random((9, len(VISEME_RIG)))
    projector = VisemeProjector(poses, mouth_channels(VISEME_RIG))
    asked: list[str] = []

    def source(visemes: str) -> VisemeProjector:
        asked.append(visemes)
        return projector

    full = resolve_profile(
        VISEME_RIG, ProfileRequest(OutputProfile(visemes="preston-blair")), source
    )
    assert full.channels == PRESTON_BLAIR_SHAPES == ("A", "B", "C", "D", "E", "F", "G", "H", "X")
    subset = resolve_profile(
        VISEME_RIG,
        ProfileRequest(OutputProfile(visemes="preston-blair", channels=("x", "d"))),
        source,
    )
    assert subset.channels == ("X", "D") and asked == ["preston-blair", "preston-blair"]
    frame = (0.25 * poses[8] + 0.75 * poses[3])[None]
    np.testing.assert_allclose(subset.apply(frame), [[0.25, 0.75]], atol=1e-5)
    with pytest.raises(ProfileError) as error:
        resolve_profile(
            VISEME_RIG,
            ProfileRequest(OutputProfile(visemes="preston-blair", channels=("viseme_PP",))),
            source,
        )
    assert error.value.code == "unknown_channel"


def test_preston_blair_key_poses_of_viseme_lerp_average_its_oculus_poses(
    trained_models: dict[str, Model],
) -> None:
    model = trained_models["viseme-lerp"]
    assert isinstance(model, VisemeLerpModel)
    oculus_poses = model.poses.astype(np.float64)
    expected = np.stack(
        [
            np.mean(
                [oculus_poses[OCULUS15.index_of(phoneme)] for phoneme in PRESTON_BLAIR.members(s)],
                axis=0,
            )
            for s in PRESTON_BLAIR_SHAPES
        ]
    )
    np.testing.assert_allclose(probe_key_poses(model, PRESTON_BLAIR), expected, atol=1e-6)


# ---- presets -----------------------------------------------------------------------------


def test_requested_profile_precedence() -> None:
    preset = OutputProfile(naming="livelink")
    output = OutputProfile(naming="suffix_lr")
    assert requested_profile(Start("a", "e", "c", channels=("jawOpen",)), preset) == ProfileRequest(
        OutputProfile(channels=("jawOpen",)), ""
    )
    assert requested_profile(Start("a", "e", "c", output=output), preset) == ProfileRequest(output)
    assert requested_profile(Start("a", "e", "c"), preset) == ProfileRequest(preset, "preset")


def test_presets_file_is_validated_by_the_codec(tmp_path: Path) -> None:
    good = tmp_path / "profiles.json"
    good.write_text(
        json.dumps(
            {
                "demo": {
                    "naming": "livelink",
                    "channels": ["JawOpen"],
                    "transforms": {"JawOpen": {"clamp": [0, 0.5]}},
                }
            }
        )
    )
    assert load_presets(good) == {
        "demo": OutputProfile(
            naming="livelink",
            channels=("JawOpen",),
            transforms={"JawOpen": ChannelTransform(clamp=(0.0, 0.5))},
        )
    }
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"demo": {"naming": "klingon"}}))
    with pytest.raises(LipstreamError) as error:
        load_presets(bad)
    assert error.value.code == "invalid_setting" and "output.naming" in error.value.message
    with pytest.raises(LipstreamError, match="invalid output profile"):
        parse_profile({"visemes": "oculus15", "naming": "arkit"}, "model.json")
