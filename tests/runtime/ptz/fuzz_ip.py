"""Fuzzing VISCA over IP: random and mutated datagrams to the camera's side and to the driver's reply parser.

Shared by tests/runtime/ptz/test_fuzz_ip.py (a few hundred datagrams, fixed seeds) and
benchmarks/bench_ptz.py ``--only fuzz-ip`` (10,000 each way).

- :func:`fuzz_emulator`: datagrams sent over UDP to a :class:`~runtime.ptz.emulator.UdpEmulator`
  on 127.0.0.1; every answer must be a well-formed datagram (a VISCA reply or a control reply
  carrying the sequence number it answers, or 0 for a completion whose command is gone); after every
  ``check_every`` datagrams, and at the end, the emulator must still answer RESET and a position
  inquiry within ``hang_s`` (otherwise a hang is counted). Exceptions are those raised in the emulator's
  thread (it would stop serving) and in this process.
- :func:`fuzz_port`: datagrams fed to the driver's UDP port (:class:`~runtime.ptz.visca_ip.ViscaIpPort`,
  opened against a RESET-answering socket) and on through the VISCA framing and the driver's dialect
  (what the reader thread runs); the port must hand on only the payloads of replies whose sequence
  number it sent and that are one terminated message each, and stay usable.
"""

from __future__ import annotations

import random
import socket
import threading
import time

from runtime.ptz import UdpEmulator, default_profile, visca, visca_ip as vip
from runtime.ptz.dialect import ViscaDialect
from runtime.ptz.visca import ViscaParser
from tests.runtime.ptz.fuzz import visca_packets


def _valid(rng: random.Random, seq: int) -> bytes:
    """A valid datagram of any type (what either end may receive)."""
    kind = rng.choice((vip.COMMAND, vip.INQUIRY, vip.REPLY, vip.CONTROL, vip.CONTROL_REPLY))
    if kind in (vip.CONTROL, vip.CONTROL_REPLY):
        payload = rng.choice((vip.RESET, vip.SEQUENCE_ERROR, vip.MESSAGE_ERROR))
    else:
        payload = rng.choice(visca_packets(rng))[:vip.MAX_PAYLOAD]
    return vip.frame(kind, seq, payload)


def _mutate(rng: random.Random, d: bytes) -> bytes:
    b = bytearray(d)
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(7)
        if op == 0 and b:
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8)
        elif op == 1:
            del b[rng.randrange(len(b) + 1):]
        elif op == 2:
            b += rng.randbytes(rng.randint(1, 20))
        elif op == 3 and len(b) >= 4:
            b[2:4] = rng.randrange(0x10000).to_bytes(2, "big")  # length field
        elif op == 4 and len(b) >= 2:
            b[0:2] = rng.choice((0x0100, 0x0110, 0x0111, 0x0200, 0x0201, rng.randrange(0x10000))).to_bytes(2, "big")
        elif op == 5 and len(b) >= 8:
            b[4:8] = rng.choice((0, 1, 0xFFFFFFFF, rng.randrange(1 << 32))).to_bytes(4, "big")
        elif op == 6 and len(b) > 8:
            i = rng.randrange(8, len(b))
            b[i] = rng.choice((0x80, 0x81, 0x88, 0x90, 0xFF, 0x00))
    return bytes(b)


def datagrams(rng: random.Random, n: int, seqs: list[int] | None = None) -> list[bytes]:
    """``n`` datagrams: half random bytes (0-40 long), half valid ones mutated (or, one in five, left valid);
    sequence numbers drawn from ``seqs`` when given (so some match what a port sent)."""
    out = []
    for i in range(n):
        seq = rng.choice(seqs) if seqs and rng.random() < 0.7 else rng.randrange(1 << 32)
        if i % 2:
            out.append(rng.randbytes(rng.randint(0, 40)))
        else:
            d = _valid(rng, seq)
            out.append(d if rng.random() < 0.2 else _mutate(rng, d))
    return out


def _well_formed_answer(data: bytes) -> bool:
    d = vip.unframe(data)
    if d is None or d.payload_type not in (vip.REPLY, vip.CONTROL_REPLY):
        return False
    if d.payload_type == vip.CONTROL_REPLY:
        return d.payload in (vip.RESET, vip.SEQUENCE_ERROR, vip.MESSAGE_ERROR)
    return visca.decode_reply(d.payload) is not None


