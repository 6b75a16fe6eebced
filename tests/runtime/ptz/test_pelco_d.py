"""Pelco-D encoders, checksums, framing (with resynchronisation on garbage) and decoding."""

from __future__ import annotations

import pytest
from hypothesis import given, strategies as st

from runtime.ptz import pelco_d
from runtime.ptz.pelco_d import GeneralResponse, Message, PelcoDParser


@pytest.mark.parametrize("packet,hex_", [
    (pelco_d.stop(1), "ff 01 00 00 00 00 01"),
    (pelco_d.set_pan_position(1, 9000), "ff 01 00 4b 23 28 97"),
    (pelco_d.set_pan_position(1, -100), "ff 01 00 4b 8c 3c 14"),   # -1 deg = 359.00 deg
    (pelco_d.set_tilt_position(2, 4500), "ff 02 00 4d 11 94 f4"),
    (pelco_d.set_zoom_position(1, 0xFFFF), "ff 01 00 4f ff ff 4e"),
    (pelco_d.query(1, pelco_d.QUERY_PAN), "ff 01 00 51 00 00 52"),
    (pelco_d.preset(1, pelco_d.GO_TO_PRESET, 3), "ff 01 00 07 00 03 0b"),
    (pelco_d.position_reply(1, pelco_d.REPLY_TILT, 0x1234), "ff 01 00 5b 12 34 a2"),
    (pelco_d.general_response(1), "ff 01 00 01"),
])
def test_packets_are_byte_exact(packet, hex_):
    assert packet == bytes.fromhex(hex_)


@given(st.integers(-50_000, 50_000))
def test_angles_wrap_into_one_turn(units):
    wire = pelco_d.wrap_angle(units)
    assert 0 <= wire < pelco_d.FULL_TURN
    back = pelco_d.unwrap_angle(wire)
    assert -18000 < back <= 18000 and (back - units) % pelco_d.FULL_TURN == 0


@given(st.integers(1, 255), st.integers(0, 0xFFFF))
def test_decode_inverts_encode(a, value):
    msg = pelco_d.decode(pelco_d.set_zoom_position(a, value))
    assert msg == Message(a, 0, pelco_d.SET_ZOOM, value >> 8, value & 0xFF) and msg.value == value
    assert pelco_d.decode(pelco_d.general_response(a, 5)) == GeneralResponse(a, 5)


def test_encoders_reject_out_of_range_values():
    for bad in (lambda: pelco_d.frame(0, 0, 0), lambda: pelco_d.set_zoom_position(1, 70000),
                lambda: pelco_d.preset(1, pelco_d.SET_PRESET, 0), lambda: pelco_d.query(1, 0x4B)):
        with pytest.raises(ValueError):
            bad()


def test_parser_resynchronises_after_a_bad_checksum_and_partial_reads():
    good = [pelco_d.set_pan_position(1, 1234), pelco_d.query(1, pelco_d.QUERY_ZOOM)]
    bad = bytearray(pelco_d.set_tilt_position(1, 10))
    bad[6] ^= 0x01
    stream = b"\x00\xff\x01" + good[0] + bytes(bad) + good[1][:3]
    p = PelcoDParser()
    got = [f for b in stream + good[1][3:] for f in p.feed(bytes((b,)))]
    assert [f.data for f in got] == good
    assert p.rejected >= 1


def test_reply_parser_reads_both_lengths():
    replies = [pelco_d.general_response(1), pelco_d.position_reply(1, pelco_d.REPLY_PAN, 35999),
               pelco_d.general_response(1, 0x80)]
    stream = b"\xff\x00" + b"".join(replies)
    got = PelcoDParser(replies=True).feed(stream)
    assert [f.data for f in got] == replies


def test_commands_with_reserved_bits_are_not_framed():
    body = bytes((1, 0x60, 0x02, 0, 0))
    packet = b"\xff" + body + bytes((pelco_d.checksum(body),))
    assert PelcoDParser().feed(packet) == []
