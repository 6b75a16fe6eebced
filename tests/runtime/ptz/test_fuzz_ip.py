"""VISCA over IP fuzzing, small and seeded (the benchmark sends 10,000 datagrams each way):
random and mutated datagrams to the UDP emulator and to the driver's reply parser.
Deterministic in what is sent; a failure is a reproducible bug."""

from __future__ import annotations

from tests.runtime.ptz.fuzz_ip import fuzz_emulator, fuzz_port

N = 600


def test_fuzzed_datagrams_to_the_emulator():
    r = fuzz_emulator(N, seed=11, check_every=200)
    assert r["exceptions"] == 0 and r["hangs"] == 0 and r["malformed_answers"] == 0, r["problems"]
    assert r["answers"] > N // 4 and r["emulator_errors"] > N // 4


def test_fuzzed_datagrams_to_the_drivers_reply_parser():
    r = fuzz_port(N, seed=12)
    assert r["exceptions"] == 0 and r["hangs"] == 0 and r["wrong"] == 0, r["problems"]
    c = r["counters"]
    assert r["passed_on"] > 0 and c["malformed_datagrams"] > N // 4 and c["stale_replies"] > 0
    assert c["sequence_errors"] > 0 and c["message_errors"] > 0
