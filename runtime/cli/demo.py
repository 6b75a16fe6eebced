"""``omnijax demo``: the whole system on a synthetic scenario, through the real serial stack, scored."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

HELP = "run the whole system on a synthetic scenario with an emulated PTZ and score it against ground truth"
DESCRIPTION = """\
Renders a synthetic scenario (people walking in a lit room, seen by the rig's omni
camera) frame by frame as a live camera would deliver them, starts the PTZ
emulator on a pseudo-terminal (--protocol visca, pelco-d) or on a UDP port of
127.0.0.1 (--protocol visca-ip: VISCA over IP, through the network stack), and
runs the real-time loop on it: detection, tracking, target choice, the head
predicted to when the PTZ gets there, pan/tilt/zoom with the propagated
uncertainty, and the commands written through the real driver to the emulator.

--ptz-count K drives K PTZs (default: as many as the scenario's rig has, 1 for
the shipped scenarios): the rig's own, and where it has fewer, copies of its
first spread evenly in azimuth around the omni camera at the first's distance
(pulled in to the wall). Each has its own emulator, its own rendered view and
its own true (miscalibrated) placement; every frame the trusted people some PTZ
can frame are assigned to the PTZs exactly (each PTZ's face size and
containment probability for each person, its slew time, how long each person
has gone uncaptured; hysteresis; spare PTZs give the weakest-framed person a
second view: docs/site.md).

