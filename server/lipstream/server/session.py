"""The per-connection protocol state machine, without I/O.

Sketch (in the manner of h11's and websockets' sans-I/O cores): ``handle``
takes one decoded client message, or the ``ProtocolError`` the codec
returned instead, with the monotonic time it arrived, and returns the
``Outgoing`` messages to send, in order. Requests are multiplexed by id;
each active one is a ``RequestState``: its ``ActiveRequest`` with the cost, work
guard, resume cursor, word stream and held input the session keeps for it, so ending
a request forgets it with one ``pop``. A ``words`` message (a TTS's timings) goes
through the front ends (``frontends``): each request keeps a ``WordStream`` that holds a
word cut at a chunk's edge, and the spans of the words completed are fed like phonemes.
``start`` is validated against the ``Catalog`` (engine, character, phoneme notation,
emotion, output profile, latency budget, engine options) and answered with ``ready``,
unless the
injected ``refuse_start`` refuses new work (the server's memory ceiling,
``overload``); every later message goes to its request, and any
``LipstreamError`` it raises ends that request with a fatal ``error`` of the
matching protocol code. Messages for
ids with no active request are answered by what last happened to the id:
input after ``end`` gets ``request_finished``, input after ``interrupt`` is
ignored, anything else gets ``unknown_request``. No exception leaves
``handle``: an unexpected fault becomes ``internal_error`` for the request
(or, with no request to blame, for the connection). A request's output
may not outgrow its limit, nor the connection's active requests together
theirs (``output_too_large``). ``expire`` ends the requests that have had no
message for ``request_timeout_s`` (``request_timeout``); the connection
layer calls it once ``next_expiry`` has passed. Sockets, timers, threads,
rate limits and closing belong to the connection layer.

Engine work: each request has a ``WorkGuard`` that meters its engine calls
against the CPU budget (``cpu_budget_exceeded`` ends the request) and that
``stop_work`` (the client's ``cancel``, read while the work runs) or
``stop_all_work`` (the connection closed) cancels: the engine stops at its
next step, and the stopped request's messages answer nothing until its
``cancel``. ``estimated_work_ms`` prices a message with the engine's own
``CallCost`` for the request's options, so the connection knows which
messages to keep off its event loop.
"""

from __future__ import annotations

import logging
import math
import time
from bisect import bisect_right
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from itertools import takewhile
from typing import Any, TypeAlias

from lipstream_client import (
    AudioChunk,
    Cancel,
    End,
    ErrorMessage,
    Interrupt,
    Message,
    Phonemes,
    ProtocolError,
    Ready,
    Start,
    Text,
    Words,
)
from lipstream_client.errors import (
    DUPLICATE_REQUEST,
    INTERNAL_ERROR,
    INVALID_AUDIO,
    INVALID_REQUEST,
    REQUEST_FINISHED,
    REQUEST_TIMEOUT,
    SHUTTING_DOWN,
    TOO_MANY_REQUESTS,
    UNKNOWN_EMOTION,
    UNKNOWN_PHONEME_SOURCE,
    UNKNOWN_REQUEST,
    UNKNOWN_TYPE,
)
from lipstream_client.float32 import FLOAT32_BYTES
from lipstream_client.messages import DoneReason, JsonValue

from ..engines.base import Model, Rung, SynthesisRequest, frame_count
from ..engines.work import WorkGuard
from ..errors import LipstreamError
from ..frontends.formats import parse_timings
from ..frontends.timings import SpeechTimings
from ..frontends.word_stream import WordStream
from ..frontends.words_to_spans import timings_to_spans
from ..output.profiles import requested_profile, resolve_profile
from ..phonemes import SOURCES
from ..timeline import EMOTIONS
from .budget import (
    CUSTOM_FIDELITY,
    BudgetInfeasible,
    RungEstimate,
    choose_rung,
    lookahead_ms,
)
from .calibration import PHONEME_S
from .catalog import Catalog
from .held_input import UNLIMITED_INPUT, InputLedger
from .outgoing import Outgoing, RequestClock
from .overload import Refusal
from .request import (
    ActiveRequest,
    RequestError,
    RequestLimits,
    RequestSpec,
    most_blocks,
    protocol_code,
    settle_frames,
)
from .request_state import RequestState
from .resume import ResumeCursor, check_seq_room, pinned_rung
from .text_input import (
    engine_audio,
    speak,
    speech_messages,
    speech_spans,
    speech_start,
)

