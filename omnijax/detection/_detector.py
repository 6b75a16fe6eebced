"""The people detector: steps 1-6 of the paper's sections 3.2.4-3.2.6 as one jitted function.

1. chromaticity of the frame at the polar samples (eq 5),
2. d^2 against the background (eq 6-7, corrected),
3. radial sums ``M(theta)`` (eq 8),
4. psi1: hysteresis sectors with thresholds from x_f and x_m (eq 9-10, corrected),
5. psi2: the windowed profile at every line of the sectors,
6. the people they hold one at a time (:mod:`omnijax.detection._blobs`: eq 11-12, corrected, per
   person; beyond the paper, which takes one per sector): each one's foot ``r_f``, ``theta_f`` (the
   centre of its own run of lines), their sigmas and the person's contrast.

Build a :class:`Detector` once per rig (:func:`build_detector`: thresholds and the
``sigma_r_f`` table are simulated there), sample the background at the polar
lines (:func:`line_background`: the detector and the background's life work on the
polar samples only), then call :func:`detect` per frame; it never recompiles for frames
of the same size.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray, UInt8

from ..camera import OmniCamera
from ..config import Rig
from ..geometry import wrap_2pi
from ._blobs import People, a_person, find_people, merge_fragments, own_feet, parted
from ._change import MEASURES, Background, ReferenceTerms, change_across_light, change_against, reference_terms
from ._foot import FootSigmaTable, build_foot_sigma_table, foot_sigma_lookup
from ._indexing import Thresholds, build_thresholds, gather_rgb, hysteresis_sectors
from ._polar import PolarIndex, build_polar_index


class Detector(eqx.Module):
    """Everything :func:`detect` needs besides the frame and the background."""

    omni: OmniCamera
    polar: PolarIndex
    thresholds: Thresholds
    foot_sigma: FootSigmaTable
    sigma_H_p: Float[Array, ""]
    max_people: int = eqx.field(static=True)
    measure: str = eqx.field(static=True, default="chromaticity")
    #: ``[detection] light_axis``: a change of the light's colour along it, as far as the change of
    #: brightness allows, is no change (:func:`~omnijax.detection.change_across_light`)
    light_axis: tuple[float, float, float] | None = eqx.field(static=True, default=None)
    #: ``[detection] noise_margin``: d^2 against the learnt sensor noise times this (:func:`line_background`)
    noise_margin: Float[Array, ""] = eqx.field(default=1.0, converter=jnp.asarray)

    @property
    def dof_per_sample(self) -> int:
        return MEASURES[self.measure][1]


def build_detector(rig: Rig, key: PRNGKeyArray | None = None, measure: str = "chromaticity") -> Detector:
    """Polar index, thresholds (simulated eq 9) and the sigma_r_f table for ``rig`` (seconds, once).

    ``measure`` is ``chromaticity`` (the paper's, eq 5-7; with ``[detection] light_axis`` a relighting
    along it is left out, :func:`~omnijax.detection.change_across_light`) or ``grey`` (grey levels,
    for comparison: what illumination invariance buys).
    """
    if measure not in MEASURES:
        raise ValueError(f"measure must be one of {sorted(MEASURES)}, got {measure!r}")
    key = jax.random.key(0) if key is None else key
    k_th, k_foot = jax.random.split(key)
    polar = build_polar_index(rig)
    axis = rig.detection.light_axis if measure == "chromaticity" else None
    dps = MEASURES[measure][1]
    return Detector(
        omni=rig.omni, polar=polar, thresholds=build_thresholds(rig, polar, k_th, dps),
        foot_sigma=build_foot_sigma_table(polar, k_foot, rig.detection.foot_mc_profiles, dps,
                                          rig.sigmas.H_p),
        sigma_H_p=jnp.asarray(rig.sigmas.H_p), max_people=rig.detection.max_people, measure=measure,
        light_axis=axis, noise_margin=rig.detection.noise_margin,
    )


def with_zones(detector: Detector, rig: Rig, key: PRNGKeyArray | None = None) -> Detector:
    """``detector`` under ``rig``'s ``[[zones]]``: the polar index (its ignore mask) and the thresholds
    rebuilt, the ``sigma_r_f`` table kept; the same as :func:`build_detector` (same ``key``) for that
    rig, in a fraction of the time. Same shapes: the detector's compiled calls are reused."""
    key = jax.random.key(0) if key is None else key
    polar = build_polar_index(rig)
    thresholds = build_thresholds(rig, polar, jax.random.split(key)[0], detector.dof_per_sample)
    return eqx.tree_at(lambda d: (d.polar, d.thresholds), detector, (polar, thresholds))


