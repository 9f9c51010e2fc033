"""The coded errors of ``lipstream capture``: each names the file and what is wrong."""

from __future__ import annotations

CORRUPT_VIDEO = "corrupt_video"
NO_VIDEO_TRACK = "no_video_track"
NO_AUDIO_TRACK = "no_audio_track"
NO_FACE = "no_face"
SEVERAL_FACES = "several_faces"
TRACKING_GAP = "tracking_gap"
MISSING_TRANSCRIPT = "missing_transcript"
MISSING_DEPENDENCY = "missing_dependency"
NO_VIDEOS = "no_videos"
