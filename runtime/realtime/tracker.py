"""Multi-person tracking on the floor: the paper's nearest neighbour, and a constant-velocity Kalman
filter with optimal assignment (the default).

Measurements are floor positions with covariances (``omnijax._track.floor_measurement``). The
Kalman filter's state is (X, Y, vX, vY) in metres and m/s, with white-acceleration process noise;
detections are assigned to tracks by the optimal (Hungarian) assignment on the Mahalanobis distance,
gated at its chi-square(2) 99.9 % quantile. A track is confirmed after ``confirm`` hits and dropped
after ``max_misses`` frames without a detection. The arithmetic (prediction, costs, assignment,
update) is vectorised and jitted in :mod:`runtime.realtime.kalman`; this module keeps the bookkeeping.

Each track also keeps what decides whether it is *trusted* as a person
(:func:`runtime.realtime.targeting.is_trusted`): its hits over the last :data:`HISTORY` frames
(``recent``, a bit mask, bit 0 the latest frame), when it was born, where (``origin``) and how far
its filtered position has since moved from there (``travel``, m).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from runtime.realtime import kalman

GATE = kalman.GATE
#: Frames of hit/miss history a track keeps (``Track.recent``).
HISTORY = 32


@dataclass
class Track:
    """One person: id, state (X, Y, vX, vY), covariance, and bookkeeping (times in seconds)."""

    id: int
    x: np.ndarray
    P: np.ndarray
    t: float
    hits: int = 1
    misses: int = 0
    captured: bool = False
    detection: int | None = None  # index of the detection it was updated with this frame
    extra: dict = field(default_factory=dict)
    recent: int = 1  # hits over the last HISTORY frames, bit 0 the latest
    born: float | None = None  # time of the first detection (default: ``t``)
    origin: np.ndarray | None = None  # position at birth (default: ``x[:2]``)
    origin_t: float | None = None  # when ``origin`` was set (default: ``born``)
    travel: float = 0.0  # largest distance of the filtered position from ``origin``, m
    trusted: bool = False  # set once by ``targeting.is_trusted`` and kept

    def __post_init__(self):
        if self.born is None:
            self.born = self.t
        if self.origin is None:
            self.origin = np.array(self.x[:2], float)
        if self.origin_t is None:
            self.origin_t = self.born

    @property
    def position(self) -> np.ndarray:
        return self.x[:2]

    def predict(self, t: float, accel_sd: float) -> tuple[np.ndarray, np.ndarray]:
        """State and covariance predicted to time ``t`` (not stored)."""
        F, Q = constant_velocity(t - self.t, accel_sd)
        return F @ self.x, F @ self.P @ F.T + Q


def constant_velocity(dt: float, accel_sd: float) -> tuple[np.ndarray, np.ndarray]:
    """Transition and process noise of the constant-velocity model over ``dt`` s (white acceleration;
    :func:`runtime.realtime.kalman.constant_velocity`, as NumPy arrays)."""
    F, Q = kalman.constant_velocity(dt, accel_sd)
    return np.asarray(F), np.asarray(Q)


#: The trackers (``LoopConfig.tracker``, ``--tracker``): constant-velocity Kalman, or the paper's nearest neighbour.
TRACKERS: tuple[str, ...] = ("kalman", "nearest")


class Tracker:
    """Keeps the people's tracks from frame to frame.

    ``mode`` is ``kalman`` (default) or ``nearest`` (the paper's nearest-neighbour: a track is
    its last position, matched to the closest detection within ``nearest_gate_m``).
    """

    def __init__(self, mode: str = "kalman", accel_sd: float = 1.5, speed_sd: float = 1.0,
                 confirm: int = 2, max_misses: int = 5, nearest_gate_m: float = 0.8):
        if mode not in TRACKERS:
            raise ValueError(f"tracker mode must be one of {TRACKERS}, got {mode!r}")
        self.mode, self.accel_sd, self.speed_sd = mode, accel_sd, speed_sd
        self.confirm, self.max_misses, self.nearest_gate_m = confirm, max_misses, nearest_gate_m
        self.tracks: list[Track] = []
        self._ids = itertools.count(1)

    def confirmed(self) -> list[Track]:
        return [t for t in self.tracks if t.hits >= self.confirm and t.misses == 0]

    def slots(self, n: int) -> tuple[np.ndarray, ...]:
        """The tracks as ``n`` slot arrays for :func:`runtime.realtime.kalman.step`: x (n, 4), P (n, 4, 4),
        t (n,), live (n,) and hits (n,) (the first ``len(tracks)`` slots, the rest empty)."""
        x, P = np.zeros((n, 4)), np.tile(np.eye(4), (n, 1, 1))
        t, live, hits = np.zeros(n), np.zeros(n, bool), np.zeros(n, np.int32)
        for i, tr in enumerate(self.tracks[:n]):
            x[i], P[i], t[i], live[i], hits[i] = tr.x, tr.P, tr.t, True, tr.hits
        return x, P, t, live, hits

    def step(self, t: float, z: np.ndarray, R: np.ndarray) -> list[Track]:
        """Advance to time ``t`` with detections ``z`` (K, 2) of covariances ``R`` (K, 2, 2)."""
        k = len(z)
        n, kk = _bucket(len(self.tracks)), _bucket(k)
        zp, Rp, valid = np.zeros((kk, 2)), np.tile(np.eye(2), (kk, 1, 1)), np.arange(kk) < k
        zp[:k], Rp[:k] = z, R
        x, P, t_tr, live, _ = self.slots(n)
        assign, x_new, P_new = kalman.step_jit(self.mode, self.accel_sd, self.nearest_gate_m, x, P, t_tr, live,
                                                t, zp, Rp, valid)
        return self.apply(t, z, R, np.asarray(assign), np.asarray(x_new), np.asarray(P_new))

    def apply(self, t: float, z: np.ndarray, R: np.ndarray, assign: np.ndarray, x_new: np.ndarray,
              P_new: np.ndarray) -> list[Track]:
        """The bookkeeping of a step whose arithmetic :func:`runtime.realtime.kalman.step` did: track
        ``i`` took detection ``assign[i]`` (-1: none) and has state ``x_new[i]``, ``P_new[i]``; then
        hits and misses, dropping, and a new track at each detection nobody took."""
        matched = set()
        for i, tr in enumerate(self.tracks):
            k = int(assign[i]) if i < len(assign) else -1
            if k >= 0:
                tr.x, tr.P, tr.t = x_new[i], P_new[i], t
                tr.hits += 1
                tr.misses = 0
                tr.detection = k
                tr.travel = max(tr.travel, float(np.linalg.norm(tr.position - tr.origin)))
                matched.add(k)
            else:
                tr.misses += 1
                tr.detection = None
            tr.recent = ((tr.recent << 1) | (k >= 0)) & ((1 << HISTORY) - 1)
        self.tracks = [tr for tr in self.tracks if tr.misses <= self.max_misses]
        for k in range(len(z)):
            if k not in matched:
                P = np.zeros((4, 4))
                P[:2, :2] = R[k]
                P[2:, 2:] = self.speed_sd**2 * np.eye(2)
                self.tracks.append(Track(id=next(self._ids), x=np.r_[z[k], 0.0, 0.0], P=P, t=t, detection=k))
        return self.tracks


def _bucket(n: int) -> int:
    """Slots for ``n`` tracks or detections: a power of two, at least 8 (few compiled shapes)."""
    return max(8, 1 << (max(n, 1) - 1).bit_length())
