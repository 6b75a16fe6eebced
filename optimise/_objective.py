"""Layout objectives: pan/tilt variance and face pixels over the floor, for one PTZ placement.

Every floor point (X, Y) goes through the aim pipeline (:func:`omnijax.aim_at_floor`) as a
detection there with the rig's default sigmas: its image position (eq 1 inverted), the pointing
covariance (autodiff, eq 13/14's quantities) and the zoom of the rig's rule. Per point:

- ``variance``: ``var(pan) + var(tilt)`` (rad^2), the paper's pan and tilt uncertainty;
- ``face_px``: the head's width in foveal pixels at the chosen zoom
  (:func:`omnijax.face_pixels`), times ``min(1, P / p_contain)`` with ``P`` the
  containment probability at the widest zoom: where even the widest zoom cannot
  hold the head with ``p_contain`` (and the rule falls back to it) the face counts
  for less, continuously, down to nothing; elsewhere the factor is 1.

The PTZ's own foot is singular (pan is undefined, its variance grows as 1 / D_p^2,
and a person under the PTZ is seen from above, never framed well). Floor points
within ``near_radius`` of it are left out of every statistic, with a weight that
rises smoothly (smoothstep) over one grid step beyond it so that the objective
stays differentiable as the PTZ moves; the maps show that zone and the reports
give its share of the floor. Floor points the omni camera cannot see (beyond its
image rim or horizon) are left out too.

Statistics over the remaining points: ``mean`` (area-weighted) and ``worst``
(largest variance, smallest face). The worst case is a maximum over points, not
differentiable where the worst point changes; the search minimises a smooth
power mean of order ``sharpness`` instead (:func:`floor_statistic`) and reports
the true worst beside it.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.special import logsumexp
from jaxtyping import Array, Bool, Float

from omnijax import Rig, aim_at_floor, containment_probability, face_pixels

#: +1 where a larger per-point value is worse (variance), -1 where it is better (face pixels).
SENSE = {"variance": 1.0, "face_px": -1.0}
OBJECTIVES = tuple(SENSE)
STATISTICS = ("mean", "worst")
#: Smallest value a per-point quantity enters the logarithms with (keeps them finite).
_TINY = 1e-30


class Layout(eqx.Module):
    """A PTZ placement: ``D_c`` (m), ``H_f`` (m), ``theta_c`` (rad), and the omni camera's ``H_o`` (m);
    scalars, or of shape (k,) for k cameras (or k layouts) at once."""

    D_c: Float[Array, "*k"]
    H_f: Float[Array, "*k"]
    theta_c: Float[Array, "*k"]
    H_o: Float[Array, "*k"]

    def as_dict(self) -> dict[str, float]:
        return {"D_c": float(self.D_c), "H_f": float(self.H_f), "theta_c": float(self.theta_c),
                "H_o": float(self.H_o)}


def configured_layout(rig: Rig) -> Layout:
    """The placement the rig file describes."""
    return Layout(D_c=rig.foveal.D_c, H_f=rig.foveal.H_f, theta_c=rig.foveal.theta_c, H_o=rig.omni.H_o)


def place(rig: Rig, layout: Layout) -> Rig:
    """``rig`` with its PTZ (and omni height) moved to ``layout``."""
    return eqx.tree_at(
        lambda r: (r.foveal.D_c, r.foveal.H_f, r.foveal.theta_c, r.omni.H_o),
        rig, (layout.D_c, layout.H_f, layout.theta_c, layout.H_o),
    )


class FloorValues(eqx.Module):
    """Per floor point: the pointing's variances (rad^2; and of sin pan, tan tilt, eq 14 and 13's
    quantities), zoom, face pixels, whether ``p_contain`` is met, the PTZ's floor distance D_p (m),
    and the point's weight in the statistics (0 to 1); with a leading axis k for k cameras."""

    var_pan: Float[Array, "*k n"]
    var_tilt: Float[Array, "*k n"]
    var_sin_pan: Float[Array, "*k n"]
    var_tan_tilt: Float[Array, "*k n"]
    zoom: Float[Array, "*k n"]
    face_px: Float[Array, "*k n"]
    feasible: Float[Array, "*k n"]
    distance: Float[Array, "*k n"]
    weight: Float[Array, "*k n"]
    live: Float[Array, "*k n"]

    def per_point(self, objective: str) -> Float[Array, "*k n"]:
        """The objective's per-point quantity: ``var(pan) + var(tilt)`` or the face pixels."""
        if objective == "variance":
            return self.var_pan + self.var_tilt
        if objective == "face_px":
            return self.face_px
        raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")