class LineBackground(eqx.Module):
    """The background at the polar line samples: its colour, the variance factor of that estimate,
    the sensor noise, and eq 5's terms of the colour (:func:`line_background`, or the background's
    life, :mod:`omnijax.detection._life`, which keeps it up to date)."""

    mean: Float[Array, "T R 3"]
    var_factor: Float[Array, "T R"]
    sigma: Float[Array, "T R"]
    ref: ReferenceTerms


@jax.jit
def line_background(detector: Detector, bg: Background) -> LineBackground:
    """A learnt (per pixel) background at the polar line samples, its noise the learnt sensor noise times
    ``detector.noise_margin`` (what every d^2 of the detector and of the background's life is taken
    against)."""
    idx = detector.polar.line_index
    sigma = bg.sigma.reshape(-1)[idx] * detector.noise_margin
    return lines_from(gather_rgb(bg.mean, idx), bg.var_factor.reshape(-1)[idx], sigma)


def lines_from(mean, var_factor, sigma) -> LineBackground:
    """A :class:`LineBackground` from its colour, variance factor and noise (eq 5's terms computed)."""
    return LineBackground(mean=mean, var_factor=var_factor, sigma=sigma, ref=reference_terms(mean, var_factor))


class Detections(eqx.Module):
    """Up to K people (``valid`` marks the real ones), strongest first.

    ``r_f`` (px) is the image radius of the person's axis foot, ``theta_f`` (rad) the centre of
    the person's run of lines; ``sigma_r_f``, ``sigma_theta_f`` their errors (:func:`_foot_sigmas`):
    the quality part, which the sigma rule scales, and ``bound_r_f``, ``bound_theta_f`` the bound
    part of a foot the detector could not see (the person reaches past the sampled radii), which it
    adds as it is (:func:`omnijax.aiming.detection_sigmas`); ``height_r_f`` (px per metre) how far
    the foot's radius moves with the person's height above the prior's when the head's top and the
    prior's height place it (:attr:`PolarIndex.hyp_dr_f_dH` at the foot), and ``from_head`` whether
    they did (:func:`_foot_sigmas`): the aim's height prior errs against it
    (:func:`omnijax.aiming.height_coupling`);
    ``contrast`` is the non-centrality per sample measured on the profile (over the samples no
    stronger person explained); ``r_in``/``r_out`` (px) the person's radial extent (the foot
    hypothesis's, or eq 12's where the foot moved out to a head seen in brightness alone,
    :data:`~omnijax.detection._blobs.SHADE_LOG`: the background's life reads the sides over it);
    ``theta_l``/``theta_r`` the run's edges; ``peak`` the profile's d^2 excess;
    ``region`` the polar samples the person explained, (first line, last line, first radius
    index, end radius index), ``last`` may pass ``T - 1``: what the background's life re-learns
    when the person is a ghost. ``strip`` marks the runs that are not people's
    (:func:`~omnijax.detection.a_person`: one line, or a head alone narrower than a head; not
    ``valid``): the background's life still judges them, a strip being as often the last of a ghost
    (:func:`life_candidates`).
    """

    valid: Bool[Array, " K"]
    r_f: Float[Array, " K"]
    theta_f: Float[Array, " K"]
    sigma_r_f: Float[Array, " K"]
    sigma_theta_f: Float[Array, " K"]
    bound_r_f: Float[Array, " K"]
    bound_theta_f: Float[Array, " K"]
    height_r_f: Float[Array, " K"]
    from_head: Bool[Array, " K"]
    contrast: Float[Array, " K"]
    r_in: Float[Array, " K"]
    r_out: Float[Array, " K"]
    theta_l: Float[Array, " K"]
    theta_r: Float[Array, " K"]
    peak: Float[Array, " K"]
    region: Int[Array, "K 4"]
    strip: Bool[Array, " K"] | None = None


