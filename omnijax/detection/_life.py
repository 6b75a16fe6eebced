"""The background's life after learning: learning what was not learnt, drift, ghost repair and
absorption, on the polar samples the detector reads (docs/design.md section 4, "The background's
life"; docs/detection.md, "The background's life").

The paper learns a background once; a system that runs for hours must keep it right. Once, before
the first frame, :func:`settle_learning` takes the learning's minority where the majority was someone
who stood through most of it (the floor they hid continues the floor around it). Then once per
frame (:func:`live_step`, two jitted calls), after detection, with the frame's d^2 (the detector's trace):

1. **Ghost evidence** of each detection (:func:`ghost_evidence`): is there an object's edge in the
   *current* image at the sides of the person's run of lines? At each radius of the person where the
   sample just inside an edge line has changed, the least d^2 between it and the samples a few pixels
   outside that edge, in the current frame (``edge_now``) and in the background (``edge_before``), each
   side averaged over its radii; a sample inside another person's explained region (the one inside the
   edge, or one outside it) is that person's, not measured for this one. A person (standing too) differs
   from the floor beside them: hundreds. A ghost (the background still holds someone who has gone, or a
   piece of furniture moved away) shows floor continuing the floor beside it, about 1, while the
   background there had an edge. Chromaticity makes this hold under shadows and the floor's shading
   (under lights of two colours, ``light_axis``, the detector's d^2 across the light: a lamp's pool is
   no edge). The verdict (:func:`verdicts`) is per side: a ghost needs one side with no edge now and
   more before, and no side with a person's edge (a ghost continues the floor on at least one side,
   whatever adjoins the other). The caller says which detections are trusted people (their tracks walked
   in, or have shown a person's edge for a while: :data:`runtime.realtime.perception.PERSON_SEEN_S`):
   those are ghosts only with both signs (no edge now, an edge :data:`GHOST_RATIO` times stronger
   before); the others with any more edge before than now. A faint edge now and less before (a person of
   nearly the floor's colour) is no verdict: neither a ghost's vote nor a person's. At a radius where the
   background is too dark to show the edge the frame shows (eq 5: a dark sample's chromaticity is
   noise), the person's test takes the edge now to have been there before (``Evidence.person_before``): a
   ghost of black shoes against a table showed "no edge" before beside the table, and the table's edge
   now looked new. A lamp of another colour switching on a bare floor has about the same (no) edge in
   both, and gets a ghost's vote in about every other frame. A sure ghost (a trusted detection's
   verdict) is set aside before anything reads the detections (:func:`set_aside_ghosts`, in the
   perception step): not a person, still judged and repaired here.
2. **Repair**: a sample that has changed, stayed unchanged from frame to frame (still) for
   ``still_frames`` and gathered ``ghost_frames`` votes of a ghost is re-learnt from the current frame
   (its variance factor 1: one frame's estimate). The votes are counted while the sample stays
   changed: +1 for each frame it lies in a ghost's region, -1 for each frame it lies in a person's
   (a detection with a person's edge), none while no detection claims it or gives no verdict; a
   ghost's evidence flickers about the threshold from frame to frame, and a run of ghost frames
   would be broken by each flicker. A sample on a detection's lines (any radius) still for
   ``floor_shows_frames`` where the frame shows the floor beside the region and the background did not
   (:func:`floor_shows`) votes +1 whatever the region's verdict: someone learnt in who walks out along
   their own line is one detection with their ghost, a person's verdict. In the region of a trusted
   detection (someone the tracker saw walk in is there), only where the frame continues the floor
   beside the sample (the nearest samples of its radius outside every detection, settled and
   unchanged now, either side) better than the background does (:func:`nearer_floor`): a ghost's
   region is its whole run of lines, and someone in it now (walking off the spot, in along their
   own line, or standing in its middle) is as still from frame to frame as the ghost's floor, but is
   not the floor.
   A sample the learning left unsettled (kept in fewer than two thirds of its frames: someone
   stood there through a third of them) is repaired after :data:`UNSETTLED_VOTES` such frames when
   the ghost shows both signs (an edge in the background, none now) and is not a trusted detection:
   the ghosts of the learning.
3. **Absorption**: a sample that has changed and stayed at rest for ``absorb_frames`` outside the
   region of every trusted person is learnt as it is now (a chair moved and left, a coat dropped).
   The count at rest (``rest``) is not "still": a frame in which the sample moved (someone passing in
   front, or sensor noise past :data:`CHANGED`, about once in 700 frames) holds it, and only the
   sample's return to the background restarts it. Restarted at every such frame, as "still" is, a
   count of a minute (1,500 frames) was reached by one sample in eight under noise alone, and in a
   room people walk across a chair's image far more often: chair_moved 9031's chair was detected
   through all of its 104 s.
   A person who stops is in a trusted person's region and is never absorbed.
4. **Drift and learning**: a sample that has not changed and lies outside every detection's
   region follows the frames at ``adapt_rate``, or faster while it has been learnt from fewer
   frames than the learning took (a mean of the frames it has been seen unoccupied in): what the
   learning could not settle, because someone stood there through most of it, is learnt as soon
   as it is free. Nothing detected and nothing changed is ever learnt, so a person who stops is
   not absorbed by drift.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, UInt8

from ._change import (
    AGREE,
    Background,
    change_across_light,
    change_against,
    change_measure,
    change_of_terms,
    current_terms,
    learned,
)
from ._detector import (
    Detections,
    DetectionTrace,
    Detector,
    LineBackground,
    change_at,
    find_sectors,
    life_candidates,
    lines_from,
    locate_people,
    polar_frame,
)
from ._indexing import gather_rgb

#: d^2 of a changed sample: the chi-square(2) 1 - 1e-3 quantile (a background sample exceeds it once
#: in 1,000); also what "unchanged from the previous frame" means.
CHANGED = AGREE
#: Under ``[detection] light_axis``: the drift rate per frame of a free sample the light relit (a change
#: of its chromaticity along the light's axis): the background follows a lamp switching within about
#: ten frames.
RELIGHT_RATE = 0.2
#: A trusted person's detection is a ghost only if the edge before was GHOST_RATIO times the edge now.
GHOST_RATIO = 4.0
#: A sample the learning left unsettled is repaired after this many frames still and in a ghost's region.
UNSETTLED_VOTES = 2.0
#: A detection whose contrast is under FAINT x ``c_min`` is faint (:func:`faint`, :func:`verdicts`): on
#: three_people 9239, lamps_switching 9235, standing_start 9239 and six_people 9235 (600 frames, 5,300
#: detections; the tuning seeds), the displaced edges were 109 false alarms at contrast 2.3, and 2 people
#: of 5,000 matched detections were this faint with one side both signs of a ghost (floor-coloured ones
#: walking: a ghost's vote, which repairs only what stays still).
FAINT = 1.0
#: Where the background shows a person's edge at a side (:data:`ASIDE_BEFORE` or more), "no edge now" is
#: an edge now under WIDE_NONE x ``ghost_edge``, not ``ghost_edge`` (:func:`verdicts`): the floor beside a
#: ghost measures 5-10 there on some floors, flickering about ``ghost_edge`` from frame to frame, and a
#: trusted ghost was judged one in 6 of its 150 frames (standing_start 9253, a walker's body re-learnt
#: as it left the spot it stood on through the learning).
WIDE_NONE = 2.0
#: ... and only where that edge before is WIDE_RATIO times the edge now or more: a trusted walker dressed
#: like the floor passing a strong edge of the background showed 5.6-9 now against 67-133 before (12-16
#: times) and was judged a ghost, its body re-learnt for 90 frames (demo three_people 9281); the ghost of
#: standing_start 9253 showed 5-10 against 800 (80 times and more).
WIDE_RATIO = 32.0
#: Ghost evidence: the sample inside an edge line lies INNER_PX inside it; the samples outside it
#: FLANK_PX pixels out.
INNER_PX, FLANK_PX = 1.5, (3.0, 5.0, 7.0)


class Life(eqx.Module):
    """The background at the polar samples and what its life keeps per sample: ``seen`` (frames its
    colour was learnt from, capped), ``prev`` (the last frame's colour), ``still`` (frames it has been
    changed and unchanged from frame to frame), ``rest`` (frames it has been changed and unchanged
    from the frame before since it last was background: a frame it moved holds the count; the
    absorption's), ``ghost`` (frames it has lain, changed, in a ghost's
    region, net of the frames in a person's: the ghost votes)."""

    lines: LineBackground
    seen: Float[Array, "T R"]
    prev: Float[Array, "T R 3"]
    still: Float[Array, "T R"]
    ghost: Float[Array, "T R"]
    rest: Float[Array, "T R"]


def start_life(lines: LineBackground) -> Life:
    """A life starting from a learnt background's polar samples (``seen`` from its variance factor:
    the learning frames each sample kept)."""
    seen = 1.0 / jnp.maximum(lines.var_factor, 1e-6)
    zeros = jnp.zeros(seen.shape, jnp.float32)
    return Life(lines=lines, seen=seen.astype(jnp.float32), prev=lines.mean, still=zeros, ghost=zeros,
                rest=zeros)


class Evidence(eqx.Module):
    """Per detection and side (left, right): the edge now and in the background (least d^2, averaged
    over the side's radii; ``inf`` where no changed sample was measured there), and the radii measured.
    ``person_before``: the edge before as a person's edge is judged against it (:func:`verdicts`): at a
    radius where the background is too dark to show the edge the frame shows, the edge now
    (:func:`ghost_evidence`; None: ``edge_before``)."""

    edge_now: Float[Array, "K 2"]
    edge_before: Float[Array, "K 2"]
    samples: Float[Array, "K 2"]
    person_before: Float[Array, "K 2"] | None = None
    #: per side, the edge now between the side's inside samples and the *other* side's flanks (averaged as
    #: ``edge_now``; None: not measured): whether what is inside now continues what adjoins the other side
    cross_now: Float[Array, "K 2"] | None = None


def verdicts(ev: Evidence, trusted: Bool[Array, " K"], edge, faint: Bool[Array, " K"] | None = None
             ) -> tuple[Array, Array]:
    """(ghost, person) per detection from its two sides. A side shows a *person* when it has an edge now
    (``edge_now >= edge``) :data:`GHOST_RATIO` times what the background shows there (a static edge, a
    table's, is in both); a *ghost* when it has none now (``< edge``) and more in the background: for a
    trusted detection :data:`GHOST_RATIO` times more (both signs), for the others any more; where the
    background's edge there is a person's (:data:`ASIDE_BEFORE` or more, :data:`WIDE_RATIO` times the edge
    now), "none now" is under :data:`WIDE_NONE` x ``edge``. A detection
    is a ghost when a side shows one and no side shows a person (a ghost continues the floor on at least
    one side, whatever adjoins the other; someone standing against a table of their colour still has
    their edge on the open side). Neither (a faint edge now and less before) is no verdict.

    A *faint* detection (``faint``: :func:`faint`, its samples changed less than the least a person's
    must) with both signs of a ghost on one side (no edge now, an edge of at least ``edge`` before,
    :data:`GHOST_RATIO` times more) is a ghost whatever its other side shows: an edge of the background
    displaced by a few lines (the frame has on one side the edge the background has on the other) looks
    like a person's edge on the side it moved to (three_people 9239: 135 frames, trusted as a person
    after 36)."""
    ratio = jnp.where(trusted, GHOST_RATIO, 1.0)[:, None]
    wide = (ev.edge_before >= ASIDE_BEFORE) & (ev.edge_before > WIDE_RATIO * ev.edge_now)
    none_now = ev.edge_now < jnp.where(wide, WIDE_NONE * edge, edge)
    ghost_side = none_now & (ev.edge_before > ratio * ev.edge_now)
    before = ev.edge_before if ev.person_before is None else ev.person_before
    person_side = (ev.edge_now >= edge) & (ev.edge_now > GHOST_RATIO * before)
    sure_side = (ev.edge_now < edge) & (ev.edge_before >= edge) & (ev.edge_before > GHOST_RATIO * ev.edge_now)
    if ev.cross_now is not None:
        # a new edge on a side where the background had an edge already (something adjoins it), whose
        # inside now continues what lies beyond the other side, where that side shows both signs of a
        # ghost, is the floor showing again against what adjoins this side, not a person: a stander's
        # body re-learnt beside a cupboard of nearly their colour (an edge of 10.5 before) gave the
        # floor's edge against the cupboard as new, and the ghost was kept to the clip's end (six_people
        # 9451: 97 frames). Someone standing against a table of their colour is the mirror image but for
        # that: their open side had no edge in the background (the floor beside the floor)
        adjoined = ev.edge_before >= edge
        person_side = person_side & ~(adjoined & sure_side[:, ::-1] & (ev.cross_now < edge))
    person = jnp.any(person_side, axis=-1)
    if faint is not None:
        person = person & ~(faint & jnp.any(sure_side, axis=-1))
    return jnp.any(ghost_side, axis=-1) & ~person, person


def faint(detector: Detector, dets: Detections) -> Bool[Array, " K"]:
    """The detections whose contrast (the non-centrality per sample over their samples) is under
    :data:`FAINT` x the detector's ``c_min``: the least a person's samples change, on average, by the
    psi2 threshold's design (a person is found at :data:`~omnijax.detection._blobs.CONTRAST_FACTOR` x
    ``c_min``, or by the head alone)."""
    return dets.contrast < FAINT * detector.thresholds.c_min


def ghost_evidence(detector: Detector, cur: Float[Array, "T R 3"], lines: LineBackground,
                   d2: Float[Array, "T R"], dets: Detections) -> Evidence:
    """Step 1 of the module docstring for every detection (``cur``: the frame at the polar samples,
    ``d2`` its change against ``lines``)."""
    polar = detector.polar
    T, R = d2.shape
    step = 2 * jnp.pi / T
    inner = jnp.ceil(INNER_PX / _spacing(detector)).astype(jnp.int32)  # (R,)
    flank = _flank_lines(detector)  # (F, R)
    first = jnp.round(dets.theta_l / step).astype(jnp.int32)
    width = jnp.round(((dets.theta_r - dets.theta_l) % (2 * jnp.pi)) / step).astype(jnp.int32)
    last = first + width
    r = jnp.arange(R)
    i_in = jnp.round(dets.r_in - polar.radii[0]).astype(jnp.int32)
    i_out = jnp.round(dets.r_out - polar.radii[0]).astype(jnp.int32)
    radial = (r[None] >= i_in[:, None]) & (r[None] < i_out[:, None])  # (K, R)
    ok = polar.line_ok
    changed = (d2 > CHANGED) & ok
    sigma = lines.sigma

    def geometry(edge_line, out):
        """The inside samples (K, R) of the edge at ``edge_line`` (K,), outward ``out`` (+-1), its flank
        samples (K, F, R) and which flanks count."""
        a = (edge_line[:, None] - out * jnp.minimum(inner[None], width[:, None] // 2)) % T  # (K, R)
        b = (edge_line[:, None, None] + out * flank[None]) % T  # (K, F, R)
        rb = jnp.broadcast_to(r, b.shape)
        # a flank sample inside another person's region shows that person, not what adjoins this one's side:
        # a faint ghost beside someone standing took their body for its own edge now (standing_start 9263)
        return a, b, ok[b, rb] & ~_elsewhere(dets, b, rb, T)

    def least(a, b, flank_ok, colours, var_factor):
        """The least d^2 between the inside samples ``a`` (K, R) and the flanks ``b`` (K, F, R) that count,
        in ``colours`` (the frame's or the background's) with the flanks' ``var_factor``."""
        rr, rb = jnp.broadcast_to(r, a.shape), jnp.broadcast_to(r, b.shape)
        sig = jnp.broadcast_to(sigma[a, rr][:, None], b.shape)
        inside = jnp.broadcast_to(colours[a, rr][:, None], (*b.shape, 3))
        if detector.light_axis is None:
            d = change_measure(inside, colours[b, rb], var_factor[b, rb], sig)
        else:  # the lights' own gradients (a lamp's pool of another colour) are no object's edge
            d = change_across_light(inside, colours[b, rb], var_factor[b, rb], sig, detector.light_axis)
        return jnp.min(jnp.where(flank_ok, d, jnp.inf), axis=1)

    once = jnp.ones_like(lines.var_factor)  # the frame: one frame's estimate

    def side(a, b, flank_ok):
        """(now, before, measured, judged) at each radius for the edge whose inside samples are ``a`` and
        flanks ``b``: the sample inside it against the samples outside it."""
        rr = jnp.broadcast_to(r, a.shape)
        rb = jnp.broadcast_to(r, b.shape)

        now = least(a, b, flank_ok, cur, once)
        before = least(a, b, flank_ok, lines.mean, lines.var_factor)
        measured = changed[a, rr] & radial & ~_elsewhere(dets, a, rr, T)
        # eq 5: chromaticity's noise grows as the light falls, so the d^2 of a pair is as small as its darker
        # sample is dark. Where the background's pair is more than sqrt(GHOST_RATIO) times darker than the
        # frame's, an edge the frame shows would measure under GHOST_RATIO times less in the background (its
        # very own): no new edge can be told there, and the person's test takes it for one that was there
        # before. A ghost of someone's black shoes against a table (6-17 grey levels against 100) "had no
        # edge" beside the table and was judged a person on the table's edge, kept all clip
        # (lamps_switching 9311: 230 frames; standing_start 9311)
        def darker(colours):
            flanks = jnp.sum(jnp.where(flank_ok[..., None], colours[b, rb], 0.0), axis=(1, 3))
            flanks = flanks / jnp.maximum(jnp.sum(flank_ok, axis=1), 1)
            return jnp.minimum(jnp.sum(colours[a, rr], -1), flanks)

        seen = darker(lines.mean) * jnp.sqrt(GHOST_RATIO) >= darker(cur)
        return now, before, measured, jnp.where(seen, before, jnp.maximum(before, now))

    # each side on its own (see verdicts): taking the two sides radius by radius let a side against
    # furniture speak for the radii where only it was measured (three_people 8810: a ghost of the
    # learning kept all clip, edge now 30 from the table beside it, about 1 on its open side)
    left, right = geometry(first, -1), geometry(last, 1)
    sides = [side(*left), side(*right)]
    (now_l, before_l, n_l), (now_r, before_r, n_r) = (_side_means(*s[:3]) for s in sides)
    person_before = [_side_means(now, judged, measured)[1] for now, _, measured, judged in sides]
    # each side's inside against the other side's flanks (verdicts: the floor showing again beside a ghost)
    cross = []
    for (a, _, _), (_, b, flank_ok), (_, _, measured, _) in ((left, right, sides[0]), (right, left, sides[1])):
        c = least(a, b, flank_ok, cur, once)
        cross.append(_side_means(c, c, measured)[0])
    return Evidence(edge_now=jnp.stack([now_l, now_r], -1), edge_before=jnp.stack([before_l, before_r], -1),
                    samples=jnp.stack([n_l, n_r], -1).astype(jnp.float32),
                    person_before=jnp.stack(person_before, -1), cross_now=jnp.stack(cross, -1))


def _spacing(detector: Detector) -> Float[Array, " R"]:
    """Pixels between neighbouring lines at each radius."""
    polar = detector.polar
    return polar.radii * (2 * jnp.pi / polar.n_theta)


def _flank_lines(detector: Detector) -> Array:
    """Lines between an edge line and its flank samples at each radius (:data:`FLANK_PX` pixels out,
    rounded up), (F, R)."""
    return jnp.stack([jnp.ceil(px / _spacing(detector)).astype(jnp.int32) for px in FLANK_PX])


#: Lines :func:`floor_shows` computes at a time (a person's run of lines is 5-30).
FLOOR_SHOWS_LINES = 32


def floor_shows(detector: Detector, cur: Float[Array, "T R 3"], lines: LineBackground, dets: Detections,
                which: Bool[Array, " K"], people: Bool[Array, "T R"],
                needed: Bool[Array, "T R"] | None = None) -> Bool[Array, "T R"]:
    """Whether the frame ``cur`` shows the floor at each polar sample on the lines of a detection in
    ``which`` (at any radius; elsewhere False): at one of the region's flanks (:data:`FLANK_PX` outside
    its first or last line, at the sample's radius; a flank in ``people``, some person's region, or not
    ``line_ok``, does not count), the frame is within :data:`CHANGED` of the flank's background and the
    sample's background is :data:`ASIDE_BEFORE` or more from it. d^2 of eq 6-7 (:func:`change_of_terms`)
    both, also under ``light_axis``: the sample and its flank are a few pixels apart under the same light
    now, and across the light a walker's shadow on a warm floor matched a grey floor beside it
    (two_spectra 9389). A ghost's sample shows the floor beside it and had a person's colour; someone's
    shows neither. A sample on the lines of several such detections is read at the first one's flanks.
    With ``needed``, only lines that hold a sample it marks are read (False elsewhere).

    :func:`verdicts` reads a region's sides; this reads inside it, sample by sample: someone who stood
    through the learning and walks out along their own line is one detection with their ghost, whose
    sides show the walker's edge (a person's verdict: every sample a person's vote) while the ghost
    reaches inward of the walker's foot (standing_start 9360)."""
    T, R = people.shape
    in_lines, _ = _in_region(dets, jnp.arange(T), jnp.arange(R), T)  # (K, T)
    on = which[:, None] & in_lines
    k = jnp.argmax(on, axis=0)  # (T,): the first such detection at each line
    flank = _flank_lines(detector)  # (F, R)
    first, last = dets.region[:, 0], dets.region[:, 1]
    b = jnp.concatenate([first[:, None, None] - flank, last[:, None, None] + flank], axis=1) % T  # (K, 2F, R)
    rb = jnp.broadcast_to(jnp.arange(R), b.shape)
    # each detection's flanks (the background's terms of eq 6-7, as the life keeps them) gathered once, and
    # only the lines asked for computed, FLOOR_SHOWS_LINES at a time (every sample of every line against
    # every flank, the life's step took 9 ms instead of 2.5 on one core beside someone standing)
    flank_ok = detector.polar.line_ok[b, rb] & ~people[b, rb]  # (K, 2F, R)
    ref = jax.tree.map(lambda a: a[b, rb], lines.ref)
    want = jnp.any(on, axis=0) if needed is None else jnp.any(on, axis=0) & jnp.any(needed, axis=1)
    L = FLOOR_SHOWS_LINES
    order = jnp.nonzero(want, size=T + L, fill_value=T)[0]  # the lines wanted, then T (none)

    def shows(rows):  # (L,) lines -> (L, R)
        at_rows = jnp.minimum(rows, T - 1)
        kk = k[at_rows]
        ref_rows = jax.tree.map(lambda a: a[kk], ref)
        sig = lines.sigma[at_rows][:, None]
        at = lambda colours: tuple(a[:, None] for a in current_terms(colours[at_rows]))  # against each flank
        floor_now = change_of_terms(at(cur), ref_rows, sig) < CHANGED
        person_before = change_of_terms(at(lines.mean), ref_rows, sig) >= ASIDE_BEFORE
        return jnp.any(flank_ok[kk] & floor_now & person_before, axis=1)

    def chunk(c, out):
        rows = lax.dynamic_slice(order, (c * L,), (L,))
        return out.at[rows].set(shows(rows), mode="drop")

    return lax.fori_loop(0, (jnp.sum(want) + L - 1) // L, chunk, jnp.zeros((T, R), bool))


def _elsewhere(dets: Detections, a: Array, rr: Array, T: int) -> Bool[Array, "K ..."]:
    """Whether the sample (line ``a[k, ...]``, radius index ``rr[k, ...]``) measured for detection ``k`` lies
    in the explained region of another person (a valid detection). Such a sample speaks for that person,
    not for ``k``: a ghost of the learning whose run of lines took in the body of someone standing nearer
    the camera at its azimuth (who had stood far out through the learning and then walked in along
    their own line) showed that person's edge as its own and was never judged (standing_start 9035:
    70 frames, 2.8 s)."""
    in_lines, in_radii = _in_region(dets, a, rr, T)  # (J, K, ...): person j's region at k's samples
    K = a.shape[0]
    other = dets.valid[:, None] & ~jnp.eye(K, dtype=bool)  # (J, K): person j, not k itself
    other = other.reshape(*other.shape, *([1] * (a.ndim - 1)))
    return jnp.any(other & in_lines & in_radii, axis=0)


def _side_means(now, before, measured):
    """One side's edge now and before, averaged over the radii measured (``inf`` where none was)."""
    measured = measured & jnp.isfinite(now) & jnp.isfinite(before)
    n = jnp.sum(measured, 1)
    mean = lambda x: jnp.where(n > 0, jnp.sum(jnp.where(measured, x, 0.0), 1) / jnp.maximum(n, 1), jnp.inf)
    return mean(now), mean(before), n


def _in_region(dets: Detections, t: Array, r: Array, T: int) -> tuple[Array, Array]:
    """Whether line indices ``t`` and radius indices ``r`` (any shape) lie in each detection's explained
    region's lines and radii: two masks of shape (K, *t.shape) and (K, *r.shape)."""
    first, last, r0, r1 = (dets.region[:, j].reshape(-1, *([1] * t.ndim)) for j in range(4))
    return (t[None] - first) % T <= (last - first), (r[None] >= r0) & (r[None] < r1)


def regions(dets: Detections, which: Bool[Array, " K"], shape) -> Bool[Array, "T R"]:
    """The polar samples inside the explained region of any detection in ``which``."""
    T, R = shape
    in_lines, in_radii = _in_region(dets, jnp.arange(T), jnp.arange(R), T)  # (K, T), (K, R)
    return jnp.any(which[:, None, None] & in_lines[:, :, None] & in_radii[:, None, :], axis=0)


class LifeRates(eqx.Module):
    """The life's time constants in frames (from the rig's ``[detection]`` seconds and the frame rate,
    :func:`runtime.realtime.perception.life_rates`) and the drift rate per frame. ``floor_shows_frames``:
    how long a changed sample must have been still before :func:`floor_shows` gives it a ghost's vote
    (``floor_shows_s``, 1 s): a ghost's samples are still from the moment its person left them, a walker's
    only while uniform clothes slide over them (10-20 frames at 25 per second); a walker dressed like a
    flank of the floor matched it and was painted in (three_people 9386, 9398)."""

    adapt_rate: Float[Array, ""]
    edge: Float[Array, ""]
    still_frames: Float[Array, ""]
    ghost_frames: Float[Array, ""]
    absorb_frames: Float[Array, ""]
    learn_frames: Float[Array, ""]
    floor_shows_frames: Float[Array, ""]


class Renewal(eqx.Module):
    """What one frame of the life does at each polar sample: ``cur`` the frame's colour there, ``fix``
    whether it is re-learnt from the frame (a ghost repaired, or absorbed), ``free`` whether it was
    seen unoccupied, ``rate`` its drift rate (0 unless free), ``still``, ``ghost`` and ``rest`` its counts after
    the frame (before a fix resets them)."""

    cur: Float[Array, "T R 3"]
    fix: Bool[Array, "T R"]
    free: Bool[Array, "T R"]
    rate: Float[Array, "T R"]
    still: Float[Array, "T R"]
    ghost: Float[Array, "T R"]
    rest: Float[Array, "T R"]


@jax.jit
def _judge(detector: Detector, life: Life, frame: UInt8[Array, "H W 3"], dets: Detections,
           d2: Float[Array, "T R"], trusted: Bool[Array, " K"],
           rates: LifeRates, trace: DetectionTrace | None = None) -> tuple[Renewal, Evidence, Array, Array]:
    """:func:`live_step`'s first half: the detections' evidence and verdicts, and what each sample does."""
    polar = detector.polar
    lines = life.lines
    cur = polar_frame(detector, jnp.asarray(frame)) if trace is None else trace.cur
    ok = polar.line_ok
    changed = (d2 > CHANGED) & ok
    known = trace is not None and trace.evidence is not None
    ev = trace.evidence if known else ghost_evidence(detector, cur, lines, d2, dets)
    valid = life_candidates(dets)
    weak = faint(detector, dets)
    sure_ghost, _ = verdicts(ev, jnp.ones_like(trusted), rates.edge, weak)  # both signs, as for the trusted
    # a faint edge now and less before is no verdict: the vote waits (a standing person never seen
    # walking in, whose edge now flickered about the threshold, 3.5-50 against none before, used to be
    # voted into the background: stops_a_minute 8506, detected in 0.26 of their minute)
    is_ghost, is_person = verdicts(ev, trusted, rates.edge, weak)
    ghostly = valid & is_ghost
    shape = d2.shape
    in_ghost = regions(dets, ghostly, shape)
    people = regions(dets, valid & is_person, shape)
    protected = regions(dets, valid & trusted & ~ghostly, shape)
    occupied = regions(dets, valid, shape)
    step = change_measure(cur, life.prev, 1.0, lines.sigma)
    still = jnp.where(changed & (step < CHANGED), life.still + 1.0, 0.0)
    rest = jnp.where(changed, life.rest + (step < CHANGED), 0.0)
    # a sample that has been still a while and shows the floor beside its detection's region, where the
    # background had a person's colour, is a ghost's whatever the region's verdict (floor_shows; the
    # lines only where a sample is still that long: none in most frames)
    long_still = changed & (still >= rates.floor_shows_frames)
    shows = floor_shows(detector, cur, lines, dets, valid, occupied, long_still) & long_still
    # a vote, not a run: +1 in a ghost's region, -1 in a person's, held where the sample changed and
    # nobody claims it; the evidence of one ghost flickers about the edge threshold from frame to frame
    vote = jnp.where((in_ghost & ~people) | shows, 1.0, jnp.where(people, -1.0, 0.0))
    ghost = jnp.where(changed, jnp.maximum(life.ghost + vote, 0.0), 0.0)
    # what the learning left unsettled (occupied through a third of its frames or more) holds a ghost
    # of someone who stood there at the learning's start as often as not: repaired on its first votes
    # when the ghost shows both signs (an edge in the background, none now); someone standing there
    # now, learnt as the floor, has no edge in the background (and keeps the slow rule)
    unsettled = ~learned(1.0 / life.seen, rates.learn_frames)
    # (not a detection the caller takes for a person: a stander seen since before the tracker started,
    # a passer-by in front hiding the sides the evidence reads, was re-learnt on two such frames:
    # stops_a_minute 9064)
    quick = (unsettled & regions(dets, valid & sure_ghost & ~trusted, shape) & (ghost >= UNSETTLED_VOTES)
             & (still >= UNSETTLED_VOTES))
    # in a trusted detection's region (someone the tracker saw walk in is there), the frame takes the
    # background's place only where it continues the floor beside the sample (the nearest samples of its
    # radius outside every detection, learnt and unchanged now) better than the background does: a
    # ghost's region is its run of lines, and someone walking off the spot, in along their own line, is
    # one detection with their ghost; the body's samples stay still from frame to frame as the image
    # slides over them and were re-learnt with the ghost's (six_people 9202: a walker painted in, a false
    # alarm for 190 frames). Elsewhere nobody is known to be there, and the floor beside
    # is not always the floor's colour (a static change one line wide, standing_start 9216, was kept)
    due = changed & (((ghost >= rates.ghost_frames) & (still >= rates.still_frames)) | quick)
    someone = regions(dets, valid & trusted, shape)
    # (the test only in a frame that has such a sample due: most have none, and it is most of the life's
    # cost, 1.4 ms of a step on one core)
    floor_now = lax.cond(jnp.any(due & someone),
                         lambda: nearer_floor(detector, lines, ok & ~occupied & ~unsettled & ~changed, cur, lines.mean),
                         lambda: jnp.zeros(shape, bool))
    repair = due & (floor_now | ~someone)
    absorb = changed & (rest >= rates.absorb_frames) & ~protected
    fix = (repair | absorb) & ok
    free = ok & ~changed & ~occupied
    learning = life.seen < rates.learn_frames - 0.5  # kept in fewer frames than the learning took
    drift = rates.adapt_rate
    if detector.light_axis is not None:
        # lights of two colours: a sample relit (a change to the paper's d^2, none across the light's
        # colour) follows the light within a few frames, so that the next shadow is measured against
        # the light as it is now (a lamp switched on, then a person's shadow from the other light: a
        # swap of the lights no change of brightness bounds)
        relit = change_against(cur, lines.ref, lines.sigma) > CHANGED
        drift = jnp.where(relit, jnp.maximum(drift, RELIGHT_RATE), drift)
    a = jnp.where(free, jnp.where(learning, jnp.maximum(drift, 1.0 / (life.seen + 1.0)), drift), 0.0)
    return (Renewal(cur=cur, fix=fix, free=free, rate=a, still=still, ghost=ghost, rest=rest), ev, ghostly,
            dets.valid & is_person)


@jax.jit
def _renew(life: Life, renewal: Renewal, rates: LifeRates) -> Life:
    """:func:`live_step`'s second half: the life after the frame, each sample as ``renewal`` says."""
    lines, cur, fix, a = life.lines, renewal.cur, renewal.fix, renewal.rate
    mean = jnp.where(fix[..., None], cur, lines.mean + a[..., None] * (cur - lines.mean))
    var_factor = jnp.where(fix, 1.0, (1 - a) ** 2 * lines.var_factor + a * a)
    seen = jnp.where(fix, 1.0, jnp.minimum(life.seen + renewal.free, rates.learn_frames))
    return Life(lines=lines_from(mean, var_factor, lines.sigma), seen=seen, prev=cur,
                still=jnp.where(fix, 0.0, renewal.still), ghost=jnp.where(fix, 0.0, renewal.ghost),
                rest=jnp.where(fix, 0.0, renewal.rest))


def live_step(detector: Detector, life: Life, frame: UInt8[Array, "H W 3"], dets: Detections,
              d2: Float[Array, "T R"], trusted: Bool[ArrayLike, " K"],
              rates: LifeRates, trace: DetectionTrace | None = None) -> tuple[Life, Evidence, Array, Array]:
    """One frame of the background's life (see the module docstring) after ``dets`` were detected in
    ``frame`` against ``life.lines`` with change ``d2``; ``trusted`` marks the detections the caller
    knows to be people who walked in. Returns the new life, each detection's evidence, which
    detections were judged ghosts, and which (valid ones) were judged people (:func:`verdicts`).
    ``trace``, if given (the detection's :class:`~omnijax.detection.DetectionTrace` of this frame),
    gives the frame at the polar samples and, when the perception step judged the detections already
    (:func:`set_aside_ghosts`), their evidence: computed once a frame, not again here.

    Two compiled calls, what each sample does (:func:`_judge`) then the new life (:func:`_renew`): in
    one, XLA's CPU fusion recomputes every sample's decisions inside the loop of each array of the life
    it writes, three times over in the colour's (1.7 ms a frame on one core against 1.0 ms)."""
    renewal, ev, ghostly, person = _judge(detector, life, frame, dets, d2, trusted, rates, trace)
    return _renew(life, renewal, rates), ev, ghostly, person


#: A ghost is set aside (:func:`set_aside_ghosts`) only where one side shows it clearly: no edge now, over
#: ASIDE_RADII radii or more, against a person's edge in the background (ASIDE_BEFORE or more). The
#: background's own edges between floor tiles of slightly different colour measure 10-50 (its variance
#: is a learnt mean's, a thirtieth of a frame's), and a person dressed like the floor, whose edge now is
#: faint, was set aside on them (six_people 9040: misses 0.013 -> 0.028 without this); a ghost of
#: someone who stood in the learning measures hundreds over tens of radii.
ASIDE_BEFORE, ASIDE_RADII = 100.0, 8.0
#: ... and only while under this share of its changed samples moved since the frame before (a ghost is
#: static: sensor noise alone moves about 1e-3 of them).
ASIDE_MOVED = 0.02


def set_aside_ghosts(detector: Detector, trace: DetectionTrace, lines: LineBackground, dets: Detections, edge,
                     prev: Float[Array, "T R 3"]) -> tuple[Detections, DetectionTrace]:
    """``dets`` with the sure ghosts no longer people (``valid``) but left to the background's life to
    judge and repair (as ``strip``). A ghost is the background's error, not someone: before, each was
    reported, tracked and counted for the frames its repair takes (ten at ``ghost_s`` 0.4 s; the ghosts
    of people who stood through the learning were most of standing_start's false alarms). Sure: both
    signs of one and no person's edge on either side (:func:`verdicts` as for a trusted detection), one
    side clear (:data:`ASIDE_BEFORE`), and nothing in its region moved since the frame before (``prev``:
    the previous frame at the polar samples, :attr:`Life.prev`; under :data:`ASIDE_MOVED` of its changed
    samples): someone walking off the spot they stood on through the learning is one detection with
    their ghost, their side's edge now no stronger than the background's there (their own, learnt), and
    was set aside with it (standing_start 9031: 24 frames missed).

    ``trace`` is the frame's detection trace (its d^2 and the frame at the polar samples); returned with
    the detections' evidence in it, for the background's life (:func:`live_step`) to read. The evidence
    is of the detections as they were before the set-aside: a sample of another detection in a ghost's
    region is not counted for it, as the life's own evidence would not count it before."""
    cur, d2 = trace.cur, trace.d2
    ev = ghost_evidence(detector, cur, lines, d2, dets)
    clear = (ev.edge_now < edge) & (ev.edge_before >= ASIDE_BEFORE) & (ev.samples >= ASIDE_RADII)
    T, R = d2.shape
    changed = (d2 > CHANGED) & detector.polar.line_ok
    moved = changed & (change_measure(cur, prev, 1.0, lines.sigma) >= CHANGED)
    in_lines, in_radii = (m.astype(jnp.float32) for m in _in_region(dets, jnp.arange(T), jnp.arange(R), T))
    count = lambda m: jnp.sum((in_lines @ m.astype(jnp.float32)) * in_radii, axis=1)  # (K,) samples in region
    still = count(moved) <= ASIDE_MOVED * count(changed)
    ghost = (dets.valid & verdicts(ev, jnp.ones_like(dets.valid), edge, faint(detector, dets))[0]
             & jnp.any(clear, axis=-1) & still)
    strip = ghost if dets.strip is None else dets.strip | ghost
    dets = eqx.tree_at(lambda d: (d.valid, d.strip), dets, (dets.valid & ~ghost, strip), is_leaf=lambda x: x is None)
    return dets, eqx.tree_at(lambda t: t.evidence, trace, ev, is_leaf=lambda x: x is None)


#: Fewest learning frames a minority colour must hold to be taken for the floor (a tenth of 30).
MINORITY_FRAMES = 3.0


def _floor_beside(sure: Bool[Array, "T R"], lines: LineBackground) -> tuple[tuple[Array, Array], ...]:
    """Per polar sample, the background (``lines``' mean colour and variance factor) at the nearest line
    on each side (left, right: lower and higher line index, round the circle) whose sample at the same
    radius is ``sure`` floor: what the floor is beside a disputed sample, a body's width away at most
    for someone's image (the sample's own where it is sure itself; at a radius with no sure sample, line
    T - 1's on the left, line 0's on the right). Returns ``((mean, var_factor) left, (mean, var_factor)
    right)``, T x R (x 3).

    Two sequential ``lax.scan`` over the lines, each carrying the last sure sample's background from
    where the circle's last (first) sure line left off. On the CPU, the line indices by ``lax.cummax`` /
    ``cummin`` over the circle doubled (reduce-windows) and the background gathered at them made
    :func:`nearer_floor` 4.6 ms on one core; with these scans it is 1.4 ms (docs/detection.md,
    "twenty-sixth session")."""
    T = sure.shape[0]
    t = jnp.arange(T)[:, None]
    r = jnp.arange(sure.shape[1])
    found = jnp.any(sure, 0)
    start_left = jnp.where(found, jnp.max(jnp.where(sure, t, -1), 0), T - 1)
    start_right = jnp.where(found, jnp.min(jnp.where(sure, t, T), 0), 0)

    def carry_sure(start, reverse):
        def keep(held, row):
            ok, mean, var_factor = row
            held = (jnp.where(ok[:, None], mean, held[0]), jnp.where(ok, var_factor, held[1]))
            return held, held

        held = (lines.mean[start, r], lines.var_factor[start, r])
        return lax.scan(keep, held, (sure, lines.mean, lines.var_factor), reverse=reverse)[1]

    return carry_sure(start_left, False), carry_sure(start_right, True)


def nearer_floor(detector: Detector, lines: LineBackground, sure: Bool[Array, "T R"], new: Float[Array, "T R 3"],
                 old: Float[Array, "T R 3"], one_side: Bool[Array, "T R"] | None = None) -> Bool[Array, "T R"]:
    """Whether each sample's ``new`` colour is nearer than its ``old`` one to the floor beside it (the
    least d^2 from the background ``lines`` at the nearest ``sure`` sample of its radius, either side,
    :func:`_floor_beside`; d^2 as the detector measures it, across the light under ``light_axis``): a
    colour that continues the floor around it, where the other does not.
    The one test of both re-learnings that put a sample's other colour in place of the background's:
    the learning's minority at the start (:func:`settle_learning`) and a ghost's repair from the
    current frame (:func:`live_step`). Where ``one_side`` holds, nearer than ``old`` on one side is
    enough: the other side may be an object of the old colour (a stander against a cabinet of their
    shirt's colour), and colour alone cannot break that tie (the caller knows more: the settling, what
    the learning's last frames showed)."""
    beside = _floor_beside(sure, lines)

    def d2(colours, mean, var_factor):
        if detector.light_axis is None:
            return change_measure(colours, mean, var_factor, lines.sigma)
        return change_across_light(colours, mean, var_factor, lines.sigma, detector.light_axis)

    (new_l, old_l), (new_r, old_r) = ((d2(new, m, v), d2(old, m, v)) for m, v in beside)
    least = jnp.minimum(new_l, new_r) < jnp.minimum(old_l, old_r)
    if one_side is None:
        return least
    return least | (one_side & ((new_l < old_l) | (new_r < old_r)))


@jax.jit
def settle_learning(detector: Detector, lines: LineBackground, bg: Background, edge,
                    frames) -> tuple[LineBackground, Array]:
    """The learning's majority settled where it was someone who stood there (before :func:`start_life`).

    Learning keeps, per sample, the colour most of its frames showed (:func:`~omnijax.learn_background`),
    so someone who stood on a spot through most of the window is learnt as the floor and stays
    invisible for as long as they stand. The frames they were not there in are one of the sample's
    *minorities* (``bg.minority``: their mean colours, ``bg.minority_n``: how many frames each;
    ``lines`` is ``bg`` at the polar samples, :func:`~omnijax.detection.line_background`), each
    tried in turn as below.
    The minority image (the minority where it holds :data:`MINORITY_FRAMES`, the majority elsewhere) is
    searched for people against the majority, and each one found is judged by the ghost evidence
    (:func:`ghost_evidence`) with the minority as "now" and the majority as "before": where the
    minority shows the floor continuing the floor around it (no edge, under ``edge``) and the majority
    an edge :data:`GHOST_RATIO` times stronger (a person against the floor), the majority was the
    person and the region's changed samples take their minority (variance factor ``1 / minority_n``:
    the life keeps learning them as they are seen free). A minority of people passing (an edge in it)
    is left out. A changed sample of such a region takes its minority only where the minority is nearer
    the floor beside it than the majority is (:func:`_floor_beside`: the nearest samples at its radius
    that every learning frame but one agreed on, ``frames`` the learning's count): a region's run of
    lines holds more than its own person, and someone who stood beside the spot early in the learning and
    then moved on to it (the minority there is that person, the majority the floor) was painted into
    the background as a ghost for the whole clip (stops_a_minute 9098: 1,536 false alarms in 1,600
    frames). Where the minority is what the learning's last third showed (its last candidate: someone
    who stood there left), nearer on one side is enough: the other may be an object of the majority's
    colour (standing_start 9341: a stander against a cabinet of their shirt's colour; a passer over a
    rug of their colour leaves the majority in the last frames, six_people 9364).
    Returns the settled lines and the samples that took their minority."""
    ok, idx = detector.polar.line_ok, detector.polar.line_index
    learnt = lines  # the learning as it was: the floor beside is read from it
    sure = ok & (1.0 / lines.var_factor >= frames - 1.0 - 1e-3)  # every learning frame but one agreed
    took = jnp.zeros(ok.shape, bool)
    # the last third's minority (learn_background's last candidate): what the spot showed once someone
    # who stood there left
    last, last_n = gather_rgb(bg.minority[-1], idx), bg.minority_n[-1].reshape(-1)[idx]
    # each candidate in turn, against the lines settled so far: one compiled body scanned over the
    # candidates (unrolled, the three took 10.9 s of a cold demo start's 48.9 s of compiling; scanned, 7.1 s)
    def settle(carry, candidate):
        lines, took = carry
        minority, minority_n = gather_rgb(candidate[0], idx), candidate[1].reshape(-1)[idx]
        has = (minority_n >= MINORITY_FRAMES) & ok & ~took
        composite = jnp.where(has[..., None], minority, lines.mean)
        d2 = jnp.where(ok, change_at(detector, composite, lines), 0.0)
        dets = locate_people(detector, d2, find_sectors(detector, d2.sum(-1)))
        ev = ghost_evidence(detector, composite, lines, d2, dets)
        floor = life_candidates(dets) & verdicts(ev, jnp.ones_like(dets.valid), edge)[0]
        recent = (last_n >= MINORITY_FRAMES) & (change_measure(minority, last, 1.0, lines.sigma) <= CHANGED)
        nearer = nearer_floor(detector, learnt, sure, minority, lines.mean, one_side=recent)
        take = regions(dets, floor, d2.shape) & has & (d2 > CHANGED) & nearer
        mean = jnp.where(take[..., None], minority, lines.mean)
        var_factor = jnp.where(take, 1.0 / jnp.maximum(minority_n, 1.0), lines.var_factor)
        settled = lines_from(mean, var_factor, lines.sigma)
        return (settled, took | take), None

    return lax.scan(settle, (lines, took), (bg.minority, bg.minority_n))[0]


def learned_share(detector: Detector, life: Life, frames: float) -> Array:
    """Share of the polar samples learnt from at least two thirds of ``frames`` frames (the learning's
    count): the floor the background is sure of."""
    ok = detector.polar.line_ok
    return jnp.sum(ok & learned(1.0 / life.seen, frames)) / jnp.maximum(jnp.sum(ok), 1)
