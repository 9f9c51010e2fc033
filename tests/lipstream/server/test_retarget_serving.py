"""Requests served through retarget maps, end to end: a real ``lipstream serve`` on loopback
and the real client SDK; stored maps, the shipped targets, a character's preset, and a bad
stored map setting its model aside with a coded error naming file and field."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.corpus.livelink import ARKIT_BLENDSHAPES
from lipstream.engines.base import Model
from lipstream.errors import LipstreamError
from lipstream.models import ModelRegistry
from lipstream.output.retarget import KeyPosePairs, fit_map, save_map
from lipstream.server.catalog import Catalog
from lipstream_client import AsyncClient, LipstreamServerError, OutputProfile, StreamResult
from lipstream_client.channels import OCULUS15_VISEMES
from tests.helpers import VRM1_EXPRESSIONS, return_frames
from tests.live_server import LiveServer, live_server

FPS = 60.0
LINE = [("sil", 0.0, 0.1), ("M", 0.1, 0.2), ("AA", 0.2, 0.5), ("P", 0.5, 0.6), ("sil", 0.6, 0.85)]
JAW_MAP = "jaw"


def jaw_map(model: Model) -> KeyPosePairs:
    """Two controls, each driven by one model channel: open = jawOpen, shut = mouthClose."""
    channels = model.channels
    keys = np.zeros((2, len(channels)))
    keys[0, channels.index("jawOpen")] = keys[1, channels.index("mouthClose")] = 1.0
    return KeyPosePairs(
        channels=channels,
        controls=("open", "shut"),
        key_names=("open", "shut"),
        source_rest=np.zeros(len(channels)),
        control_rest=np.zeros(2),
        source_keys=keys,
        control_keys=np.eye(2),
        channel_weights=np.ones(len(channels)),
    )


@pytest.fixture(scope="module")
def served(
    trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory
) -> Iterator[LiveServer]:
    root = tmp_path_factory.mktemp("retarget-models")
    model = trained_models["viseme-lerp"]
    model.save(root / "viseme-lerp")
    save_map(root / "viseme-lerp" / "retarget" / JAW_MAP, fit_map(JAW_MAP, jaw_map(model)))
    presets = root.parent / "presets.json"
    presets.write_text(json.dumps({"demo": {"retarget": "oculus15"}}))
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("LIPSTREAM_PROFILES", str(presets))
        with live_server(root) as server:
            yield server


async def request(url: str, output: OutputProfile | None) -> StreamResult:
    async with AsyncClient(url, encoding="msgpack") as client:
        stream = await client.start("viseme-lerp", "demo", fps=FPS, output=output)
        await stream.send_phonemes(LINE)
        await stream.end()
        return await asyncio.wait_for(stream.collect(), 20)


def offline(model: Model) -> tuple[np.ndarray, tuple[str, ...]]:
    frames = np.asarray(model.synthesize(LINE, fps=FPS).frames, dtype=np.float64)
    return frames, model.channels


def test_a_stored_map_serves_its_controls_over_the_websocket(
    served: LiveServer, trained_models: dict[str, Model]
) -> None:
    result = asyncio.run(request(served.ws, OutputProfile(retarget=JAW_MAP)))
    assert result.ready.channels == ("open", "shut")
    frames, channels = offline(trained_models["viseme-lerp"])
    columns = [channels.index("jawOpen"), channels.index("mouthClose")]
    expected = np.clip(frames[:, columns], 0.0, 1.0)
    rows = np.asarray(result.rows())
    assert len(rows) == len(expected) + return_frames(FPS)
    np.testing.assert_allclose(rows[: len(expected)], expected, atol=1e-6)


def test_arkit52_with_a_subset_holds_channels_the_model_lacks_at_rest(
    served: LiveServer, trained_models: dict[str, Model]
) -> None:
    frames, channels = offline(trained_models["viseme-lerp"])
    lacking = next(name for name in ARKIT_BLENDSHAPES if name not in channels)
    profile = OutputProfile(retarget="arkit52", channels=("jawOpen", lacking))
    result = asyncio.run(request(served.ws, profile))
    assert result.ready.channels == ("jawOpen", lacking)
    rows = np.asarray(result.rows())
    assert len(rows) == len(frames) + return_frames(FPS)
    np.testing.assert_allclose(
        rows[: len(frames), 0], np.clip(frames[:, channels.index("jawOpen")], 0, 1), atol=1e-6
    )
    assert not rows[:, 1].any()


def test_the_characters_preset_names_a_shipped_target(served: LiveServer) -> None:
    result = asyncio.run(request(served.ws, None))
    assert result.ready.channels == OCULUS15_VISEMES
    rows = np.asarray(result.rows())
    assert rows.min() >= 0.0 and rows.max() <= 1.0
    # The middle of the opening silence is the silence key pose: viseme_sil alone.
    np.testing.assert_allclose(rows[3], np.eye(15)[0], atol=1e-5)
    assert rows[round(0.35 * FPS)].argmax() == OCULUS15_VISEMES.index("viseme_aa")


def test_an_unknown_map_is_unknown_retarget_listing_the_presets_and_maps(
    served: LiveServer,
) -> None:
    with pytest.raises(LipstreamServerError) as caught:
        asyncio.run(request(served.ws, OutputProfile(retarget="nope")))
    assert caught.value.code == "unknown_retarget"
    assert "output.retarget" in caught.value.message
    for name in ("jaw", "oculus15", "arkit52", "vrm1", "vrm0", "vroid", "rpm", "unified"):
        assert name in caught.value.message
    assert "metahuman" in caught.value.message and "a2f68" in caught.value.message


def test_a_request_picks_the_vrm1_preset_by_name(served: LiveServer) -> None:
    result = asyncio.run(request(served.ws, OutputProfile(retarget="vrm1")))
    assert result.ready.channels == VRM1_EXPRESSIONS
    rows = np.asarray(result.rows())
    mouth = rows[:, :5]
    # LINE: AA over 0.2-0.5 s opens the mouth in aa; M (0.1-0.2) and P (0.5-0.6) close it.
    assert mouth[round(0.35 * FPS)].argmax() == 0 and mouth[round(0.35 * FPS), 0] > 0.8
    for closed in (0.15, 0.55):
        assert mouth[round(closed * FPS)].max() < 0.15
    assert rows.min() >= 0.0 and rows.max() <= 1.0


def test_a_malformed_stored_map_sets_its_model_aside_naming_file_and_field(
    trained_models: dict[str, Model], tmp_path: Path
) -> None:
    trained_models["viseme-lerp"].save(tmp_path / "viseme-lerp")
    stored = save_map(
        tmp_path / "viseme-lerp" / "retarget" / JAW_MAP,
        fit_map(JAW_MAP, jaw_map(trained_models["viseme-lerp"])),
    )
    manifest = json.loads((stored / "retarget.json").read_text())
    manifest["channels"] = manifest["channels"][:-1]
    (stored / "retarget.json").write_text(json.dumps(manifest))
    registry = ModelRegistry.load(tmp_path)
    with pytest.raises(LipstreamError):  # its only model is set aside
        Catalog.build(registry, ServerSettings())
    assert not registry.models
    failure = registry.failures["viseme-lerp"].error
    assert failure.code == "model_invalid"
    assert failure.where == f"{stored / 'retarget.json'}: channels"
