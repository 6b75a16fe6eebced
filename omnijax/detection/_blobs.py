"""Steps 5-6 for several people per sector: psi2 at every line, and the people it holds one at a time.

The paper (section 3.2.6) takes one windowed profile per psi1 sector, along the sector's centre
line, and one foot on it (eq 11-12). A sector holds two people whenever they stand side by side
or one behind the other as the camera sees them, and the paper's estimate then finds one of them
(or neither: a foot between the two). This module goes beyond the paper (docs/detection.md,
"More than one person per sector"):

1. **psi2 at every line** of the psi1 sectors (:func:`window_sums`): the windowed profile is the
   sum of d^2 over the polar samples across the line, ``window_lines[r]`` lines each side (the
   paper's window: a person's width at that radius), one circular cumulative sum for all lines.
2. **One person at a time** (:func:`find_people`, a ``lax.while_loop`` of at most ``max_people``
   passes, ending at the first that finds nobody):
   - eq 12 (corrected) on every line's profile gives that line's best foot hypothesis ``i`` and
     the excess d^2 it holds over the background's mean, ``excess = sum (d2 - dof)``;
   - the line of largest excess among those whose hypothesis is a person is the next person:
     its contrast over its samples not yet explained (the non-centrality per sample, eq 9's
     ``c``) at least :data:`CONTRAST_FACTOR` times ``c_min``, and at least :data:`SUPPORT` of its
     radii with a significant profile (the psi2 threshold for ``x_f``); or the same over the
     person's neck and head alone (``hyp_head`` to the outer end) with :data:`HEAD_CONTRAST_FACTOR`:
     a person dressed like the floor, whose body the chromaticity measure cannot see;
   - its lines (:func:`person_lines`): the run of lines around that line whose d^2 over the
     person's radii is significant, cut where the angular profile dips and rises again (a
     second person beside the first: a valley between two humps), never wider than
     :data:`RUN_WIDTHS` times the person's width; its centre line is the run's middle (the
     paper's theta_f, per person), and the foot is eq 12's on the profile there;
   - its samples are *explained*: over its lines (and at least the model's width around its
     centre) and its radii (from its foot to the top of a person :data:`TALL_SIGMAS` standard
     deviations taller than the prior), d^2 is set to the background's mean, so that no later
     step finds the same person again and the next person is sought in what is left;
   - once all are found, a person whose change on their centre line runs on inward of eq 12's foot
     (every other person's samples set aside) is taller than the prior's extent: eq 12 kept their head
     and put the foot outward, so it moves to where that change starts (:func:`_off_prior_height`, within
     :data:`TALL_SIGMAS` of the prior's height; docs/detection.md, "Taller than the prior"); one whose
     change starts outward of eq 12's foot (nothing inward of it shows) has the foot from the head's top
     and the prior's height, eq 12's extent filled by empty samples (``from_head``: a person shorter
     than the prior, legs that do not show, or legs behind furniture; the sigma carries the height's
     spread, :data:`EMPTY_INNER`; docs/detection.md, "Shorter than the prior"), unless the frame's brightness
     shows their head past the change's end (dark hair over a face the colour of what is behind it): the foot
     then moves out to the hypothesis whose top reaches it, never past where the change starts
     (:data:`SHADE_LOG`; docs/detection.md, "A head the colour of what is behind it").
3. Two people's feet are at least a shoulder width apart; two detections whose feet are closer
   than :data:`MERGE_M` on the floor are one person's fragments and the weaker goes, and a run of
   fewer than :data:`MIN_RUN_LINES` lines (or one found by the head alone narrower than
   :data:`HEAD_RUN_WIDTHS` of a body, :func:`a_person`) is a strip beside someone, not a person
   (:func:`merge_fragments`, the one place where detections are merged); so are two on the
   innermost foot hypothesis (someone under the camera, whose image fans over a wide angle)
   within the blind disc's diameter. Two whose runs share lines and whose feet from their own lines
   (those no other run holds) are :data:`MERGE_M` or more apart are two people, one's image over the
   other's (:func:`parted`): not merged, each with the foot from its own lines.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._foot import foot_scores
from ._polar import PolarIndex

#: A person's contrast over its unexplained samples must reach CONTRAST_FACTOR x ``c_min``.
CONTRAST_FACTOR = 2.0
#: Share of a person's radii whose psi2 profile must be significant.
SUPPORT = 0.25
#: A person dressed like the floor changes only their neck and head (``hyp_head .. hyp_out``, about a
#: third of their radii): found by those alone when their contrast there reaches HEAD_CONTRAST_FACTOR x
#: ``c_min`` (SUPPORT of those radii significant), and kept only if their run spans HEAD_RUN_WIDTHS of
#: a body's width (a head is 2 R_h / shoulder width = 0.44 of it: two thirds of a head). Chosen on
#: six_people 9089, 9093 and two_spectra 9087, 9089, 9094 (the new detections matched against the
#: truth: 271 people, 113 false alarms, mostly coloured shadows and strips beside people; kept 181 and
#: 25); docs/detection.md, "Dressed like the floor".
HEAD_CONTRAST_FACTOR = 3.0
HEAD_RUN_WIDTHS = 0.3
#: A person's run of lines is at most RUN_WIDTHS times its model width (a sector of one person).
RUN_WIDTHS = 1.5
#: The run stops where the angular profile has fallen below VALLEY of its value at the person's
#: line and rises again (a valley between two people): more than the model's half width from the
#: person's line, or nearer where the line that rises has its own foot :data:`MERGE_M` or more from
#: the person's on the floor (someone nearer or farther out). A dip nearer than a half width with
#: the foot where the person's is, is the person's own (their two legs, near the axis); two people
#: side by side are a body's width apart.
VALLEY = 0.6
#: Explained: the model's width plus MARGIN_LINES each side; radii from MARGIN_R before the foot
#: to MARGIN_R past the top of a person TALL_SIGMAS prior standard deviations taller.
MARGIN_LINES, MARGIN_R, TALL_SIGMAS = 1, 3, 3.0
#: Someone taller than the prior (:func:`_off_prior_height`): eq 12 with the prior's extent keeps their head and puts
#: the foot where a person of the prior's height with that head's top would stand, outward of the true
#: one, while the samples inward of it still hold their legs' change (weak, for someone dressed like the
#: floor: three_people and six_people 9182, a person 2.5 standard deviations tall placed 0.5-0.6 m out).
#: A sample of the windowed profile on the person's centre line counts as the person's where the mean of
#: three exceeds ``dps + TALL_CHARGE c_min`` a sample (every other person's samples set aside); the
#: foot moves to where an unbroken run of such samples starts, counted from TALL_EDGE samples inward of
#: eq 12's foot (the edge of anyone's image there, the body's round base over the window's lines, is
#: eq 12's own), if the run reaches TALL_MIN samples inward of it (about 1.5 standard deviations of the
#: prior's height at 2-3 m; a strong person's spill past eq 12's inner end is shorter) and ends within
#: the extent of a person TALL_SIGMAS taller with the same head's top (one that runs on is something
#: else inward: a shadow, someone undetected, and the foot stays).
TALL_CHARGE = 0.25
TALL_EDGE = 2
TALL_MIN = 6
#: A foot from the head (:func:`_off_prior_height`): eq 12's extent holds the person's image and empty
#: samples inward of it, EMPTY_INNER or more before the change starts (counted as for the taller: the
#: first sample from which three count as the person's). Every hypothesis whose extent holds the image
#: scores alike but for the empty samples it takes in, and the inner ones win (their extents are longer
#: in this mirror), so the foot is where a person of the prior's height with that head's top would stand.
#: Moving it out to where the change starts is right for a person shorter than the prior (seed 9201's
#: person 0, 1.614 m: 0.35-0.55 m inward at 3.2-4.1 m) and wrong for legs behind furniture (six_people
#: 9211: a 1.80-m walker whose lower legs a table hid, thrown 0.5-0.6 m outward): the change's start is
#: sharp in both, the background's own edges do not part them, and the prior's odds of a 2.7-sigma
#: person are 1 in 40 of one at the mean; so the foot stays, and its sigma carries the prior height's
#: spread (docs/detection.md, "Shorter than the prior": the move tried and not kept). Three samples,
#: not one or two: the body's round base over the window's lines makes a soft edge of a sample or two
#: at eq 12's own foot (the edge TALL_EDGE allows for).
EMPTY_INNER = 3
#: The head beyond the change (:func:`_off_prior_height`, with the frame's ``shade``): a head whose skin and
#: hair have the chromaticity of what lies behind them (a brown floor or cupboard, dark hair whose
#: chromaticity is noise) ends the person's change at the neck, and eq 12 puts the foot where a person of
#: the prior's height with that top would stand, 0.4-0.6 m inward at 3 m (six_people 9281's person 2, demo
#: target on no person). Their hair still shows in brightness: a sample whose log brightness against the
#: background's differs from its line's level (the mean off the person) by SHADE_LOG or more (2.7 times darker
#: or brighter: dark hair at 0.1-0.3 of a floor counts, a person's shadow, about 0.5, and brown hair do
#: not) on two of the centre line and its neighbours, in a run that starts within the model's neck and
#: head past the change's end (a face of the background's colour between), is the head; where that run
#: ends HEAD_MIN samples or more past eq 12's top, the foot moves out to the hypothesis
#: whose top reaches it, never past where the change starts (the legs); not at all where that hypothesis
#: lies more than HEAD_MIN past the change's start (what shows dark beyond is not this person's head), nor
#: without such a run (a change that runs on past eq 12's top is someone farther out on the line of sight:
#: lamps_switching 9271, where the first form moved the foot onto them). The
#: background's life keeps reading the person's sides over eq 12's extent (``People.foot``): reading them
#: over the moved one let a ghost of the learning last 290 frames (standing_start 9271). Beyond the paper;
#: docs/detection.md, "A head the colour of what is behind it".
SHADE_LOG = 1.0
HEAD_MIN = 3
#: Feet closer than this on the floor (m) are one person's (two people's are a shoulder width apart).
MERGE_M = 0.45
#: Fewest lines in a person's run: a body spans at least 5 lines (2 asin(rho / R) at the room's far
#: end) and the psi2 window 13, so a run of one line is a strip beside someone (the edge of their
#: shadow or of their body past the run that explained them), not a person. Measured on tuning seeds
#: 6201-6203 (six scenes, 600 frames): runs of one line were 11 of 7,300 matched detections and 32
#: of 270 false alarms (28 of them fragments); docs/detection.md, "A strip is not a person".
MIN_RUN_LINES = 2
#: Fewest lines of its own (no other person's run holds them) a person needs for a foot from them
#: alone (:func:`own_feet`): a body spans at least 5 lines, and one or two lines beside someone else's
#: run are too little of it.
OWN_LINES = 3
#: Lines searched either side of a person's line for its run (the widest person near the axis).
REACH = 64
#: A pass after a person whose explained lines number at most NARROW_LINES recomputes a band that
#: much wider than a window's reach either side (a person beyond the first metre or so); a wider one
#: the band of :func:`_band_lines` (the widest person, under the camera). Speed only: the same figures.
NARROW_LINES = 32


class People(eqx.Module):
    """Up to K people found in one frame, strongest first (``valid`` marks the real ones).

    ``i``: the foot hypothesis (index into the polar radii); ``centre``: the centre line
    (fractional line index); ``first``/``last``: the run of lines (``last`` may pass ``T - 1``);
    ``contrast``: non-centrality per sample over the unexplained samples; ``excess``: d^2 above
    the background's mean on the person's profile; ``support``: share of significant radii;
    ``visible``: share of the person's window samples that no earlier person explained;
    ``explained``: the samples this person explained, as (first line, last line, first radius,
    end radius), the region the background's life repairs when it is a ghost; ``head_only``: found
    by their neck and head alone (the whole person's contrast under the gate: dressed like the floor);
    ``from_head``: the foot from the head's top and the prior's height, nothing changed over the inner
    end of eq 12's extent (:data:`EMPTY_INNER`); ``foot``: the hypothesis the foot is read from where it
    is not ``i``'s (a head seen in brightness past the change, :data:`SHADE_LOG`; None: ``i``'s): ``i``
    stays the extent the background's life reads the person's sides over.
    """

    valid: Bool[Array, " K"]
    i: Int[Array, " K"]
    centre: Float[Array, " K"]
    first: Int[Array, " K"]
    last: Int[Array, " K"]
    contrast: Float[Array, " K"]
    excess: Float[Array, " K"]
    support: Float[Array, " K"]
    visible: Float[Array, " K"]
    explained: Int[Array, "K 4"]
    head_only: Bool[Array, " K"]
    from_head: Bool[Array, " K"]
    foot: Int[Array, " K"] | None = None


def prefix_sums(x: Float[Array, "n ..."]) -> Float[Array, "n_plus_1 ..."]:
    """``[0, x[0], x[0] + x[1], ...]`` along the first axis, summed in order.

    A sequential ``lax.scan``: on the CPU, ``jnp.cumsum`` (a reduce-window) took 0.47 ms for the
    720 x 174 table of :func:`window_sums` against 0.07 ms, and each pass of :func:`find_people`
    takes five (docs/detection.md, "Measured")."""
    zero = jnp.zeros(x.shape[1:], x.dtype)
    _, sums = jax.lax.scan(lambda c, row: (c + row, c + row), zero, x)
    return jnp.concatenate([zero[None], sums], 0)


def window_sums(x: Float[Array, "T R"], half: Int[Array, " R"], reach: int = 0) -> Float[Array, "T R"]:
    """Sum of ``x`` over lines ``t - half[r] .. t + half[r]`` (circular in t) at every (t, r); ``reach``,
    if given, is at least ``max(half)`` (static): the table is wrapped round by that many lines each
    side instead of half the circle (the prefix sum runs over ``T + 2 reach`` lines)."""
    T = x.shape[0]
    H = _wrap(T, reach)
    return _windows(jnp.concatenate([x[T - H:], x, x[:H]], 0), half, H, T)


@functools.partial(jax.jit, static_argnums=2)
def window_count_prefix(line_ok: Bool[Array, "T R"], half: Int[Array, " R"], reach: int) -> Float[Array, "T R1"]:
    """Per line, the samples that count (``line_ok``) in its psi2 window (:func:`window_sums`) at each
    radius, summed along the radii with a leading 0 (float32, exact: whole numbers); a constant of the
    rig, kept in :class:`~omnijax.detection.PolarIndex` (``window_ok_prefix``)."""
    return _prefix(window_sums(line_ok.astype(jnp.float32), half, reach))


def _wrap(T: int, reach: int) -> int:
    """Lines the table is wrapped round by for window sums that reach ``reach`` lines (half the circle
    when that is unknown, 0, or more)."""
    return reach if 0 < reach < T // 2 else T // 2


def _windows(rows: Float[Array, "n R"], half: Int[Array, " R"], reach: int, B: int) -> Float[Array, "B R"]:
    """Window sums of lines ``reach .. reach + B - 1`` of ``rows`` (``B + 2 reach`` consecutive lines)."""
    c = prefix_sums(rows)
    t = jnp.arange(B)[:, None]
    return jnp.take_along_axis(c, t + reach + half[None] + 1, 0) - jnp.take_along_axis(c, t + reach - half[None], 0)


def argmax_rows(x: Float[Array, "n m"]) -> Int[Array, " n"]:
    """``jnp.argmax(x, 1)`` (the first of equal maxima) as a max and a min: XLA's CPU argmax, a
    variadic reduce, took 0.18 ms on the 360 x 174 table of eq 12 against 0.05 ms."""
    top = jnp.max(x, 1, keepdims=True)
    return jnp.min(jnp.where(x == top, jnp.arange(x.shape[1]), x.shape[1]), 1)


def _prefix(x):
    """Prefix sums along the radii (axis 1), a leading zero column."""
    return prefix_sums(x.T).T


def _span(P, a, b):
    """Row-wise ``P[t, b[t]] - P[t, a[t]]`` of a prefix-sum table."""
    return jnp.take_along_axis(P, b[:, None], 1)[:, 0] - jnp.take_along_axis(P, a[:, None], 1)[:, 0]


def person_lines(excess_line: Float[Array, " L"], hw, apart: Bool[Array, " L"]) -> tuple[Array, Array]:
    """The run of lines of the person at offset 0 of ``excess_line`` (its d^2 excess per line over
    its radii, offsets ``-REACH .. REACH``): offsets ``(left, right)``, bounded by significance
    (``excess_line > 0``), the valley rule and :data:`RUN_WIDTHS` x ``hw`` (the model's half width).
    A valley parts two people beyond ``hw``, or nearer where ``apart`` (per offset: that line's own
    foot is :data:`MERGE_M` or more from the person's on the floor)."""
    peak = jnp.maximum(excess_line[REACH], 1e-6)
    limit = jnp.ceil(RUN_WIDTHS * hw).astype(jnp.int32) + 1
    offset = jnp.arange(1, REACH + 1)

    def side(values, other):  # offsets 1 .. REACH going outward
        prev = jnp.concatenate([values[:1], values[:-1]])
        low = jax.lax.cummin(values) < VALLEY * peak
        stop = (values <= 0) | (low & (values > prev) & ((offset > hw) | other)) | (offset > limit)
        return jnp.argmax(jnp.concatenate([stop, jnp.ones(1, bool)]))  # lines kept on this side

    right = side(excess_line[REACH + 1:], apart[REACH + 1:])
    left = side(excess_line[:REACH][::-1], apart[:REACH][::-1])
    return -left, right


def _band_lines(polar: PolarIndex) -> int:
    """How many lines a person's pass can change the line figures of (static): the lines it explains
    (its run, at most :data:`RUN_WIDTHS` x the widest person's half width each side of its line, and
    the model's half width plus :data:`MARGIN_LINES` round its centre) and a window's reach either
    side of them; one more for rounding."""
    T = polar.n_theta
    run = min(math.ceil(RUN_WIDTHS * polar.person_half_lines) + 1, REACH)
    k = math.ceil(polar.person_half_lines) + MARGIN_LINES
    return min(T, 2 * run + 2 * max(MARGIN_LINES, k) + 1 + 2 * polar.window_reach + 1)


def find_people(polar: PolarIndex, d2: Float[Array, "T R"], ok: Float[Array, "T R"], candidate: Bool[Array, " T"],
                window: Float[Array, " R"], c_min, dof_per_sample: int, sigma_H_p, max_people: int,
                shade: Callable[[Int[Array, " n"]], Float[Array, "n R"]] | None = None) -> People:
    """Step 5-6 per person (see the module docstring) on the frame's polar d^2 (``ok`` 1 where a
    sample counts), among the ``candidate`` lines (the psi1 sectors); ``window`` the psi2
    significance threshold per radius; ``shade`` gives the frame's log brightness against the
    background's at the samples of the lines it is given (None: no head is sought beyond the change,
    :data:`SHADE_LOG`; a few lines a person, not the whole frame).

    Each line's figures (its best foot, excess, contrast, support) depend on the samples within a
    window's reach of it, so after a person is explained only the lines round what it explained
    change: the first pass computes every line, each later one a band of lines round what the last
    person explained (:data:`NARROW_LINES` past a window's reach either side, or :func:`_band_lines`
    for a person too wide for that): the same figures, to float rounding (the sums start elsewhere)."""
    T, R = d2.shape
    step = 2 * jnp.pi / T
    half = polar.window_lines
    out = polar.hyp_out
    r_idx = jnp.arange(R)
    line_idx = jnp.arange(T)
    reach = _wrap(T, polar.window_reach)
    n_all = polar.window_ok_prefix.astype(d2.dtype)
    dps = dof_per_sample
    d2_frame = d2

    def figures(d2, explained, start, B):
        """Lines ``start .. start + B - 1`` (mod T) and their figures: best foot, samples, unexplained
        samples, excess, contrast, support (``explained`` None: nothing is, the first pass)."""
        rows = (start - reach + jnp.arange(B + 2 * reach)) % T
        lines = rows[reach:reach + B]
        Q = _windows(d2[rows], half, reach, B)
        PQ = _prefix(Q)
        eq12 = jnp.where(polar.hyp_ok[None], 2 * (PQ[:, out] - PQ[:, :-1]) - PQ[:, -1:], -jnp.inf)
        i_line = argmax_rows(eq12)
        o_line = out[i_line]
        h_line = polar.hyp_head[i_line]
        n_prefix = n_all[lines]
        if explained is None:  # every sample unexplained: the window's samples that count (whole numbers)
            vis_prefix = n_prefix
        else:
            vis_prefix = _prefix(_windows((ok * (1.0 - explained))[rows], half, reach, B))
        sig_prefix = _prefix((Q > window[None]).astype(jnp.float32))

        def part(a):
            """Over radii ``a .. o_line``: the samples, excess, contrast over the unexplained samples
            (explained ones hold exactly dps) and support."""
            n = jnp.maximum(_span(n_prefix, a, o_line), 1.0)
            vis = _span(vis_prefix, a, o_line)
            excess = _span(PQ, a, o_line) - dps * n
            support = _span(sig_prefix, a, o_line) / jnp.maximum(o_line - a, 1)
            return n, vis, excess, excess / jnp.maximum(vis, 1.0), support

        n_line, vis_line, excess, contrast, support = part(i_line)
        _, _, _, head_contrast, head_support = part(h_line)
        return lines, (i_line, n_line, vis_line, excess, contrast, support, head_contrast, head_support)

    def pick(d2, explained, fig):
        """The next person from every line's figures ``fig``; ``d2`` and ``explained`` with them explained."""
        i_line, n_line, vis_line, excess, contrast, support, head_contrast, head_support = fig
        whole = (contrast >= CONTRAST_FACTOR * c_min) & (support >= SUPPORT)
        head = (head_contrast >= HEAD_CONTRAST_FACTOR * c_min) & (head_support >= SUPPORT)
        person = candidate & (whole | head)
        score = jnp.where(person, excess, -jnp.inf)
        t0 = jnp.argmax(score)
        found = jnp.isfinite(score[t0])
        i0 = i_line[t0]
        hw = 0.5 * polar.hyp_width[i0] / step  # the model's half width, lines
        rad = (r_idx >= i0) & (r_idx < out[i0])
        ring = (t0 + jnp.arange(-REACH, REACH + 1)) % T
        per_line = jnp.sum(jnp.where(rad[None], d2[ring] - dps * ok[ring], 0.0), 1)
        sig = per_line - 0.5 * c_min * jnp.sum(jnp.where(rad[None], ok[ring], 0.0), 1)
        R0, R1 = polar.hyp_R[i0], polar.hyp_R[i_line[ring]]
        gap = 2 * (1 - jnp.cos(step * jnp.arange(-REACH, REACH + 1)))  # |u0 - u1|^2 of unit vectors
        apart = (R0 - R1) ** 2 + R0 * R1 * gap >= MERGE_M**2  # feet MERGE_M or more apart on the floor
        left, right = person_lines(sig, hw, apart)
        first, last = t0 + left, t0 + right
        centre = 0.5 * (first + last)
        tc = jnp.floor(centre).astype(jnp.int32)  # unwrapped, as first and last (a run may cross line 0)
        i = i_line[tc % T]
        # explain: the run and the model's width around the centre, the person's radii (tall)
        k = jnp.ceil(0.5 * polar.hyp_width[i] / step).astype(jnp.int32) + MARGIN_LINES
        e_first, e_last = jnp.minimum(first - MARGIN_LINES, tc - k), jnp.maximum(last + MARGIN_LINES, tc + k)
        tall = jnp.ceil(TALL_SIGMAS * sigma_H_p * polar.hyp_dout_dH[i]).astype(jnp.int32)
        r0 = jnp.maximum(jnp.minimum(i, i0) - MARGIN_R, 0)
        r1 = jnp.minimum(jnp.maximum(out[i], out[i0]) + tall + MARGIN_R, R)
        in_lines = (line_idx - e_first) % T <= e_last - e_first
        on = found & in_lines[:, None] & (r_idx[None] >= r0) & (r_idx[None] < r1)
        d2 = jnp.where(on, dps * ok, d2)
        visible = vis_line[t0] / n_line[t0]
        rec = dict(valid=found, i=i, centre=centre, first=first, last=last, contrast=contrast[t0],
                   excess=excess[t0], support=support[t0], visible=visible,
                   explained=jnp.stack([e_first, e_last, r0, r1]), head_only=found & ~whole[t0],
                   from_head=jnp.zeros_like(found))
        return d2, explained | on, rec

    # one person a pass, until a pass finds nobody: the passes after it would find nobody either (nothing
    # is explained, so their table is the same), and their slots stay empty; after the first pass only
    # the band of lines round what the last person explained is computed again
    B = _band_lines(polar)
    B_narrow = min(B, 2 * reach + NARROW_LINES)

    def refresh(B, d2, explained, fig, e_first):
        lines, band = figures(d2, explained, e_first - reach, B)
        return jax.tree.map(lambda a, v: a.at[lines].set(v), fig, band)

    def body(state):
        k, d2, explained, fig, people, _ = state
        e_first, e_last = people["explained"][k - 1, 0], people["explained"][k - 1, 1]
        narrow = e_last - e_first + 1 + 2 * reach <= B_narrow  # most people: the widest band is for the axis
        fig = jax.lax.cond(narrow, functools.partial(refresh, B_narrow), functools.partial(refresh, B),
                           d2, explained, fig, e_first)
        d2, explained, rec = pick(d2, explained, fig)
        people = jax.tree.map(lambda a, v: a.at[k].set(v), people, rec)
        return k + 1, d2, explained, fig, people, rec["valid"]

    explained = jnp.zeros(d2.shape, bool)
    _, fig = figures(d2, None, 0, T)
    d2, explained, rec = pick(d2, explained, fig)
    people = jax.tree.map(lambda v: jnp.zeros((max_people, *v.shape), v.dtype).at[0].set(v), rec)
    state = (jnp.asarray(1), d2, explained, fig, people, rec["valid"])
    people = jax.lax.while_loop(lambda s: (s[0] < max_people) & s[5], body, state)[4]
    return _off_prior_height(polar, d2_frame, ok, People(**people), dps, dps + TALL_CHARGE * c_min, sigma_H_p, shade)


def _off_prior_height(polar: PolarIndex, d2: Float[Array, "T R"], ok: Float[Array, "T R"], people: People, dps,
                      level, sigma_H_p, shade=None) -> People:
    """Each person's foot moved inward from eq 12's to where their change starts on their centre line, for
    someone taller than the prior (:data:`TALL_CHARGE` and after), with every other person's explained
    samples at the background's mean ``dps`` (someone nearer on the same azimuth is not this person's
    legs); ``level`` the change a sample that counts as the person's. Their explained region (what the
    background's life repairs if they are a ghost) grows inward with the foot. A person whose change
    starts :data:`EMPTY_INNER` or more samples outward of eq 12's foot is marked ``from_head``: their foot
    is the head's top and the prior's height (shorter than the prior, or legs that do not show). Beyond
    the paper."""
    T, R = d2.shape
    reach = _wrap(T, polar.window_reach)
    out, r_idx = polar.hyp_out, jnp.arange(R)
    K = people.valid.shape[0]
    e = people.explained
    grown = (out[people.i][:, None] - out[None]) <= TALL_SIGMAS * sigma_H_p * polar.hyp_dout_dH[None]
    lowest = jnp.argmax(grown & polar.hyp_ok[None] & (r_idx[None] >= polar.hyp_first), 1)  # tallest allowed

    def one(k):
        t = jnp.floor(people.centre[k]).astype(jnp.int32)
        rows = (t - reach + jnp.arange(1 + 2 * reach)) % T
        other = people.valid & (jnp.arange(K) != k)
        in_lines = ((rows[None] - e[:, 0, None]) % T <= (e[:, 1] - e[:, 0])[:, None])  # (K, rows)
        in_radii = (r_idx[None] >= e[:, 2, None]) & (r_idx[None] < e[:, 3, None])  # (K, R)
        hidden = jnp.any(other[:, None, None] & in_lines[:, :, None] & in_radii[:, None, :], 0)
        usable = ok[rows]  # 1 where a sample lies on the floor's image: the background's mean counts there
        q = _windows(jnp.where(hidden, dps * usable, d2[rows]) - level * usable, polar.window_lines, reach, 1)[0]
        q = jnp.convolve(q, jnp.ones(3) / 3, mode="same")  # over three samples: a weak change is noisy
        edge = people.i[k] - TALL_EDGE
        gap = jnp.max(jnp.where((r_idx < edge) & (q <= 0.0), r_idx, -1))  # the run ends after it
        j = gap + 1
        move = people.valid[k] & (j <= people.i[k] - TALL_MIN) & (j >= lowest[k]) & (gap >= 0)
        start = jnp.min(jnp.where((r_idx >= people.i[k]) & (q > 0.0), r_idx, R))  # where the change starts
        # not under the camera (that foot is anywhere in the blind disc, a bound of its own)
        empty = people.valid[k] & ~move & (people.i[k] > polar.hyp_first) & (start >= people.i[k] + EMPTY_INNER)
        i = jnp.where(move, j, people.i[k])
        if shade is None:
            return i, empty, i
        # the head beyond the change's end, seen in brightness (SHADE_LOG): the run of such samples from there
        mid = rows[reach - 1:reach + 2]
        seen = (ok[mid] > 0) & ~hidden[reach - 1:reach + 2]
        s = shade(mid)
        # the light's level a line: the mean of its seen samples off the person's extent and a head past it (a
        # median cost a sort a line, 0.4 ms of the detector's 2.6)
        o = out[people.i[k]]
        off = seen & ((r_idx < people.i[k]) | (r_idx >= 2 * o - polar.hyp_head[people.i[k]]))[None]
        light = jnp.sum(jnp.where(off, s, 0.0), 1, keepdims=True) / jnp.maximum(jnp.sum(off, 1, keepdims=True), 1)
        g = jnp.sum(seen & (jnp.abs(s - light) >= SHADE_LOG), 0) >= 2
        g = g | (jnp.roll(g, 1) & jnp.roll(g, -1))  # a sample's gap
        end = jnp.min(jnp.where((r_idx > start) & (q <= 0.0), r_idx, R)) - 1  # the change's last sample
        # the hair may start a neck and a face past it (skin of the colour behind): within the model's neck and head
        first = jnp.min(jnp.where((r_idx > end) & g, r_idx, R))
        near = (first < R) & (first <= end + 1 + o - polar.hyp_head[people.i[k]])
        top = jnp.min(jnp.where((r_idx > first) & ~g, r_idx, R))  # just past the head seen (if near)
        reach_top = (out >= top) & polar.hyp_ok & (r_idx >= people.i[k])
        j_top = jnp.argmax(reach_top)  # the first hypothesis whose top reaches the head's
        # a head whose prior-height foot lies past where the change starts (more than HEAD_MIN) is not this
        # person's: something dark beyond them (someone farther out on the line of sight)
        out_move = (empty & near & jnp.any(reach_top) & (top >= o + HEAD_MIN)
                    & (j_top <= start + HEAD_MIN) & (j_top > people.i[k]))
        j_top = jnp.minimum(j_top, start)
        # a foot at the change's start is seen, not the head's
        return i, empty & ~(out_move & (j_top >= start)), jnp.where(out_move, j_top, i)

    i, from_head, foot = jax.vmap(one)(jnp.arange(K))
    explained = e.at[:, 2].set(jnp.minimum(e[:, 2], jnp.maximum(i - MARGIN_R, 0)))
    return eqx.tree_at(lambda p: (p.i, p.explained, p.from_head, p.foot), people,
                       (i.astype(people.i.dtype), explained.astype(e.dtype), from_head, foot.astype(people.i.dtype)),
                       is_leaf=lambda x: x is None)


def _distances(xy: Float[Array, "K 2"]) -> Float[Array, "K K"]:
    """Floor distances between every two detections' feet."""
    return jnp.linalg.norm(xy[:, None] - xy[None], axis=-1)


def _runs(people: People, T: int) -> tuple[Array, Array]:
    """Per person, its run's lines (K, T), and the same for those whose run has at least
    :data:`MIN_RUN_LINES` lines (a strip of one line is no one's)."""
    line = jnp.arange(T)
    runs = people.valid[:, None] & ((line[None] - people.first[:, None]) % T <= (people.last - people.first)[:, None])
    return runs, runs & (people.last - people.first + 1 >= MIN_RUN_LINES)[:, None]


def own_lines(people: People, T: int) -> Bool[Array, "K T"]:
    """Per person, the lines of its run that no other person's run (of at least :data:`MIN_RUN_LINES`
    lines) holds."""
    runs, whole = _runs(people, T)
    others = jnp.sum(whole, 0)[None] - whole  # runs of the others holding each line
    return runs & (others == 0)


def own_feet(polar: PolarIndex, d2: Float[Array, "T R"], people: People) -> tuple[Array, Array]:
    """Each person's foot hypothesis from its own lines alone (:func:`own_lines`): eq 12 (corrected) on
    the sum of ``d2`` over them; and whether it has one (its run shares lines with another person's, and
    it has at least :data:`OWN_LINES` lines of its own)."""
    runs, whole = _runs(people, polar.n_theta)
    others = jnp.sum(whole, 0)[None] - whole
    own = runs & (others == 0)  # own_lines, from the same runs
    shares = jnp.any(whole & (others > 0), 1)
    eq12 = jax.vmap(foot_scores, in_axes=(0, None))(own.astype(d2.dtype) @ d2, polar)
    return argmax_rows(eq12), shares & (jnp.sum(own, 1) >= OWN_LINES)


def parted(valid: Bool[Array, " K"], floor_xy: Float[Array, "K 2"], own_xy: Float[Array, "K 2"],
           has_own: Bool[Array, " K"]) -> Bool[Array, "K K"]:
    """Pairs of valid people whose feet are within :data:`MERGE_M` on the floor but whose feet from
    their own lines (``own_xy``, where ``has_own``: :func:`own_feet`) are :data:`MERGE_M` or more apart:
    two people whose images overlap in azimuth, not one person's fragments.

    One nearer the camera and the other farther out a few degrees aside share most of their lines; the
    run of the first found holds both, and the foot on its centre line falls between them, near enough
    the other's to merge it away: stops_a_minute 9078's two standers, 1.25 and 1.81 m out and 8
    degrees apart, had their feet placed 0.41 m apart and the nearer one was merged away in 199
    person-frames (docs/detection.md, "merged people"). The lines only one of them covers show each
    alone. Used only to part a pair the merge would join: a person's own lines are few and at the edge
    of their body, and their foot from those alone is worse than the centre line's where nothing
    overlaps (six_people 6202: 3.06 m placed at 4.18 m)."""
    near, apart = _distances(floor_xy) < MERGE_M, _distances(own_xy) >= MERGE_M
    both = valid & has_own
    return both[:, None] & both[None] & near & apart


def a_person(polar: PolarIndex, people: People, i: Int[Array, " K"]) -> Bool[Array, " K"]:
    """Whether each found person's run can be a person's (foot hypotheses ``i``): at least
    :data:`MIN_RUN_LINES` lines (one line is a strip beside someone), and one found by their head alone
    at least :data:`HEAD_RUN_WIDTHS` of a body's width (narrower is a strip too: the edge of a
    coloured shadow or of someone's body)."""
    run = people.last - people.first + 1
    width = run * (2 * jnp.pi / polar.n_theta)
    return (run >= MIN_RUN_LINES) & ~(people.head_only & (width < HEAD_RUN_WIDTHS * polar.hyp_width[i]))


def merge_fragments(valid: Bool[Array, " K"], floor_xy: Float[Array, "K 2"], innermost: Bool[Array, " K"] | None = None,
                    inner_R=0.0) -> Bool[Array, " K"]:
    """``valid`` less every detection whose foot lies within :data:`MERGE_M` of an earlier (stronger)
    valid one's on the floor (runs that are no person's, :func:`a_person`, are left out of ``valid``
    first by the caller); or, both on the ``innermost`` foot hypothesis (the person reaches into
    the blind disc under the camera: the foot is somewhere inside the circle of floor radius
    ``inner_R``, and a person there spans a wide fan of lines that splits into fragments), within
    the disc's diameter."""
    d = _distances(floor_xy)
    idx = jnp.arange(valid.shape[0])
    near = d < MERGE_M
    if innermost is not None:
        near = near | (innermost[:, None] & innermost[None] & (d < 2 * inner_R))
    beaten = jnp.any(valid[None] & near & (idx[None] < idx[:, None]), axis=1)
    return valid & ~beaten
