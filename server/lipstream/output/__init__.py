"""What a request's frames are turned into on the way out: viseme schemes, retarget maps to
rig controls, and the rig presets built on them. Used by the server and the command line alike."""
