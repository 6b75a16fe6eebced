"""How the driver speaks each protocol: which packets a target needs, and what answers each one.

A dialect turns a :class:`~runtime.ptz.profile.DeviceTarget` into one
:class:`Exchange` per independently-moving group (VISCA: ``pan_tilt`` and
``zoom``; Pelco-D: ``pan``, ``tilt``, ``zoom``), and every framed reply into a
protocol-neutral :class:`Event`. Pure: no I/O, no clock.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from . import pelco_d, visca
from .packets import Packet
from .pelco_d import PelcoDParser
from .profile import DeviceProfile, DeviceTarget
from .visca import ErrorCode, ViscaParser

EventKind = Literal["ack", "completion", "error", "answer", "network_change", "address_set", "if_clear", "general"]


@dataclass(frozen=True)
class Event:
    """A reply from the device. ``answer`` carries ``values`` (and, Pelco-D, the reply ``opcode``)."""

    kind: EventKind
    socket: int = 0
    code: int = 0
    values: tuple[int, ...] = ()
    opcode: int = 0


@dataclass(frozen=True)
class Exchange:
    """One packet to write and the test for the reply that answers it.

    ``answered=False``: nothing answers it (a Pelco-D device without general
    responses); the write is all there is.
    """

    packet: bytes
    group: str
    answers: Callable[[Event], bool]
    answered: bool = True


def _is(*kinds: str) -> Callable[[Event], bool]:
    return lambda e: e.kind in kinds


class ViscaDialect:
    """VISCA: AddressSet + IF_Clear to initialise, ACK/completion per command, inquiries for position."""

    completions = True
    buffer_full = int(ErrorCode.BUFFER_FULL)
    cancelled = int(ErrorCode.CANCELLED)

    def __init__(self, profile: DeviceProfile) -> None:
        self.profile = profile
        self.address = profile.address

    def parser(self) -> ViscaParser:
        return ViscaParser()

    def event(self, packet: Packet) -> Event | None:
        if packet.error:
            return None
        r = visca.decode_reply(packet.data)
        if r is None or (r.address not in (0, self.address)):
            return None
        if r.kind == "completion" and r.socket == 0 and r.payload:
            if len(r.payload) % 4:
                return None
            try:
                values = tuple(visca.decode_nibbles(r.payload[i:i + 4], signed=True)
                               for i in range(0, len(r.payload) - 3, 4))
            except visca.ViscaError:
                return None
            return Event("answer", values=values)
        return Event(r.kind, r.socket, r.code, tuple(r.payload))

    def init(self) -> list[Exchange]:
        """AddressSet (its answer must show a camera at our address: ``w > address``), then IF_Clear."""
        a = self.address

        def chain_reaches_us(e: Event) -> bool:
            return e.kind == "address_set" and len(e.values) == 1 and e.values[0] > a

        return [Exchange(visca.address_set(1), "init", chain_reaches_us),
                Exchange(visca.if_clear(), "init", _is("if_clear"))]

    def commands(self, t: DeviceTarget) -> list[tuple[str, tuple[int, ...], Exchange]]:
        p, a = self.profile, self.address
        pt = visca.pan_tilt_absolute(a, p.pan.speed, p.tilt.speed, t.pan, t.tilt)  # at AxisSection.move_deg_s
        zoom = visca.zoom_direct(a, t.zoom)
        return [("pan_tilt", (t.pan, t.tilt), Exchange(pt, "pan_tilt", _is("ack", "error"))),
                ("zoom", (t.zoom,), Exchange(zoom, "zoom", _is("ack", "error")))]

    def queries(self) -> list[Exchange]:
        a = self.address

        def answer(n: int) -> Callable[[Event], bool]:
            return lambda e: (e.kind == "answer" and len(e.values) == n) or (e.kind == "error" and e.socket == 0)

        return [Exchange(visca.pan_tilt_position_inquiry(a), "query", answer(2)),
                Exchange(visca.zoom_position_inquiry(a), "query", answer(1))]

    def position(self, answers: list[Event]) -> tuple[int, int, int]:
        (pan, tilt), (zoom,) = answers[0].values, answers[1].values
        return pan, tilt, zoom & 0xFFFF


class PelcoDDialect:
    """Pelco-D: no initialisation, a general response per command (if the device sends them), queries."""

    completions = False
    buffer_full = -1
    cancelled = -1

    def __init__(self, profile: DeviceProfile) -> None:
        self.profile = profile
        self.address = profile.address
        self.acknowledged = profile.pelco_d.general_response

    def parser(self) -> PelcoDParser:
        return PelcoDParser(replies=True)

    def event(self, packet: Packet) -> Event | None:
        msg = pelco_d.decode(packet.data)
        if msg.address != self.address:
            return None
        if isinstance(msg, pelco_d.GeneralResponse):
            return Event("general", code=msg.alarms)
        return Event("answer", values=(msg.value,), opcode=msg.cmd2)

    def init(self) -> list[Exchange]:
        return []

    def commands(self, t: DeviceTarget) -> list[tuple[str, tuple[int, ...], Exchange]]:
        a, ack = self.address, self.acknowledged
        return [(group, (units,), Exchange(encode(a, units), group, _is("general"), ack))
                for group, units, encode in (("pan", t.pan, pelco_d.set_pan_position),
                                             ("tilt", t.tilt, pelco_d.set_tilt_position),
                                             ("zoom", t.zoom, pelco_d.set_zoom_position))]

    def queries(self) -> list[Exchange]:
        def answer(opcode: int) -> Callable[[Event], bool]:
            return lambda e: e.kind == "answer" and e.opcode == opcode

        return [Exchange(pelco_d.query(self.address, q), "query", answer(r)) for q, r in pelco_d.QUERY_REPLY.items()]

    def position(self, answers: list[Event]) -> tuple[int, int, int]:
        pan, tilt, zoom = (e.values[0] for e in answers)
        return pelco_d.unwrap_angle(pan), pelco_d.unwrap_angle(tilt), zoom


def dialect_for(profile: DeviceProfile) -> ViscaDialect | PelcoDDialect:
    return ViscaDialect(profile) if profile.protocol == "visca" else PelcoDDialect(profile)
