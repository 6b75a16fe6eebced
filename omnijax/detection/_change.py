"""Background model and the illumination-invariant change measure d^2 (eq 5-7, corrected).

The background is learnt from N frames robustly (people may walk through while it
learns): per pixel, the mean of the samples within 3 sigma of the temporal median.
Its chromaticity then carries ``var_factor = 1 / N_kept`` of the sensor's covariance
(eq 5); after adaptation the factor follows the exponential average. The change
measure compares the current chromaticity with the background's:

    d^2 = delta^T (Sigma(current) + var_factor Sigma(background))^-1 delta,

the covariance of (current - background) of docs/design.md section 4.4, which makes
background d^2 chi-square with 2 degrees of freedom; eq 7's ``2 Sigma`` is N = 1.
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Shaped, UInt8

from ._chroma import chromaticity_planes


class Background(eqx.Module):
    """Per-pixel background colour, the variance factor of its estimate, and the sensor noise (grey levels).

    A learnt background also keeps its learning's *minorities* (:func:`learn_background`): per pixel,
    the mean colours of the samples that disagreed with the median but agree with a candidate colour,
    and how many they were; the background's life settles from them whether the majority was the
    floor or someone who stood there (:func:`omnijax.detection.settle_learning`).
    """

    mean: Float[Array, "H W 3"]
    var_factor: Float[Array, "H W"]
    sigma: Float[Array, "H W"]
    minority: Float[Array, "M H W 3"] | None = None
    minority_n: Float[Array, "M H W"] | None = None


@functools.partial(jax.jit, static_argnames="pool")
def estimate_sensor_noise(frames: UInt8[ArrayLike, "N H W 3"], floor=0.5, pool: int = 5) -> Float[Array, "H W"]:
    """Per-pixel sensor noise sigma (grey levels, pooled over the channels) from N frames.

    From the differences ``d`` of successive frames (variance ``2 sigma^2``, quantisation included),
    counted at a pixel only where the pair is *calm* round it: the mean of ``d`` over the ``pool`` x
    ``pool`` neighbourhood, in every channel, within 3 of its robust scale over the image's unclipped
    pixels (1.4826 MAD), and ``|d|`` within 6 of ``d``'s own (at least 0.5). Noise is calm: it averages
    out over a neighbourhood. What else changes between frames does not: the soft edge of a shadow
    that moved, a lamp, a person passing. Learning frames are spread over seconds (people move a metre
    between two of them), so where people walk most pairs hold such a change of a few grey levels; a
    gate on ``|d|`` alone lets them through and put sigma at 1.2-1.5 times the truth there (six_people,
    lamps_switching, two_spectra: docs/detection.md, "The sensor noise, measured where people walk").
    Each pixel's variance is the mean of its calm ``d^2 / 2`` pooled over the ``pool`` x ``pool``
    neighbourhood (where no pair was calm, the image's median), floored at ``floor``. Compressed video
    (long runs of identical values, then jumps) needs a floor near its encoder's error, e.g. 2 grey
    levels (MOG2's minimum).
    """
    frames = jnp.asarray(frames)
    box = lambda x: jax.lax.reduce_window(x, 0.0, jax.lax.add, (pool, pool, 1)[: x.ndim], (1,) * x.ndim,
                                          "SAME") / pool**2

    def pair(i, step=1):  # one pair at a time: a stack of differences of 30 frames of 1920 x 1920 is 1.3 GB
        a, b = (frames[i + k, ::step, ::step].astype(jnp.float32) for k in (0, 1))
        return b - a, (_inside(_planes(a), 0.5, 254.5) & _inside(_planes(b), 0.5, 254.5))[..., None]

    def spreads(i):  # |d| and |local mean| on every 4th row and column, NaN where clipped
        d, clear = pair(i, 4)
        # the pool x pool mean round every 4th pixel only (box(d)[::4, ::4], a 16th of the sums)
        half = pool // 2
        local = jax.lax.reduce_window(pair(i)[0], 0.0, jax.lax.add, (pool, pool, 1), (4, 4, 1),
                                      ((half, half), (half, half), (0, 0))) / pool**2
        pick = lambda x: jnp.where(clear, jnp.abs(x), jnp.nan)
        return pick(d), pick(local)

    pairs = jnp.arange(frames.shape[0] - 1)
    d_s, local_s = jax.lax.map(spreads, pairs)
    # both are integers over a known step (8-bit differences, and their pool^2 sums): the medians by counts
    gate = 6.0 * jnp.maximum(1.4826 * _stepped_median(d_s, 1.0, 255), 0.5)
    scale_local = jnp.maximum(1.4826 * _stepped_median(local_s, 1.0 / pool**2, 255 * pool**2),
                              0.5 * math.sqrt(2.0) / pool)

    def add(acc, i):
        d = pair(i)[0]
        local = box(d)
        calm = jnp.all(jnp.abs(local) <= 3.0 * scale_local, axis=-1, keepdims=True) & (jnp.abs(d) <= gate)
        return (acc[0] + calm.sum(-1), acc[1] + jnp.where(calm, d * d, 0.0).sum(-1)), None

    H, W = frames.shape[1:3]
    zero = jnp.zeros((H, W), jnp.float32)
    (n, ssq), _ = jax.lax.scan(add, (zero, zero), pairs)
    n, ssq = box(n), box(ssq)
    var = ssq / jnp.maximum(n, 1e-6) / 2.0
    var = jnp.where(n > 0, var, jnp.nanmedian(jnp.where(n > 0, var, jnp.nan)))
    return jnp.sqrt(jnp.maximum(var, jnp.asarray(floor, jnp.float32) ** 2))


def _stepped_median(x: Float[ArrayLike, "..."], step: float, top: int) -> Float[Array, ""]:
    """``jnp.nanmedian(x)`` for values that are whole multiples of ``step`` in ``[0, top * step]``
    (NaN where missing), from the count of each multiple: exact, and one pass where the sort behind
    ``nanmedian`` took 0.36 s for a million samples on the CPU."""
    k = jnp.round(jnp.nan_to_num(jnp.asarray(x), nan=-1.0) / step).astype(jnp.int32)
    counts = jnp.zeros(top + 2, jnp.int32).at[jnp.where(k < 0, top + 1, jnp.minimum(k, top))].add(1)
    below = jnp.cumsum(counts[: top + 1])  # samples at or under each multiple
    m = below[-1]
    rank = lambda r: jnp.searchsorted(below, r, side="right")  # the value of order statistic r (0-based)
    return jnp.where(m > 0, 0.5 * (rank((m - 1) // 2) + rank(m // 2)) * step, jnp.nan)


#: A learning sample agrees with the pixel's median colour when its d^2 against it is under the
#: chi-square(2) 1 - 1e-3 quantile.
AGREE = 13.8155


@jax.jit
def learn_background(frames: UInt8[ArrayLike, "N H W 3"], sigma=None, floor=0.5) -> Background:
    """Background from N frames: per pixel, the mean of the samples whose chromaticity agrees with the
    median colour's (d^2 of eq 6-7 between the two below :data:`AGREE`; people walking or standing
    through less than half of the frames are left out, and so is nothing that only changes the light's
    intensity: a lamp switching or a shadow, under one spectrum). ``var_factor = 1 / kept``, so a
    pixel whose frames agreed less often (``kept`` small: it was occupied for a while) is known to be
    less certain; :func:`learned` says which pixels agreed in most frames. Where no colour has half
    of the frames the median is a mixture none of them showed; that is left as it is (a change
    against the floor and against whoever stands there at the end), and the background's life
    repairs its ghost at once (:mod:`omnijax.detection._life`: unsettled samples). A clipped sample
    (a channel at 0 or 255: a white shirt under a lamp) agrees with any colour, since d^2 holds no
    evidence there; it is kept out of the mean unless every frame of the pixel was clipped.

    The samples left out are kept as three *minorities* (``minority`` (3 H W 3), ``minority_n`` (3 H
    W)), for :func:`omnijax.detection.settle_learning`: the mean of those that agree with a candidate
    colour, and their count (the mean where there are none), for three candidates: their own median,
    and the medians of the window's first and last thirds (someone who slowed down onto the spot and
    stayed leaves no colour with a majority, but the first frames show the floor; someone who stood
    there through most of the window and left, the last ones).

    ``sigma`` (grey levels, scalar or per pixel) defaults to :func:`estimate_sensor_noise` of
    the frames with the given ``floor``.
    """
    f = jnp.asarray(frames, jnp.float32)
    H, W = f.shape[1:3]
    sigma = estimate_sensor_noise(frames, floor) if sigma is None else jnp.broadcast_to(
        jnp.asarray(sigma, jnp.float32), (H, W))
    med = _temporal_median(jnp.asarray(frames))
    # a clipped sample agrees with any colour (d^2 carries no evidence there): it is averaged only
    # where every frame was clipped
    unclipped = _inside(_planes(f), 0.5, 254.5)
    unclipped = unclipped | ~unclipped.any(0)
    keep = ((change_measure(f, jnp.broadcast_to(med, f.shape), 1.0, sigma) <= AGREE) & unclipped)[..., None]
    n = jnp.maximum(_frame_sum(keep), 1)
    mean = _frame_sum(jnp.where(keep, f, 0.0)) / n
    mean = jnp.where(keep.any(0), mean, med)
    # the minorities: the unclipped samples left out, around each of three candidate colours: their own
    # median, and the medians of the window's first and last thirds (someone who slowed down onto the
    # spot leaves no majority at all, but the first frames show the floor; someone who stood there
    # and left, the last frames)
    other = ~keep[..., 0] & unclipped
    raw = jnp.asarray(frames)
    third = max(raw.shape[0] // 3, 1)
    candidates = (_temporal_median(jnp.where(other[..., None], raw, jnp.zeros((), raw.dtype)), _frame_sum(other)),
                  _temporal_median(raw[:third]), _temporal_median(raw[-third:]))
    agree = [(change_measure(f, jnp.broadcast_to(c, f.shape), 1.0, sigma) <= AGREE) & other for c in candidates]
    n2 = jnp.stack([_frame_sum(a) for a in agree])
    minority = jnp.stack([_frame_sum(jnp.where(a[..., None], f, 0.0)) for a in agree]) / jnp.maximum(n2, 1)[..., None]
    return Background(mean=mean, var_factor=1.0 / n[..., 0].astype(jnp.float32), sigma=sigma,
                      minority=jnp.where(n2[..., None] > 0, minority, mean), minority_n=n2.astype(jnp.float32))


def learned(var_factor: Float[ArrayLike, "*b"], frames: float | ArrayLike,
            share: float = 2.0 / 3.0) -> Bool[Array, "*b"]:
    """Samples of a background learnt from ``frames`` frames whose frames agreed in at least ``share``
    of them (``1 / var_factor`` of them were kept): certainly background. The others were occupied
    for more than a third of the learning window; the background's life learns them as they are seen
    unoccupied (:mod:`omnijax.detection._life`)."""
    return 1.0 / jnp.asarray(var_factor) >= share * frames - 1e-3


def _frame_sum(x: Shaped[Array, "N H W *c"]) -> Array:
    """The sum over the frames (axis 0), as a chain of N - 1 elementwise adds that XLA fuses with
    what made them: its CPU reduction along the major axis took 0.19 s for 20 frames of 640 x 480 x 3,
    ten times this."""
    return functools.reduce(jnp.add, list(x.astype(jnp.int32) if x.dtype == jnp.bool_ else x))


def _temporal_median(frames: Shaped[Array, "N H W 3"], count=None) -> Float[Array, "H W 3"]:
    """Per-pixel median over the frames: sorted in their own (8-bit) type along the minor
    axis, which XLA's CPU sort does several times faster than a float median over axis 0.

    ``count`` (H W): the median of the last ``count`` of each pixel's samples once sorted, for frames
    whose other samples were set to 0 (any 0 among the counted ones ties with them, so the order
    statistics are unchanged)."""
    n = frames.shape[0]
    srt = jnp.sort(jnp.moveaxis(frames, 0, -1), axis=-1).astype(jnp.float32)
    if count is None:
        return 0.5 * (srt[..., (n - 1) // 2] + srt[..., n // 2])
    c = jnp.asarray(count, jnp.int32)[..., None, None]
    lo = jnp.clip(n - c + (c - 1) // 2, 0, n - 1)
    hi = jnp.clip(n - c + c // 2, 0, n - 1)
    return 0.5 * (jnp.take_along_axis(srt, lo, -1)[..., 0] + jnp.take_along_axis(srt, hi, -1)[..., 0])


class ReferenceTerms(eqx.Module):
    """What d^2 needs of the background, per sample: its chromaticity, eq 5's covariance
    entries per unit noise variance scaled by ``var_factor``, and whether it is unclipped."""

    r: Float[Array, "*b"]
    g: Float[Array, "*b"]
    rr: Float[Array, "*b"]
    rg: Float[Array, "*b"]
    gg: Float[Array, "*b"]
    unclipped: Bool[Array, "*b"]


def reference_terms(background: Float[ArrayLike, "*b 3"], var_factor: Float[ArrayLike, "*#b"]) -> ReferenceTerms:
    """The background's half of eq 6-7, computed once per background update."""
    planes = _planes(background)
    r, g, rr, rg, gg = chromaticity_planes(*planes)
    v = jnp.asarray(var_factor, jnp.float32)
    return ReferenceTerms(r=r, g=g, rr=v * rr, rg=v * rg, gg=v * gg, unclipped=_inside(planes, 1.0, 254.0))