logger = logging.getLogger("lipstream.server")

DEFAULT_PHONEME_SOURCE = "auto"
_LONGEST_WAIT_MS = 86_400_000.0  # the protocol's bound on ready.lookahead_ms: a day
REMEMBERED_IDS = 256
_MAX_TEXT = 4096
_CLIPPED = "..."

InputMessage: TypeAlias = Message | ProtocolError
RequestInput: TypeAlias = Phonemes | AudioChunk | Text | Words | End | Cancel | Interrupt


@dataclass(frozen=True)
class SessionLimits:
    """How many requests a connection may hold at once, each request's limits, its engine
    work's CPU seconds (``cpu_budget_s``), the output values its active requests may commit
    to in all, and how long a request may go without a message (None: no limit)."""

    max_requests: int
    request: RequestLimits
    remembered_ids: int = REMEMBERED_IDS
    cpu_budget_s: float | None = None
    max_values: int | None = None
    request_timeout_s: float | None = None


class Session:
    """The requests of one connection and the rules that govern them."""

    def __init__(
        self,
        catalog: Catalog,
        limits: SessionLimits,
        refuse_start: Callable[[str], Refusal | None] = lambda engine: None,
        input_ledger: InputLedger | None = None,
        timer: Callable[[], float] = time.perf_counter,
    ) -> None:
        """``refuse_start`` says whether the server takes on a new request of an engine now
        (its memory ceiling and load: ``overload``); a refusal ends the ``start`` with its
        code and details.
        ``input_ledger`` counts the audio input the process's requests hold (``held_input``;
        by default this session's own, without a limit). ``timer`` (s) times speech
        synthesis, which a text request's lag does not count."""
        self.catalog = catalog
        self.timer = timer
        self.limits = limits
        self.refuse_start = refuse_start
        self.input_ledger = input_ledger or InputLedger(UNLIMITED_INPUT)
        self.requests: dict[str, RequestState] = {}
        self.ended: OrderedDict[str, DoneReason] = OrderedDict()
        self.draining = False
        self.stopped_work = 0
        self.output_values = 0

    @property
    def active_requests(self) -> int:
        return len(self.requests)

    def begin_drain(self) -> None:
        """Refuse new ``start``s from now on; requests in flight continue."""
        self.draining = True

    def close(self) -> int:
        """Stop and drop every active request (the connection is gone); how many were
        dropped."""
        self.stop_all_work()
        dropped = len(self.requests)
        for state in self.requests.values():
            state.release()
        self.requests.clear()
        self.output_values = 0
        return dropped

    def estimated_work_ms(self, received: InputMessage) -> float:
        """How long ``handle(received)`` may keep the engine busy, in milliseconds: the engine's
        call cost for the request's options (``Model.call_cost``) for the phonemes the message
        decides and the frames it may release (``math.inf`` when the engine knows no bound)."""
        if type(received) is Phonemes:  # the common message, first
            state = self.requests.get(received.id)
            if state is None:
                return 0.0
            items = received.items
            until = state.active.phonemes_end
            if items and items[-1].end > until:
                until = items[-1].end
            return self._cost(state, len(items), until, 0)
        if not isinstance(received, (Phonemes, AudioChunk, Text, Words, End, Interrupt)):
            return 0.0
        state = self.requests.get(received.id)
        if state is None:
            return 0.0
        request = state.active
        if isinstance(received, (Text, Words)):
            return math.inf  # espeak-ng in a worker process (words CMUdict lacks): heavy lane
        fps = request.spec.fps
        until = request.phonemes_end
        extra_frames = 0
        if isinstance(received, Phonemes):
            phonemes = len(received.items)
            if phonemes and received.items[-1].end > until:
                until = received.items[-1].end
        elif isinstance(received, AudioChunk):
            phonemes = math.ceil(received.duration / PHONEME_S)
        else:
            phonemes = len(request.ends) - bisect_right(request.ends, request.next_frame / fps)
            default_ms = self.limits.request.default_return_ms
            if isinstance(received, Interrupt):  # the return to rest, from the cut frame on
                return_ms = default_ms if received.return_ms is None else received.return_ms
                extra_frames = settle_frames(return_ms, fps) + 1
            else:  # the return to rest after the last frame
                extra_frames = max(1, settle_frames(default_ms, fps))
        return self._cost(state, phonemes, until, extra_frames)

    def _cost(self, state: RequestState, phonemes: int, until: float, extra_frames: int) -> float:
        """The call cost of deciding ``phonemes`` and releasing the frames up to ``until``
        (s) and ``extra_frames`` more."""
        request = state.active
        released = min(frame_count(until, request.spec.fps), self.limits.request.max_frames)
        frames = max(0, released - request.next_frame) + extra_frames
        return state.cost.ms(phonemes, frames)

    def check_queued(self, identifier: str, phonemes: int) -> None:
        """Active request ``identifier`` has ``phonemes`` more phonemes received and waiting
        (read ahead while its work runs): if its engine cannot take that many more
        (``Synthesizer.check_more_phonemes``: PQ-Matching's ``search_too_large``), stop its
        work now; its next message handled ends it with that error. (The count is a lower
        bound, since the message being handled is no longer waiting and the engine may not
        have taken it yet, so no request is refused that would have been taken.)"""
        state = self.requests.get(identifier)
        if state is None or state.too_large is not None:
            return
        try:
            state.active.synthesizer.check_more_phonemes(phonemes)
        except LipstreamError as error:
            state.too_large = error
            state.guard.cancel()

    def stop_work(self, identifier: str) -> None:
        """Stop the work of active request ``identifier`` at its next step (the client sent
        ``cancel`` for it); its messages then answer nothing until that ``cancel``."""
        state = self.requests.get(identifier)
        if state is not None:
            state.guard.cancel()

    def stop_all_work(self) -> None:
        """Stop the work of every active request at its next step (the connection is over)."""
        for state in list(self.requests.values()):
            state.guard.cancel()

    def next_expiry(self) -> float | None:
        """The monotonic time at which the longest-silent active request times out; None
        without a request timeout or an active request. (``requests`` is kept in the order
        of their last message, so that request is the first.)"""
        timeout = self.limits.request_timeout_s
        if timeout is None or not self.requests:
            return None
        return next(iter(self.requests.values())).active.last_input + timeout

    def expire(self, now: float) -> list[Outgoing]:
        """End every request that has had no message for the request timeout by ``now``:
        the fatal ``request_timeout`` errors to send."""
        timeout = self.limits.request_timeout_s
        if timeout is None or not self.requests:
            return []
        if now - next(iter(self.requests.values())).active.last_input < timeout:
            return []  # the longest-silent request is within its timeout: every message but few
        expired = list(
            takewhile(
                lambda r: now - r.last_input >= timeout,
                (state.active for state in self.requests.values()),
            )
        )
        for request in expired:
            self._forget(request.id)
        return [
            _error(
                REQUEST_TIMEOUT,
                f"no message for request {request.id!r} in {timeout:g} s; it has ended",
                request.id,
                fatal=True,
                details={"request_timeout_s": timeout},
                clock=request.spec.clock,
            )
            for request in expired
        ]

    def handle(
        self, received: InputMessage, now: float, meter_clock: Callable[[], float] | None = None
    ) -> list[Outgoing]:
        """The messages that answer ``received``, which arrived at monotonic time ``now``;
        the engine's time is counted against the request's CPU budget on ``meter_clock``
        (by default the calling thread's CPU time)."""
        try:
            if type(received) is Phonemes:  # the common message: straight to its request
                state = self.requests.get(received.id)
                if state is not None:
                    return self._to_request(state, received, now, meter_clock)
            if isinstance(received, ProtocolError):
                return self._rejected(received)
            return self._dispatch(received, now, meter_clock)
        except Exception:
            identifier = getattr(received, "id", None)
            logger.exception(
                "unexpected fault handling %s for request %r", type(received).__name__, identifier
            )
            state = self.requests.get(identifier) if isinstance(identifier, str) else None
            request = state.active if state is not None else None
            if request is not None:
                self._forget(request.id)
            return [
                _error(
                    INTERNAL_ERROR,
                    "an unexpected server fault ended this request"
                    if identifier
                    else "an unexpected server fault",
                    identifier if isinstance(identifier, str) else None,
                    fatal=True,
                    clock=request.spec.clock if request is not None else None,
                )
            ]

    # ---- dispatch -------------------------------------------------------------------------

    def _rejected(self, error: ProtocolError) -> list[Outgoing]:
        state = self.requests.get(error.id) if error.id is not None and error.fatal else None
        if state is None:
            return [Outgoing(error.to_message())]
        self._forget(state.active.id)
        return [Outgoing(error.to_message(), state.active.spec.clock)]

    def _dispatch(
        self, received: Message, now: float, meter_clock: Callable[[], float] | None
    ) -> list[Outgoing]:
        if isinstance(received, Start):
            return self._start(received, now)
        if not isinstance(received, (Phonemes, AudioChunk, Text, Words, End, Cancel, Interrupt)):
            return [_error(UNKNOWN_TYPE, f"a client may not send {received.type!r}", None)]
        state = self.requests.get(received.id)
        if state is None:
            return self._orphan(received)
        return self._to_request(state, received, now, meter_clock)

    def _to_request(
        self,
        state: RequestState,
        received: RequestInput,
        now: float,
        meter_clock: Callable[[], float] | None,
    ) -> list[Outgoing]:
        """``received`` handled by its active request ``state``."""
        request = state.active
        request.last_input = now
        requests = self.requests
        if len(requests) > 1:  # kept in the order of their last message (``next_expiry``)
            requests[request.id] = requests.pop(request.id)
        if state.too_large is not None and not isinstance(received, Cancel):
            return self._end_with(request, state.too_large)
        try:
            outgoing = self._metered(state, received, now, meter_clock)
            if state.resume is not None:
                outgoing = state.resume.filter(outgoing)
        except LipstreamError as error:
            if state.too_large is not None and not isinstance(received, Cancel):
                return self._end_with(request, state.too_large)
            if state.guard.cancelled and not isinstance(received, Cancel):
                # Stopped by the client's cancel, which follows in order and ends it, or by
                # the end of the connection.
                self.stopped_work += 1
                return []
            return self._end_with(request, error)
        if isinstance(received, (End, Cancel, Interrupt)):
            self._forget(request.id)
            self._remember(request.id, _REASONS[type(received)])
        else:
            self._hold(state)
        return outgoing

    def _end_with(self, request: ActiveRequest, error: LipstreamError) -> list[Outgoing]:
        """End ``request`` with ``error``, fatal."""
        self._forget(request.id)
        details = error.details if isinstance(error, RequestError) else None
        code = error.code if isinstance(error, RequestError) else None
        return [
            _error(
                code or protocol_code(error, INVALID_REQUEST),
                _located(error),
                request.id,
                fatal=True,
                details=details,
                clock=request.spec.clock,
            )
        ]

    def _hold(self, state: RequestState) -> None:
        """Count what the request holds of its input now (only an engine that reads audio
        holds any)."""
        request = state.active
        if not request.spec.uses_audio:
            return
        state.holding_in(self.input_ledger).update(request.synthesizer.held_input_bytes)

    def _admit_input(self, state: RequestState, n_samples: int, sample_rate: int) -> None:
        """``input_too_large`` unless the process may hold what the request holds while it
        takes in ``n_samples`` more at ``sample_rate`` Hz (its engine's bound, and the new
        samples as float32); that much is counted until the request reports what it holds
        after."""
        request = state.active
        if not request.spec.uses_audio:
            return
        bound = request.synthesizer.held_input_bytes_after(n_samples, sample_rate)
        state.holding_in(self.input_ledger).admit(bound + n_samples * FLOAT32_BYTES)

    def _metered(
        self,
        state: RequestState,
        received: RequestInput,
        now: float,
        meter_clock: Callable[[], float] | None,
    ) -> list[Outgoing]:
        """``_apply`` with the engine's time counted against the request's CPU budget
        (``cancel`` does no engine work, so it runs even when the work was stopped)."""
        if isinstance(received, Cancel):
            return self._apply(state, received, now)
        with state.guard.metering(meter_clock):
            if type(received) is Phonemes:
                return self._add_phonemes(state.active, received, now)
            return self._apply(state, received, now)

    def _add_phonemes(
        self, request: ActiveRequest, received: Phonemes, now: float
    ) -> list[Outgoing]:
        before = request.output_values
        try:
            return request.add_phonemes(
                received.items, now, self.limits.max_values, self.output_values - before
            )
        finally:
            self.output_values += request.output_values - before

    def _apply(self, state: RequestState, received: RequestInput, now: float) -> list[Outgoing]:
        request = state.active
        if isinstance(received, Phonemes):
            return self._add_phonemes(request, received, now)
        if isinstance(received, AudioChunk):
            _check_audio_start(request, received)
            self._admit_input(state, received.n_samples, received.sample_rate)
            return request.add_audio(received, now)
        if isinstance(received, Text):
            return self._speak(state, received, now)
        if isinstance(received, Words):
            return self._take_words(request, state.words(), received, now)
        if isinstance(received, End):
            stream = state.word_stream
            held = self._feed_timings(request, stream, stream.finish(), now) if stream else []
            return held + request.end(now)
        if isinstance(received, Cancel):
            return request.cancel()
        return request.interrupt(received.at, received.return_ms, now)

    def _speak(self, state: RequestState, received: Text, now: float) -> list[Outgoing]:
        """Speak ``received`` (``text_input``): its ``audio`` messages, then the frames of the
        speech and spans it hands the engine together. The speech was ready the synthesis
        time after ``now``: its frames' lag counts from then, and the synthesis time is
        reported apart (``done.stats.speech_synthesis_ms``)."""
        request = state.active
        began = self.timer()
        speech = speak(received)
        synthesis_s = max(0.0, self.timer() - began)
        request.spec.clock.spoke(synthesis_s)
        ready_at = now + synthesis_s
        start = speech_start(request)
        outgoing = speech_messages(request, speech, start)
        chunk = engine_audio(request, speech, start)
        self._admit_input(state, len(chunk.samples), chunk.sample_rate)
        before = request.output_values
        try:
            outgoing += request.add_speech(
                speech_spans(speech, start),
                chunk,
                ready_at,
                self.limits.max_values,
                self.output_values - before,
            )
        finally:
            self.output_values += request.output_values - before
        return outgoing

    def _take_words(
        self, request: ActiveRequest, stream: WordStream, received: Words, now: float
    ) -> list[Outgoing]:
        """A TTS's timings (``frontends``): the words they complete become spans, from the
        end of the input so far; a word that may go on in ``stream``, the request's, is
        held."""
        if received.voice is not None:
            stream.voice = received.voice
        try:
            timings = parse_timings(received.timings, received.format).shifted(received.offset)
            completed = stream.take(timings)
        except LipstreamError as error:
            raise RequestError(
                error.message, code=error.code, where=f"timings: {error.where or 'input'}"
            ) from None
        return self._feed_timings(request, stream, completed, now)

    def _feed_timings(
        self,
        request: ActiveRequest,
        stream: WordStream,
        completed: list[SpeechTimings],
        now: float,
    ) -> list[Outgoing]:
        outgoing: list[Outgoing] = []
        if not completed:
            return outgoing
        durations = self.catalog.word_durations(request.spec.engine, request.spec.character)
        for timings in completed:
            try:
                spans = timings_to_spans(
                    timings, durations, stream.voice, request.phonemes_end, require_speech=False
                )
            except LipstreamError as error:
                raise RequestError(
                    error.message, code=error.code, where=f"timings: {error.where or 'input'}"
                ) from None
            before = request.output_values
            try:
                outgoing += request.add_spans(
                    spans, now, self.limits.max_values, self.output_values - before
                )
            finally:
                self.output_values += request.output_values - before
        return outgoing

    def _orphan(self, received: RequestInput) -> list[Outgoing]:
        reason = self.ended.get(received.id)
        if reason == "interrupt":
            return []
        if reason == "end":
            return [
                _error(
                    REQUEST_FINISHED,
                    f"request {received.id!r} has already ended; this {received.type} was dropped",
                    received.id,
                )
            ]
        return [
            _error(
                UNKNOWN_REQUEST,
                f"no active request {received.id!r} on this connection; send start first",
                received.id,
            )
        ]

    def _forget(self, identifier: str) -> None:
        state = self.requests.pop(identifier, None)
        if state is not None:
            self.output_values -= state.active.output_values
            state.release()

    def _remember(self, identifier: str, reason: DoneReason) -> None:
        self.ended[identifier] = reason
        self.ended.move_to_end(identifier)
        while len(self.ended) > self.limits.remembered_ids:
            self.ended.popitem(last=False)

    # ---- start ----------------------------------------------------------------------------

    def _start(self, start: Start, now: float) -> list[Outgoing]:
        if start.id in self.requests:
            return [
                _error(
                    DUPLICATE_REQUEST,
                    f"request {start.id!r} is active; this start "
                    f"was dropped and that request continues",
                    start.id,
                )
            ]
        if self.draining:
            return [
                _error(
                    SHUTTING_DOWN,
                    "the server is shutting down and accepts no new "
                    "requests; reconnect to another instance",
                    start.id,
                    fatal=True,
                )
            ]
        refusal = self.refuse_start(start.engine)
        if refusal is not None:
            return [
                _error(refusal.code, refusal.message, start.id, fatal=True, details=refusal.details)
            ]
        if len(self.requests) >= self.limits.max_requests:
            return [
                _error(
                    TOO_MANY_REQUESTS,
                    f"this connection already has "
                    f"{len(self.requests)} active requests, the server's maximum",
                    start.id,
                    fatal=True,
                    details={"max_requests": self.limits.max_requests},
                )
            ]
        try:
            state, ready = self._open(start, now)
        except BudgetInfeasible as error:
            return [
                _error(
                    error.code,
                    _located(error),
                    start.id,
                    fatal=True,
                    details={"min_budget_ms": error.min_budget_ms},
                )
            ]
        except LipstreamError as error:
            return [
                _error(protocol_code(error, INVALID_REQUEST), _located(error), start.id, fatal=True)
            ]
        self.requests[start.id] = state
        self.ended.pop(start.id, None)
        return [Outgoing(ready, state.active.spec.clock)]

    def _open(self, start: Start, now: float) -> tuple[RequestState, Ready]:
        catalog = self.catalog
        model = catalog.model(start.engine, start.character)
        source = _phoneme_source(start.phoneme_source)
        if start.emotion is not None and start.emotion not in EMOTIONS:
            raise LipstreamError(
                f"unknown emotion {start.emotion!r}; known: {', '.join(EMOTIONS)}",
                where="emotion",
                code=UNKNOWN_EMOTION,
            )
        emotion = start.emotion or catalog.default_emotion(model)
        ladder = catalog.ladder(model)
        check_seq_room(start.resume, most_blocks(self.limits.request))
        estimate = pinned_rung(ladder, start.resume) or choose_rung(ladder, start.latency_budget_ms)
        profile = resolve_profile(
            model.channels,
            requested_profile(start, catalog.preset(start.character)),
            lambda visemes: catalog.projector(model, visemes),
            catalog.retargets(model),
        )
        options = _merged_options(
            start.options, estimate.rung.options, budgeted=start.latency_budget_ms is not None
        )
        guard = WorkGuard(self.limits.cpu_budget_s)
        synthesizer = model.start(SynthesisRequest(start.fps, emotion, options, guard))
        rest = profile.apply(catalog.rest_pose(model, emotion)[None])[0]
        clock = RequestClock(model.manifest.engine, now, start.latency_budget_ms)
        spec = RequestSpec(
            start.id,
            model.manifest.engine,
            start.fps,
            source,
            model.uses_audio,
            profile,
            rest,
            clock,
            audio_only=model.accepts_audio_only,
            character=model.name,
        )
        fidelity, lookahead = self._fidelity(model, estimate, options)
        ready = Ready(
            id=start.id,
            engine=model.manifest.engine,
            character=model.name,
            fps=start.fps,
            channels=profile.channels,
            lookahead_ms=lookahead,
            fidelity=fidelity,
            emotion=emotion,
            latency_budget_ms=start.latency_budget_ms,
            options=options,
            phoneme_source=source,
        )
        state = RequestState(
            ActiveRequest(spec, synthesizer, self.limits.request),
            catalog.call_cost(model, options),
            guard,
            ResumeCursor.of(start.resume) if start.resume is not None else None,
        )
        return state, ready

    def _fidelity(
        self, model: Model, estimate: RungEstimate, options: Mapping[str, JsonValue]
    ) -> tuple[str, float]:
        """The rung's name and lookahead (ms), or, when the client's options change one the
        rung pins or select another rung (possible without a budget: say ``causal: true``),
        ``custom`` and the lookahead of those options (a frame that may wait for the end of
        the input: the longest request)."""
        resolved = model.rung_for(options)
        if (resolved is None or resolved.name == estimate.rung.name) and all(
            options.get(key) == json_value(value) for key, value in estimate.rung.options.items()
        ):
            return estimate.rung.name, estimate.lookahead_ms
        settings = self.catalog.settings
        lookahead = model.lookahead_for(options)
        if lookahead is None:
            return CUSTOM_FIDELITY, min(
                _LONGEST_WAIT_MS, float(settings.max_phonemes_per_request * settings.max_phoneme_ms)
            )
        return CUSTOM_FIDELITY, lookahead_ms(
            Rung(CUSTOM_FIDELITY, lookahead), settings.max_phoneme_ms
        )


