"""Search of the PTZ placement: optimistix BFGS from several starts, checked against a vmapped grid.

optimistix's minimisers take no box bounds, so each bounded variable is mapped
from the real line, ``x = lower + (upper - lower) (1 + sin u) / 2``, and BFGS runs
on ``u``; a periodic azimuth box (a full circle) is searched as it is. The sine
map reaches its bounds at finite ``u`` (``+-pi / 2``) with zero slope, so an
optimum on a bound is an ordinary stationary point for BFGS (a sigmoid map would
send ``u`` off to infinity, at ever smaller steps); :meth:`Box.bound_side` names it.
The landscape, a vmapped grid of layouts over the same box, is the global check:
when its best cell beats every start, BFGS is run once more from there.
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
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, Float

from omnijax import LAYOUT_NAMES, Rig

from ._floor import FloorGrid
from ._objective import SENSE, FloorValues, Layout, configured_layout, floor_values, layout_objective, summarise

#: BFGS on the unconstrained variables (the objective is a logarithm, so tolerances are relative).
_SOLVER = optx.BFGS(rtol=1e-6, atol=1e-6)
MAX_STEPS = 200
#: Starts are kept this far (share of the box) inside its bounds, where the map to u is well scaled.
START_MARGIN = 0.02
#: A variable within this share of its box's width from a bound is reported as on that bound.
BOUND_TOL = 1e-3
#: Power-mean orders of the smooth worst case, sharpened in turn from one BFGS run to the next.
SHARPNESS = (32.0, 256.0)

#: ``progress(stage, done)``: called with ``done`` False when a stage starts (its first call
#: compiles) and True after each of its units (landscape rows, BFGS runs, the maps).
Progress = Callable[[str, bool], None]


class Box(eqx.Module):
    """Bounds of the varied placement variables and their map to an unconstrained space."""

    names: tuple[str, ...] = eqx.field(static=True)
    lower: Float[Array, " k"]
    upper: Float[Array, " k"]
    periodic: tuple[bool, ...] = eqx.field(static=True)

    # Jitted, as they are called on the host too: eagerly, each jnp operation was a program to compile.
    @jax.jit
    def from_unconstrained(self, u: Float[Array, "*c k"]) -> Float[Array, "*c k"]:
        """``x = lower + (upper - lower) (1 + sin u) / 2``; periodic variables pass through (broadcasts
        over leading axes, e.g. cameras)."""
        bounded = self.lower + (self.upper - self.lower) * 0.5 * (1.0 + jnp.sin(u))
        return jnp.where(jnp.asarray(self.periodic), u, bounded)

    @jax.jit
    def to_unconstrained(self, x: Float[Array, "*c k"]) -> Float[Array, "*c k"]:
        """The ``u`` in ``[-pi / 2, pi / 2]`` that :meth:`from_unconstrained` maps to ``x`` (inside the box)."""
        frac = (x - self.lower) / (self.upper - self.lower)
        return jnp.where(jnp.asarray(self.periodic), x, jnp.arcsin(jnp.clip(2.0 * frac - 1.0, -1.0, 1.0)))

    def wrap(self, x) -> np.ndarray:
        """``x`` with periodic variables brought back into their box."""
        x, lo, hi = np.asarray(x, float), np.asarray(self.lower), np.asarray(self.upper)
        return np.where(self.periodic, lo + np.mod(x - lo, hi - lo), x)

    def inset(self, x, margin: float = START_MARGIN) -> np.ndarray:
        """``x`` clipped to the box shrunk by ``margin`` of its width on every side."""
        lo, hi = np.asarray(self.lower), np.asarray(self.upper)
        x = self.wrap(x)
        return np.clip(x, lo + margin * (hi - lo), hi - margin * (hi - lo))

    def bound_side(self, x, tol: float = BOUND_TOL) -> dict[str, str]:
        """``{name: "lower" | "upper"}`` for each bounded variable within ``tol`` of the box's width of a bound."""
        lo, hi = np.asarray(self.lower), np.asarray(self.upper)
        frac = (np.asarray(x) - lo) / (hi - lo)
        out = {}
        for name, f, periodic in zip(self.names, frac, self.periodic):
            if not periodic and f <= tol:
                out[name] = "lower"
            elif not periodic and f >= 1 - tol:
                out[name] = "upper"
        return out

    def layout(self, x: Float[Array, " k"] | Float[np.ndarray, " k"], base: Layout) -> Layout:
        """``base`` with the varied variables set to ``x`` (a NumPy ``x`` on the host: no device op)."""
        return eqx.tree_at(lambda lay: tuple(getattr(lay, n) for n in self.names), base,
                           tuple(x[i] for i in range(len(self.names))))

    def values(self, layout: Layout) -> np.ndarray:
        """The varied variables of ``layout``, in :attr:`names` order."""
        return np.array([float(getattr(layout, n)) for n in self.names])


