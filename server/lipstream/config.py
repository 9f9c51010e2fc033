"""Settings from the environment (``LIPSTREAM_*``), read in this one place.

Sketch: every setting is declared once in ``ENV_SETTINGS`` (variable, field,
parser, description); ``load_settings`` reads them from an environment
mapping, so the server, the CLI and the tests see one table, and
``docs/reference/server.md`` documents the same table. A value that does not parse or
is out of range is a ``LipstreamError`` (code ``invalid_setting``) naming the
variable. CLI flags override these.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from .errors import LipstreamError, UnknownEngineError

ENV_PREFIX = "LIPSTREAM_"
DEMO_DIR = "demo"
DEMO_MODELS_DIR = "models"
KERNEL_CACHE_DIR = "numba-cache"
RESULTS_DIR = "bench"
NUMBA_CACHE_VARIABLE = "NUMBA_CACHE_DIR"
LOG_LEVELS: tuple[str, ...] = ("critical", "error", "warning", "info", "debug", "trace")
"""uvicorn's log levels (``LIPSTREAM_LOG_LEVEL``, ``lipstream serve --log-level``)."""


def _home(environ: Mapping[str, str]) -> Path:
    explicit = environ.get("LIPSTREAM_HOME")
    if explicit:
        return Path(explicit)
    cache = environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache) / "lipstream"


@dataclass(frozen=True)
class ServerSettings:
    """Limits and policies of one server process (a worker); see ``docs/reference/server.md``.

    Times are in seconds unless the name ends in ``_ms``; sizes in bytes.
    """

    workers: int = 1
    log_level: str = "info"
    max_sessions: int = 500
    max_connections: int = 4096
    max_client_connections: int = 256
    client_upgrade_rate: float = 20.0
    client_upgrade_burst: int = 100
    handshake_timeout_s: float = 10.0
    max_memory_mb: int = 0
    max_input_mb: float = 0.0
    max_loop_lag_ms: float = 50.0
    max_loop_busy: float = 0.9
    max_session_rate: float = 150.0
    max_requests_per_session: int = 64
    max_message_bytes: int = 1 << 20
    max_body_bytes: int = 16 << 20
    max_phonemes_per_request: int = 10_000
    max_request_frames: int = 100_000
    max_request_s: float = 1000.0
    max_request_values: int = 4_000_000
    max_session_values: int = 16_000_000
    request_timeout_s: float = 60.0
    message_rate: float = 500.0
    message_burst: int = 1000
    idle_timeout_s: float = 60.0
    send_timeout_s: float = 10.0
    auth_tokens: tuple[str, ...] = ()
    allowed_origins: tuple[str, ...] = ()
    drain_timeout_s: float = 30.0
    return_ms: float = 150.0
    max_phoneme_ms: float = 200.0
    compute_margin_ms: float = 5.0
    calibration_cpu_s: float = 60.0
    max_model_session_cost: float = 0.25
    inline_work_ms: float = 2.0
    request_cpu_s: float = 10.0
    synth_threads: int = 2
    heavy_work_ms: float = 50.0
    heavy_threads: int = 1
    speech_threads: int = 1
    profiles: Path | None = None
    ping_interval_s: float = 20.0
    ping_timeout_s: float = 20.0
    strict_models: bool = False
    health_port: int = 0
    liveness_stall_s: float = 30.0
    recordings_enabled: bool = True
    recordings_dir: Path | None = None
    max_take_bytes: int = 64 << 20
    max_takes: int = 40
    max_recording_jobs: int = 1
    recording_min_takes: int = 0

    def with_changes(self, **changes: Any) -> ServerSettings:
        """A copy with some fields replaced (tests and the CLI use it)."""
        return replace(self, **changes)


@dataclass(frozen=True)
class Settings:
    """Server and CLI defaults. CLI flags override these."""

    home: Path
    models: Path
    host: str
    port: int
    server: ServerSettings = field(default_factory=ServerSettings)

    @property
    def demo_dir(self) -> Path:
        return self.home / DEMO_DIR

    @property
    def demo_models_dir(self) -> Path:
        return self.demo_dir / DEMO_MODELS_DIR

    def results_file(self, given: str | None, name: str) -> Path:
        """Where a measuring command writes its results: ``given`` (``--results``) when
        there is one, else ``$LIPSTREAM_HOME/bench/<name>``, never the current directory
        unasked (a checkout's committed ``bench/*.json`` are measurements)."""
        return Path(given) if given else self.home / RESULTS_DIR / name


