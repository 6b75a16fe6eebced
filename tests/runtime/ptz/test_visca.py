"""VISCA encoders, framing and decoding: byte-exact packets, round trips, partial and garbled reads."""

from __future__ import annotations

import pytest
from hypothesis import given, strategies as st

from runtime.ptz import visca
from runtime.ptz.visca import ErrorCode, ViscaError, ViscaParser


@pytest.mark.parametrize("packet,hex_", [
    (visca.address_set(), "88 30 01 ff"),
    (visca.if_clear(), "88 01 00 01 ff"),
    (visca.if_clear(2), "82 01 00 01 ff"),
    (visca.cancel(1, 2), "81 22 ff"),
    (visca.pan_tilt_absolute(1, 0x18, 0x14, 432, -288), "81 01 06 02 18 14 00 01 0b 00 0f 0e 0e 00 ff"),
    (visca.zoom_direct(1, 0x4000), "81 01 04 47 04 00 00 00 ff"),
    (visca.pan_tilt_position_inquiry(3), "83 09 06 12 ff"),
    (visca.zoom_position_inquiry(1), "81 09 04 47 ff"),
    (visca.ack(1, 1), "90 41 ff"),
    (visca.completion(2, 2), "a0 52 ff"),
    (visca.error(1, 0, ErrorCode.SYNTAX), "90 60 02 ff"),
    (visca.error(1, 1, ErrorCode.NOT_EXECUTABLE), "90 61 41 ff"),
    (visca.network_change(1), "90 38 ff"),
    (visca.address_set_reply(2), "88 30 02 ff"),
    (visca.pan_tilt_position_reply(1, -1, 1), "90 50 0f 0f 0f 0f 00 00 00 01 ff"),
    (visca.zoom_position_reply(1, 0x1606), "90 50 01 06 00 06 ff"),
])
def test_packets_are_byte_exact(packet, hex_):
    assert packet == bytes.fromhex(hex_)


@given(st.integers(-0x8000, 0x7FFF))
def test_signed_nibbles_round_trip(v):
    assert visca.decode_nibbles(visca.encode_nibbles(v), signed=True) == v


def test_nibbles_reject_what_does_not_fit():
    with pytest.raises(ValueError):
        visca.encode_nibbles(0x10000)
    with pytest.raises(ViscaError) as exc:
        visca.decode_nibbles(b"\x00\x10\x00\x00", signed=False)
    assert exc.value.code == ErrorCode.SYNTAX


@given(st.integers(1, 7), st.integers(1, 0x18), st.integers(1, 0x17), st.integers(-0x8000, 0x7FFF),
       st.integers(-0x8000, 0x7FFF), st.integers(0, 0xFFFF))
def test_commands_decode_to_what_was_encoded(a, vv, ww, pan, tilt, zoom):
    cmd = visca.decode_command(visca.pan_tilt_absolute(a, vv, ww, pan, tilt))
    assert (cmd.kind, cmd.receiver, cmd.args) == ("pan_tilt_absolute", a, (vv, ww, pan, tilt))
    assert visca.decode_command(visca.zoom_direct(a, zoom)).args == (zoom,)
    assert visca.decode_command(visca.pan_tilt_position_inquiry(a)).kind == "pan_tilt_inquiry"
    assert visca.decode_command(visca.zoom_position_inquiry(a)).kind == "zoom_inquiry"
    assert visca.decode_command(visca.cancel(a, 1)).args == (1,)
    assert visca.decode_command(visca.address_set(a)).args == (a,)


@pytest.mark.parametrize("hex_,code", [
    ("81 01 06 02 18 14 00 01 0b 00 0f 0e 0e ff", ErrorCode.SYNTAX),      # one nibble short
    ("81 01 06 02 18 14 00 01 1b 00 0f 0e 0e 00 ff", ErrorCode.SYNTAX),   # a "nibble" above 0x0f
    ("81 01 7f ff", ErrorCode.SYNTAX),                                    # unknown command
    ("90 41 ff", ErrorCode.SYNTAX),                                       # a reply is no command
    ("81 ff", ErrorCode.MESSAGE_LENGTH),
    ("81" + " 01" * 16 + " ff", ErrorCode.MESSAGE_LENGTH),
])
def test_bad_commands_name_their_error(hex_, code):
    with pytest.raises(ViscaError) as exc:
        visca.decode_command(bytes.fromhex(hex_))
    assert exc.value.code == code