def search_box(rig: Rig) -> Box:
    """The box of the rig's ``[layout]`` section over its varied variables."""
    spec = rig.layout
    idx = [LAYOUT_NAMES.index(n) for n in spec.vary]
    lower, upper = np.asarray(spec.lower)[idx], np.asarray(spec.upper)[idx]
    periodic = tuple(bool(n == "theta_c" and hi - lo >= 2 * math.pi - 1e-9)
                     for n, lo, hi in zip(spec.vary, lower, upper))
    return Box(names=spec.vary, lower=jnp.asarray(lower), upper=jnp.asarray(upper), periodic=periodic)


def _with_gradient(f: Callable[[Array, object], Array]) -> Callable[[Array, object], Array]:
    """``f(u, args)`` whose derivative in ``u`` is computed with its value, in forward mode (one tangent
    per variable), and handed on as the gradient's dot product with the tangent.

    optimistix's BFGS linearises its function and applies the linear part in the branch of an accepted
    step: the objective was in its program twice, the value with its residuals in the loop and the
    tangent program in a ``cond`` (about 15 % more to compile, 6.1 against 5.2 s of CPU for the paper's
    rig). The price: the gradient is also computed at line-search points that are rejected. ``args``
    are not differentiated (a tangent of theirs is refused).
    """
    g = jax.custom_jvp(f)

    def jvp(primals, tangents):
        (u, args), (du, d_args) = primals, tangents
        zero = lambda t: isinstance(t, SymbolicZero)
        if not all(map(zero, jax.tree.leaves(d_args, is_leaf=zero))):
            raise ValueError("the objective is differentiated in u only")
        basis = jnp.eye(u.shape[0], dtype=u.dtype)
        value, grad = jax.vmap(lambda e: jax.jvp(lambda v: f(v, args), (u,), (e,)), out_axes=(None, 0))(basis)
        return value, jnp.zeros_like(value) if zero(du) else grad @ du

    g.defjvp(jvp, symbolic_zeros=True)
    return g


@eqx.filter_jit
def _minimise(rig: Rig, box: Box, base: Layout, X, Y, live, step: float, u0, sharpness):
    """BFGS on the unconstrained variables from ``u0``: ``(u, steps, converged)``."""
    spec = rig.layout
    sense = SENSE[spec.objective]

    @_with_gradient
    def loss(u, args):
        rig, box, base, X, Y, live, sharpness = args
        layout = box.layout(box.from_unconstrained(u), base)
        smooth = sharpness if spec.statistic == "worst" else None
        return sense * jnp.log(layout_objective(rig, layout, X, Y, step, smooth, live))

    sol = optx.minimise(loss, _SOLVER, u0, args=(rig, box, base, X, Y, live, sharpness),
                        options={"autodiff_mode": "fwd"}, max_steps=MAX_STEPS, throw=False)
    return sol.value, sol.stats["num_steps"], sol.result == optx.RESULTS.successful


@eqx.filter_jit
def _evaluate(rig: Rig, layouts: Layout, X, Y, live, step: float) -> tuple[FloorValues, dict[str, Array]]:
    """Per-point values and every statistic for a batch of layouts.

    Vmapped over the floor points and looped (``lax.map``) over the layouts, so
    that the intermediates (points x quadrature nodes) stay one layout's size.
    """

    def one(layout):
        fv = floor_values(rig, layout, X, Y, step, live)
        return fv, summarise(rig, fv)

    return jax.lax.map(one, layouts)


def _stack(layouts: Sequence[Layout]) -> Layout:
    """Layouts stacked on the host (NumPy): one eager device op per leaf and layout took 2 s of a cold
    ``omnijax optimise`` (470 one-element slices, each compiled on first use)."""
    return jax.tree.map(lambda *v: np.stack([np.asarray(a) for a in v]), *layouts)