def _alive(sock: socket.socket, hang_s: float) -> bool:
    """RESET, AddressSet (the fuzz may have renumbered the camera), then a zoom inquiry under number 2:
    answered within ``hang_s``."""
    deadline = time.monotonic() + hang_s
    sock.send(vip.frame(vip.CONTROL, 0, vip.RESET))
    sock.send(vip.frame(vip.COMMAND, 1, visca.address_set(1)))
    sock.send(vip.frame(vip.INQUIRY, 2, visca.zoom_position_inquiry(1)))
    got_reset = got_answer = False
    while time.monotonic() < deadline and not (got_reset and got_answer):
        sock.settimeout(max(1e-3, deadline - time.monotonic()))
        try:
            d = vip.unframe(sock.recv(2048))
        except TimeoutError:
            break
        if d is None:
            continue
        got_reset |= d.payload_type == vip.CONTROL_REPLY and d.payload == vip.RESET
        got_answer |= d.payload_type == vip.REPLY and d.seq == 2 and d.payload[1:2] == b"\x50"
    return got_reset and got_answer


def fuzz_emulator(n: int, seed: int, check_every: int = 500, hang_s: float = 2.0) -> dict:
    rng = random.Random(seed)
    problems: list[str] = []
    errors: list[BaseException] = []
    answers = malformed = hangs = 0
    hook = threading.excepthook
    threading.excepthook = lambda args: errors.append(args.exc_value)
    t0 = time.perf_counter()
    try:
        with UdpEmulator(default_profile("visca")) as emu, \
                socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.connect(("127.0.0.1", emu.address[1]))
            batch = datagrams(rng, n)
            for i, data in enumerate(batch, 1):
                sock.send(data)
                if i % 20 == 0 or i == n:  # collect the answers now and then (the socket buffer is finite)
                    sock.settimeout(0.02)
                    while True:
                        try:
                            reply = sock.recv(2048)
                        except TimeoutError:
                            break
                        answers += 1
                        if not _well_formed_answer(reply):
                            malformed += 1
                            if len(problems) < 10:
                                problems.append(f"malformed answer {reply.hex(' ')} after {data.hex(' ')}")
                if i % check_every == 0 or i == n:
                    if not _alive(sock, hang_s):
                        hangs += 1
                        problems.append(f"no answer to RESET + inquiry after datagram {i}")
            state = emu.state()
            thread_alive = emu._thread is not None and emu._thread.is_alive()
    finally:
        threading.excepthook = hook
    if not thread_alive:
        problems.append("the emulator's thread ended")
    return {"datagrams": n, "answers": answers, "malformed_answers": malformed, "exceptions": len(errors),
            "hangs": hangs + (not thread_alive), "emulator_errors": state["errors"],
            "seconds": time.perf_counter() - t0, "problems": problems + [repr(e) for e in errors[:5]]}


class _ResetAnswerer:
    """A UDP socket on 127.0.0.1 that answers RESET (so that a :class:`ViscaIpPort` opens) and nothing else."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, peer = self.sock.recvfrom(2048)
            except (TimeoutError, OSError):
                continue
            d = vip.unframe(data)
            if d is not None and d.payload_type == vip.CONTROL and d.payload == vip.RESET:
                self.sock.sendto(vip.frame(vip.CONTROL_REPLY, d.seq, vip.RESET), peer)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.sock.close()


def fuzz_port(n: int, seed: int, hang_s: float = 0.5) -> dict:
    rng = random.Random(seed)
    profile = default_profile("visca")
    dialect = ViscaDialect(profile)
    answerer = _ResetAnswerer()
    problems: list[str] = []
    exceptions = hangs = passed_on = wrong = 0
    t0 = time.perf_counter()
    try:
        counters: dict = {}
        port = vip.ViscaIpPort("127.0.0.1", answerer.port, timeout=0.05, ack_timeout_s=0.5, counters=counters)
        try:
            for _ in range(8):  # some numbers of its own, for replies to match
                port.write(visca.pan_tilt_position_inquiry(1))
            mine = list(port._mine)
            parser = ViscaParser()
            for data in datagrams(rng, n, seqs=mine):
                before = len(port._buffer)
                t = time.perf_counter()
                try:
                    port._take(data)
                    got = port.read(4096) if port.in_waiting else b""
                    for packet in parser.feed(got):
                        dialect.event(packet)
                except Exception as exc:  # what escaped would end the driver's reader thread
                    exceptions += 1
                    if len(problems) < 10:
                        problems.append(f"{type(exc).__name__}: {exc} on {data.hex(' ')}")
                    continue
                if time.perf_counter() - t > hang_s:
                    hangs += 1
                d = vip.unframe(data)
                expected = (d.payload if d is not None and d.payload_type == vip.REPLY and d.seq in port._mine
                            and visca.message(d.payload).error != "unterminated" else b"")
                if got != expected or before:
                    wrong += 1
                    if len(problems) < 10:
                        problems.append(f"passed on {got.hex(' ')} for {data.hex(' ')}")
                passed_on += bool(got)
            port.write(visca.zoom_position_inquiry(1))  # still usable: the write goes out
        finally:
            port.close()
    finally:
        answerer.close()
    return {"datagrams": n, "passed_on": passed_on, "wrong": wrong, "exceptions": exceptions, "hangs": hangs,
            "counters": counters, "seconds": time.perf_counter() - t0, "problems": problems}

