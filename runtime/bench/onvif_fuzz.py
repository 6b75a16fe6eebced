"""Fuzzing the ONVIF emulator and driver with random and mutated SOAP bodies (``benchmarks/onvif_fuzz.py``).

- :func:`fuzz_emulator`: ``n`` bodies (genuine requests of every operation, mutated; random bytes;
  hostile XML) straight into :meth:`OnvifService.handle`: each must come back as an HTTP status and
  a SOAP body, never an exception, within ``hang_s``.
- :func:`fuzz_driver`: a hostile camera (:class:`MutatingCamera`) that answers the driver's requests
  with mutated replies; the driver keeps running (targets set, positions asked every few
  requests) until ``n`` mutated replies were served: no exception may escape a public method but
  :class:`PtzError`/``TimeoutError``, the worker must stay alive, and no call may hang.
"""

from __future__ import annotations

import math
import random
import re
import threading
import time
from dataclasses import dataclass, field

from runtime.ptz.onvif_emulator import OnvifCamera, OnvifEmulator, OnvifService
from runtime.ptz.onvif_soap import TDS, TRT, envelope
from runtime.ptz.profile import DeviceProfile

_TOKEN = '<tptz:ProfileToken>profile_1</tptz:ProfileToken>'
#: Genuine requests of every operation the emulator serves (and one it does not).
REQUESTS = [
    f"<tds:GetCapabilities xmlns:tds='{TDS}'><tds:Category>All</tds:Category></tds:GetCapabilities>",
    f"<tds:GetServices xmlns:tds='{TDS}'><tds:IncludeCapability>false</tds:IncludeCapability></tds:GetServices>",
    f"<trt:GetProfiles xmlns:trt='{TRT}'/>",
    "<tptz:GetConfigurationOptions><tptz:ConfigurationToken>ptz_config_1</tptz:ConfigurationToken>"
    "</tptz:GetConfigurationOptions>",
    f'<tptz:AbsoluteMove>{_TOKEN}<tptz:Position><tt:PanTilt x="0.25" y="-0.5"/><tt:Zoom x="0.3"/>'
    f'</tptz:Position></tptz:AbsoluteMove>',
    f'<tptz:RelativeMove>{_TOKEN}<tptz:Translation><tt:PanTilt x="0.1" y="0.05"/><tt:Zoom x="-0.1"/>'
    f'</tptz:Translation><tptz:Speed><tt:PanTilt x="0.5" y="0.5"/></tptz:Speed></tptz:RelativeMove>',
    f'<tptz:ContinuousMove>{_TOKEN}<tptz:Velocity><tt:PanTilt x="0.3" y="0"/></tptz:Velocity>'
    f'<tptz:Timeout>PT0.5S</tptz:Timeout></tptz:ContinuousMove>',
    f"<tptz:Stop>{_TOKEN}<tptz:PanTilt>true</tptz:PanTilt><tptz:Zoom>false</tptz:Zoom></tptz:Stop>",
    f"<tptz:GetStatus>{_TOKEN}</tptz:GetStatus>",
    f"<tptz:GotoHomePosition>{_TOKEN}</tptz:GotoHomePosition>",
    f"<tptz:GetPresets>{_TOKEN}</tptz:GetPresets>",
]
_HOSTILE = [
    b'<?xml version="1.0"?><!DOCTYPE l [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
    b'<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">]><l>&c;</l>',
    b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]><x>&e;</x>',
    b"<a>" * 5000 + b"</a>" * 5000,
    b"\xff\xfe<\x00e\x00",
    b"",
]
_NUMBERS = ["nan", "inf", "-inf", "1e999", "-1e308", "", "0x10", "1,5", "9" * 400, "-0", "1e-400"]


def mutate(rng: random.Random, data: bytes) -> bytes:
    """One random mutation of ``data`` (structure-aware some of the time)."""
    kind = rng.randrange(10)
    b = bytearray(data)
    if kind == 0 and b:  # flip bits
        for _ in range(rng.randint(1, 8)):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8)
        return bytes(b)
    if kind == 1 and b:  # truncate
        return bytes(b[:rng.randrange(len(b))])
    if kind == 2:  # insert random bytes
        i = rng.randrange(len(b) + 1)
        return bytes(b[:i]) + rng.randbytes(rng.randint(1, 64)) + bytes(b[i:])
    if kind == 3:  # numbers become hostile
        return re.sub(rb'"-?[0-9.]+"', lambda m: f'"{rng.choice(_NUMBERS)}"'.encode(), data)
    if kind == 4:  # drop an element
        tags = list(re.finditer(rb"<([A-Za-z0-9:]+)[^<>]*>(?:[^<]*</\1>)?", data))
        if tags:
            m = rng.choice(tags)
            return data[:m.start()] + data[m.end():]
    if kind == 5:  # duplicate a span
        if b:
            i, j = sorted(rng.randrange(len(b) + 1) for _ in range(2))
            return bytes(b[:j]) + bytes(b[i:j]) + bytes(b[j:])
    if kind == 6:  # rename a tag or a namespace
        return data.replace(rng.choice([b"tt:", b"tptz:", b"trt:", b"tds:", b"s:", b"onvif.org"]),
                            rng.choice([b"x:", b"", b"tt:", b"evil.org", b"s:"]), 1)
    if kind == 7:
        return rng.choice(_HOSTILE)
    if kind == 8:  # entirely random
        return rng.randbytes(rng.randint(0, 300))
    # change a token or a word value
    return re.sub(rb">([A-Za-z_0-9.]+)<", lambda m: b">" + rng.choice([b"", b"MOVING", b"x" * 300, b"-1",
                                                                     b"profile_2", b"\xc3("]) + b"<", data, count=1)


