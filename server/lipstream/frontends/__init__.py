"""Front ends: what turns the timing data people have into phoneme spans.

``align``: recorded speech and its transcript, by forced alignment (pocketsphinx).
"""
