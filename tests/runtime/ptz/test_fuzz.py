"""Parser fuzzing: 1500 random and 1500 mutated streams per parser, fixed seeds (the benchmark runs >= 1e4).

Deterministic (seeded), so no false failures: a failure is a reproducible bug.
Properties per stream: no exception, the same packets whether fed whole or in
random chunks, every packet well-formed and equal to the bytes at its offsets,
every intact valid packet found (Pelco-D: unless noise overlapping it formed a
checksum-valid packet, which is counted, and must stay rare).
"""

from __future__ import annotations

import pytest

from tests.runtime.ptz.fuzz import KINDS, run

N = 1500


@pytest.mark.parametrize("name", sorted(KINDS))
def test_fuzzed_streams(name):
    totals = run(KINDS[name], n_random=N, n_mutated=N, seed=6)
    assert totals["failures"] == 0, totals["problems"]
    assert totals["packets"] > 3 * N
    if name == "visca":
        assert totals["explained"] == 0  # a header byte always restarts framing: nothing can be lost
    else:
        assert totals["explained"] <= 0.005 * totals["packets"]