def life_candidates(dets: Detections) -> Bool[Array, " K"]:
    """What the background's life judges: the people, and the strips beside them (one line wide, not
    people, but the last of a ghost as often as a shadow's edge: left unjudged, standing_start 9005
    kept one 5.4 s)."""
    return dets.valid if dets.strip is None else dets.valid | dets.strip


class DetectionTrace(eqx.Module):
    """Intermediate results, for the background's life, overlays and characterisation: the radial
    sums ``M`` (eq 8), d^2 at every polar sample (0 where a sample does not count), the frame at the
    polar samples (``cur``, float32 RGB), and, once the detections were judged for ghosts before anyone
    read them (:func:`~omnijax.detection.set_aside_ghosts`), their ghost evidence
    (:class:`~omnijax.detection.Evidence`; ``None`` until then): the background's life reads both
    instead of computing them again."""

    M: Float[Array, " T"]
    d2: Float[Array, "T R"]
    cur: Float[Array, "T R 3"]
    evidence: object = None


def line_change(detector: Detector, frame: UInt8[Array, "H W 3"], lines: LineBackground) -> Array:
    """Steps 1-2: d^2 at every polar sample (0 where ``line_ok`` is false)."""
    return _change_of(detector, polar_frame(detector, frame), lines)


def polar_frame(detector: Detector, frame: UInt8[Array, "H W 3"]) -> Float[Array, "T R 3"]:
    """The frame at the polar samples (float32 RGB)."""
    return gather_rgb(frame, detector.polar.line_index).astype(jnp.float32)


def _change_of(detector: Detector, cur: Float[Array, "T R 3"], lines: LineBackground) -> Array:
    return jnp.where(detector.polar.line_ok, change_at(detector, cur, lines), 0.0)


def change_at(detector: Detector, cur: Float[Array, "T R 3"], lines: LineBackground) -> Float[Array, "T R"]:
    """The detector's change measure of colours ``cur`` at the polar samples against ``lines``."""
    if detector.light_axis is not None:
        return change_across_light(cur, lines.mean, lines.var_factor, lines.sigma, detector.light_axis)
    if detector.measure == "chromaticity":
        return change_against(cur, lines.ref, lines.sigma)
    return MEASURES[detector.measure][0](cur, lines.mean, lines.var_factor, lines.sigma)


#: Azimuth sigma (rad) of a person who reaches into the blind disc under the camera: the foot is
#: anywhere in the disc of radius rho inside the first foot hypothesis (uniform: rho / 2 a side), seen
#: from the hypothesis at about rho (measured on tuning seeds 6201-6203, every person under the camera:
#: |error| median 0.37 rad, 90 % 0.75 rad; r_f error RMS 7.2 px against r_1 / sqrt(6) = 7.9 px;
#: docs/detection.md, "Honest sigmas").
BLIND_THETA_SIGMA = 0.5


