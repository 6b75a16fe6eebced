"""Fuzzing the PTZ parsers: random and mutated byte streams, fed in random chunks.

Shared by tests/test_ptz_fuzz.py (a few thousand streams, fixed seeds) and
benchmarks/bench_ptz.py (>= 1e4 streams). For each stream it checks that no
exception escapes, that chunking does not change what is found, that every
packet found is well-formed and is the bytes it claims to be, and that every
valid packet left intact in a mutated stream is found, unless (Pelco-D, which
has no escaping) noise in front of it formed a checksum-valid packet that
overlaps it; such losses are reported as ``explained``.
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from dataclasses import dataclass

from runtime.ptz import pelco_d, visca
from runtime.ptz.pelco_d import PelcoDParser
from runtime.ptz.visca import ErrorCode, ViscaParser

#: Pelco-D addresses whose 4-byte general response starts like a position reply (documented ambiguity).
_AMBIGUOUS_PELCO = {pelco_d.REPLY_PAN, pelco_d.REPLY_TILT, pelco_d.REPLY_ZOOM}


def visca_packets(rng: random.Random) -> list[bytes]:
    """A random mix of valid VISCA commands and replies (what either end may receive)."""
    a = rng.randint(1, 7)
    s16 = lambda: rng.randint(-0x8000, 0x7FFF)
    choices: list[Callable[[], bytes]] = [
        lambda: visca.address_set(rng.randint(1, 7)),
        lambda: visca.if_clear(rng.choice([a, visca.BROADCAST])),
        lambda: visca.cancel(a, rng.randint(1, 2)),
        lambda: visca.pan_tilt_absolute(a, rng.randint(1, 0x18), rng.randint(1, 0x17), s16(), s16()),
        lambda: visca.zoom_direct(a, rng.randint(0, 0xFFFF)),
        lambda: visca.pan_tilt_position_inquiry(a),
        lambda: visca.zoom_position_inquiry(a),
        lambda: visca.ack(a, rng.randint(1, 2)),
        lambda: visca.completion(a, rng.randint(1, 2)),
        lambda: visca.error(a, rng.randint(0, 2), rng.choice(list(ErrorCode))),
        lambda: visca.network_change(a),
        lambda: visca.pan_tilt_position_reply(a, s16(), s16()),
        lambda: visca.zoom_position_reply(a, rng.randint(0, 0xFFFF)),
    ]
    return [rng.choice(choices)() for _ in range(rng.randint(1, 12))]


def pelco_command_packets(rng: random.Random) -> list[bytes]:
    """Valid Pelco-D commands: absolute positions, queries, presets, stop, random standard commands."""
    a = rng.randint(1, 255)
    choices: list[Callable[[], bytes]] = [
        lambda: pelco_d.set_pan_position(a, rng.randint(0, 35999)),
        lambda: pelco_d.set_tilt_position(a, rng.randint(-9000, 9000)),
        lambda: pelco_d.set_zoom_position(a, rng.randint(0, 0xFFFF)),
        lambda: pelco_d.query(a, rng.choice(list(pelco_d.QUERY_REPLY))),
        lambda: pelco_d.preset(a, rng.choice([pelco_d.SET_PRESET, pelco_d.CLEAR_PRESET, pelco_d.GO_TO_PRESET]),
                               rng.randint(1, 255)),
        lambda: pelco_d.stop(a),
        lambda: pelco_d.frame(a, rng.randint(0, 255) & ~0x60, rng.randrange(0, 256, 2),
                              rng.randint(0, 0x3F), rng.randint(0, 0x3F)),
    ]
    return [rng.choice(choices)() for _ in range(rng.randint(1, 12))]


def pelco_reply_packets(rng: random.Random) -> list[bytes]:
    """Valid Pelco-D replies: position answers and general responses."""
    a = rng.choice([x for x in range(1, 256) if x not in _AMBIGUOUS_PELCO])
    choices: list[Callable[[], bytes]] = [
        lambda: pelco_d.position_reply(a, rng.choice(sorted(pelco_d.REPLY_OPCODES)), rng.randint(0, 0xFFFF)),
        lambda: pelco_d.general_response(a, rng.randint(0, 255)),
    ]
    return [rng.choice(choices)() for _ in range(rng.randint(1, 12))]


@dataclass(frozen=True)
class Kind:
    """A parser under test: how to make it, valid packets for it, and what a well-formed packet is."""

    name: str
    parser: Callable[[], ViscaParser | PelcoDParser]
    packets: Callable[[random.Random], list[bytes]]
    well_formed: Callable[[bytes], bool]
    #: Bytes that start a packet: garbage is biased towards them, to be hard on resynchronisation.
    starts: bytes


def _visca_ok(p: bytes) -> bool:
    """Framed as a packet: a header, no header nor terminator inside (a body byte may be >= 0x80), the terminator."""
    return (3 <= len(p) <= visca.MAX_PACKET and p[0] in visca.HEADERS and p[-1] == 0xFF
            and not any(b in visca.HEADERS or b == 0xFF for b in p[1:-1]))


def _pelco_command_ok(p: bytes) -> bool:
    return len(p) == 7 and p[0] == 0xFF and p[6] == pelco_d.checksum(p[1:6])


def _pelco_reply_ok(p: bytes) -> bool:
    if len(p) == 4:
        return p[0] == 0xFF and p[3] == pelco_d.checksum(p[1:3])
    return _pelco_command_ok(p) and p[2] == 0 and p[3] in pelco_d.REPLY_OPCODES


KINDS = {
    "visca": Kind("visca", ViscaParser, visca_packets, _visca_ok, bytes((0x81, 0x88, 0x90, 0xFF))),
    "pelco-d": Kind("pelco-d", PelcoDParser, pelco_command_packets, _pelco_command_ok, bytes((0xFF,))),
    "pelco-d-replies": Kind("pelco-d-replies", lambda: PelcoDParser(replies=True), pelco_reply_packets,
                            _pelco_reply_ok, bytes((0xFF,))),
}


def _garbage(rng: random.Random, kind: Kind, n: int) -> bytes:
    return bytes(rng.choice(kind.starts) if rng.random() < 0.2 else rng.randrange(256) for _ in range(n))


def _mutate(rng: random.Random, packet: bytes, kind: Kind) -> bytes:
    """One corruption: flip a bit, drop, insert or replace a byte, truncate, or double a byte."""
    i = rng.randrange(len(packet))
    op = rng.randrange(6)
    if op == 0:
        return packet[:i] + bytes((packet[i] ^ (1 << rng.randrange(8)),)) + packet[i + 1:]
    if op == 1:
        return packet[:i] + packet[i + 1:]
    if op == 2:
        return packet[:i] + _garbage(rng, kind, 1) + packet[i:]
    if op == 3:
        return packet[:i] + _garbage(rng, kind, 1) + packet[i + 1:]
    if op == 4:
        return packet[:max(1, i)]
    return packet[:i] + packet[i:i + 1] + packet[i:]


def random_stream(rng: random.Random, kind: Kind) -> tuple[bytes, list[tuple[int, int]]]:
    """Random bytes (biased towards packet starts); no packet is known to be in it."""
    return _garbage(rng, kind, rng.randint(0, 400)), []


def mutated_stream(rng: random.Random, kind: Kind) -> tuple[bytes, list[tuple[int, int]]]:
    """Valid packets, some corrupted, with garbage (and fragments of packets) between them.

    Returns the stream and the (start, end) spans of the packets left intact.
    """
    out = bytearray()
    intact: list[tuple[int, int]] = []
    for packet in kind.packets(rng):
        r = rng.random()
        if r < 0.3:
            out += _garbage(rng, kind, rng.randint(1, 24))
        elif r < 0.4:
            out += rng.choice(kind.packets(rng))[: rng.randint(1, 6)]
        if rng.random() < 0.25:
            out += _mutate(rng, packet, kind)
        else:
            intact.append((len(out), len(out) + len(packet)))
            out += packet
    if rng.random() < 0.3:
        out += rng.choice(kind.packets(rng))[:-1]
    return bytes(out), intact


def _feed_chunked(parser, stream: bytes, rng: random.Random) -> list:
    out, i = [], 0
    while i < len(stream):
        n = rng.choice((1, 1, 2, 3, 5, 8, 17, 64))
        out += parser.feed(stream[i:i + n])
        i += n
    return out


@dataclass
class StreamResult:
    """What one stream showed; ``problems`` lists every violated property (empty: all good)."""

    packets: int = 0
    found: int = 0
    explained: int = 0
    spurious: int = 0
    seconds: float = 0.0
    problems: tuple[str, ...] = ()


def check_stream(kind: Kind, stream: bytes, intact: list[tuple[int, int]], rng: random.Random) -> StreamResult:
    """Parse ``stream`` whole and in random chunks; check every property (see the module docstring)."""
    problems = []
    t0 = time.perf_counter()
    try:
        whole = kind.parser().feed(stream)
        chunked = _feed_chunked(kind.parser(), stream, rng)
    except Exception as exc:  # the property under test: nothing escapes
        return StreamResult(len(intact), problems=(f"exception {type(exc).__name__}: {exc}",))
    seconds = time.perf_counter() - t0
    if whole != chunked:
        problems.append("chunking changed the packets")
    for f in whole:
        if f.error is None and (stream[f.start:f.end] != f.data or not kind.well_formed(f.data)):
            problems.append(f"bad packet {f.data.hex(' ')} at {f.start}")
    spans = {(f.start, f.end) for f in whole if f.error is None}
    spurious = [s for s in spans if s not in set(intact)]
    found = explained = 0
    for start, end in intact:
        if (start, end) in spans:
            found += 1
        elif any(s < end and e > start for s, e in spurious):
            explained += 1
        else:
            problems.append(f"intact packet {stream[start:end].hex(' ')} at {start} not found")
    return StreamResult(len(intact), found, explained, len(spurious), seconds, tuple(problems))


def run(kind: Kind, n_random: int, n_mutated: int, seed: int) -> dict:
    """Fuzz one parser; returns totals and the first few problems."""
    rng = random.Random(seed)
    totals = {"random_streams": n_random, "mutated_streams": n_mutated, "bytes": 0, "packets": 0, "found": 0,
              "explained": 0, "spurious": 0, "failures": 0, "max_stream_ms": 0.0}
    problems: list[str] = []
    for make, n in ((random_stream, n_random), (mutated_stream, n_mutated)):
        for _ in range(n):
            stream, intact = make(rng, kind)
            r = check_stream(kind, stream, intact, rng)
            totals["bytes"] += len(stream)
            for key in ("packets", "found", "explained", "spurious"):
                totals[key] += getattr(r, key)
            totals["max_stream_ms"] = max(totals["max_stream_ms"], 1e3 * r.seconds)
            if r.problems:
                totals["failures"] += 1
                problems += r.problems[:1]
    totals["problems"] = problems[:5]
    return totals
