"""``lipstream capture``: a corpus from video of a person talking.

Sketch: decode (PyAV) -> track the face (MediaPipe FaceMesh) -> check faces and bridge
short gaps -> remove head pose (similarity alignment) -> geometric measures -> ARKit-named
channels on the speaker's range; the speech is force-aligned to the transcript
(``lipstream.frontends.align``) and the corpus written in lipstream's own format
(``pipeline``). Ships as the ``capture`` extra (PyAV, mediapipe); importing this package
imports neither, and the server never imports it. See docs/how-to/capture-from-video.md.
"""
