"""Phoneme maps: picking is exact at a vertex and a convex blend inside; a real cluster embeds
to finite points; time- and context-correct highlights."""

from __future__ import annotations

import numpy as np

from lipstream.engines.expressive_dp.isomap import PhonemeMaps, embed
from lipstream.engines.expressive_dp.nodes import NodeDatabase
from lipstream.phonemes import PHONEME_INDEX

AA, S, SIL = PHONEME_INDEX["AA"], PHONEME_INDEX["S"], PHONEME_INDEX["sil"]


def _maps() -> tuple[PhonemeMaps, np.ndarray]:
    """Three AA nodes of 3 frames on a 3 x 3 grid of points, frames (x, y, x * y)."""
    xs, ys = np.meshgrid(np.arange(3.0), np.arange(3.0))
    points = np.column_stack([xs.ravel(), ys.ravel()])
    frames = np.column_stack([points, points[:, 0] * points[:, 1]])
    nodes = NodeDatabase(
        phoneme=np.array([AA, AA, AA]),
        emotion=np.zeros(3, dtype=np.int64),
        previous=np.array([SIL, S, SIL]),
        next=np.array([S, SIL, S]),
        pre=np.full(3, -1),
        suc=np.full(3, -1),
        offsets=np.array([0, 3, 6, 9]),
        frames=frames,
        fps=100.0,
    )
    return PhonemeMaps(nodes, points), frames


def test_a_vertex_picks_its_own_frame() -> None:
    maps, frames = _maps()
    for row in range(9):
        picked = maps.pick(AA, *maps.points[row])
        assert picked.inside
        np.testing.assert_allclose(picked.frame, frames[row], atol=1e-12)


def test_inside_a_triangle_the_pick_is_a_convex_blend_of_its_corners() -> None:
    maps, frames = _maps()
    rng = np.random.default_rng(0)
    for point in rng.uniform(0.05, 1.95, size=(20, 2)):
        picked = maps.pick(AA, *point)
        assert picked.inside and len(picked.vertices) == 3
        assert (picked.weights >= 0).all() and abs(picked.weights.sum() - 1) < 1e-12
        np.testing.assert_allclose(picked.weights @ maps.points[picked.vertices], point, atol=1e-9)
        np.testing.assert_allclose(picked.frame, picked.weights @ frames[picked.vertices])


def test_outside_the_map_the_nearest_frame_is_picked() -> None:
    maps, frames = _maps()
    picked = maps.pick(AA, 5.0, 5.2)
    assert not picked.inside
    np.testing.assert_allclose(picked.frame, frames[8])


def test_time_and_context_correct_highlights() -> None:
    maps, _ = _maps()
    members, placed = maps.time_correct(AA, 0.5)
    assert members.tolist() == [0, 1, 2]
    np.testing.assert_allclose(placed, maps.points[[1, 4, 7]])  # the middle frame of each
    assert maps.context_correct(AA, SIL, S).tolist() == [0, 2]


def test_a_curved_cluster_embeds_to_finite_points_that_keep_its_order() -> None:
    t = np.linspace(0.0, 3.0, 150)
    spiral = np.column_stack([t * np.cos(3 * t), t * np.sin(3 * t), 0.1 * t])
    placed = embed(spiral)
    assert placed.shape == (150, 2) and np.isfinite(placed).all()
    # Isomap unrolls the curve: its first coordinate follows arc length, up to sign
    correlation = abs(np.corrcoef(placed[:, 0], t)[0, 1])
    assert correlation > 0.95
