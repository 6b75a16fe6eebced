"""The loop's one compiled call per frame: frame -> detections -> tracks -> pan/tilt/zoom.

:func:`control_step` fuses, with no host round trip in between:

1. detection and the detections' floor positions with covariances (:func:`perceive`: the detector
   and the aim pipeline's :func:`~omnijax.aiming.floor_from_detections`);
2. the tracker's arithmetic over its slots (:func:`runtime.realtime.kalman.step`: prediction,
   gated costs, the assignment, the update);
3. for every PTZ of the rig and every track confirmed after this frame (at most ``max_people``,
   since a confirmed track was just matched), the aim pipeline (:func:`~omnijax.aiming.aim_at_floor`,
   vmapped over the tracks and over the PTZs' stacked one-PTZ rigs, :meth:`~omnijax.Rig.ptz_stack`):
   the head predicted to when that PTZ's pan and tilt get there from its last command (their slew
   time from the pan/tilt of a first aim at the track as it is now; the zoom keeps adjusting
   meanwhile and does not lengthen the horizon), from the prediction's floor covariance plus the
   covariance of the detection the track took (a person's foot errors persist from frame to frame,
   so the track is no surer than one detection), with that detection's coupling of the foot's radius
   to the person's height (:func:`~omnijax.aiming.height_coupling`: the same error persists in the
   track, against the aim's height prior, as in ``omnijax validate``'s aims), pan/tilt, their
   covariance, the zoom of every rule and the face's width in pixels at that zoom.

The host then does the bookkeeping (:meth:`~runtime.realtime.tracker.Tracker.apply`), asks the
target selector (one PTZ) or the assignment (several, :mod:`runtime.realtime.assignment`) which
track each PTZ looks at, and takes those (PTZ, track) aims: no second aim call whichever it picks.
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp

from omnijax import Aim, Detector, Rig, aim_at_floor, detect, floor_from_detections
from omnijax.aiming import height_coupling
from omnijax.detection import set_aside_ghosts
from omnijax.geometry import wrap_pi
from omnijax.zoom import ZOOM_RULES, face_pixels
from runtime.realtime import kalman


@jax.jit
def perceive(detector: Detector, rig: Rig, frame, lines, prev=None):
    """Detection (steps 1-6) against the background's polar samples ``lines`` and the detections'
    floor positions with covariances (the aim pipeline's :func:`~omnijax.aiming.floor_from_detections`,
    under its sigma rule). Returns the detections, their trace (the frame's d^2, the frame at the polar
    samples and, given ``prev``, the detections' ghost evidence: what the background's life reads), the
    floor points and covariances. A detection whose foot lies more than ``[detection]
    off_floor_m`` outside the room's floor (beyond the outline or inside an excluded zone: a change on
    a wall or on furniture) is no person and is marked invalid; so, given ``prev`` (the previous frame at
    the polar samples, the background's life's), is a sure ghost that has not moved (no edge now, a
    strong one in the background: :func:`~omnijax.detection.set_aside_ghosts`), left to the life."""
    dets, trace = detect(detector, frame, lines)
    z, R = floor_from_detections(rig, dets.r_f, dets.theta_f, dets.sigma_r_f, dets.sigma_theta_f,
                                 dets.bound_r_f, dets.bound_theta_f)
    on_floor = rig.room.outside_by(z[:, 0], z[:, 1]) <= rig.detection.off_floor_m
    dets = eqx.tree_at(lambda d: d.valid, dets, dets.valid & on_floor)
    if prev is not None:
        dets, trace = set_aside_ghosts(detector, trace, lines, dets, rig.detection.ghost_edge, prev)
    return dets, trace, z, R


def pan_tilt_slew_s(pan, tilt, sent_pan, sent_tilt, pan_deg_s, tilt_deg_s):
    """Seconds the PTZ's pan and tilt need from (``sent_pan``, ``sent_tilt``) to (``pan``, ``tilt``) rad
    at their slew rates (deg/s): the slower axis."""
    d_pan = jnp.abs(wrap_pi(pan - sent_pan)) * (180.0 / math.pi)
    d_tilt = jnp.abs(tilt - sent_tilt) * (180.0 / math.pi)
    return jnp.maximum(d_pan / pan_deg_s, d_tilt / tilt_deg_s)


class Slew(eqx.Module):
    """What the head's prediction horizon needs, per PTZ (arrays (K,) in the rig's order; a scalar
    applies to every PTZ): whether a command was sent (and a PTZ profile is known: otherwise the
    horizon is 0), its pan and tilt (rad), the slew rates (deg/s) and the device's command latency (s,
    the profile's ``link.command_latency_s``)."""

    known: jax.Array
    pan: jax.Array
    tilt: jax.Array
    pan_deg_s: jax.Array
    tilt_deg_s: jax.Array
    latency_s: jax.Array