Every processed frame is scored against the world's ground truth: detection
misses and false alarms, the foot position error on the floor, and for each
frame with a target whether the true head would be inside the PTZ frame for
both zoom rules (the paper's and the calibrated one), and its width in pixels;
for each frame on which the PTZ had arrived at the command it holds on its
target, the NEES of that pan/tilt against the true head direction under the
aim's covariance, and whether the head is in the frame at each rule's zoom
for p_contain 0.9, 0.95, 0.99 (summary.json's pointing);
the share of target-frames aimed at no person; per person the share of their
time in view with their face framed by some PTZ (face coverage); per PTZ its
target-frames, the share framed and its hand-offs (cameras); and the frames with
someone in view but no target, by reason (tracks not yet trusted, tracks the
PTZ cannot frame at p_contain, no track).

Writes DIR/summary.json (docs/design.md section 7.3), DIR/log.jsonl (one line per
frame), DIR/annotated.mp4 (the operator's view: the omni frame with sectors,
centre lines, feet, heads, tracks with 95 % ellipses, and the foveal view
rendered from the synthetic world at the emulated PTZ's actual position) and
DIR/view.png (one frame of it, --screenshot; not written if the run ends before
that frame or the drawing thread had to skip it). Drawing, the video and the log
run on their own thread: frames it had no time for are skipped, counted and
listed in summary.json (off_path), never waited for.

DIR/events.jsonl has the events (person appeared, face captured with the PTZ's
image in DIR/faces/, person left); --mqtt URL publishes them to a broker.
--serve HOST:PORT serves the operator's console while the demo runs: the live
view, the status, the controls (choose the target, point the PTZ, pause, home),
zones (saved into the scenario's rig file), events and a calibration assistant
(docs/console.md); it prints "serving http://HOST:PORT/?token=TOKEN" on stderr at
start, and only requests with that token change anything.

Ctrl-C or SIGTERM during start-up (building the world, learning the background,
compiling: 20-30 s) stops it at once: nothing is written, the emulator is stopped,
exit code 130. Once the loop runs, they end it and everything is written (exit 0);
a second one while the outputs are written cuts that short and keeps what was
recorded (exit 130).

--faults injects faults while running, e.g.
  broken@300,wrong-size@350,ptz-unplug@400:2,end@900
(a broken frame, a frame of the wrong size, the (first) PTZ's port vanishing for
2 s and returning, the source ending early); the summary counts each.
"""

DEFAULT_SCENARIO = Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "three_people.toml"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import EMULATED, PACES, add_background_options, add_loop_options

    p = sub.add_parser("demo", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--scenario", default=str(DEFAULT_SCENARIO), metavar="S",
                   help="scenario TOML, or a name in configs/scenarios (default three_people)")
    p.add_argument("--frames", type=int, default=1000, metavar="N",
                   help="scenario frames, background learning (the first 10 s) included (default 1000: 40 s at 25 fps)")
    p.add_argument("--seed", type=int, metavar="K", help="world seed (default: the scenario's)")
    p.add_argument("--pace", choices=PACES, default="live",
                   help="live: frames arrive at the scenario's rate, late ones are dropped (default); "
                        "all: every frame is processed, as fast as possible")
    p.add_argument("--ptz-count", type=int, metavar="K",
                   help="PTZs to drive, each with its own emulator (default: the scenario rig's; where the rig has "
                        "fewer, copies of its first spread evenly in azimuth)")
    p.add_argument("--protocol", choices=EMULATED, default="visca", metavar="NAME",
                   help="protocol of the emulated PTZ: %(choices)s (default visca; visca-ip: VISCA over IP, "
                        "through the UDP stack; onvif: ONVIF, SOAP over HTTP on localhost)")
    p.add_argument("--inset-every", type=int, default=8, metavar="K",
                   help="re-render the foveal inset every K frames (default 8; ray casting is slow)")
    p.add_argument("--screenshot", type=int, default=150, metavar="N",
                   help="save the view of the N-th processed frame as DIR/view.png (default 150)")
    add_background_options(p)
    add_loop_options(p)
    p.set_defaults(func=run)


class FovealInset:
    """The foveal view of PTZ ``ptz`` (the rig's order) for the operator's view: rendered from the world
    at its emulator's actual position (its state file), every ``every`` frames."""

    def __init__(self, world, emulator, every: int, size=(192, 144), ptz: int = 0):
        self.world, self.emulator, self.every, self.size, self.ptz = world, emulator, every, size, ptz
        self.name = "PTZ" if world.rig.ptz_count == 1 else f"PTZ {ptz}"
        self.image, self.label, self.n = None, f"{self.name} (offline)", 0

    def warm_up(self) -> None:
        from omnijax.world import render_foveal

        render_foveal(self.world, 0, 0.0, 0.0, 1.0, self.size, self.ptz).block_until_ready()

    def __call__(self, frame, loop):
        import numpy as np

        from omnijax.world import render_foveal

        if self.n % self.every == 0:
            state = self.emulator.state()
            if state is not None and self.emulator.proc is not None:
                g = state["geometry"]
                pan, tilt, zoom = math.radians(g["pan_deg"]), math.radians(g["tilt_deg"]), state["zoom"]
                t = min(frame.index, self.world.n_frames - 1)
                self.image = np.asarray(render_foveal(self.world, t, pan, tilt, zoom, self.size, self.ptz))
                moving = " moving" if state.get("moving") else ""
                self.label = f"{self.name}  pan {g['pan_deg']:6.1f}  tilt {g['tilt_deg']:5.1f}  x{zoom:4.1f}{moving}"
            else:
                self.image, self.label = None, f"{self.name}  port down"
        self.n += 1
        return self.image, self.label


def run(args: argparse.Namespace) -> int:
    from runtime.cli._options import (
        MAX_FRAMES,
        background_settings,
        console_and_events,
        load_ptz_profile,
        loop_config,
        parse_faults,
        scenario_file,
    )
    from runtime.errors import UsageError, interrupted_during

    config = loop_config(args)
    if args.frames > MAX_FRAMES:
        raise UsageError(f"--frames: expected at most {MAX_FRAMES} (the walks are simulated up front), "
                         f"got {args.frames}")
    if args.inset_every < 1:
        raise UsageError(f"--inset-every: expected a positive count, got {args.inset_every}")
    if args.screenshot < 1:
        raise UsageError(f"--screenshot: expected a processed frame number >= 1, got {args.screenshot}")
    if args.seed is not None and args.seed < 0:
        raise UsageError(f"--seed: expected an integer >= 0, got {args.seed}")
    from omnijax.config import MAX_PTZS

    if args.ptz_count is not None and not 1 <= args.ptz_count <= MAX_PTZS:
        raise UsageError(f"--ptz-count: expected 1 to {MAX_PTZS} PTZs, got {args.ptz_count}")
    plan = parse_faults(args.faults)
    scenario = scenario_file(args.scenario)

    import contextlib

    from omnijax.config import with_ptz_count
    from omnijax.world import build_world
    from runtime.files import load_scenario, scenario_rig_path
    from runtime.ptz import PtzError, make_driver
    from runtime.ptz.child import EmulatorProcess
    from runtime.ptz.profile import DEFAULT_PROFILES
    from runtime.ptz.transports import EMULATED
    from runtime.realtime.perception import learning_step
    from runtime.realtime.ptz_link import PtzLink
    from runtime.realtime.session import run_session
    from runtime.realtime.sources import FaultySource, SyntheticSource
    from runtime.validation.scoring import DemoScorer

    rig, sc = load_scenario(scenario)
    K = args.ptz_count or rig.ptz_count
    rig = with_ptz_count(rig, K)
    n_bg, seconds = background_settings(args, rig)
    n_learn = (n_bg - 1) * learning_step(sc.fps, n_bg, seconds) + 1
    if args.frames < n_learn + 20:
        raise UsageError(f"--frames: expected at least {n_learn + 20} (background learning takes the first "
                         f"{n_learn}), got {args.frames}")
    with console_and_events(args, scenario_rig_path(scenario), DEFAULT_PROFILES[EMULATED[args.protocol]]) as (
            console, mqtt):
        print(f"omnijax demo: building the world '{sc.name}' ({args.frames} frames at {sc.fps:g} fps) ...",
              file=sys.stderr, flush=True)
        with interrupted_during("during start-up"):
            try:
                world = build_world(rig, sc, args.seed, n_frames=args.frames)
            except ValueError as exc:
                raise UsageError(f"{scenario}: {exc}") from None
            synthetic = SyntheticSource(world)
            source = FaultySource(synthetic, plan) if not plan.empty else synthetic
            scorer = DemoScorer(world, synthetic)
        profile = load_ptz_profile(None, EMULATED[args.protocol])
        # the emulators are stopped when this block is left in any way, and stop by themselves if this process dies
        with interrupted_during("during start-up"), contextlib.ExitStack() as stack:
            emulators = [stack.enter_context(EmulatorProcess(args.protocol)) for _ in range(K)]
            drivers = []
            for emulator in emulators:
                driver = make_driver(emulator.url, profile)
                stack.callback(driver.disconnect)
                try:
                    driver.connect(timeout=30)  # ONVIF: the first connect parses the WSDLs (seconds on a busy machine)
                except PtzError as exc:
                    raise RuntimeError(f"the PTZ emulator did not answer: {exc}") from None
                drivers.append(driver)

            unplugs = dict(plan.ptz_unplug)

            def unplug(record, frame, *_):
                due = [k for k in unplugs if k <= frame.index]  # the frame itself may have been dropped
                if due:
                    seconds = unplugs.pop(min(due))
                    emulators[0].unplug(seconds)
                    return {"fault": f"PTZ port unplugged for {seconds:g} s"}
                return {}

            def finish(summary):
                scores = scorer.summary(float(rig.p_contain), args.zoom_rule)
                scores["cameras"] = [{**run, **score, "emulator": emulator.state(settle_s=1.0)}
                                     for run, score, emulator in zip(summary["cameras"], scores["cameras"], emulators)]
                summary.update(scores)
                summary["scenario"] = {"file": str(scenario), "name": sc.name, "frames": args.frames,
                                       "seed": world.seed, "fps": sc.fps, "pace": args.pace, "ptz_count": K}
                summary["faults"]["injected"] = plan.describe()
                summary["faults"]["ptz_unplugged"] = emulators[0].unplugs
                summary["emulator"] = emulators[0].state(settle_s=1.0)

            where = ", ".join(emulator.pty for emulator in emulators)
            print(f"omnijax demo: {K} PTZ emulator{'s' if K > 1 else ''} ({profile.name}) on {where}; learning the "
                  "background, compiling ...", file=sys.stderr, flush=True)
            summary = run_session(
                rig, source, Path(args.out), links=[PtzLink(k, d, profile) for k, d in enumerate(drivers)],
                config=config, paced=args.pace == "live", background_frames=n_bg, background_seconds=seconds,
                video=not args.no_video, record=args.record, title=f"OMNI 1  {sc.name}",
                fovea=[FovealInset(world, emulator, args.inset_every, ptz=k) for k, emulator in enumerate(emulators)],
                hooks=(scorer,), control_hooks=(unplug,), finish=finish, screenshot_at=args.screenshot,
                console=console, mqtt=mqtt)
    _report(summary, args.out)
    return 0


def _report(s: dict, out) -> None:
    import numpy as np

    from runtime.realtime.session import home_warning

    c, f, d = s["containment"], s["face_px"], s["detection"]
    lat = s["latency_ms"]
    print(f"{s['frames']} frames at {s['fps']:.1f} fps ({s['stop_reason']}); latency frame -> PTZ bytes "
          f"p50 {lat['p50'] or float('nan'):.2f} ms, p99 {lat['p99'] or float('nan'):.2f} ms")
    cov = s["face_coverage"]
    for rule, r in c["rules"].items():
        rf = r["rate_feasible"]
        print(f"  {rule:10s} zoom: head in frame {r['rate']:.4f} of all {r['trials']} target-frames "
              f"({rf if rf is not None else float('nan'):.4f} of the {r['feasible_trials']} where p_contain "
              f"{c['p_contain']} was reachable; {r['rate_person_frames']:.4f} of the {c['person_frames']} frames "
              f"with someone in view), median face {f['rules'][rule]['median']:.0f} px, face coverage "
              f"{np.mean([q['rules'][rule] for q in cov['people']]) if cov['people'] else float('nan'):.3f}")
    h = c["held"]
    print(f"  target-frames on no person: {c['no_person_share'] or 0:.4f}; no target with someone in view: "
          f"{h['untrusted']} frames untrusted, {h['unframeable']} unframeable, {h['no_track']} no track")
    pt = s.get("pointing")
    if pt and pt["frames"]:
        by_rule = {rule: "/".join(f"{c['rate']:.3f}" for c in pt["curve"] if c["rule"] == rule)
                   for rule in dict.fromkeys(c["rule"] for c in pt["curve"])}
        print(f"  pointing on the {pt['frames']} frames the PTZ had arrived on its target: NEES per dof "
              f"{pt['nees_mean']:.3f} (1 when the covariance is right), P(NEES > 5.99) {pt['nees_over_5_99']:.3f} "
              f"(0.05); head in frame at p_contain 0.9/0.95/0.99: "
              + ", ".join(f"{rule} {rates}" for rule, rates in by_rule.items()))
        people = [q for q in pt.get("people", ()) if q["frames"]]
        if len(people) > 1:
            worst = max(people, key=lambda q: q["nees_mean"])
            print(f"  pointing per person: the worst person {worst['person']} ({worst['H_p_m']:.2f} m tall), NEES "
                  f"{worst['nees_mean']:.3f} (tilt {worst['tilt_nees_mean']:.3f}) on {worst['frames']} frames; "
                  "each person in summary.json pointing.people")
    fe = s["foot_error_m"]["rms"]
    print(f"  detection: miss rate {d['miss_rate'] or 0:.4f}, false alarms {d['false_alarm_rate'] or 0:.4f} "
          f"of detections; foot error RMS {fe if fe is not None else float('nan'):.3f} m")
    p = s["ptz"]
    print(f"  PTZ: {p['commands']} commands, {p['errors']} errors, {p['reconnects']} reconnects; "
          f"faults: {s['faults']['broken_frames']} broken, {s['faults']['wrong_size_frames']} wrong size")
    cams = s.get("cameras") or []
    if len(cams) > 1:
        for cam in cams:
            fr = cam["framed_rate"]
            print(f"  PTZ {cam['id']}: head in frame {fr if fr is not None else float('nan'):.4f} of its "
                  f"{cam['target_frames']} target-frames, {cam['handoffs']} hand-offs taken, "
                  f"{cam['handed_over']} given")
    o = s["outputs"]
    written = ["summary.json", "log.jsonl", *(o[k] for k in ("video", "record", "view") if k in o)]
    print(f"demo outputs: {out}/ ({', '.join(written)})", flush=True)
    if (warning := home_warning(s)) is not None:
        print(f"omnijax demo: {warning}", file=sys.stderr, flush=True)