@dataclass
class FuzzResult:
    bodies: int = 0
    exceptions: int = 0
    hangs: int = 0
    statuses: dict = field(default_factory=dict)
    seconds: float = 0.0
    examples: list = field(default_factory=list)


def fuzz_emulator(profile: DeviceProfile, n: int, seed: int = 0, hang_s: float = 1.0, user: str | None = None
                  ) -> FuzzResult:
    """``n`` random and mutated bodies into the emulator's SOAP service (see the module docstring)."""
    rng = random.Random(seed)
    service = OnvifService(OnvifCamera(profile, time.monotonic()), "http://127.0.0.1:1", user,
                           "pw" if user else None)
    bodies = [envelope(r) for r in REQUESTS]
    out = FuzzResult()
    t_start = time.perf_counter()
    for _ in range(n):
        body = rng.choice(bodies)
        for _ in range(rng.choice((1, 1, 2, 3))):
            body = mutate(rng, body)
        t0 = time.perf_counter()
        try:
            status, reply = service.handle(body)
            if not (isinstance(status, int) and isinstance(reply, bytes) and reply):
                raise TypeError(f"handle returned {status!r}, {type(reply).__name__}")
            out.statuses[status] = out.statuses.get(status, 0) + 1
        except Exception as exc:  # what the fuzz is here to find
            out.exceptions += 1
            if len(out.examples) < 5:
                out.examples.append(f"{type(exc).__name__}: {exc} for {body[:200]!r}")
        if time.perf_counter() - t0 > hang_s:
            out.hangs += 1
        out.bodies += 1
    out.seconds = time.perf_counter() - t_start
    return out


class MutatingCamera(OnvifEmulator):
    """An :class:`OnvifEmulator` whose replies are mutated with probability ``p`` (``seed`` fixed)."""

    def __init__(self, profile: DeviceProfile, p: float = 0.5, seed: int = 0, **kwargs) -> None:
        super().__init__(profile, **kwargs)
        rng, genuine = random.Random(seed), self.service.handle
        self.mutated = 0
        lock = threading.Lock()

        def handle(data: bytes) -> tuple[int, bytes]:
            status, reply = genuine(data)
            with lock:
                if rng.random() < p:
                    self.mutated += 1
                    reply = mutate(rng, reply)
                    if rng.random() < 0.1:
                        status = rng.choice((200, 400, 401, 500, 503))
            return status, reply

        self.service.handle = handle


def fuzz_driver(profile: DeviceProfile, n: int, seed: int = 0, hang_s: float = 10.0, p: float = 0.5) -> FuzzResult:
    """The driver against :class:`MutatingCamera` until ``n`` mutated replies were served."""
    from runtime.ptz import PtzError
    from runtime.ptz.onvif import OnvifDriver

    rng = random.Random(seed + 1)
    out = FuzzResult()
    t_start = time.perf_counter()
    with MutatingCamera(profile, p=p, seed=seed) as cam:
        driver = OnvifDriver(f"onvif://127.0.0.1:{cam.address[1]}", profile)
        driver.connect(timeout=None)
        try:
            last, stalled_since = -1, time.monotonic()
            while cam.mutated < n:
                t0 = time.perf_counter()
                try:
                    driver.set_target(math.radians(rng.uniform(-150, 150)), math.radians(rng.uniform(-20, 80)),
                                      rng.uniform(1, 18))
                    if rng.random() < 0.3:
                        try:
                            driver.query_position(timeout=hang_s)
                        except (PtzError, TimeoutError):
                            pass
                    driver.stats()
                except Exception as exc:
                    out.exceptions += 1
                    if len(out.examples) < 5:
                        out.examples.append(f"{type(exc).__name__}: {exc}")
                if time.perf_counter() - t0 > hang_s:
                    out.hangs += 1
                if driver._worker is None or not driver._worker.is_alive():
                    out.exceptions += 1
                    out.examples.append(f"worker died: {driver.last_error}")
                    break
                if cam.mutated != last:
                    last, stalled_since = cam.mutated, time.monotonic()
                elif time.monotonic() - stalled_since > hang_s:  # the driver stopped asking: a hang
                    out.hangs += 1
                    break
                time.sleep(0.002)
            out.bodies = cam.mutated
        finally:
            driver.disconnect()
        out.statuses = dict(driver.stats(), requests=cam.service.counts["requests"])
        out.statuses.pop("latency_ms", None)
    out.seconds = time.perf_counter() - t_start
    return out
