"""libespeak-ng through ctypes, standard library only, and a worker that runs it.

Sketch: libespeak-ng runs in synchronous mode with phoneme events switched on.
One callback collects the PCM16 chunks, the ``espeakEVENT_PHONEME`` events
(name, ``audio_position`` in ms) and the ``espeakEVENT_WORD`` events (the word's
first character, 1-based, its length in characters, and ``audio_position``). The
phoneme names are espeak-ng's mnemonics, or, for a library made with ``ipa_names``
(``espeakINITIALIZE_PHONEME_IPA``, an option of initialization only), their IPA: the
notation every language shares. The library keeps global state and is not reentrant,
so a process holds one ``Library`` behind one lock.

This module imports nothing beyond the standard library, so that
``python -I libespeak.py`` starts in tens of milliseconds: that is the worker
(``main``) the text front end and the demo corpus run, one process per batch,
so that a crash or a hang of libespeak-ng ends that batch only. It reads a JSON
list of requests (voice, rate, pitch, pitch_range, text) on stdin and writes one
JSON line (per request: sample rate, PCM byte count, phoneme and word events; or an
error) and
then every request's PCM16 bytes, in order, on stdout.
"""

from __future__ import annotations

import ctypes
import json
import sys
import threading
from dataclasses import dataclass, field
from typing import Any

LIBRARY_NAME = "libespeak-ng.so.1"

_AUDIO_OUTPUT_SYNCHRONOUS = 2
_INITIALIZE_PHONEME_EVENTS = 0x0001
_INITIALIZE_PHONEME_IPA = 0x0002
_CHARS_UTF8 = 1
_POS_CHARACTER = 1
_EVENT_LIST_TERMINATED = 0
_EVENT_WORD = 1
_EVENT_PHONEME = 7
_PARAM_RATE = 1
_PARAM_PITCH = 3
_PARAM_RANGE = 4
_EE_OK = 0
_BUFFER_MS = 200

RawSpeech = tuple[bytes, int, list[tuple[str, int]]]
"""PCM16 little-endian mono bytes, sample rate in Hz, (espeak phoneme name, start ms) events."""
WordEvent = tuple[int, int, int]
"""One word espeak-ng spoke: (first character, 1-based, in the text; length in characters;
start ms). A token espeak-ng expands ("$42") gives several words at the same position."""


class EspeakFailure(Exception):
    """libespeak-ng is missing or refused a call; ``where`` names the setting or step."""

    def __init__(self, message: str, where: str = "espeak") -> None:
        super().__init__(message)
        self.message = message
        self.where = where


class _EventId(ctypes.Union):
    _fields_ = [("number", ctypes.c_int), ("name", ctypes.c_char_p), ("string", ctypes.c_char * 8)]


class Event(ctypes.Structure):
    """``espeak_EVENT`` from speak_lib.h (40 bytes on LP64: the pointer aligns to 8)."""

    _fields_ = [
        ("type", ctypes.c_int),
        ("unique_identifier", ctypes.c_uint),
        ("text_position", ctypes.c_int),
        ("length", ctypes.c_int),
        ("audio_position", ctypes.c_int),
        ("sample", ctypes.c_int),
        ("user_data", ctypes.c_void_p),
        ("id", _EventId),
    ]


_SynthCallback = ctypes.CFUNCTYPE(
    ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int, ctypes.POINTER(Event)
)


@dataclass
class _Capture:
    """What one ``espeak_Synth`` call delivered: PCM16 bytes and (name, ms) phoneme events."""

    pcm: list[bytes] = field(default_factory=list)
    events: list[tuple[str, int]] = field(default_factory=list)
    words: list[WordEvent] = field(default_factory=list)