#: Layouts per call of the evaluator (the last call of a list is padded).
BATCH = 16


class Evaluator:
    """Evaluates layouts in batches of one fixed size (one compilation for the landscape,
    the starts and the maps alike); per-point values come back without the padding."""

    def __init__(self, rig: Rig, floor: FloorGrid, batch: int = BATCH):
        self.rig, self.floor, self.batch = rig, floor, batch
        self.X, self.Y, self.live = floor.padded()

    def __call__(self, layouts: Sequence[Layout]) -> tuple[list[FloorValues], list[dict[str, float]]]:
        values, summaries = [], []
        for i in range(0, len(layouts), self.batch):
            chunk = list(layouts[i:i + self.batch])
            padded = chunk + [chunk[-1]] * (self.batch - len(chunk))
            fv, summ = _evaluate(self.rig, _stack(padded), self.X, self.Y, self.live, self.floor.step)
            fv = jax.tree.map(lambda a: np.asarray(a)[:, :self.floor.size], fv)
            summ = {k: np.asarray(v) for k, v in summ.items()}
            for j in range(len(chunk)):
                values.append(jax.tree.map(lambda a, j=j: a[j], fv))
                summaries.append({k: float(v[j]) for k, v in summ.items()})
        return values, summaries


@dataclass
class Landscape:
    """The objective over a grid of layouts: ``axes[name]`` (n,) and ``summaries[key]`` of shape (n,) * k."""

    axes: dict[str, np.ndarray]
    summaries: dict[str, np.ndarray]

    def best(self, key: str, sense: float) -> tuple[tuple[int, ...], float]:
        v = self.summaries[key]
        idx = np.unravel_index(np.argmin(sense * np.where(np.isfinite(v), v, sense * np.inf)), v.shape)
        return tuple(int(i) for i in idx), float(v[idx])


def landscape_layouts(box: Box, base: Layout, n: int) -> tuple[dict[str, np.ndarray], list[Layout]]:
    """A grid of ``n`` values per varied variable over the box (bounds included; a periodic box
    without its duplicate end), and the layouts at its cells in C order."""
    axes = {}
    for name, lo, hi, periodic in zip(box.names, np.asarray(box.lower), np.asarray(box.upper), box.periodic):
        axes[name] = np.linspace(lo, hi, n, endpoint=not periodic)
    cells = [box.layout(np.asarray(x), base) for x in itertools.product(*axes.values())]
    return axes, cells


def _halton(i: int, base: int) -> float:
    f, r = 1.0, 0.0
    while i > 0:
        f /= base
        r += f * (i % base)
        i //= base
    return r


def start_points(box: Box, configured: np.ndarray, count: int) -> list[np.ndarray]:
    """The configured layout (inset into the box), the box's centre, then Halton points (bases 2, 3, 5, 7)."""
    lo, hi = np.asarray(box.lower), np.asarray(box.upper)
    points = [box.inset(configured), box.inset(0.5 * (lo + hi))]
    i = 1
    while len(points) < count:
        frac = np.array([_halton(i, b) for b in (2, 3, 5, 7)[:len(lo)]])
        points.append(box.inset(lo + frac * (hi - lo)))
        i += 1
    return points[:count]


@dataclass
class StartResult:
    start: np.ndarray
    x: np.ndarray
    objective: float
    steps: int
    converged: bool


@dataclass
class SearchResult:
    """What :func:`search` found (all values in natural units: m, rad, rad^2 or px)."""

    box: Box
    configured: Layout
    best: Layout
    objective: float
    objective_start: float
    summary_start: dict[str, float]
    summary_best: dict[str, float]
    starts: list[StartResult]
    landscape: Landscape
    grid_best: Layout
    grid_objective: float
    polished_from_grid: bool
    on_bound: dict[str, str]
    values_start: FloorValues
    values_best: FloorValues
    evaluations: dict[str, int] = field(default_factory=dict)


Minimiser = Callable[..., tuple[Array, Array, Array]]


def compile_minimiser(rig: Rig, floor: FloorGrid) -> Minimiser:
    """The BFGS program of :func:`search` for ``rig`` and ``floor``, traced and compiled ahead of time.

    Compiling it is the longest step of a search; a caller may do it on another
    thread while the landscape runs and hand the result to :func:`search`.
    """
    box, base = search_box(rig), configured_layout(rig)
    X, Y, live = floor.padded()
    u0 = jnp.zeros(len(box.names))
    return _minimise.lower(rig, box, base, X, Y, live, floor.step, u0, jnp.asarray(0.0)).compile()


