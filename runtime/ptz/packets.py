"""What the incremental protocol parsers return: one framed packet with its place in the byte stream."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Packet:
    """One packet cut out of a byte stream.

    ``start`` and ``end`` are offsets into everything the parser has been fed
    (``end`` exclusive), so a caller can tell which bytes a packet came from.
    ``error`` is ``None`` for a well-framed packet; otherwise it names why the
    packet cannot be valid (``"overlong"``, ``"short"``; ``"unterminated"``: a VISCA-over-IP
    payload that is not one terminated message) and ``data`` holds its
    first bytes only (enough to read the address and reply with an error).
    """

    data: bytes
    start: int
    end: int
    error: str | None = None
