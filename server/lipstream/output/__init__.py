"""What a request's frames are turned into on the way out: output profiles (``profiles``:
channel subsets, naming, scaling), viseme schemes and the projection of frames onto them
(``visemes``, ``viseme_projection``), retarget maps to rig controls, and the rig presets built
on them. Used by the server and the command line alike; it imports neither."""
