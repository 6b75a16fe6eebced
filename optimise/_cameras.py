"""Several PTZs: the layout objective over the floor of the best camera's framing, and its search.

Each PTZ has its own placement and, from the same floor estimate, its own pointing covariance and
zoom: the one-camera per-point values (:func:`~optimise.floor_values`, the aim pipeline) are
computed for every camera at once (``jax.vmap`` over the stacked one-PTZ rigs and placements), and
at each floor point the best camera counts: the largest face, or the smallest variance, among the
cameras that serve the point (weight above 0: outside their near zone). A point's weight is
``1 - prod_i (1 - w_i)``: 1 where any camera serves it fully, 0 where none does. The floor's
statistic (mean or worst) then runs over the best values as for one camera.

The best camera is a maximum over cameras, not differentiable where the best camera changes; the
search uses a weighted power mean over the cameras (:func:`~optimise.power_mean`, weights ``w_i``,
order ``+-q``) instead, which is exact for one camera and where cameras tie on equal values and
lies below the best by at most ``log(k) / q`` (relative) elsewhere; BFGS runs at ``q`` = 32, then
256 (:data:`~optimise.SHARPNESS`), and every reported value is the true best.

Placements are searched per camera over ``(reach, H_f, theta_c)``: ``theta_c`` over the ``[layout]``
box (a full circle by default, periodic), ``H_f`` over its box, and ``reach`` in [0, 1] the share of
the way from ``layout.D_c``'s lower bound to the wall along the camera's own azimuth
(:func:`wall_reach`), so that every placement is in the room or on its wall, whatever the azimuth.
The objective is symmetric under exchanging cameras of one kind, so it has several equivalent
optima and saddles between them: several starts (cameras spread evenly around the omni axis,
Halton points), and the global check is a grid of single placements (candidates) whose per-point
values are combined over every set of ``k`` candidates (exhaustively where there are at most
:data:`EXHAUSTIVE_MAX` sets, else by greedy choice and coordinate descent); BFGS runs once more
from the grid's best set when it beats every start.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from omnijax import Rig, Room
from omnijax.config import stack_ptzs as stack

from ._floor import FloorGrid
from ._objective import SENSE, FloorValues, Layout, floor_statistic, floor_values, power_mean
from ._search import _SOLVER, MAX_STEPS, SHARPNESS, Box, Progress, _halton

#: Candidate sets the grid check tries one by one at most (beyond, greedy choice and coordinate descent).
EXHAUSTIVE_MAX = 200_000
#: The room's outline is padded (its last corner repeated) to a multiple of this many corners, so that
#: rooms share compiled programs.
OUTLINE_PAD = 8
#: Names of the per-camera search variables.
CAMERA_VARIABLES = ("reach", "H_f", "theta_c")


def wall_reach(outline: Float[Array, "m 2"], theta) -> Array:
    """Distance (m) from the omni axis along azimuth ``theta`` (rad) to where the ray leaves the room's
    outline first (0 if it never does: the axis outside the room, looking away).

    A crossing of an edge is an exit where the ray meets the edge's outer side; with the outline's
    orientation ``s`` (+1 counter-clockwise), that is ``s (d x e) > 0`` for direction ``d`` and edge
    ``e``. Zero-length edges (padding) never count. Differentiable in ``theta`` except where the
    nearest exit moves from one edge to another (the room's corners).
    """
    a = outline
    e = jnp.roll(a, -1, axis=0) - a
    signed_area = 0.5 * jnp.sum(a[:, 0] * jnp.roll(a[:, 1], -1) - a[:, 1] * jnp.roll(a[:, 0], -1))
    d = jnp.stack([jnp.cos(theta), jnp.sin(theta)])
    denom = d[0] * e[:, 1] - d[1] * e[:, 0]
    exits = jnp.sign(signed_area) * denom > 1e-12
    safe = jnp.where(exits, denom, 1.0)
    dist = (a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0]) / safe
    frac = (a[:, 0] * d[1] - a[:, 1] * d[0]) / safe
    hit = exits & (dist > 0) & (frac >= 0) & (frac <= 1)
    nearest = jnp.min(jnp.where(hit, dist, jnp.inf))
    return jnp.where(jnp.isfinite(nearest), nearest, 0.0)


def kernel_rig(rig: Rig) -> Rig:
    """``rig`` as the k-camera kernels take it: its outline padded to a multiple of :data:`OUTLINE_PAD`
    corners and no excluded zones (the floor grid has left them out already), so that rooms of
    similar shape share one compiled program (and its cache entry)."""
    outline = np.asarray(rig.room.outline)
    m = -(-len(outline) // OUTLINE_PAD) * OUTLINE_PAD
    padded = np.concatenate([outline, np.repeat(outline[-1:], m - len(outline), axis=0)])
    return eqx.tree_at(lambda r: r.room, rig, Room(outline=jnp.asarray(padded), exclude=()))


class CameraBox(eqx.Module):
    """The per-camera search box: :class:`~optimise.Box` over ``(reach, H_f, theta_c)`` (broadcast over
    cameras), the lower bound of D_c and the padded outline that ``reach`` runs to."""

    box: Box
    D_c_lower: Float[Array, ""]
    outline: Float[Array, "m 2"]

    def placements(self, x: Float[Array, "k 3"], H_o) -> Layout:
        """The cameras' placements (a :class:`~optimise.Layout` of ``(k,)`` leaves) at box values ``x``."""
        reach, H_f, theta = x[:, 0], x[:, 1], x[:, 2]
        wall = jax.vmap(wall_reach, in_axes=(None, 0))(self.outline, theta)
        D_c = self.D_c_lower + reach * jnp.maximum(wall - self.D_c_lower, 0.0)
        return Layout(D_c=D_c, H_f=H_f, theta_c=theta, H_o=jnp.broadcast_to(H_o, D_c.shape))

    def from_unconstrained(self, u: Float[Array, "k 3"]) -> Float[Array, "k 3"]:
        return self.box.from_unconstrained(u)


def camera_box(rig: Rig) -> CameraBox:
    """The per-camera box of ``rig``'s ``[layout]`` section: H_f and theta_c over theirs (theta_c
    periodic over a full circle), D_c from its lower bound to the wall along each camera's azimuth."""
    lo, hi = np.asarray(rig.layout.lower), np.asarray(rig.layout.upper)
    lower = np.array([0.0, lo[1], lo[2]])
    upper = np.array([1.0, hi[1], hi[2]])
    periodic = (False, False, bool(hi[2] - lo[2] >= 2 * math.pi - 1e-9))
    box = Box(names=CAMERA_VARIABLES, lower=jnp.asarray(lower), upper=jnp.asarray(upper), periodic=periodic)
    return CameraBox(box=box, D_c_lower=jnp.asarray(lo[0]), outline=kernel_rig(rig).room.outline)


def camera_values(rigs: Rig, layouts: Layout, X, Y, step: float, live=None) -> FloorValues:
    """Per-point values of every camera: :func:`~optimise.floor_values` vmapped over the stacked one-PTZ
    ``rigs`` and their ``layouts`` (leaves of leading axis k); arrays (k, n)."""
    return jax.vmap(lambda r, lay: floor_values(r, lay, X, Y, step, live))(rigs, layouts)


def best_camera(fv: FloorValues, objective: str, sharpness=None) -> tuple[Array, Array, Array]:
    """The best camera's value at each floor point, the point's weight and which camera is best.

    ``fv`` holds every camera's values (k, n). Best: the largest face or smallest variance among the
    cameras of positive weight; with ``sharpness`` q, the weighted power mean of order ``-sense q`` over
    the cameras (weights: theirs), its smooth stand-in. Weight: ``1 - prod_i (1 - w_i)``. Which: the
    index of the best camera (of the true best), -1 where none serves the point.
    """
    sense = SENSE[objective]
    v, w = fv.per_point(objective), fv.weight
    served = w > 0
    score = jnp.where(served, -sense * v, -jnp.inf)
    which = jnp.where(jnp.any(served, axis=0), jnp.argmax(score, axis=0), -1)
    if sharpness is None:
        best = jnp.where(jnp.any(served, axis=0), -sense * jnp.max(score, axis=0), 1.0)
    else:
        best = power_mean(v, w, -sense * sharpness, axis=0)
    return best, 1.0 - jnp.prod(1.0 - w, axis=0), which


def cameras_objective(rig: Rig, rigs: Rig, layouts: Layout, X, Y, step: float, sharpness=None, live=None) -> Array:
    """The rig's configured objective and statistic over the floor of the best camera (natural units).

    With ``sharpness`` both the best camera and a worst case are their smooth power means.
    """
    spec = rig.layout
    fv = camera_values(rigs, layouts, X, Y, step, live)
    best, weight, _ = best_camera(fv, spec.objective, sharpness)
    return floor_statistic(best, weight, spec.statistic, SENSE[spec.objective],
                           sharpness if spec.statistic == "worst" else None)


def framed(rig: Rig, fv: FloorValues) -> Array:
    """Per floor point: whether some camera serves it (weight above 0), meets ``p_contain`` at its zoom
    and gives a face of at least ``layout.face_target_px`` (the operational region of several cameras)."""
    return jnp.any((fv.weight > 0) & (fv.feasible > 0) & (fv.face_px >= rig.layout.face_target_px), axis=0)


def summarise_cameras(rig: Rig, fv: FloorValues) -> dict[str, Array]:
    """Every statistic of both objectives over the best camera (true best), and ``framing``: the share
    of the room's floor points (padding left out) that are :func:`framed`."""
    out = {}
    for objective, sense in SENSE.items():
        best, weight, _ = best_camera(fv, objective)
        for statistic in ("mean", "worst"):
            out[f"{objective}_{statistic}"] = floor_statistic(best, weight, statistic, sense)
    live = fv.live[0]
    out["framing"] = jnp.sum(live * framed(rig, fv)) / jnp.sum(live)
    out["served_fraction"] = jnp.sum(live * (1.0 - jnp.prod(1.0 - fv.weight, axis=0))) / jnp.sum(live)
    return out


# ---------------------------------------------------------------------------------------------
# Compiled programs


@eqx.filter_jit
def _minimise_cameras(rig: Rig, rigs: Rig, cbox: CameraBox, X, Y, live, step: float, u0, sharpness):
    """BFGS on the cameras' unconstrained variables ``u0`` (k, 3): ``(u, steps, converged)``."""
    sense = SENSE[rig.layout.objective]

    def loss(u, args):
        rig, rigs, cbox, X, Y, live, sharpness = args
        layouts = cbox.placements(cbox.from_unconstrained(u), rig.omni.H_o)
        return sense * jnp.log(cameras_objective(rig, rigs, layouts, X, Y, step, sharpness, live))

    # reverse mode: 3k variables, one backward pass per gradient (forward mode needs 3k tangents; the
    # zoom's implicit-function JVP transposes)
    sol = optx.minimise(loss, _SOLVER, u0, args=(rig, rigs, cbox, X, Y, live, sharpness),
                        options={"autodiff_mode": "bwd"}, max_steps=MAX_STEPS, throw=False)
    return sol.value, sol.stats["num_steps"], sol.result == optx.RESULTS.successful


@eqx.filter_jit
def _evaluate_cameras(rig: Rig, rigs: Rig, cbox: CameraBox, x, X, Y, live, step: float):
    """Every camera's per-point values and the summary at box values ``x`` (k, 3), and the placements."""
    layouts = cbox.placements(x, rig.omni.H_o)
    fv = camera_values(rigs, layouts, X, Y, step, live)
    return fv, summarise_cameras(rig, fv), layouts


@eqx.filter_jit
def _candidate_values(rig: Rig, one: Rig, cbox: CameraBox, xs, X, Y, live, step: float):
    """Per-point values (objective's quantity, weight, framed) of one camera at each candidate ``xs``
    (c, 3), looped (``lax.map``) so that the intermediates stay one placement's size."""
    spec = rig.layout

    def each(x):
        layout = jax.tree.map(lambda a: a[0], cbox.placements(x[None], rig.omni.H_o))
        fv = floor_values(one, layout, X, Y, step, live)
        ok = (fv.weight > 0) & (fv.feasible > 0) & (fv.face_px >= spec.face_target_px)
        return fv.per_point(spec.objective), fv.weight, ok

    return jax.lax.map(each, xs)


# ---------------------------------------------------------------------------------------------
# The search


@dataclass
class CameraStart:
    start: np.ndarray
    x: np.ndarray
    objective: float
    steps: int
    converged: bool


@dataclass
class CamerasResult:
    """What :func:`search_cameras` found for k cameras (natural units: m, rad, rad^2 or px).

    ``x``: box values (k, 3) of the best placements; ``layouts``: their D_c, H_f, theta_c (k,);
    ``values``: every camera's per-point values there (k, n, padding removed); ``summary``: every
    statistic and the framing; ``grid_x``, ``grid_layouts``, ``grid_objective``: the grid's best set of
    candidates.
    """

    k: int
    x: np.ndarray
    layouts: dict[str, np.ndarray]
    objective: float
    summary: dict[str, float]
    values: FloorValues
    starts: list[CameraStart]
    grid_x: np.ndarray
    grid_layouts: dict[str, np.ndarray]
    grid_objective: float
    grid_method: str
    polished_from_grid: bool
    on_bound: list[dict[str, str]]
    start_objective: float
    start_summary: dict[str, float]
    seconds: dict[str, float] = field(default_factory=dict)


class Cameras:
    """The k-camera search of one room: the rig, its floor, the candidate grid (computed once and
    shared by every k) and the compiled programs.

    ``rigs``: the one-PTZ rig of each camera slot (slot i of k uses ``rigs[min(i, len - 1)]``; default
    the rig's PTZs); ``cells``: candidate values per search variable of the grid check.
    """

    def __init__(self, rig: Rig, floor: FloorGrid, rigs: Sequence[Rig] | None = None, cells: int = 7):
        self.rig = kernel_rig(rig)
        self.slots = [kernel_rig(r) for r in (rigs if rigs is not None else [rig.ptz(i) for i in
                                                                             range(rig.ptz_count)])]
        self.floor, self.cells = floor, cells
        self.cbox = camera_box(rig)
        self.X, self.Y, self.live = floor.padded()
        self.sense = SENSE[rig.layout.objective]
        self.key = f"{rig.layout.objective}_{rig.layout.statistic}"
        self._candidates: tuple[np.ndarray, dict[int, tuple[np.ndarray, ...]]] | None = None

    def rigs(self, k: int) -> list[Rig]:
        return [self.slots[min(i, len(self.slots) - 1)] for i in range(k)]

    def evaluate(self, x: np.ndarray) -> tuple[FloorValues, dict[str, float], dict[str, np.ndarray]]:
        """Per-camera values (padding removed), the summary and the placements at box values ``x`` (k, 3)."""
        rigs = stack(self.rigs(len(x)))
        fv, summ, layouts = _evaluate_cameras(self.rig, rigs, self.cbox, jnp.asarray(x, float), self.X, self.Y,
                                              self.live, self.floor.step)
        fv = jax.tree.map(lambda a: np.asarray(a)[:, :self.floor.size], fv)
        return fv, {k: float(v) for k, v in summ.items()}, {n: np.asarray(getattr(layouts, n))
                                                           for n in ("D_c", "H_f", "theta_c")}

    # -- the grid of candidates --------------------------------------------------------------

    def candidates(self, progress: Progress | None = None) -> tuple[np.ndarray, dict[int, tuple[np.ndarray, ...]]]:
        """The candidate placements (c, 3) over the box (``cells`` values per variable) and, per camera
        slot, their per-point (value, weight, framed) arrays (c, n)."""
        if self._candidates is not None:
            return self._candidates
        tick = progress or (lambda stage, done: None)
        n, box = self.cells, self.cbox.box
        axes = [np.linspace(lo, hi, n, endpoint=not periodic)
                for lo, hi, periodic in zip(np.asarray(box.lower), np.asarray(box.upper), box.periodic)]
        xs = np.array(list(itertools.product(*axes)))
        tick("grid", False)
        per_slot = {}
        for i, one in enumerate(self.slots):
            out = _candidate_values(self.rig, one, self.cbox, jnp.asarray(xs), self.X, self.Y, self.live,
                                    self.floor.step)
            per_slot[i] = tuple(np.asarray(a)[:, :self.floor.size] for a in out)
            tick("grid", True)
        self._candidates = (xs, per_slot)
        return self._candidates

    def _set_scores(self, values: list[np.ndarray], weights: list[np.ndarray]) -> np.ndarray:
        """The objective (true best camera, configured statistic) of candidate sets: ``values[i]`` and
        ``weights[i]`` (s, n) are slot i's candidate per set; returns (s,)."""
        v, w = np.stack(values), np.stack(weights)
        score = np.where(w > 0, -self.sense * v, -np.inf)
        any_served = np.any(w > 0, axis=0)
        best = np.where(any_served, -self.sense * score.max(axis=0), 1.0)
        weight = 1.0 - np.prod(1.0 - w, axis=0)
        if self.rig.layout.statistic == "mean":
            return np.sum(weight * best, axis=1) / np.sum(weight, axis=1)
        return self.sense * np.max(np.where(weight > 0, self.sense * best, -np.inf), axis=1)

    def grid_best(self, k: int, progress: Progress | None = None) -> tuple[np.ndarray, float, str]:
        """The grid's best set of k candidates: box values (k, 3), its objective and how it was found."""
        xs, per_slot = self.candidates(progress)
        c = len(xs)
        slot = [min(i, len(self.slots) - 1) for i in range(k)]
        V = [per_slot[s][0] for s in slot]
        W = [per_slot[s][1] for s in slot]
        alike = len(set(slot)) == 1
        count = math.comb(c, k) if alike else c**k
        if count <= EXHAUSTIVE_MAX:
            sets = np.array(list(itertools.combinations(range(c), k) if alike else itertools.product(range(c),
                                                                                                       repeat=k)))
            scores = np.concatenate([
                self._set_scores([V[i][chunk[:, i]] for i in range(k)], [W[i][chunk[:, i]] for i in range(k)])
                for chunk in np.array_split(sets, max(1, len(sets) // 2048))])
            best = int(np.argmin(self.sense * scores))
            return xs[sets[best]], float(scores[best]), f"exhaustive over {count} sets of {c} candidates"
        chosen: list[int] = []
        for i in range(k):  # greedy: add the candidate that helps most
            trial = [self._set_scores([V[j][[chosen[j]] * c] for j in range(i)] + [V[i]],
                                      [W[j][[chosen[j]] * c] for j in range(i)] + [W[i]])]
            chosen.append(int(np.argmin(self.sense * trial[0])))
        passes, improved = 0, True
        while improved and passes < 20:  # coordinate descent: move one camera at a time to its best candidate
            improved, passes = False, passes + 1
            for i in range(k):
                vals = [V[j][[chosen[j]] * c] if j != i else V[i] for j in range(k)]
                wts = [W[j][[chosen[j]] * c] if j != i else W[i] for j in range(k)]
                scores = self._set_scores(vals, wts)
                j = int(np.argmin(self.sense * scores))
                if self.sense * scores[j] < self.sense * scores[chosen[i]] - 1e-12 * abs(scores[j]):
                    chosen[i], improved = j, True
        final = self._set_scores([V[i][[chosen[i]]] for i in range(k)], [W[i][[chosen[i]]] for i in range(k)])
        return xs[chosen], float(final[0]), (f"greedy choice and coordinate descent ({passes} passes) over "
                                             f"{c} candidates ({count} sets)")

    # -- starts and BFGS -----------------------------------------------------------------------

    def start_points(self, k: int, count: int) -> list[np.ndarray]:
        """Starts (k, 3): the rig's own placements where it has k PTZs, the cameras spread evenly in
        azimuth (at 3/4 of the way to the wall, mid-height), then Halton points of the 3k-dimensional box."""
        box = self.cbox.box
        lo, hi = np.asarray(box.lower), np.asarray(box.upper)
        mid = 0.5 * (lo + hi)
        points = []
        if len(self.slots) == k:
            points.append(np.array([self._box_values(r) for r in self.slots]))
        theta0 = float(self.rig.foveal.theta_c)
        spread = np.array([[0.75, mid[1], theta0 + 2 * math.pi * (i + 0.5) / k] for i in range(k)])
        points.append(spread)
        primes = [p for p in range(2, 200) if all(p % q for q in range(2, int(p**0.5) + 1))]
        i = 1
        while len(points) < count:
            frac = np.array([_halton(i, b) for b in primes[:3 * k]]).reshape(k, 3)
            points.append(lo + frac * (hi - lo))
            i += 1
        return [box.inset(p) for p in points[:count]]

    def placements(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """D_c, H_f and theta_c (k,) of box values ``x`` (k, 3)."""
        layouts = self.cbox.placements(jnp.asarray(x, float), self.rig.omni.H_o)
        return {n: np.asarray(getattr(layouts, n)) for n in ("D_c", "H_f", "theta_c")}

    def _box_values(self, one: Rig) -> np.ndarray:
        """A configured PTZ's placement as box values (reach as the share of the way to its wall)."""
        theta, D_c = float(one.foveal.theta_c), float(one.foveal.D_c)
        wall = float(wall_reach(self.cbox.outline, theta))
        lo = float(self.cbox.D_c_lower)
        reach = (D_c - lo) / (wall - lo) if wall > lo else 0.0
        return np.array([reach, float(one.foveal.H_f), theta])

    def minimiser(self, k: int):
        """The compiled BFGS program for k cameras (a caller may compile it on another thread)."""
        rigs = stack(self.rigs(k))
        u0 = jnp.zeros((k, 3))
        return _minimise_cameras.lower(self.rig, rigs, self.cbox, self.X, self.Y, self.live, self.floor.step, u0,
                                       jnp.asarray(0.0)).compile()

    def _bfgs(self, program, k: int, x0: np.ndarray) -> tuple[np.ndarray, int, bool]:
        box = self.cbox.box
        u = box.to_unconstrained(jnp.asarray(x0))
        rigs = stack(self.rigs(k))
        schedule = SHARPNESS if k > 1 or self.rig.layout.statistic == "worst" else SHARPNESS[-1:]
        steps, converged = 0, True
        for q in schedule:
            u, n, ok = program(self.rig, rigs, self.cbox, self.X, self.Y, self.live, self.floor.step, u,
                               jnp.asarray(q))
            steps += int(n)
            converged = converged and bool(ok)
        return box.wrap(box.from_unconstrained(u)), steps, converged

    def search(self, k: int, progress: Progress | None = None,
               minimiser: Callable[[], Callable] | None = None) -> CamerasResult:
        """Optimise the placements of k cameras: BFGS from ``layout.starts`` starts, checked against (and
        polished from) the grid's best set. Stages reported to ``progress``: ``grid``, ``search``, ``maps``."""
        import time

        tick = progress or (lambda stage, done: None)
        t0 = time.perf_counter()
        grid_x, grid_objective, method = self.grid_best(k, progress)
        t1 = time.perf_counter()
        tick("search", False)
        program = minimiser() if minimiser is not None else _minimise_cameras
        starts = []
        for x0 in self.start_points(k, self.rig.layout.starts):
            x, steps, ok = self._bfgs(program, k, x0)
            starts.append(CameraStart(start=x0, x=x, objective=self.evaluate(x)[1][self.key], steps=steps,
                                      converged=ok))
            tick("search", True)
        best = min(starts, key=lambda s: self.sense * s.objective)
        polished = False
        if self.sense * grid_objective < self.sense * best.objective:
            x0 = self.cbox.box.inset(grid_x)
            x, steps, ok = self._bfgs(program, k, x0)
            polish = CameraStart(start=x0, x=x, objective=self.evaluate(x)[1][self.key], steps=steps, converged=ok)
            starts.append(polish)
            polished = self.sense * polish.objective < self.sense * best.objective
            best = polish if polished else best
            tick("search", True)
        t2 = time.perf_counter()
        tick("maps", False)
        fv, summ, layouts = self.evaluate(best.x)
        _, start_summ, _ = self.evaluate(starts[0].start)
        tick("maps", True)
        return CamerasResult(
            k=k, x=best.x, layouts=layouts, objective=summ[self.key], summary=summ, values=fv, starts=starts,
            grid_x=grid_x, grid_layouts=self.placements(grid_x), grid_objective=grid_objective,
            grid_method=method, polished_from_grid=polished,
            on_bound=[self.cbox.box.bound_side(x) for x in best.x], start_objective=start_summ[self.key],
            start_summary=start_summ, seconds={"grid": t1 - t0, "search": t2 - t1,
                                               "maps": time.perf_counter() - t2},
        )
