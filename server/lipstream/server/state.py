"""What one server process holds for its whole life, shared by every route."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from ..config import ServerSettings
from ..models import ModelRegistry
from .catalog import Catalog
from .client_limits import ClientLimits
from .held_input import UNLIMITED_INPUT, InputLedger
from .lanes import FairLane
from .lifecycle import Lifecycle
from .metrics import Metrics
from .overload import Overload
from .request import RequestLimits
from .session import SessionLimits


@dataclass
class ServerState:
    """Resident models and what was derived from them, settings, metrics, the connections'
    lifecycle, the thread pools (``executor`` for ordinary engine work; two fair lanes,
    ``lanes.FairLane``: ``heavy`` for costly engine messages and large JSON answers, so those
    never queue ordinary sessions behind them, and ``speech`` for speech synthesis and REST,
    so those never queue behind a costly search), the load-based admission, the per-client
    limits and the ledger of the audio input requests hold."""

    registry: ModelRegistry
    catalog: Catalog
    settings: ServerSettings
    metrics: Metrics
    lifecycle: Lifecycle
    executor: ThreadPoolExecutor
    heavy: FairLane
    speech: FairLane
    overload: Overload
    clients: ClientLimits
    loaded: bool = True
    answer_bytes: int = 0  # bytes held by REST answers still being sent (``rest``)
    drain_flag: Path | None = None  # marked by the workers' supervisor (``runner``)
    input_ledger: InputLedger = field(default_factory=lambda: InputLedger(UNLIMITED_INPUT))

    @property
    def ready(self) -> bool:
        """Models are loaded and neither this process nor its supervisor drains."""
        if not self.loaded or self.lifecycle.draining:
            return False
        return self.drain_flag is None or not self.drain_flag.exists()

    @property
    def session_limits(self) -> SessionLimits:
        settings = self.settings
        return SessionLimits(
            max_requests=settings.max_requests_per_session,
            request=RequestLimits(
                settings.max_phonemes_per_request,
                settings.max_request_frames,
                settings.return_ms,
                max_values=settings.max_request_values,
                max_seconds=settings.max_request_s,
            ),
            cpu_budget_s=settings.request_cpu_s,
            max_values=settings.max_session_values,
            request_timeout_s=settings.request_timeout_s,
        )
