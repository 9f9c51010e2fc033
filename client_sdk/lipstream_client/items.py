"""What the clients accept as phonemes, and which URLs they treat as this machine's.

Sketch: a phoneme may be given as a ``PhonemeItem``, a ``(phoneme, start,
end[, emotion])`` tuple or a mapping with those keys; ``phoneme_items``
turns any mix into ``PhonemeItem``s and names the first item of another
shape. ``is_loopback_url`` tells a loopback URL (the clients bypass proxies
for it). No I/O: shared by the WebSocket and HTTP clients.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Iterable, Mapping
from typing import TypeAlias
from urllib.parse import urlsplit

from .messages import PhonemeItem

PhonemeLike: TypeAlias = (
    PhonemeItem
    | tuple[str, float, float]
    | tuple[str, float, float, str | None]
    | Mapping[str, object]
)


def _coerce_item(item: PhonemeLike, where: str) -> PhonemeItem:
    if isinstance(item, PhonemeItem):
        return item
    if isinstance(item, Mapping):
        unknown = set(item) - {"phoneme", "start", "end", "emotion"}
        if unknown:
            raise ValueError(f"{where}: unknown keys {sorted(unknown)}")
        try:
            phoneme, start, end = item["phoneme"], item["start"], item["end"]
        except KeyError as missing:
            raise ValueError(f"{where}: missing key {missing}") from None
        emotion = item.get("emotion")
        return PhonemeItem(phoneme, start, end, emotion)  # type: ignore[arg-type]
    if isinstance(item, tuple) and len(item) in (3, 4):
        return PhonemeItem(*item)
    raise ValueError(
        f"{where}: expected a PhonemeItem, a (phoneme, start, end[, emotion]) "
        f"tuple or a mapping, got {item!r}"
    )


def phoneme_items(items: Iterable[PhonemeLike]) -> tuple[PhonemeItem, ...]:
    """``PhonemeItem``s from items, (phoneme, start, end[, emotion]) tuples or mappings;
    ValueError naming the first item of another shape."""
    return tuple(_coerce_item(item, f"items[{index}]") for index, item in enumerate(items))


def is_loopback_url(url: str) -> bool:
    """True when ``url``'s host is ``localhost`` or a loopback IP address."""
    host = urlsplit(url).hostname or ""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
