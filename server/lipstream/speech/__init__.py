"""Speech from text with espeak-ng: audio and the exact phoneme events of what it said.

Sketch: ``libespeak`` binds libespeak-ng through ctypes (standard library
only) and doubles as the worker script; ``espeak`` speaks in this process and
turns espeak-ng's events into contiguous ``PhonemeSpan``s of the phoneme set;
``worker`` speaks in a fresh process under a timeout; ``text_frontend`` is what
the server and the CLI use: checked text in, audio and spans out, with coded
errors.
"""
