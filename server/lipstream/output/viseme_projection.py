"""Viseme weights from blendshape frames, by non-negative least squares.

Method: each viseme v of a set (the 15 Oculus visemes, or the nine Preston
Blair mouth shapes of Rhubarb Lip Sync) has a key pose p_v (one value per model
channel). A frame x is explained as a convex combination of the key poses:
minimise ||P w - x||² over w >= 0 with sum(w) = 1, where the columns of P
are the key poses. The sum constraint enters as one extra, heavily weighted
row of ones, and each frame is solved by Lawson-Hanson NNLS
(``scipy.optimize.nnls``); weights below 1e-9 (solver rounding) are zeroed
and the rest renormalised to sum to 1 exactly. Like OVRLipSync's output, the
weights are a distribution over visemes, and the key pose of silence maps
to silence (``viseme_sil``, shape ``X``) = 1. Only mouth channels
(``jaw*``, ``mouth*``, ``cheek*``, ``tongue*``) enter the fit, so blinks and
brows do not leak into the visemes; a rig with none of them uses every
channel.

Key poses are probed from a model (``lipstream.output.probes``): every
canonical phoneme is synthesized held for 200 ms between silences, the frame
at its centre is taken, and the frames are averaged over the phonemes of each
class of the set's scheme (``lipstream.visemes.OCULUS15``,
``PRESTON_BLAIR``); silence's pose is the frame at the centre of a silence.
One probe serves every set. The server
probes the character's ``viseme-lerp`` model when one with the same channels
is loaded: its frame at a span centre is exactly its trained key pose (the
mean of the corpus frames of that viseme class), so the projection inverts
that model. Otherwise it probes the request's model, as ``lipstream synth``
does.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from ..visemes import OCULUS15, PRESTON_BLAIR, VisemeScheme
from .probes import key_poses, mouth_channels

# Output viseme sets (``lipstream.visemes``) and their schemes; each scheme's class order is the
# set's channel order (lipstream_client.channels.VISEME_CHANNELS).
VISEME_SCHEMES: dict[str, VisemeScheme] = {"oculus15": OCULUS15, "preston-blair": PRESTON_BLAIR}

_SUM_WEIGHT = 100.0
_NEGLIGIBLE = 1e-9  # rounding residue of the solver, not a viseme


def projectors_from(
    phoneme_poses: dict[str, np.ndarray], channels: tuple[str, ...]
) -> dict[str, VisemeProjector]:
    """A projector per output viseme set, from probed phoneme poses."""
    poses, mask = phoneme_poses, mouth_channels(channels)
    return {
        name: VisemeProjector(key_poses(poses, scheme), mask)
        for name, scheme in VISEME_SCHEMES.items()
    }


class VisemeProjector:
    """Projects frames (n, n_channels) onto key ``poses`` (n_visemes, n_channels) as convex
    weights."""

    def __init__(self, poses: np.ndarray, mask: np.ndarray) -> None:
        poses = np.asarray(poses, dtype=np.float64)
        if poses.ndim != 2 or poses.shape[0] < 1:
            raise ValueError(f"key poses must be (n_visemes, n_channels), got {poses.shape}")
        self.poses = poses
        self.mask = np.asarray(mask, dtype=bool)
        scale = _SUM_WEIGHT * max(1.0, float(np.abs(poses[:, self.mask]).max(initial=0.0)))
        self._system = np.vstack([poses[:, self.mask].T, np.full((1, len(poses)), scale)])
        self._sum_target = scale

    @property
    def n_channels(self) -> int:
        return int(self.poses.shape[1])

    def weights(self, frames: np.ndarray) -> np.ndarray:
        """Viseme weights float64 (n, n_visemes), each row >= 0 and summing to 1."""
        frames = np.asarray(frames, dtype=np.float64)
        out = np.empty((len(frames), len(self.poses)))
        target = np.empty(self._system.shape[0])
        target[-1] = self._sum_target
        for index, frame in enumerate(frames):
            target[:-1] = frame[self.mask]
            solution, _ = nnls(self._system, target)
            solution[solution < _NEGLIGIBLE] = 0.0
            out[index] = solution / solution.sum()
        return out
