"""What one server process holds for its whole life, shared by every route."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from ..config import ServerSettings
from ..models import ModelRegistry
from .catalog import Catalog
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
    so those never queue behind a costly search) and the load-based admission."""

    registry: ModelRegistry
    catalog: Catalog
    settings: ServerSettings
    metrics: Metrics
    lifecycle: Lifecycle
    executor: ThreadPoolExecutor
    heavy: FairLane
    speech: FairLane
    overload: Overload
    loaded: bool = True

    @property
    def ready(self) -> bool:
        """Models are loaded and the process is not draining."""
        return self.loaded and not self.lifecycle.draining

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