def _foot_sigmas(detector: Detector, i, contrast, width, visible=1.0,
                 from_head=False) -> tuple[Array, Array, Array, Array, Array]:
    """``(sigma_r_f, sigma_theta_f, bound_r_f, bound_theta_f, height_r_f)`` of a detection whose foot
    hypothesis is ``i``.

    One upright person's image is symmetric about the foot's azimuth, so the run's centre is
    unbiased and its error is where the two edges fall inside their lines' bins of width
    ``step``: uniform, ``step^2 / 12`` each, a quarter of their sum for the mean. (The paper's
    alternative, the sector width as a 99 % interval, overstates it about tenfold in the
    synthetic world: docs/detection.md.) The failure modes, by the run's width against one
    person's there (a vertical cylinder spans ``2 asin(rho / R)``):

    - wider (a person and a ghost or a shadow, two people the valley rule did not part): the
      person sits at one end of the run, its centre off by half the excess width either way
      (``excess^2 / 4``);
    - narrower (partly hidden, or only part of a low-contrast person over the threshold): the
      visible part is anywhere along the person (``deficit^2 / 12``);
    - either way the centre line may miss the person's axis, so the foot's radius takes a share
      ``min((excess + deficit) / width_1, 1)`` of a uniform spread over the person's extent on top
      of the Monte Carlo ``sigma_r_f``, and the share of the person's window that a stronger
      person hid (``1 - visible``).

    These are the quality part, which the sigma rule's fitted gain scales. The bound part is a foot
    the detector did not see: when the foot hypothesis is the first or last possible one (the person
    reaches past the sampled radii: the blind centre or the image's edge; the quality part keeps the
    Monte Carlo term): at the last, the foot is anywhere along the person's extent (``bound_r_f^2 =
    extent^2 / 12``); at the first, under the camera, anywhere in the blind disc inside the first
    hypothesis's image radius ``r_1`` (uniform over the disc: ``bound_r_f^2 = r_1^2 / 6`` about
    ``r_1``, ``bound_theta_f`` = :data:`BLIND_THETA_SIGMA`); the rule adds it as it is. A person
    found by their neck and head alone (dressed like the floor), or whose change starts outward of
    eq 12's foot (``from_head``: shorter than the prior, legs that do not show or behind furniture),
    has their foot from the head's top and the prior's height (``from_head`` here covers both): a
    height ``sigma_H_p`` off moves the top ``dout/dH`` px and the foot with it, ``d r_f / d out`` px a
    px (``PolarIndex.hyp_dr_f_dH``, by autodiff; 0.05-0.19 m on the floor from 1 to 3.8 m out in the
    paper's rig): a foot the detector did not see, so a bound part too.

    ``height_r_f`` (px per metre of the person's height above the prior's) is how a foot from the
    head follows the height, ``hyp_dr_f_dH``: the height part of its bound. The aim's height is the
    prior's too, wrong by the same amount the other way, so the two errors are correlated, not
    independent (:func:`omnijax.aiming.height_coupling`); on the fisheye rig they cancel in the tilt
    by a half and more (docs/validation.md). A seen foot follows the height less (eq 12's window has
    the prior's length): the sigma rule's fitted share of ``height_r_f``. (The foot's Monte Carlo puts
    that share at about one half, against 0.16-0.31 fitted in the walking scenes.)
    """
    polar = detector.polar
    step = 2 * jnp.pi / polar.n_theta
    one = polar.hyp_width[i]
    excess = jnp.maximum(width - one - step, 0.0)
    deficit = jnp.maximum(one - width - step, 0.0)
    sigma_theta = jnp.sqrt(step**2 / 24 + excess**2 / 4 + deficit**2 / 12)
    extent = (polar.hyp_out[i] - i).astype(jnp.float64)
    first, last = polar.hyp_first, polar.hyp_last
    edge = (i <= first) | (i >= last)
    share = jnp.where(edge, 0.0, jnp.minimum((excess + deficit) / one + (1.0 - visible), 1.0))
    sigma_r = jnp.sqrt(foot_sigma_lookup(detector.foot_sigma, i, contrast) ** 2 + share * extent**2 / 12)
    blind = i <= first
    # under the camera: the foot uniform over the blind disc of image radius r_1 (the first hypothesis's),
    # reported at r_1: E[(r_1 - r)^2] = r_1^2 / 6; at the image's edge: anywhere along the extent
    bound_r = jnp.where(blind, polar.hyp_r_f[i] / jnp.sqrt(6.0), jnp.where(edge, extent / jnp.sqrt(12.0), 0.0))
    dr_f_dH = polar.hyp_dr_f_dH[i]
    height = detector.sigma_H_p * dr_f_dH
    bound_r = jnp.where(from_head, jnp.sqrt(bound_r**2 + height**2), bound_r)
    bound_theta = jnp.where(blind, BLIND_THETA_SIGMA, 0.0)
    return sigma_r, sigma_theta, bound_r, bound_theta, dr_f_dH


def find_sectors(detector: Detector, M: Float[Array, " T"]):
    """Step 4 (psi1): hysteresis sectors of ``M`` (:class:`~omnijax.detection.Sectors`)."""
    return hysteresis_sectors(M, detector.thresholds.lower, detector.thresholds.upper, detector.max_people)


def sector_lines(sectors, n_theta: int) -> Bool[Array, " T"]:
    """The lines inside any valid sector."""
    rel = (jnp.arange(n_theta)[None, :] - sectors.first[:, None]) % n_theta
    return jnp.any(sectors.valid[:, None] & (rel <= (sectors.last - sectors.first)[:, None]), 0)


