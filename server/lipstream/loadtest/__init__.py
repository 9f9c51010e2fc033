"""Load-testing tools: real-time sessions against a server on this machine.

``load`` runs the Audio2Face-3D style load test (``lipstream loadtest``):
``sessions`` drives each WebSocket session in real time, ``workers`` spreads
them over processes, ``clips`` makes the synthetic speech, ``stats`` and
``cpu`` summarize what was measured. ``capacity`` searches for the most
sessions under a lag limit (``lipstream loadtest capacity``); ``soak`` runs
valid sessions among the ``hostile`` clients (``lipstream loadtest soak``);
``command`` declares the command's options.
"""