class Control(eqx.Module):
    """One frame's result. ``dets`` and ``trace`` (the frame's change at the polar samples and what the
    background's life reads besides: :class:`~omnijax.detection.DetectionTrace`); ``z``, ``R`` the
    detections' floor points and covariances. Tracker: ``assign`` (N,) each slot's detection (-1:
    none), ``x`` (N, 4), ``P`` (N, 4, 4) after the step.
    Aims: ``aim_slot`` (A,) the slots of the confirmed tracks (``aim_ok`` (A,) which entries are
    real); per PTZ and track, ``aims`` their :class:`~omnijax.aiming.Aim` (batched, (K, A)), ``lead``
    (K, A) the prediction horizon (s: that PTZ's command latency and slew time to the track),
    ``floor_sd`` (K, A, 2) the sd of the floor position the aim used (m: the prediction's covariance plus
    the covariance of the detection the track took) and ``face_px`` {rule: (K, A)}
    the head's width in the PTZ's image at that rule's zoom (px)."""

    dets: object
    trace: object
    z: jax.Array
    R: jax.Array
    assign: jax.Array
    x: jax.Array
    P: jax.Array
    aim_slot: jax.Array
    aim_ok: jax.Array
    aims: Aim
    lead: jax.Array
    floor_sd: jax.Array
    face_px: dict[str, jax.Array]


@functools.partial(jax.jit, static_argnames=("mode", "confirm"))
def control_step(detector: Detector, rig: Rig, frame, lines, slots, t, accel_sd, nearest_gate_m,
                 slew: Slew, mode: str = "kalman", confirm: int = 2, prev=None) -> Control:
    """Frame -> detections -> tracks -> pan/tilt/zoom of every (PTZ, confirmed track) pair, in one
    compiled call (see the module docstring). ``slots``: the tracker's (x, P, t, live, hits) slot arrays
    (:meth:`~runtime.realtime.tracker.Tracker.slots`); ``t``: the frame's time (s); ``slew``: each PTZ's
    last command and rates; ``mode``, ``accel_sd``, ``nearest_gate_m``, ``confirm``: the tracker's
    settings; ``prev``: the previous frame at the polar samples (:func:`perceive`)."""
    dets, trace, z, R = perceive(detector, rig, frame, lines, prev)
    x, P, t_tracks, live, hits = slots
    assign, x_new, P_new = kalman.step(mode, accel_sd, nearest_gate_m, x, P, t_tracks, live, t, z, R, dets.valid)
    confirmed = (assign >= 0) & (hits + 1 >= confirm)
    n_aim = dets.valid.shape[0]
    aim_slot = jnp.nonzero(confirmed, size=n_aim, fill_value=0)[0]
    aim_ok = jnp.arange(n_aim) < confirmed.sum()
    slew = jax.tree.map(lambda a: jnp.broadcast_to(a, (rig.ptz_count,)), slew)

    # a track is no surer of where its person is than the detection it took: one person's foot errors
    # persist from frame to frame (the pose, the body's shape, the same shadow), which the filter's
    # covariance, built for independent errors, averages away (demo three_people 8711: the target's
    # floor error a median 3.8 times the filter's sd)
    R_taken = R[jnp.maximum(assign, 0)]
    # and its foot's error follows the person's height as the detection's did (the same person, the same
    # error): the aim's height prior errs against it (omnijax.aiming.height_coupling)
    coupling_taken = height_coupling(rig, dets.height_r_f, dets.from_head)[jnp.maximum(assign, 0)]

    def one(ptz, slew, x, P, R_det, coupling):
        now = aim_at_floor(ptz, x[:2], P[:2, :2], ZOOM_RULES).pointing  # only pan/tilt are kept (the rest is dead)
        lead = jnp.where(slew.known, slew.latency_s + pan_tilt_slew_s(now.pan, now.tilt, slew.pan, slew.tilt,
                                                                      slew.pan_deg_s, slew.tilt_deg_s), 0.0)
        xp, Pp = kalman.predict(x, P, lead, accel_sd)
        floor_cov = Pp[:2, :2] + R_det
        aimed = aim_at_floor(ptz, xp[:2], floor_cov, ZOOM_RULES, coupling=coupling)
        face = {rule: face_pixels(ptz.foveal.lens, aimed.zooms[rule].zoom, aimed.pointing.slant, ptz.person.R_h)
                for rule in ZOOM_RULES}
        return aimed, lead, jnp.sqrt(jnp.diagonal(floor_cov)), face

    def camera(ptz, slew):
        return jax.vmap(functools.partial(one, ptz, slew))(x_new[aim_slot], P_new[aim_slot], R_taken[aim_slot],
                                                           coupling_taken[aim_slot])

    aims, lead, floor_sd, face = jax.vmap(camera)(rig.ptz_stack(), slew)
    return Control(dets=dets, trace=trace, z=z, R=R, assign=assign, x=x_new, P=P_new, aim_slot=aim_slot,
                   aim_ok=aim_ok, aims=aims, lead=lead, floor_sd=floor_sd, face_px=face)