Parser = Callable[[str, str], Any]


def _integer(low: int, high: int) -> Parser:
    def parse(name: str, text: str) -> int:
        try:
            value = int(text.strip())
        except ValueError:
            raise _invalid(name, text, "an integer") from None
        if not low <= value <= high:
            raise _invalid(name, text, f"an integer in [{low}, {high}]")
        return value

    return parse


def _number(low: float, high: float, *, above: bool = False) -> Parser:
    def parse(name: str, text: str) -> float:
        try:
            value = float(text.strip())
        except ValueError:
            raise _invalid(name, text, "a number") from None
        inside = (low < value if above else low <= value) and value <= high
        if not inside:
            opening = "(" if above else "["
            raise _invalid(name, text, f"a number in {opening}{low:g}, {high:g}]")
        return value

    return parse


def _words(name: str, text: str) -> tuple[str, ...]:
    return tuple(word.strip() for word in text.split(",") if word.strip())


def _log_level(name: str, text: str) -> str:
    level = text.strip().lower()
    if level not in LOG_LEVELS:
        raise _invalid(name, text, f"one of {', '.join(LOG_LEVELS)}")
    return level


def _flag(name: str, text: str) -> bool:
    word = text.strip().lower()
    if word not in ("1", "true", "yes", "on", "0", "false", "no", "off"):
        raise _invalid(name, text, "one of 1, true, yes, on, 0, false, no, off")
    return word in ("1", "true", "yes", "on")


def _path(name: str, text: str) -> Path | None:
    return Path(text.strip()) if text.strip() else None


def _invalid(name: str, text: str, expected: str) -> LipstreamError:
    return LipstreamError(f"must be {expected}, got {text!r}", where=name, code="invalid_setting")


@dataclass(frozen=True)
class EnvSetting:
    """One ``ServerSettings`` field read from ``variable``."""

    variable: str
    field: str
    parse: Parser
    description: str


