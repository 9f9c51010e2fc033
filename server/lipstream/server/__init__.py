"""The HTTP/WebSocket server (see ``docs/reference/server.md``).

Sketch: ``app.create_app`` builds the FastAPI app; ``runner.serve`` runs it
under uvicorn. Streaming is split into a sans-I/O core, ``session`` (the
per-connection state machine) and ``request`` (one request's frames and
endings), and its only asynchronous shell, ``websocket``. Around them:
``catalog`` (resident models, ``calibration`` and ``budget`` for latency
ladders, the output profiles of ``lipstream.output``), ``request_state`` (what a
session keeps per request), ``outgoing`` (send-side timing), ``admission`` (tokens, Origin, rate),
``lifecycle`` (session cap, drain on SIGTERM), ``load`` and ``overload``
(the load monitor and the admission that follows it), ``handshake`` (the
request-head deadline, the connection cap, ``/healthz`` before the app),
``open_files`` (the open-file limit), ``log_throttle`` (repeated log lines),
``rest``, ``openapi``, ``metrics`` and ``state``.
"""