def _run_bfgs(minimiser: Minimiser, rig: Rig, box: Box, base: Layout, floor: FloorGrid,
              x0: np.ndarray) -> tuple[np.ndarray, int, bool]:
    """BFGS from ``x0`` (sharpened in turn for the worst case): the optimum, total steps, converged."""
    u = box.to_unconstrained(jnp.asarray(x0))
    schedule = SHARPNESS if rig.layout.statistic == "worst" else (0.0,)
    steps, converged = 0, True
    X, Y, live = floor.padded()
    for sharpness in schedule:
        u, n, ok = minimiser(rig, box, base, X, Y, live, floor.step, u, jnp.asarray(sharpness))
        steps += int(n)
        converged = converged and bool(ok)
    return box.wrap(box.from_unconstrained(u)), steps, converged


def search(rig: Rig, floor: FloorGrid, progress: Progress | None = None,
           minimiser: Callable[[], Minimiser] | None = None) -> SearchResult:
    """Optimise the PTZ placement of ``rig`` over ``floor`` under its ``[layout]`` section.

    ``minimiser``, if given, returns the compiled BFGS program
    (:func:`compile_minimiser`); it is asked for only once the landscape is done.

    Stages (reported to ``progress``): ``landscape``, the grid; ``search``, BFGS
    from every start, and once more from the grid's best cell where it beats them
    all; ``maps``, per-point values at the configured and the optimised layout.
    """
    spec = rig.layout
    key, sense = f"{spec.objective}_{spec.statistic}", SENSE[spec.objective]
    box = search_box(rig)
    base = configured_layout(rig)
    evaluate = Evaluator(rig, floor)
    tick = progress or (lambda stage, done: None)

    axes, cells = landscape_layouts(box, base, spec.landscape)
    summaries: list[dict[str, float]] = []
    tick("landscape", False)
    for i in range(0, len(cells), evaluate.batch):
        summaries += evaluate(cells[i:i + evaluate.batch])[1]
        tick("landscape", True)
    shape = tuple(len(a) for a in axes.values())
    landscape = Landscape(axes=axes, summaries={k: np.array([s[k] for s in summaries]).reshape(shape)
                                                 for k in summaries[0]})
    grid_idx, grid_objective = landscape.best(key, sense)
    grid_x = np.array([axes[n][i] for n, i in zip(box.names, grid_idx)])

    starts = []
    tick("search", False)
    bfgs = minimiser() if minimiser is not None else _minimise
    for x0 in start_points(box, box.values(base), spec.starts):
        x, steps, ok = _run_bfgs(bfgs, rig, box, base, floor, x0)
        starts.append(StartResult(start=x0, x=x, objective=math.nan, steps=steps, converged=ok))
        tick("search", True)
    _, summ = evaluate([box.layout(np.asarray(s.x), base) for s in starts])
    for s, sm in zip(starts, summ):
        s.objective = sm[key]
    best = min(starts, key=lambda s: sense * s.objective)
    polished = False
    if sense * grid_objective < sense * best.objective:
        x, steps, ok = _run_bfgs(bfgs, rig, box, base, floor, box.inset(grid_x))
        polished = evaluate([box.layout(np.asarray(x), base)])[1][0][key]
        polish = StartResult(start=box.inset(grid_x), x=x, objective=polished,
                             steps=steps, converged=ok)
        polished = sense * polish.objective < sense * best.objective
        if polished:
            best = polish
        starts.append(polish)
        tick("search", True)

    best_layout = box.layout(np.asarray(best.x), base)
    tick("maps", False)
    (v_start, v_best), (s_start, s_best) = evaluate([base, best_layout])
    tick("maps", True)
    return SearchResult(
        box=box, configured=base, best=best_layout, objective=s_best[key], objective_start=s_start[key],
        summary_start=s_start, summary_best=s_best, starts=starts, landscape=landscape,
        grid_best=box.layout(np.asarray(grid_x), base), grid_objective=grid_objective,
        polished_from_grid=polished, on_bound=box.bound_side(best.x), values_start=v_start, values_best=v_best,
        evaluations={"landscape_layouts": len(cells), "floor_points": floor.size},
    )
