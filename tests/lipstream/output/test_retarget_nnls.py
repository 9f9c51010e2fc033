"""The shipped presets through the warm-started compiled NNLS, against scipy.optimize.nnls per
frame on the demo character's engines, streamed in blocks as a session sends them.

Tolerances: the presets have more keys than fitted channels, so only the residual is unique;
the controls agree where the blend is unique and, where it is not, the keys it may trade
(exact duplicates, or the in-context closure keys that dam and cohen-massaro make within
about 1e-8 radians of each other) share their controls. What remains is how the two
factorisations resolve nearly parallel keys (module docstring of ``numerics.nnls``): up to
4e-8 on a control and 3e-9 on the residual norm were seen, so 1e-7 and 1e-8.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest
from scipy.optimize import nnls

from lipstream.numerics.nnls import solve_nnls_rows, warm_nnls
from lipstream.output.probes import probe_rig
from lipstream.output.rig_presets import model_maps

if TYPE_CHECKING:
    from lipstream.engines.base import Model
    from lipstream.output.retarget import RetargetMap

# The blend is checked for optimality to RESIDUAL_ATOL; the controls less tightly, since two
# nearly dependent closure keys (dam, cohen-massaro) leave the minimizer ill-conditioned:
# scipy and the warm-started solver then part by a few 1e-7 in a control.
CONTROL_ATOL = 1e-6
RESIDUAL_ATOL = 1e-8
FPS = 60.0
ENGINES = ("viseme-lerp", "dam", "cohen-massaro", "expressive-dp", "hmm")
NNLS_PRESETS = ("oculus15", "vrm1", "vrm0", "vroid", "rpm")
SPOKEN = tuple(
    "sil HH AH L OW W ER L D sil M AA P B IY S T UW CH EH F sil W UW B UW M AA sil".split()
)


def sentence() -> list[tuple[str, float, float]]:
    return [(label, 0.09 * index, 0.09 * (index + 1)) for index, label in enumerate(SPOKEN)]


@pytest.fixture(scope="module")
def streamed(
    trained_models: dict[str, Model],
) -> dict[str, tuple[np.ndarray, dict[str, RetargetMap]]]:
    lerp = trained_models["viseme-lerp"]
    out = {}
    for engine in ENGINES:
        model = trained_models[engine]
        frames = np.asarray(model.synthesize(sentence(), fps=FPS).frames, dtype=np.float64)
        out[engine] = (frames, model_maps(model, None, probe=probe_rig(model, phoneme_source=lerp)))
    return out


def targets_of(retarget: RetargetMap, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The stage-1 system and per-frame targets, built from the pairs."""
    pairs = retarget.pairs
    fitted = pairs.channel_weights > 0
    system = (pairs.source_keys - pairs.source_rest).T[fitted] * pairs.channel_weights[fitted, None]
    targets = (frames - pairs.source_rest)[:, fitted] * pairs.channel_weights[fitted]
    return system, targets


def scipy_controls(retarget: RetargetMap, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Controls and residual norms with every frame's blend from scipy.optimize.nnls."""
    pairs = retarget.pairs
    system, targets = targets_of(retarget, frames)
    weights = np.array([nnls(system, target)[0] for target in targets])
    controls = np.clip(
        pairs.control_rest + weights @ (pairs.control_keys - pairs.control_rest), 0.0, 1.0
    )
    return controls, np.linalg.norm(targets - weights @ system.T, axis=1)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("preset", NNLS_PRESETS)
def test_a_streamed_preset_matches_scipy_frame_by_frame(
    streamed: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]], engine: str, preset: str
) -> None:
    frames, maps = streamed[engine]
    retarget = maps[preset]
    expected, expected_residual = scipy_controls(retarget, frames)
    stream = retarget.stream()
    controls = np.vstack(
        [stream.apply(frames[first : first + 5]) for first in range(0, len(frames), 5)]
    )
    np.testing.assert_allclose(controls, expected, atol=CONTROL_ATOL)
    system, targets = targets_of(retarget, frames)
    weights = retarget.blend_weights(frames)
    assert (weights >= 0).all()
    np.testing.assert_allclose(
        np.linalg.norm(targets - weights @ system.T, axis=1), expected_residual, atol=RESIDUAL_ATOL
    )


def test_a_stream_keeps_its_own_warm_start(
    streamed: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]],
) -> None:
    frames, maps = streamed["dam"]
    retarget = maps["vrm1"]
    first, second = retarget.stream(), retarget.stream()
    first.apply(frames[:40])
    assert first.passive.any() and not second.passive.any()
    one_by_one = np.vstack([second.apply(frames[index : index + 1]) for index in range(40, 80)])
    np.testing.assert_allclose(one_by_one, first.apply(frames[40:80]), atol=1e-12)


def test_rest_and_a_frame_at_rest_plus_nothing_give_the_rest_controls(
    streamed: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]],
) -> None:
    _, maps = streamed["dam"]
    for preset in NNLS_PRESETS:
        retarget = maps[preset]
        rest = retarget.pairs.source_rest[None]
        controls = retarget.stream().apply(np.vstack([rest, rest]))
        np.testing.assert_array_equal(controls, np.tile(retarget.pairs.control_rest, (2, 1)))


def test_the_kernel_warmed_at_start_up_is_the_one_a_stream_calls(
    streamed: dict[str, tuple[np.ndarray, dict[str, RetargetMap]]],
) -> None:
    warm_nnls()
    warmed = set(solve_nnls_rows.signatures)
    frames, maps = streamed["dam"]
    maps["vrm1"].stream().apply(frames[:20])
    assert set(solve_nnls_rows.signatures) == warmed