ENV_SETTINGS: tuple[EnvSetting, ...] = (
    EnvSetting(
        "LIPSTREAM_WORKERS", "workers", _integer(1, 256), "uvicorn worker processes (`--workers`)"
    ),
    EnvSetting("LIPSTREAM_LOG_LEVEL", "log_level", _log_level, "uvicorn log level"),
    EnvSetting(
        "LIPSTREAM_MAX_SESSIONS",
        "max_sessions",
        _integer(1, 1_000_000),
        "concurrent WebSocket sessions per worker, a hard ceiling above load-based "
        "admission; beyond: `server_busy`, close 1013",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_CONNECTIONS",
        "max_connections",
        _integer(1, 10_000_000),
        "open TCP connections per worker (HTTP, WebSocket, and those still sending their "
        "request head), at most the open-file limit less a reserve; beyond: HTTP 503 with "
        "`Retry-After`, only `/healthz` answered",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_CLIENT_CONNECTIONS",
        "max_client_connections",
        _integer(0, 10_000_000),
        "open TCP connections per worker from one client address; beyond: HTTP 503 "
        "`too_many_client_connections` with `Retry-After`, only `/healthz` answered; 0 = no "
        "cap (behind a reverse proxy, where every client has the proxy's address)",
    ),
    EnvSetting(
        "LIPSTREAM_CLIENT_UPGRADE_RATE",
        "client_upgrade_rate",
        _number(0.0, 1e9),
        "sustained WebSocket upgrades per second per worker from one client address; beyond: "
        "HTTP 503 `too_many_client_connections`; 0 = no limit",
    ),
    EnvSetting(
        "LIPSTREAM_CLIENT_UPGRADE_BURST",
        "client_upgrade_burst",
        _integer(1, 1_000_000_000),
        "WebSocket upgrades one client address may make at once above the rate",
    ),
    EnvSetting(
        "LIPSTREAM_HANDSHAKE_TIMEOUT_S",
        "handshake_timeout_s",
        _number(0.0, 3600.0, above=True),
        "seconds a connection has to send a complete request head (or WebSocket upgrade) "
        "after it opens or after its previous response; then it is closed",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_MEMORY_MB",
        "max_memory_mb",
        _integer(0, 1 << 30),
        "resident memory (MiB) per worker above which new sessions, `start`s and "
        "`POST /v1/synthesize` are refused with `server_busy`; 0 = 80 % of the machine's "
        "(or container's) memory divided by the workers",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_INPUT_MB",
        "max_input_mb",
        _number(0.0, float(1 << 30)),
        "audio input (MiB) all requests of a worker may hold at once (speech features and a "
        "window of samples each); a request whose next chunk would pass it ends with "
        "`input_too_large`; 0 = a quarter of the memory ceiling",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_LOOP_LAG_MS",
        "max_loop_lag_ms",
        _number(0.0, 60_000.0, above=True),
        "event-loop lag above which new sessions are refused with `server_busy` (once 16 "
        "sessions are open)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_LOOP_BUSY",
        "max_loop_busy",
        _number(0.0, 1.0, above=True),
        "fraction of one core the event loop may be busy, counting the sessions admitted in "
        "the last second at their estimated cost, before new sessions are refused",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_SESSION_RATE",
        "max_session_rate",
        _number(0.0, 1e6),
        "new sessions (WebSocket upgrades) admitted per second per worker, over every 100 ms "
        "(a WebSocket's handshake and close cost the loop more than a millisecond of CPU, so a "
        "storm admitted faster stalls every session for its handshakes: "
        "reports/hostile-clients.md); beyond: `server_busy` (`admission_rate`); 0 = no limit",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_REQUESTS_PER_SESSION",
        "max_requests_per_session",
        _integer(1, 100_000),
        "active requests per connection (`too_many_requests`)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_MESSAGE_BYTES",
        "max_message_bytes",
        _integer(1024, 1 << 30),
        "largest client message (`message_too_large`, close 1009)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_BODY_BYTES",
        "max_body_bytes",
        _integer(1024, 1 << 31),
        "largest `POST /v1/synthesize` body (HTTP 413)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_PHONEMES",
        "max_phonemes_per_request",
        _integer(1, 10_000_000),
        "phonemes per request (`too_many_phonemes`)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_REQUEST_FRAMES",
        "max_request_frames",
        _integer(1, 100_000_000),
        "frames per request, i.e. utterance length × fps (`invalid_times`)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_REQUEST_S",
        "max_request_s",
        _number(0.0, 86_400.0, above=True),
        "utterance length per request in seconds, whatever the fps (`invalid_times`, "
        "`invalid_audio`)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_REQUEST_VALUES",
        "max_request_values",
        _integer(1, 1_000_000_000),
        "output values per request, frames up to the end of its phonemes × channels "
        "(`output_too_large`)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_SESSION_VALUES",
        "max_session_values",
        _integer(1, 1_000_000_000),
        "output values of all active requests of a connection together (`output_too_large`)",
    ),
    EnvSetting(
        "LIPSTREAM_REQUEST_TIMEOUT_S",
        "request_timeout_s",
        _number(0.0, 1e9, above=True),
        "seconds an active request may go without a message before `request_timeout`",
    ),
    EnvSetting(
        "LIPSTREAM_MESSAGE_RATE",
        "message_rate",
        _number(0.0, 1e9, above=True),
        "sustained client messages per second per connection (`rate_limited`)",
    ),
    EnvSetting(
        "LIPSTREAM_MESSAGE_BURST",
        "message_burst",
        _integer(1, 1_000_000_000),
        "messages a connection may send at once above the rate",
    ),
    EnvSetting(
        "LIPSTREAM_IDLE_TIMEOUT_S",
        "idle_timeout_s",
        _number(0.0, 1e9, above=True),
        "seconds without a message or active request before `idle_timeout`, close 1000",
    ),
    EnvSetting(
        "LIPSTREAM_SEND_TIMEOUT_S",
        "send_timeout_s",
        _number(0.0, 3600.0, above=True),
        "deadline of every WebSocket send; missing it closes the `slow_consumer` (1008); "
        "a connection whose unsent bytes do not shrink for this long while the app is "
        "not writing (a closed WebSocket, an HTTP response the client stopped reading) "
        "is reset",
    ),
    EnvSetting(
        "LIPSTREAM_AUTH_TOKENS",
        "auth_tokens",
        _words,
        "comma-separated bearer tokens; empty = no authentication",
    ),
    EnvSetting(
        "LIPSTREAM_ALLOWED_ORIGINS",
        "allowed_origins",
        _words,
        "comma-separated WebSocket `Origin` allow-list; empty = any origin",
    ),
    EnvSetting(
        "LIPSTREAM_DRAIN_TIMEOUT_S",
        "drain_timeout_s",
        _number(0.0, 86400.0),
        "longest wait for in-flight requests on SIGTERM before closing with 1001",
    ),
    EnvSetting(
        "LIPSTREAM_RETURN_MS",
        "return_ms",
        _number(0.0, 10_000.0),
        "time for the face to return to rest after `end` and (by default) `interrupt`",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_PHONEME_MS",
        "max_phoneme_ms",
        _number(0.0, 10_000.0, above=True),
        "longest phoneme assumed when estimating a rung's worst-case latency",
    ),
    EnvSetting(
        "LIPSTREAM_COMPUTE_MARGIN_MS",
        "compute_margin_ms",
        _number(0.0, 60_000.0),
        "added to each rung's measured compute time in latency estimates",
    ),
    EnvSetting(
        "LIPSTREAM_CALIBRATION_CPU_S",
        "calibration_cpu_s",
        _number(0.0, 86_400.0, above=True),
        "CPU seconds one model's start-up probes, warm-up and calibration may take; a model that "
        "needs more is not served (`model_too_costly`, in `/readyz` and the log)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_MODEL_SESSION_COST",
        "max_model_session_cost",
        _number(0.0, 100.0, above=True),
        "largest fraction of one core a session of real-time speech may need on any of a "
        "model's rungs, as calibrated; a costlier model is not served (`model_too_costly`)",
    ),
    EnvSetting(
        "LIPSTREAM_INLINE_WORK_MS",
        "inline_work_ms",
        _number(0.0, 60_000.0),
        "estimated engine work above which a message is synthesized in the thread pool",
    ),
    EnvSetting(
        "LIPSTREAM_REQUEST_CPU_S",
        "request_cpu_s",
        _number(0.0, 86400.0, above=True),
        "CPU seconds of engine work one request may use; beyond: `cpu_budget_exceeded`",
    ),
    EnvSetting(
        "LIPSTREAM_SYNTH_THREADS",
        "synth_threads",
        _integer(1, 256),
        "threads of the synthesis pool (messages above `LIPSTREAM_INLINE_WORK_MS`)",
    ),
    EnvSetting(
        "LIPSTREAM_HEAVY_WORK_MS",
        "heavy_work_ms",
        _number(0.0, 86_400_000.0),
        "estimated engine work above which a message runs in the heavy lane, apart from "
        "the synthesis pool",
    ),
    EnvSetting(
        "LIPSTREAM_HEAVY_THREADS",
        "heavy_threads",
        _integer(1, 256),
        "threads of the heavy lane (costly engine messages, large JSON answers), which takes "
        "turns between connections",
    ),
    EnvSetting(
        "LIPSTREAM_SPEECH_THREADS",
        "speech_threads",
        _integer(1, 256),
        "threads of the speech lane (`text` messages, `POST /v1/synthesize`, the phoneme-map "
        "routes), apart from the heavy lane; it takes turns between connections and REST "
        "clients",
    ),
    EnvSetting(
        "LIPSTREAM_PROFILES", "profiles", _path, "JSON file of preset output profiles per character"
    ),
    EnvSetting(
        "LIPSTREAM_PING_INTERVAL_S",
        "ping_interval_s",
        _number(0.0, 3600.0, above=True),
        "WebSocket keep-alive ping interval",
    ),
    EnvSetting(
        "LIPSTREAM_PING_TIMEOUT_S",
        "ping_timeout_s",
        _number(0.0, 3600.0, above=True),
        "close a connection whose pong is this late",
    ),
    EnvSetting(
        "LIPSTREAM_STRICT_MODELS",
        "strict_models",
        _flag,
        "refuse to start when any model fails to load (`--strict-models`); otherwise the "
        "others are served and the failure is reported",
    ),
    EnvSetting(
        "LIPSTREAM_HEALTH_PORT",
        "health_port",
        _integer(0, 65535),
        "a second port answering only `GET /healthz`, from a thread, for liveness probes (0: none)",
    ),
    EnvSetting(
        "LIPSTREAM_LIVENESS_STALL_S",
        "liveness_stall_s",
        _number(0.0, 86400.0, above=True),
        "the health port answers 503 once the event loop has not run its load monitor for "
        "this long",
    ),
    EnvSetting(
        "LIPSTREAM_RECORDINGS_ENABLED",
        "recordings_enabled",
        _flag,
        "serve the `/v1/recordings` routes (record a face, train a character, serve it); "
        "off: they answer 404 `recordings_disabled`",
    ),
    EnvSetting(
        "LIPSTREAM_RECORDINGS_DIR",
        "recordings_dir",
        _path,
        "where recording sessions, their takes and jobs, and the characters trained from "
        "them are kept (shared by every worker); default `$LIPSTREAM_HOME/recordings`",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_TAKE_BYTES",
        "max_take_bytes",
        _integer(1024, 1 << 34),
        "largest upload of one recording (`take_too_large`, HTTP 413)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_TAKES",
        "max_takes",
        _integer(1, 1000),
        "recordings (prompt sentences) per recording session (`too_many_takes`)",
    ),
    EnvSetting(
        "LIPSTREAM_MAX_RECORDING_JOBS",
        "max_recording_jobs",
        _integer(1, 256),
        "training jobs running at once over all workers (`server_busy`, HTTP 503)",
    ),
    EnvSetting(
        "LIPSTREAM_RECORDING_MIN_TAKES",
        "recording_min_takes",
        _integer(0, 1000),
        "good recordings a training job needs; 0 = the recipe's "
        "(`lipstream.recording.recipe.MIN_GOOD_TAKES`)",
    ),
)


