"""Which TextGrid tier holds the phones, and in which notation its labels are.

Sketch: aligners name their phone tier differently: the Montreal Forced
Aligner writes ``phones`` (``<speaker> - phones`` for several speakers) with
ARPAbet or IPA labels, WebMAUS writes ``MAU`` with SAMPA labels and ``<p:>``
pauses, others write ``phone`` or ``segments``. Without a requested name the
first of those present is taken (names matched case-insensitively); with one
(``--tier``, ``corpus.json``'s ``tier``) exactly that tier is taken. A known
tier's notation is fixed; any other tier's is detected over all its labels
(``phonemes.detect_source``), as for ``.lab`` files.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from types import MappingProxyType

from ..errors import CorpusError
from ..phonemes import detect_source

# Tier name -> label notation; None: detected from the labels. In preference order.
PHONE_TIERS = MappingProxyType({"phones": "mfa", "MAU": "sampa", "phone": None, "segments": None})
MFA_SPEAKER_SUFFIX = " - phones"
MFA_SOURCE = "mfa"


def choose_phone_tier(names: Sequence[str], requested: str | None, where: str) -> str:
    """The tier of ``names`` holding the phones; CorpusError listing the tiers found."""
    found = ", ".join(repr(name) for name in names) or "none"
    if requested is not None:
        chosen = _match(requested, names)
        if chosen is None:
            raise CorpusError(f"no tier named {requested!r}; tiers found: {found}", where=where)
        return chosen
    for known in PHONE_TIERS:
        chosen = _match(known, names)
        if chosen is not None:
            return chosen
    speaker_tiers = [name for name in names if name.endswith(MFA_SPEAKER_SUFFIX)]
    if len(speaker_tiers) == 1:
        return speaker_tiers[0]
    expected = ", ".join(repr(name) for name in PHONE_TIERS)
    raise CorpusError(
        f"no phone tier ({expected} or '<speaker>{MFA_SPEAKER_SUFFIX}'); tiers found: {found}; "
        "name the tier with --tier or corpus.json's 'tier'",
        where=where,
    )


def tier_source(name: str, labels: Iterable[str], where: str) -> str:
    """The notation of tier ``name``'s labels: fixed for the aligners' tiers, else detected
    over the non-empty ``labels``."""
    for known, source in PHONE_TIERS.items():
        if name.lower() == known.lower() and source is not None:
            return source
    if name.endswith(MFA_SPEAKER_SUFFIX):
        return MFA_SOURCE
    spoken = [label.strip() for label in labels if label.strip()]
    return detect_source(spoken, where=where) if spoken else MFA_SOURCE


def _match(wanted: str, names: Sequence[str]) -> str | None:
    if wanted in names:
        return wanted
    folded = [name for name in names if name.lower() == wanted.lower()]
    return folded[0] if len(folded) == 1 else None
