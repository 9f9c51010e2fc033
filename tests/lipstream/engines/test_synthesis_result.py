"""A ``SynthesisResult`` is indexed as it unpacks: frames, channels, fps."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream import SynthesisResult


def test_indexing_matches_unpacking() -> None:
    frames = np.arange(6, dtype=np.float32).reshape(3, 2)
    result = SynthesisResult(frames, ("jawOpen", "mouthClose"), 60.0, {"frames": 3})
    unpacked_frames, channels, fps = result
    assert len(result) == 3
    assert result[0] is frames and unpacked_frames is frames
    assert result[1] == channels == ("jawOpen", "mouthClose")
    assert result[2] == fps == 60.0
    assert result[-1] == 60.0 and result[-3] is frames
    assert result[np.int64(1)] == ("jawOpen", "mouthClose")
    assert result[1:] == (("jawOpen", "mouthClose"), 60.0)
    assert tuple(result) == (frames, ("jawOpen", "mouthClose"), 60.0)
    assert result.stats == {"frames": 3}
    with pytest.raises(IndexError):
        result[3]
