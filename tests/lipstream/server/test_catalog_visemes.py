"""The catalog's viseme projectors of a served model: a frame blended from two of
``viseme-lerp``'s key poses projects onto those visemes (or mouth shapes) in the known
proportions, and its rest pose onto silence."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.engines.viseme_lerp import VisemeLerpModel
from lipstream.server.catalog import Catalog
from lipstream.visemes import OCULUS15
from lipstream_client.channels import OCULUS15_VISEMES


def test_a_viseme_lerp_frame_projects_onto_the_two_visemes_it_blends(catalog: Catalog) -> None:
    model = catalog.model("viseme-lerp", "demo")
    assert isinstance(model, VisemeLerpModel)
    projector = catalog.projector(model)
    poses = model.poses.astype(np.float64)
    pp, aa = OCULUS15_VISEMES.index("viseme_PP"), OCULUS15_VISEMES.index("viseme_aa")
    frame = 0.7 * poses[pp] + 0.3 * poses[aa]
    expected = np.zeros(15)
    expected[[pp, aa]] = (0.7, 0.3)
    np.testing.assert_allclose(projector.weights(frame[None])[0], expected, atol=1e-4)
    rest = catalog.rest_pose(model, None)
    assert projector.weights(rest[None])[0, 0] == pytest.approx(1.0, abs=1e-6)


def test_a_viseme_lerp_frame_projects_onto_mouth_shapes(catalog: Catalog) -> None:
    model = catalog.model("viseme-lerp", "demo")
    assert isinstance(model, VisemeLerpModel)
    projector = catalog.projector(model, "preston-blair")
    poses = model.poses.astype(np.float64)
    # Shape A is P B M (all Oculus PP); shape D is AA AY AW (all Oculus aa).
    frame = 0.7 * poses[OCULUS15.classes.index("PP")] + 0.3 * poses[OCULUS15.classes.index("aa")]
    expected = np.zeros(9)
    expected[[0, 3]] = (0.7, 0.3)
    np.testing.assert_allclose(projector.weights(frame[None])[0], expected, atol=1e-4)
    rest = catalog.rest_pose(model, None)
    assert projector.weights(rest[None])[0, 8] == pytest.approx(1.0, abs=1e-6)