def load_server_settings(environ: Mapping[str, str] | None = None) -> ServerSettings:
    """``ServerSettings`` from ``environ`` (default ``os.environ``); unset or empty variables
    keep their defaults."""
    environ = os.environ if environ is None else environ
    values: dict[str, Any] = {}
    for setting in ENV_SETTINGS:
        text = environ.get(setting.variable)
        if text is not None and text.strip():
            values[setting.field] = setting.parse(setting.variable, text)
    return ServerSettings(**values)


def load_settings(environ: Mapping[str, str] | None = None) -> Settings:
    environ = os.environ if environ is None else environ
    home = _home(environ)
    models = Path(environ.get("LIPSTREAM_MODELS") or home / DEMO_DIR / DEMO_MODELS_DIR)
    return Settings(
        home=home,
        models=models,
        host=environ.get("LIPSTREAM_HOST", "127.0.0.1"),
        port=_integer(0, 65535)("LIPSTREAM_PORT", environ.get("LIPSTREAM_PORT", "8000")),
        server=load_server_settings(environ),
    )


def demo_model_path(engine: str = "viseme-lerp", settings: Settings | None = None) -> Path:
    """Where the demo character's ``engine`` model is, or will be once built:
    ``$LIPSTREAM_HOME/demo/models/<engine>`` (``~/.cache/lipstream`` without the variable).
    An engine that is not registered is an ``UnknownEngineError``."""
    from .engines import engine_names

    if engine not in engine_names():
        raise UnknownEngineError(
            f"unknown engine {engine!r}; available: {', '.join(engine_names())}", where="engine"
        )
    return (settings or load_settings()).demo_models_dir / engine