def change_against(
    current: Float[ArrayLike, "*b 3"], ref: ReferenceTerms, sigma: Float[ArrayLike, "*#b"]
) -> Float[Array, "*b"]:
    """d^2 of eq 6-7 (corrected) of ``current`` against precomputed background terms."""
    return change_of_terms(current_terms(current), ref, sigma)


def current_terms(current: Float[ArrayLike, "*b 3"]) -> tuple[Array, ...]:
    """The current colour's half of eq 6-7 (:func:`change_of_terms`): its chromaticity, eq 5's covariance
    entries per unit noise variance, and whether it is unclipped; computed once where one colour is
    measured against several backgrounds (broadcast)."""
    cur = _planes(current)
    return (*chromaticity_planes(*cur), _inside(cur, 0.5, 254.5))


def change_of_terms(cur: tuple[Array, ...], ref: ReferenceTerms, sigma: Float[ArrayLike, "*#b"]) -> Float[Array, "*b"]:
    """d^2 of eq 6-7 (corrected) from the current colour's terms (:func:`current_terms`) and the
    background's (:func:`reference_terms`)."""
    r1, g1, a1, b1, c1, inside = cur
    s2 = jnp.asarray(sigma, jnp.float32) ** 2
    a, b, c = s2 * (a1 + ref.rr), s2 * (b1 + ref.rg), s2 * (c1 + ref.gg)
    dx, dy = r1 - ref.r, g1 - ref.g
    d2 = (c * dx * dx - 2 * b * dx * dy + a * dy * dy) / (a * c - b * b)
    return jnp.where(inside & ref.unclipped, d2, 2.0)


