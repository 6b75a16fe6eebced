"""Multi-person tracking on the floor: the paper's nearest neighbour, and a constant-velocity Kalman
filter with optimal assignment (the default).

Measurements are floor positions with covariances (``omnijax._track.floor_measurement``). The
Kalman filter's state is (X, Y, vX, vY) in metres and m/s, with white-acceleration process noise;
detections are assigned to tracks by SciPy's ``linear_sum_assignment`` on the Mahalanobis distance,
gated at its chi-square(2) 99.9 % quantile. A track is confirmed after ``confirm`` hits and dropped
after ``max_misses`` frames without a detection.

Each track also keeps what decides whether it is *trusted* as a person
(:func:`runtime.realtime.targeting.is_trusted`): its hits over the last :data:`HISTORY` frames
(``recent``, a bit mask, bit 0 the latest frame), when it was born, where (``origin``) and how far
its filtered position has since moved from there (``travel``, m).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

GATE = float(chi2.ppf(0.999, 2))
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
    """Transition and process noise of the constant-velocity model over ``dt`` s (white acceleration)."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    q = accel_sd**2 * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    Q = np.zeros((4, 4))
    Q[np.ix_([0, 2], [0, 2])] = q
    Q[np.ix_([1, 3], [1, 3])] = q
    return F, Q


H = np.hstack([np.eye(2), np.zeros((2, 2))])
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

    def step(self, t: float, z: np.ndarray, R: np.ndarray) -> list[Track]:
        """Advance to time ``t`` with detections ``z`` (K, 2) of covariances ``R`` (K, 2, 2)."""
        for tr in self.tracks:
            tr.detection = None
        if self.mode == "kalman":
            pairs = self._assign_kalman(t, z, R)
        else:
            pairs = self._assign_nearest(z)
        matched_tracks, matched_dets = set(), set()
        for ti, k in pairs:
            tr = self.tracks[ti]
            self._update(tr, t, z[k], R[k])
            tr.hits += 1
            tr.misses = 0
            tr.detection = int(k)
            tr.travel = max(tr.travel, float(np.linalg.norm(tr.position - tr.origin)))
            matched_tracks.add(ti)
            matched_dets.add(k)
        for ti, tr in enumerate(self.tracks):
            tr.recent = ((tr.recent << 1) | (ti in matched_tracks)) & ((1 << HISTORY) - 1)
            if ti not in matched_tracks:
                tr.misses += 1
        self.tracks = [tr for tr in self.tracks if tr.misses <= self.max_misses]
        for k in range(len(z)):
            if k not in matched_dets:
                P = np.zeros((4, 4))
                P[:2, :2] = R[k]
                P[2:, 2:] = self.speed_sd**2 * np.eye(2)
                self.tracks.append(Track(id=next(self._ids), x=np.r_[z[k], 0.0, 0.0], P=P, t=t, detection=k))
        return self.tracks

    def _update(self, tr: Track, t: float, z: np.ndarray, R: np.ndarray) -> None:
        if self.mode == "nearest":
            tr.x = np.r_[z, 0.0, 0.0]
            tr.P = np.zeros((4, 4))
            tr.P[:2, :2] = R
            tr.t = t
            return
        x, P = tr.predict(t, self.accel_sd)
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        tr.x = x + K @ (z - H @ x)
        tr.P = (np.eye(4) - K @ H) @ P
        tr.t = t

    def _assign_kalman(self, t, z, R) -> list[tuple[int, int]]:
        if not self.tracks or not len(z):
            return []
        cost = np.full((len(self.tracks), len(z)), 1e6)
        for i, tr in enumerate(self.tracks):
            x, P = tr.predict(t, self.accel_sd)
            S = H @ P @ H.T + R  # (K, 2, 2)
            d = z - x[:2]
            m = np.einsum("ka,kab,kb->k", d, np.linalg.inv(S), d)
            cost[i] = np.where(m <= GATE, m + np.log(np.linalg.det(S)), 1e6)
        rows, cols = linear_sum_assignment(cost)
        return [(r, c) for r, c in zip(rows, cols) if cost[r, c] < 1e6]

    def _assign_nearest(self, z) -> list[tuple[int, int]]:
        pairs, used = [], set()
        if not self.tracks or not len(z):
            return pairs
        dist = np.linalg.norm(np.stack([tr.position for tr in self.tracks])[:, None] - z[None], axis=-1)
        for flat in np.argsort(dist, axis=None):
            i, k = np.unravel_index(flat, dist.shape)
            if dist[i, k] > self.nearest_gate_m:
                break
            if i in {p[0] for p in pairs} or k in used:
                continue
            pairs.append((int(i), int(k)))
            used.add(k)
        return pairs