_REASONS: dict[type, DoneReason] = {End: "end", Cancel: "cancel", Interrupt: "interrupt"}


def _check_audio_start(request: ActiveRequest, chunk: AudioChunk) -> None:
    """A client's chunk that names its ``start`` must start where the request's audio ends."""
    if chunk.start is not None and abs(chunk.start - request.audio_s) > 0.5 / chunk.sample_rate:
        raise RequestError(
            f"starts at {chunk.start:g} s, but the request's audio so far ends at "
            f"{request.audio_s:g} s (chunks are contiguous)",
            code=INVALID_AUDIO,
            where="start",
        )


def _phoneme_source(requested: str | None) -> str:
    source = requested or DEFAULT_PHONEME_SOURCE
    if source not in SOURCES:
        raise LipstreamError(
            f"unknown phoneme notation {source!r}; expected one of {', '.join(SOURCES)}",
            where="phoneme_source",
            code=UNKNOWN_PHONEME_SOURCE,
        )
    return source


def _merged_options(
    client: Mapping[str, JsonValue], rung: Mapping[str, Any], budgeted: bool
) -> dict[str, JsonValue]:
    """Engine options: with a budget the rung's options win (they are what meets it);
    without one the client's do."""
    selected = {key: json_value(value) for key, value in rung.items()}
    return {**dict(client), **selected} if budgeted else {**selected, **dict(client)}


def json_value(value: Any) -> JsonValue:
    """``value`` as a JSON value: numpy scalars and tuples converted, others as strings."""
    if hasattr(value, "item") and callable(value.item):
        value = value.item()
    if isinstance(value, (list, tuple)):
        return [json_value(item) for item in value]
    if isinstance(value, Mapping):
        return {str(key): json_value(item) for key, item in value.items()}
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return str(value)


def _located(error: LipstreamError) -> str:
    return f"{error.where}: {error.message}" if error.where else error.message


def _error(
    code: str,
    message: str,
    identifier: str | None,
    fatal: bool = False,
    details: Mapping[str, JsonValue] | None = None,
    clock: RequestClock | None = None,
) -> Outgoing:
    """An error message; ``clock`` is the request's when the error ends an active request."""
    if len(message) > _MAX_TEXT:
        message = message[: _MAX_TEXT - len(_CLIPPED)] + _CLIPPED
    error = ErrorMessage(code, message or code, identifier, fatal)
    return Outgoing(replace(error, details=dict(details)) if details else error, clock)
