"""Polar indexing of the omni image (eq 8-10 set-up): precomputed sample positions.

Built once per rig (NumPy-free, but not traced: sizes come out of the geometry):

- radial lines: ``n_theta`` lines, one sample per pixel of radius from ``r_min`` to
  ``r_max``, nearest-neighbour, with a flag for samples that repeat the previous
  pixel of the line (they are left out, so that the samples of a line stay
  independent and ``M(theta)`` is chi-square with ``samples(theta)`` times the
  measure's degrees of freedom per sample);
- psi2 windows: at each radius, how many lines either side of a line span the width of a
  person there (``window_lines``; the window sums the polar samples of those lines,
  :func:`omnijax.detection.window_sums`), and the samples in it (``window_n``);
- foot hypotheses: for each inner end ``i`` of a person along a line, the index just
  past its outer end, the index where its head and neck begin (the shoulders, on its axis), the
  image radius of its axis foot (what eq 1 turns into R_p), that floor radius R_p (m) and the
  person's azimuth span there;
- the rig's *ignore* zones (``[[zones]]``, :mod:`omnijax.config`): line samples inside them are
  left out like repeats (``line_ok``), so that nothing is detected there and a line's
  chi-square counts only the samples left.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..config import ConfigError, Rig, zone_mask
from ..geometry import SHOULDER, floor_radius, person_image_extent, point_image_radius

#: Fewest pixels of radius the polar sampling needs (a person's profile along a line).
MIN_POLAR_SPAN_PX = 8


class PolarIndex(eqx.Module):
    """Precomputed sampling of the omni image; see the module docstring."""

    theta: Float[Array, " T"]
    radii: Float[Array, " R"]
    line_index: Int[Array, "T R"]
    line_ok: Bool[Array, "T R"]
    samples: Float[Array, " T"]
    window_lines: Int[Array, " R"]
    window_n: Float[Array, " R"]
    hyp_out: Int[Array, " R"]
    #: per foot hypothesis, the index where the head and neck begin (the shoulders on the axis):
    #: ``hyp_head .. hyp_out`` is what is left of a person dressed like the floor
    hyp_head: Int[Array, " R"]
    hyp_ok: Bool[Array, " R"]
    hyp_r_f: Float[Array, " R"]
    hyp_R: Float[Array, " R"]
    hyp_dout_dH: Float[Array, " R"]
    #: per foot hypothesis, how far (px) the foot that the head's top places with the prior's height moves a
    #: metre of the person's height (the outer end fixed): the height part of a foot from the head
    hyp_dr_f_dH: Float[Array, " R"]
    hyp_width: Float[Array, " R"]
    #: per line, the samples that count (``line_ok``) in its psi2 window at each radius, summed along the
    #: radii with a leading 0 (:func:`~omnijax.detection.window_count_prefix`): a foot hypothesis's
    #: window holds the span between its ends. A constant of the rig (0.2 ms a frame when computed there)
    window_ok_prefix: Float[Array, "T R1"]
    image_size: tuple[int, int] = eqx.field(static=True)
    #: the widest psi2 window's half width (lines): how far a window sum reaches round the circle
    window_reach: int = eqx.field(static=True)
    #: the widest person's half width (lines, over the possible foot hypotheses): how far one person's
    #: run of lines can reach
    person_half_lines: float = eqx.field(static=True)

    @property
    def n_theta(self) -> int:
        return self.theta.shape[0]

    @property
    def n_r(self) -> int:
        return self.radii.shape[0]

    @property
    def hyp_first(self) -> Array:
        """Index of the first possible foot hypothesis (the innermost: the blind disc's edge)."""
        return jnp.argmax(self.hyp_ok)

    @property
    def hyp_last(self) -> Array:
        """Index of the last possible foot hypothesis (the outermost)."""
        return self.hyp_ok.shape[0] - 1 - jnp.argmax(self.hyp_ok[::-1])


def body_radius(rig: Rig) -> Array:
    """Radius of the person's body cylinder (m): half the shoulder width."""
    return 0.5 * rig.person.shoulder_width


def polar_range(rig: Rig) -> tuple[float, float]:
    """Radii (px) between which people are sought: from the floor circle of ``min_floor_radius``
    to the outer end of a person standing at the room's farthest point (or ``r_max``).

    A rig whose range is less than :data:`MIN_POLAR_SPAN_PX` wide cannot see anybody: one-line
    :class:`~omnijax.config.ConfigError` naming the keys that decide it.
    """
    omni, det = rig.omni, rig.detection
    poly = np.asarray(rig.room.outline)
    t = np.linspace(0.0, 1.0, 64)[:, None]
    edges = np.concatenate([a + t * (b - a) for a, b in zip(poly, np.roll(poly, -1, 0))])
    R_far = float(np.hypot(edges[:, 0], edges[:, 1]).max())
    r_min, r_out = (float(v) for v in _range_radii(rig, R_far))
    r_max = det.r_max if det.r_max is not None else r_out + 2.0
    W, H = omni.image_size
    r_max = min(r_max, float(omni.rim), math.hypot(W, H))
    if not r_max > r_min + MIN_POLAR_SPAN_PX:
        raise ConfigError(
            f"the room images between radii {r_min:.1f} and {r_max:.1f} px, less than {MIN_POLAR_SPAN_PX} px "
            f"apart: from detection.min_floor_radius ({float(det.min_floor_radius):g} m) to a person at the room's "
            "far end, within omni.rim and the image; nobody could be detected (check omni.H_o, omni.r_m, "
            "omni.rim, detection.r_max and room.outline)"
        )
    return r_min, r_max


@jax.jit
def _range_radii(rig: Rig, R_far):
    """Image radius of the floor circle of ``min_floor_radius`` and the outer end of a person at
    floor radius ``R_far`` (one compiled program: op by op, it took seconds at every start)."""
    omni = rig.omni
    r_min = point_image_radius(rig.detection.min_floor_radius, 0.0, omni.r_m, omni.H_o, omni.profile)
    _, r_out = person_image_extent(R_far, omni, rig.person.H_p, rig.person.R_h, body_radius(rig))
    return r_min, r_out


@jax.jit
def _geometry_tables(rig: Rig, radii, theta):
    """Pixels of the line samples; per radius: floor radius, and the outer end, the shoulders (on
    the axis) and the axis-foot radius of a person whose inner end, as the psi2 window sees it, is
    there; the outer end's derivative in the person's height, and that of the axis foot placed
    from the outer end with the prior's height (``d r_f / d H`` at a fixed outer end: a taller
    person's top is farther out, so is the foot the prior's height puts under it), by autodiff.

    Two distances from the inner end to the axis. The person's image as the window sees it (its
    outer end, its azimuth span) is that of a body whose round base starts, on average over the
    window's columns, ``pi rho / 4`` before the axis (the mean of ``sqrt(rho^2 - y^2)`` over
    ``|y| < rho``). The foot reported is ``rho`` beyond the inner end: eq 12 finds the inner end
    where the centre line meets the body, the near side of its base (``benchmarks/table1_bias.py``:
    with ``pi rho / 4`` there every foot of Table 1 fell 1-2 px short; docs/detection.md, "The foot
    is rho beyond the inner end").
    """
    omni = rig.omni
    x, y = omni.to_pixel(radii[None, :], theta[:, None])
    R_floor = floor_radius(radii, omni.r_m, omni.H_o, omni.profile)[0]
    rho = body_radius(rig)
    R_seen = R_floor + 0.25 * jnp.pi * rho
    outer = lambda R, H_p: person_image_extent(R, omni, H_p, rig.person.R_h, rho)[1]
    H_p = rig.person.H_p
    r_out, dout_dH = jax.jvp(lambda H: outer(R_seen, H), (H_p,), (jnp.ones_like(H_p),))
    dout_dR = jax.jvp(lambda R: outer(R, H_p), (R_seen,), (jnp.ones_like(R_seen),))[1]
    width = 2 * jnp.arcsin(jnp.minimum(rho / R_seen, 1.0))  # a vertical cylinder's azimuth span
    R_axis = R_floor + rho
    foot = lambda R: point_image_radius(R, 0.0, omni.r_m, omni.H_o, omni.profile)
    r_f, dr_f_dR = jax.jvp(foot, (R_axis,), (jnp.ones_like(R_axis),))
    dr_f_dH = dout_dH / dout_dR * dr_f_dR
    r_head = point_image_radius(R_axis, SHOULDER * rig.person.H_p, omni.r_m, omni.H_o, omni.profile)
    return x, y, R_floor, r_out, r_head, r_f, dout_dH, dr_f_dH, width, R_axis


def build_polar_index(rig: Rig) -> PolarIndex:
    """Sample positions, windows and foot hypotheses for ``rig`` (run once, outside jit)."""
    omni, det = rig.omni, rig.detection
    W_img, H_img = omni.image_size
    r_min, r_max = polar_range(rig)
    n_r = int(math.floor(r_max - r_min))
    radii = r_min + np.arange(n_r, dtype=float)
    theta = 2 * np.pi * np.arange(det.n_theta) / det.n_theta

    tables = _geometry_tables(rig, jnp.asarray(radii), jnp.asarray(theta))
    x, y, R_floor, r_out, r_head, hyp_r_f, dout_dH, dr_f_dH, hyp_width, hyp_R = (np.asarray(v) for v in tables)
    xi, yi = np.rint(x).astype(np.int64), np.rint(y).astype(np.int64)
    inside = (xi >= 0) & (xi < W_img) & (yi >= 0) & (yi < H_img)
    flat = np.where(inside, yi * W_img + xi, 0)
    repeat = np.zeros_like(inside)
    repeat[:, 1:] = flat[:, 1:] == flat[:, :-1]
    ignore = zone_mask(rig.zones, "ignore", (W_img, H_img))
    line_ok = inside & ~repeat & ~ignore.reshape(-1)[flat]

    # the paper's psi2 window: a person's width (px) at each radius, as lines either side
    rho = float(body_radius(rig))
    half_px = np.maximum(1.0, np.floor(radii * np.arctan(rho / (R_floor + rho))))
    window_lines = np.maximum(1, np.round(half_px / (2 * np.pi * radii / det.n_theta))).astype(np.int64)
    window_lines = np.minimum(window_lines, det.n_theta // 2 - 1)

    hyp_out = np.ceil(r_out - r_min).astype(np.int64)
    hyp_ok = (hyp_out <= n_r) & (hyp_out > np.arange(n_r))
    hyp_head = np.clip(np.floor(r_head - r_min).astype(np.int64), np.arange(n_r), np.maximum(hyp_out - 1, 0))
    from ._blobs import window_count_prefix  # the psi2 window's one definition

    window_lines_j = jnp.asarray(window_lines, dtype=jnp.int32)
    return PolarIndex(
        theta=jnp.asarray(theta), radii=jnp.asarray(radii),
        line_index=jnp.asarray(flat, dtype=jnp.int32), line_ok=jnp.asarray(line_ok),
        samples=jnp.asarray(line_ok.sum(1), dtype=float),
        window_lines=window_lines_j, window_n=jnp.asarray(2.0 * window_lines + 1),
        window_ok_prefix=window_count_prefix(jnp.asarray(line_ok), window_lines_j, int(window_lines.max())),
        hyp_out=jnp.asarray(np.minimum(hyp_out, n_r), dtype=jnp.int32),
        hyp_head=jnp.asarray(np.minimum(hyp_head, n_r), dtype=jnp.int32), hyp_ok=jnp.asarray(hyp_ok),
        hyp_r_f=jnp.asarray(hyp_r_f), hyp_R=jnp.asarray(hyp_R), hyp_dout_dH=jnp.asarray(dout_dH),
        hyp_dr_f_dH=jnp.asarray(dr_f_dH),
        hyp_width=jnp.asarray(hyp_width), image_size=(W_img, H_img), window_reach=int(window_lines.max()),
        person_half_lines=float(0.5 * hyp_width[hyp_ok].max() * det.n_theta / (2 * np.pi)) if hyp_ok.any() else 0.0,
    )