def change_across_light(current: Float[ArrayLike, "*b 3"], background: Float[ArrayLike, "*b 3"],
                        var_factor: Float[ArrayLike, "*#b"], sigma: Float[ArrayLike, "*#b"],
                        light_axis: tuple[float, float, float]) -> Float[Array, "*b"]:
    """d^2 of a change of colour that is not a change of the light's colour along ``light_axis``.

    Under lights of two colours (daylight and warm lamps) the floor a person shades from one of them
    is lit by the other alone, and a lamp switching relights the floor round it: the colour becomes
    ``B exp(t w)`` per channel, ``w = light_axis`` (log RGB; any ``t``), a change of chromaticity the
    paper's eq 5-7 see as a person. In log chromaticity ``(log R/G, log B/G)`` that relighting is a
    translation by ``t (w_R - w_G, w_B - w_G)``, the same for every colour; eq 5's covariance there
    is ``sigma^2 [[1/R^2 + 1/G^2, 1/G^2], [1/G^2, 1/B^2 + 1/G^2]]`` per colour (the current one, and
    the background's scaled by ``var_factor``), and d^2 is the least Mahalanobis distance over the
    relightings the change of brightness allows. ``w`` is the log ratio of the two lights' colours (a
    grey card under one and under the other); ``t`` is then, to first order, the change of the second
    light's share of the brightness, and taking away (or adding) a share ``f`` of the light changes the
    brightness by the factor ``s = 1 - f`` (or ``1 / (1 - f)``): so ``|t| <= |1 - s| / max(s, 1)``,
    with ``s`` the current over the background's sum of channels. A shadow of one light, or a lamp
    switching, is left out; a person of the floor's brightness keeps all of the paper's d^2, and so,
    nearly, does the unchanged background (the paper's chi-square(2) thresholds apply; the noise of
    ``s`` lets a little go: mean 1.72 against 2 at sigma 2 grey levels on a floor of 60-200, so they
    are a little conservative); only someone both darker (or brighter) than the floor and a warmer or
    bluer version of it by less than that darkening allows is lost. A swap of the lights (a lamp
    switched on, then a shadow from the other light on the same spot) is bounded by neither; the
    background's life follows a relit sample within a few frames
    (:data:`omnijax.detection._life.RELIGHT_RATE`). Clipped samples count at the mean, 2.
    """
    cur, bg = _planes(current), _planes(background)

    def logs(planes):
        R, G, B = (jnp.maximum(x, 0.5) for x in planes)  # quantisation: a 0 channel is under 0.5
        return jnp.log(R / G), jnp.log(B / G), 1.0 / (R * R), 1.0 / (G * G), 1.0 / (B * B)

    x1, y1, iR1, iG1, iB1 = logs(cur)
    x0, y0, iR0, iG0, iB0 = logs(bg)
    s2, v = jnp.asarray(sigma, jnp.float32) ** 2, jnp.asarray(var_factor, jnp.float32)
    a = s2 * (iR1 + iG1 + v * (iR0 + iG0))
    b = s2 * (iG1 + v * iG0)
    c = s2 * (iB1 + iG1 + v * (iB0 + iG0))
    dx, dy = x1 - x0, y1 - y0
    det = a * c - b * b
    wx, wy = light_axis[0] - light_axis[1], light_axis[2] - light_axis[1]
    ux, uy = c * wx - b * wy, a * wy - b * wx  # det A^-1 w
    along, ww = ux * dx + uy * dy, ux * wx + uy * wy
    # the relighting that explains most, within what the change of brightness allows (see above)
    bright = (cur[0] + cur[1] + cur[2]) / jnp.maximum(bg[0] + bg[1] + bg[2], 1.0)
    reach = jnp.minimum(jnp.abs(1.0 - bright) / jnp.maximum(bright, 1.0), 1.0)
    t = jnp.clip(along / ww, -reach, reach)
    d2 = (c * dx * dx - 2 * b * dx * dy + a * dy * dy - 2 * t * along + t * t * ww) / det
    return jnp.where(_inside(cur, 0.5, 254.5) & _inside(bg, 1.0, 254.0), d2, 2.0)


