"""The languages and voice variants espeak-ng speaks, as it lists them, and a request's ``lang``.

Method: ``espeak-ng --voices`` lists one voice per line (priority, language,
gender, name, file, other languages with their priorities) and
``espeak-ng --voices=variant`` the voice variants (``!v/f3`` is variant
``f3``). A request's ``lang`` is a language of that list or one of the other
languages a voice names (``en`` is served by ``en-gb``, priority 2; ``zh`` by
``cmn``), matched without regard to case; the voice with the lowest priority
number wins, as in espeak-ng's own selection. The voice is then asked for by
its file (``gmw/de``), which espeak-ng loads directly, plus ``+variant``.
Both lists are read once per process.
"""

from __future__ import annotations

import re
import subprocess
from dataclasses import dataclass
from functools import cache

from lipstream_client.errors import INVALID_REQUEST, SPEECH_FAILED, UNKNOWN_LANGUAGE

from ..errors import LipstreamError

ESPEAK_PROGRAM = "espeak-ng"
LIST_TIMEOUT_S = 20.0
_OTHER_LANGUAGE = re.compile(r"\(([^\s()]+)\s+(\d+)\)")


@dataclass(frozen=True)
class EspeakLanguage:
    """One espeak-ng language voice: its ``code`` (``de``, ``en-gb``), ``title``
    (``German``), voice ``file`` (``gmw/de``) and ``priority`` (lower is preferred)."""

    code: str
    title: str
    file: str
    priority: int

    @property
    def english(self) -> bool:
        """Whether espeak-ng's English phoneme tables speak it (its file is ``gmw/en...``)."""
        return self.file.split("/")[-1].lower().startswith("en")

    def voice(self, variant: str | None = None) -> str:
        """The name espeak-ng loads: the voice file, plus ``+variant``."""
        return self.file if not variant else f"{self.file}+{variant}"


def _listing(argument: str) -> list[str]:
    try:
        finished = subprocess.run(
            [ESPEAK_PROGRAM, argument],
            capture_output=True,
            timeout=LIST_TIMEOUT_S,
            check=True,
        )
    except (OSError, subprocess.SubprocessError) as exc:
        raise LipstreamError(
            f"cannot list espeak-ng's voices ({exc}); install the Debian package espeak-ng",
            where="espeak",
            code=SPEECH_FAILED,
        ) from None
    return finished.stdout.decode("utf-8", "replace").splitlines()[1:]


def parse_voices(lines: list[str]) -> list[tuple[EspeakLanguage, list[tuple[str, int]]]]:
    """``espeak-ng --voices`` lines (header removed): each voice and its other languages."""
    voices: list[tuple[EspeakLanguage, list[tuple[str, int]]]] = []
    for line in lines:
        fields = line.split()
        if len(fields) < 5 or not fields[0].isdigit():
            continue
        priority, code, _, title, file = fields[:5]
        rest = " ".join(fields[5:])
        others = [(other, int(rank)) for other, rank in _OTHER_LANGUAGE.findall(rest)]
        voices.append((EspeakLanguage(code, title.replace("_", " "), file, int(priority)), others))
    return voices


@cache
def espeak_languages() -> tuple[EspeakLanguage, ...]:
    """espeak-ng's languages in its listing order, one per language code."""
    seen: dict[str, EspeakLanguage] = {}
    for language, _ in parse_voices(_listing("--voices")):
        seen.setdefault(language.code.lower(), language)
    return tuple(seen.values())


@cache
def _by_name() -> dict[str, EspeakLanguage]:
    chosen: dict[str, tuple[int, EspeakLanguage]] = {}
    for language, others in parse_voices(_listing("--voices")):
        for name, rank in [(language.code, 0), *others]:
            key = name.lower()
            if key not in chosen or rank < chosen[key][0]:
                chosen[key] = (rank, language)
    return {name: language for name, (_, language) in chosen.items()}


@cache
def espeak_variants() -> tuple[str, ...]:
    """The voice variants espeak-ng lists (``f3``, ``m1``, ``klatt``, ...), by file name."""
    variants: list[str] = []
    for line in _listing("--voices=variant"):
        fields = line.split()
        if len(fields) >= 5 and fields[4].startswith("!v/"):
            variants.append(fields[4][3:])
    return tuple(dict.fromkeys(variants))


def resolve_language(lang: str, where: str = "lang") -> EspeakLanguage:
    """The espeak-ng language ``lang`` names; ``unknown_language`` naming it otherwise."""
    found = _by_name().get(lang.lower()) if isinstance(lang, str) else None
    if found is None:
        raise LipstreamError(
            f"espeak-ng speaks no language {lang!r}; docs/reference/languages.md "
            "lists those it does (de, fr-fr, cmn, ...)",
            where=where,
            code=UNKNOWN_LANGUAGE,
        )
    return found


def find_language(lang: str) -> EspeakLanguage | None:
    """The espeak-ng language ``lang`` names, or None."""
    return _by_name().get(lang.lower())


def resolve_variant(variant: str, where: str = "voice") -> str:
    """``variant`` if espeak-ng has that voice variant (case as listed), else
    ``invalid_request`` naming it."""
    for known in espeak_variants():
        if known.lower() == variant.lower():
            return known
    raise LipstreamError(
        f"espeak-ng has no voice variant {variant!r}; with lang, voice names a variant "
        "such as f3, m1 or klatt",
        where=where,
        code=INVALID_REQUEST,
    )