def _smoothstep(s):
    s = jnp.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def floor_values(rig: Rig, layout: Layout, X: Float[Array, " n"], Y: Float[Array, " n"], step: float,
                 live: Bool[Array, " n"] | None = None) -> FloorValues:
    """Pointing uncertainty, zoom and face pixels at floor points (X, Y) (m) for the PTZ at ``layout``.

    ``step`` (m) is the floor grid's spacing: the weight rises from 0 at
    ``near_radius`` from the PTZ's foot to 1 one step further out. Points where
    ``live`` is False (padding) get weight 0.
    """
    rig = place(rig, layout)
    omni = rig.omni
    aimed = jax.vmap(aim_at_floor, in_axes=(None, 0))(rig, jnp.stack([X, Y], -1))
    p, z, cov, lens = aimed.pointing, aimed.zoom, aimed.covariance, rig.foveal.lens
    r_f = aimed.x[:, 0]
    # The probability at the widest zoom, not at the chosen one: the same where the
    # factor is below 1 and for feasibility, and it keeps the zoom's root out of P's
    # gradient (which halved the search's compile time).
    widest = jax.vmap(containment_probability, in_axes=(None, None, 0, 0, 0, None))(
        lens, lens.zoom_range[0], cov.pan_tilt, p.tilt, p.slant, rig.person.R_h)
    shortfall = jnp.minimum(1.0, widest / rig.p_contain)
    face = face_pixels(lens, z.zoom, p.slant, rig.person.R_h) * shortfall
    seen = p.valid & (r_f <= omni.rim) & (True if live is None else live)
    near = rig.layout.near_radius
    weight = jnp.where(seen, _smoothstep((p.distance - near) / step), 0.0)
    return FloorValues(var_pan=cov.var_pan, var_tilt=cov.var_tilt, var_sin_pan=cov.var_sin_pan,
                       var_tan_tilt=cov.var_tan_tilt, zoom=z.zoom, face_px=face,
                       feasible=(widest >= rig.p_contain).astype(float), distance=p.distance, weight=weight,
                       live=jnp.ones_like(weight) if live is None else live.astype(float))


def floor_statistic(v: Float[Array, " n"], w: Float[Array, " n"], statistic: str, sense: float,
                    sharpness: float | None = None) -> Array:
    """Weighted ``mean`` or ``worst`` of per-point values ``v`` (weights ``w``).

    ``worst`` is the largest ``v`` where ``sense`` is +1 and the smallest where it is
    -1, over points of positive weight; with ``sharpness`` q it is instead the
    weighted power mean of order ``sense * q``, ``(sum w v^(sense q) / sum w)^(1 / (sense q))``,
    a smooth stand-in that approaches the worst case from the better side as q grows.
    """
    if statistic == "mean":
        return jnp.sum(w * v) / jnp.sum(w)
    if statistic != "worst":
        raise ValueError(f"statistic must be one of {STATISTICS}, got {statistic!r}")
    if sharpness is None:
        return sense * jnp.max(jnp.where(w > 0, sense * v, -jnp.inf))
    return power_mean(v, w, sense * sharpness)


def power_mean(v: Float[Array, "*a n"], w: Float[Array, "*a n"], order, axis: int | None = None) -> Array:
    """Weighted power mean ``(sum w v^order / sum w)^(1 / order)`` of positive ``v`` over ``axis`` (all
    axes: ``None``), in logarithms (finite for any order). It approaches the largest ``v`` of positive
    weight as ``order`` grows, the smallest as it falls, from the mean's side. Where every weight
    along ``axis`` is 0 it is 1, with zero gradient (the double-``where`` of a guarded division)."""
    total = jnp.sum(w, axis=axis, keepdims=True)
    some = total > 0
    w_safe = jnp.where(some, w, 1.0)
    log_v = jnp.log(jnp.maximum(jnp.where(w_safe > 0, v, 1.0), _TINY))
    log_mean = (logsumexp(order * log_v, axis=axis, b=w_safe, keepdims=True)
                - jnp.log(jnp.sum(w_safe, axis=axis, keepdims=True))) / order
    out = jnp.where(some, jnp.exp(log_mean), 1.0)
    return jnp.squeeze(out, axis=axis) if axis is not None else out.reshape(())


def summarise(rig: Rig, fv: FloorValues) -> dict[str, Array]:
    """Every statistic of both objectives from per-point values, and the floor's shares (scalars).

    Keys ``<objective>_<statistic>`` (true worst case), ``var_<q>_mean`` for q in
    pan, tilt, sin_pan, tan_tilt; ``operational_fraction``: share of the served floor (by
    weight) where ``p_contain`` is met and the face is at least ``face_target_px``
    wide; ``near_fraction``: share of the room's floor points left out.
    """
    w = fv.weight
    out = {}
    for objective, sense in SENSE.items():
        v = fv.per_point(objective)
        for statistic in STATISTICS:
            out[f"{objective}_{statistic}"] = floor_statistic(v, w, statistic, sense)
    for q in ("pan", "tilt", "sin_pan", "tan_tilt"):
        out[f"var_{q}_mean"] = floor_statistic(getattr(fv, f"var_{q}"), w, "mean", 1.0)
    ok = (fv.feasible > 0) & (fv.face_px >= rig.layout.face_target_px)
    out["operational_fraction"] = jnp.sum(w * ok) / jnp.sum(w)
    out["near_fraction"] = jnp.sum(fv.live * (w == 0)) / jnp.sum(fv.live)
    return out


def layout_objective(rig: Rig, layout: Layout, X, Y, step: float, sharpness=None, live=None) -> Array:
    """The rig's configured objective and statistic at ``layout`` (natural units: rad^2 or px).

    With ``sharpness`` the worst case is the smooth power mean of :func:`floor_statistic`.
    """
    spec = rig.layout
    fv = floor_values(rig, layout, X, Y, step, live)
    return floor_statistic(fv.per_point(spec.objective), fv.weight, spec.statistic, SENSE[spec.objective], sharpness)