def change_measure(current: Float[ArrayLike, "*b 3"], background: Float[ArrayLike, "*b 3"],
                   var_factor: Float[ArrayLike, "*#b"], sigma: Float[ArrayLike, "*#b"]) -> Float[Array, "*b"]:
    """d^2 of eq 6-7 (corrected) between current and background colours, any batch shape.

    ``var_factor`` scales eq 5's covariance at the background colour (1 / N for a
    mean of N frames); the current colour contributes its own eq 5 covariance;
    ``sigma`` is the sensor noise (grey levels), per sample or one for all.
    Clipped samples (a channel at 0 or 255, now or in the background) are not
    illumination invariant: they carry no evidence and count at the measure's mean, 2.
    """
    return change_against(current, reference_terms(background, var_factor), sigma)


def _planes(rgb) -> tuple[Array, Array, Array]:
    rgb = jnp.asarray(rgb, jnp.float32)
    return rgb[..., 0], rgb[..., 1], rgb[..., 2]


def _inside(planes, lo: float, hi: float) -> Array:
    """All three channel planes strictly inside ``(lo, hi)`` (not clipped)."""
    lowest = jnp.minimum(jnp.minimum(planes[0], planes[1]), planes[2])
    highest = jnp.maximum(jnp.maximum(planes[0], planes[1]), planes[2])
    return (lowest > lo) & (highest < hi)


