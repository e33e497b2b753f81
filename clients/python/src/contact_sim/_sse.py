"""Server-Sent Events as the WHATWG spec frames them: ``event:`` and ``data:`` lines (data
lines joined by newlines), ``:`` comments (the server's keep-alives) skipped, a blank line
ending an event."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Iterator


@dataclass
class Event:
    event: str
    data: str


def events(lines: Iterable[str]) -> Iterator[Event]:
    name = ""
    data: list[str] = []
    for raw in lines:
        line = raw.rstrip("\r\n")
        if not line:
            if data:
                yield Event(name or "message", "\n".join(data))
            name, data = "", []
            continue
        if line.startswith(":"):
            continue
        key, _, value = line.partition(":")
        if value.startswith(" "):
            value = value[1:]
        if key == "event":
            name = value
        elif key == "data":
            data.append(value)
    # An event cut off by the end of the stream is dropped, as the spec says: its data may be
    # incomplete.