RECORDINGS_DIR = "recordings"


def recordings_root(settings: ServerSettings, environ: Mapping[str, str] | None = None) -> Path:
    """Where recording sessions and the characters trained from them live:
    ``LIPSTREAM_RECORDINGS_DIR``, else ``$LIPSTREAM_HOME/recordings``."""
    if settings.recordings_dir is not None:
        return settings.recordings_dir
    return _home(os.environ if environ is None else environ) / RECORDINGS_DIR


def kernel_cache_dir(environ: Mapping[str, str] | None = None) -> Path:
    """Where numba caches lipstream's compiled kernels: ``$NUMBA_CACHE_DIR`` when set, else
    ``$LIPSTREAM_HOME/numba-cache/lipstream-<version>-py<X.Y>-numba<version>``, one folder
    per combination, so an upgrade starts a fresh one and the old can be deleted whole."""
    import sys
    from importlib.metadata import PackageNotFoundError, version

    from ._version import __version__

    environ = os.environ if environ is None else environ
    explicit = environ.get(NUMBA_CACHE_VARIABLE, "").strip()
    if explicit:
        return Path(explicit)
    try:
        numba_version = version("numba")
    except PackageNotFoundError:
        numba_version = "unknown"
    python = f"{sys.version_info.major}.{sys.version_info.minor}"
    folder = f"lipstream-{__version__}-py{python}-numba{numba_version}"
    return _home(environ) / KERNEL_CACHE_DIR / folder


def server_setting_fields() -> tuple[str, ...]:
    """Every ``ServerSettings`` field (each has one ``ENV_SETTINGS`` row)."""
    return tuple(item.name for item in fields(ServerSettings))