def detections_of(detector: Detector, people: People, d2: Float[Array, "T R"]) -> Detections:
    """The :class:`Detections` of :func:`~omnijax.detection.find_people`'s people (found in the frame's
    polar ``d2``): feet, sigmas, edges; fragments merged (:func:`~omnijax.detection.merge_fragments`),
    but two people whose images overlap parted (:func:`~omnijax.detection.parted`), each with its foot
    from its own lines."""
    polar = detector.polar
    step = 2 * jnp.pi / polar.n_theta
    theta_f = wrap_2pi(people.centre * step)
    floor = lambda i: polar.hyp_R[i][:, None] * jnp.stack([jnp.cos(theta_f), jnp.sin(theta_f)], -1)
    i_own, has_own = own_feet(polar, d2, people)
    foot = people.i if people.foot is None else people.foot
    two = parted(people.valid, floor(people.i), floor(i_own), has_own)
    i = jnp.where(jnp.any(two, 1), i_own, foot)
    i_extent = jnp.where(jnp.any(two, 1), i_own, people.i)  # what the background's life reads the sides over
    width = (people.last - people.first + 1) * step
    from_head = people.head_only | people.from_head
    sigma_r, sigma_theta, bound_r, bound_theta, height_r_f = _foot_sigmas(
        detector, i, people.contrast, width, people.visible, from_head)
    first = polar.hyp_first
    xy = floor(i)
    person = a_person(polar, people, i)
    valid = merge_fragments(people.valid & person, xy, i == first, polar.hyp_R[first])
    strip = merge_fragments(people.valid, xy, i == first, polar.hyp_R[first]) & ~person
    return Detections(
        valid=valid, r_f=polar.hyp_r_f[i], theta_f=theta_f, sigma_r_f=sigma_r, sigma_theta_f=sigma_theta,
        bound_r_f=bound_r, bound_theta_f=bound_theta, height_r_f=height_r_f, from_head=from_head,
        contrast=people.contrast, r_in=polar.radii[i_extent], r_out=polar.radii[0] + polar.hyp_out[i_extent],
        theta_l=wrap_2pi(people.first * step), theta_r=wrap_2pi(people.last * step), peak=people.excess,
        region=people.explained, strip=strip,
    )


def locate_people(detector: Detector, d2: Float[Array, "T R"], sectors, shade=None) -> Detections:
    """Steps 5-6 in the psi1 ``sectors`` of a frame whose polar d^2 is ``d2``: its people
    (:func:`~omnijax.detection.find_people`) as :class:`Detections`; ``shade`` (:func:`shade_of`) lets a
    head that shows in brightness alone place the foot (:data:`~omnijax.detection._blobs.SHADE_LOG`)."""
    polar, th = detector.polar, detector.thresholds
    ok = polar.line_ok.astype(d2.dtype)
    people = find_people(polar, d2, ok, sector_lines(sectors, polar.n_theta), th.window, th.c_min,
                         detector.dof_per_sample, detector.sigma_H_p, detector.max_people, shade)
    return detections_of(detector, people, d2)


@jax.jit
def detect(detector: Detector, frame: UInt8[Array, "H W 3"],
           lines: LineBackground) -> tuple[Detections, DetectionTrace]:
    """Steps 1-6 for one frame: every person's foot (r_f, theta_f) with its sigmas."""
    cur = polar_frame(detector, frame)
    d2 = _change_of(detector, cur, lines)
    M = d2.sum(-1)
    dets = locate_people(detector, d2, find_sectors(detector, M), functools.partial(shade_of, cur, lines))
    return dets, DetectionTrace(M=M, d2=d2, cur=cur)


def shade_of(cur: Float[Array, "T R 3"], lines: LineBackground, rows: Int[Array, " n"]) -> Float[Array, "n R"]:
    """The log of the frame's brightness (the sum of its channels) over the background's at the polar
    samples of lines ``rows``: what the chromaticity leaves out, read only where a person's change ends
    short of their head (:data:`~omnijax.detection._blobs.SHADE_LOG`), a few lines a person."""
    return jnp.log((cur[rows].sum(-1) + 1.0) / (lines.mean[rows].sum(-1) + 1.0))
