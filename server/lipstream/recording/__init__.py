"""Record your face, hear it speak: recording sessions that become a served character.

Sketch: ``POST /v1/recordings`` opens a session with prompt sentences that cover the
phonemes evenly (``prompts``); each recording (a take) is uploaded to disk
(``sessions``); ``train`` starts a job in a separate process (``runner``, which runs
``python -m lipstream.recording.job``): capture over the takes, the prompt sentence as
each one's transcript, then training with the ``recipe``. The job writes its state and the
trained models to disk, and every server worker picks up the new models (``watcher``)
and serves them without a restart (``lipstream.server.hot_load``). The routes are
``lipstream.server.recordings``; see docs/reference/recordings.md.
"""