def grey_change_measure(current: Float[ArrayLike, "*b 3"], background: Float[ArrayLike, "*b 3"],
                        var_factor: Float[ArrayLike, "*#b"], sigma: Float[ArrayLike, "*#b"]) -> Float[Array, "*b"]:
    """The grey-level counterpart of :func:`change_measure`, chi-square with 1 dof on the background.

    ``(I - I_b)^2 / ((1 + var_factor) sigma^2 / 3)`` with ``I`` the mean of R, G, B:
    what the detector sees without illumination invariance (for comparison only).
    """
    cur, bgr = _planes(current), _planes(background)
    d = (sum(cur) - sum(bgr)) / 3.0
    d2 = d * d / ((1.0 + jnp.asarray(var_factor)) * jnp.asarray(sigma) ** 2 / 3.0)
    return jnp.where(_inside(cur, 0.5, 254.5) & _inside(bgr, 1.0, 254.0), d2, 1.0)


#: Change measures by name, with their degrees of freedom per background sample.
MEASURES = {"chromaticity": (change_measure, 2), "grey": (grey_change_measure, 1)}


def change_image(
    frame: UInt8[ArrayLike, "H W 3"], bg: Background, measure: str = "chromaticity"
) -> Float[Array, "H W"]:
    """d^2 at every pixel of ``frame`` (for overlays and per-pixel masks)."""
    return MEASURES[measure][0](jnp.asarray(frame, jnp.float32), bg.mean, bg.var_factor, bg.sigma)


def adapt_background(bg: Background, frame: UInt8[ArrayLike, "H W 3"], still: Bool[ArrayLike, "H W"],
                     rate) -> Background:
    """Exponential update ``mean <- (1 - a) mean + a frame`` where ``still`` (nothing detected).

    The estimate's variance factor follows: ``v <- (1 - a)^2 v + a^2``, so that d^2
    keeps its chi-square(2) calibration while the background tracks slow drift.
    """
    a = jnp.where(jnp.asarray(still), rate, 0.0).astype(jnp.float32)
    f = jnp.asarray(frame, jnp.float32)
    mean = bg.mean + a[..., None] * (f - bg.mean)
    var_factor = (1 - a) ** 2 * bg.var_factor + a * a
    return Background(mean=mean, var_factor=var_factor, sigma=bg.sigma)