class Library:
    """A libespeak-ng handle (one per process; phoneme names in IPA with ``ipa_names``);
    use it through ``speak`` (which locks)."""

    def __init__(self, ipa_names: bool = False) -> None:
        try:
            self._lib = ctypes.CDLL(LIBRARY_NAME)
        except OSError as exc:
            raise EspeakFailure(
                f"cannot load {LIBRARY_NAME} ({exc}); install the Debian package espeak-ng"
            ) from None
        self._declare_signatures()
        options = _INITIALIZE_PHONEME_EVENTS | (_INITIALIZE_PHONEME_IPA if ipa_names else 0)
        sample_rate = self._lib.espeak_Initialize(
            _AUDIO_OUTPUT_SYNCHRONOUS, _BUFFER_MS, None, options
        )
        if sample_rate <= 0:
            raise EspeakFailure(
                "espeak_Initialize failed (voice data missing?); "
                "install the Debian package espeak-ng"
            )
        self.sample_rate = int(sample_rate)
        self._capture = _Capture()
        self._callback = _SynthCallback(self._on_synth)
        self._lib.espeak_SetSynthCallback(self._callback)

    def _declare_signatures(self) -> None:
        lib = self._lib
        lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
        lib.espeak_Initialize.restype = ctypes.c_int
        lib.espeak_SetSynthCallback.argtypes = [_SynthCallback]
        lib.espeak_SetSynthCallback.restype = None
        lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
        lib.espeak_SetVoiceByName.restype = ctypes.c_int
        lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
        lib.espeak_SetParameter.restype = ctypes.c_int
        lib.espeak_Synth.argtypes = [
            ctypes.c_void_p,
            ctypes.c_size_t,
            ctypes.c_uint,
            ctypes.c_int,
            ctypes.c_uint,
            ctypes.c_uint,
            ctypes.POINTER(ctypes.c_uint),
            ctypes.c_void_p,
        ]
        lib.espeak_Synth.restype = ctypes.c_int

    def _on_synth(self, wav: Any, n_samples: int, events: Any) -> int:
        if n_samples > 0:
            self._capture.pcm.append(ctypes.string_at(wav, n_samples * 2))
        index = 0
        while events[index].type != _EVENT_LIST_TERMINATED:
            event = events[index]
            if event.type == _EVENT_PHONEME:
                name = bytes(event.id.string).split(b"\0", 1)[0].decode("utf-8", "replace")
                self._capture.events.append((name, int(event.audio_position)))
            elif event.type == _EVENT_WORD:
                word = (int(event.text_position), int(event.length), int(event.audio_position))
                self._capture.words.append(word)
            index += 1
        return 0

    def _configure(self, voice: str, rate: int, pitch: int, pitch_range: int) -> None:
        if self._lib.espeak_SetVoiceByName(voice.encode("utf-8")) != _EE_OK:
            raise EspeakFailure(f"espeak-ng has no voice {voice!r}", "EspeakSynthesizer.voice")
        for parameter, value in (
            (_PARAM_RATE, rate),
            (_PARAM_PITCH, pitch),
            (_PARAM_RANGE, pitch_range),
        ):
            if self._lib.espeak_SetParameter(parameter, value, 0) != _EE_OK:
                raise EspeakFailure(f"espeak-ng rejected parameter {parameter}={value}")

    def _synthesize(self, text: str) -> _Capture:
        encoded = text.encode("utf-8") + b"\0"
        self._capture = _Capture()
        status = self._lib.espeak_Synth(
            encoded, len(encoded), 0, _POS_CHARACTER, 0, _CHARS_UTF8, None, None
        )
        if status != _EE_OK:
            raise EspeakFailure(f"espeak_Synth failed with status {status}")
        return self._capture

    def speak(self, voice: str, rate: int, pitch: int, pitch_range: int, text: str) -> RawSpeech:
        """espeak-ng's own output for ``text`` with these settings."""
        pcm, sample_rate, events, _ = self.speak_words(voice, rate, pitch, pitch_range, text)
        return pcm, sample_rate, events

    def speak_words(
        self, voice: str, rate: int, pitch: int, pitch_range: int, text: str
    ) -> tuple[bytes, int, list[tuple[str, int]], list[WordEvent]]:
        """``speak``'s output and the word events of the same utterance."""
        with LOCK:
            self._configure(voice, rate, pitch, pitch_range)
            capture = self._synthesize(text)
            pcm = b"".join(capture.pcm)
            return pcm, self.sample_rate, list(capture.events), list(capture.words)


LOCK = threading.Lock()
_library: Library | None = None


def shared_library() -> Library:
    """The process-wide handle, created on first use."""
    global _library
    with LOCK:
        if _library is None:
            _library = Library()
        return _library


def serve(requests: list[dict[str, Any]]) -> tuple[dict[str, Any], list[bytes]]:
    """Speak each request: the JSON header and the PCM bytes, in order."""
    header: list[dict[str, Any]] = []
    pcm: list[bytes] = []
    try:
        naming = {bool(request.get("ipa_names", False)) for request in requests}
        if len(naming) > 1:
            raise EspeakFailure("a batch must ask for one kind of phoneme names", "ipa_names")
        library = Library(ipa_names=True) if naming == {True} else shared_library()
        for request in requests:
            audio, rate, events, words = library.speak_words(
                str(request["voice"]),
                int(request["rate"]),
                int(request["pitch"]),
                int(request["pitch_range"]),
                str(request["text"]),
            )
            header.append(
                {"sample_rate": rate, "n_bytes": len(audio), "events": events, "words": words}
            )
            pcm.append(audio)
    except EspeakFailure as exc:
        return {"error": {"message": exc.message, "where": exc.where}}, []
    return {"results": header}, pcm


def main() -> None:
    """Worker entry: a JSON list of requests on stdin; a JSON line and the PCM on stdout."""
    requests = json.loads(sys.stdin.buffer.read().decode("utf-8"))
    header, pcm = serve(requests)
    out = sys.stdout.buffer
    out.write(json.dumps(header).encode("utf-8") + b"\n")
    for chunk in pcm:
        out.write(chunk)
    out.flush()


if __name__ == "__main__":
    main()