@pytest.mark.parametrize("packet,kind,socket,extra", [
    (visca.ack(1, 2), "ack", 2, None),
    (visca.completion(1, 1), "completion", 1, None),
    (visca.error(1, 0, ErrorCode.BUFFER_FULL), "error", 0, ErrorCode.BUFFER_FULL),
    (visca.error(1, 2, ErrorCode.CANCELLED), "error", 2, ErrorCode.CANCELLED),
    (visca.network_change(1), "network_change", 0, None),
    (visca.address_set_reply(2), "address_set", 0, None),
    (visca.if_clear_reply(), "if_clear", 0, None),
])
def test_replies_are_classified(packet, kind, socket, extra):
    r = visca.decode_reply(packet)
    assert (r.kind, r.socket) == (kind, socket)
    if extra is not None:
        assert r.code == extra


def test_commands_are_not_replies():
    for packet in (visca.pan_tilt_position_inquiry(1), visca.zoom_direct(1, 5), visca.cancel(1, 1)):
        assert visca.decode_reply(packet) is None


def test_parser_survives_partial_reads_and_garbage():
    packets = [visca.ack(1, 1), visca.pan_tilt_position_reply(1, 100, -5), visca.completion(1, 1)]
    stream = b"\x00\x13\xff" + packets[0] + b"\x91\x02" + packets[1] + b"\x7f\x7f" + packets[2]
    p = ViscaParser()
    got = [f for b in stream for f in p.feed(bytes((b,)))]
    assert [f.data for f in got] == packets
    assert [stream[f.start:f.end] for f in got] == packets
    assert p.garbage_bytes == len(stream) - sum(map(len, packets))


def test_parser_reports_overlong_and_short_packets_then_resynchronises():
    overlong = bytes.fromhex("81" + " 01" * 20 + " ff")
    p = ViscaParser()
    got = p.feed(overlong + bytes.fromhex("81 ff") + visca.ack(1, 1))
    assert [f.error for f in got] == ["overlong", "short", None]
    assert got[0].start == 0 and got[0].end == len(overlong)
    assert len(got[0].data) < visca.MAX_PACKET
    assert got[2].data == visca.ack(1, 1)


@pytest.mark.parametrize("hex_", ["81 01 ee 77 ff", "81 01 06 99 ff", "81 80 ff"])
def test_a_body_byte_of_0x80_or_above_stays_in_its_packet(hex_):
    """A byte >= 0x80 that is no header belongs to the packet (a camera answers it with a syntax error);
    only a header byte restarts the framing."""
    data = bytes.fromhex(hex_)
    (got,) = ViscaParser().feed(data)
    assert got.data == data and got.error is None and (got.start, got.end) == (0, len(data))
    with pytest.raises(ViscaError) as exc:
        visca.decode_command(got.data)
    assert exc.value.code == ErrorCode.SYNTAX
    assert [f.data for f in ViscaParser().feed(bytes.fromhex("81 01 99") + visca.ack(1, 1))] == [visca.ack(1, 1)]


@pytest.mark.parametrize("hex_,error", [("81 01 ee 77 ff", None), ("81 01", "unterminated"),
                                        ("81 ff 81 ff", "unterminated"), ("81 ff", "short"),
                                        ("81" + " 01" * 20 + " ff", "overlong")])
def test_an_ip_payload_is_one_message(hex_, error):
    data = bytes.fromhex(hex_)
    got = visca.message(data)
    assert got.error == error and (got.start, got.end) == (0, len(data))
    if error is None:
        assert got.data == data
