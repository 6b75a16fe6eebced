"""``omnijax plan``: the PTZ layout of every room of a building, as tasks on Dask distributed."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time
from pathlib import Path

HELP = "plan a building: every room's PTZ layout (k = the site's candidates) as tasks on Dask: site.json"
DESCRIPTION = """\
Optimises every room of a site file (each a rig file, or an outline with the
site's rig) as `omnijax optimise --cameras K` does, for every candidate number
of PTZs k; chooses the fewest PTZs whose framing (share of the floor where the
best camera meets p_contain with a face of at least layout.face_target_px)
reaches the site's framing_target, else the most framing; and checks the
chosen layout: its objective and framing on a floor grid shifted by half a
step, and a Monte Carlo of pointing containment (a true rig, person and
detection error drawn per trial; is the whole head in the frame?).

Rooms run as tasks on Dask distributed: by default an embedded local cluster
of --workers worker processes on 127.0.0.1 (stopped at the end); with
--scheduler ADDRESS the same tasks on a running `dask scheduler` and its
`dask worker`s (which must have omnijax installed). A worker that dies
mid-task has its room rerun on another; a room that fails (a bad rig, a failed
task) is reported as failed and the others finish.

Writes DIR/rooms/NAME.json as each room finishes (each file complete: written
aside, then renamed) and DIR/site.json at the end: rooms [{name, status
ok|failed, k, cameras [{D_c_m, H_f_m, theta_c_deg}], objective, framing,
cost, validation, ...}], seconds. Run again with the same DIR to resume: rooms
whose result is there (same room, same settings) are not run again; failed
ones are. Compiled programs are kept in --cache-dir (JAX's persistent
compilation cache), shared by every worker of this machine.

Exit code 1 when some room failed (site.json written all the same).
See configs/sites/building.toml for every key of a site file.
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from runtime.cli._options import add_cache_options

    p = sub.add_parser("plan", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("site", metavar="SITE.toml", help="site file: the rooms and the candidate numbers of PTZs")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created; an earlier run's is resumed)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the embedded local cluster (default: cores, at most the rooms)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on this Dask scheduler (tcp://HOST:PORT) instead of an embedded cluster")
    add_cache_options(p)
    p.set_defaults(func=run)


def write_json(path: Path, obj) -> None:
    """``obj`` as JSON at ``path``, complete or not at all: written beside it, then renamed over it."""
    from runtime.output import dumps

    tmp = path.with_name(f".{path.name}.partial")
    tmp.write_text(dumps(obj) + "\n")
    os.replace(tmp, path)


def finished(rooms_dir: Path, specs) -> dict[str, dict]:
    """Results of an earlier run to keep: complete, ``ok``, and for the same room and settings."""
    done = {}
    for spec in specs:
        path = rooms_dir / f"{spec.name}.json"
        try:
            result = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if result.get("status") == "ok" and result.get("fingerprint") == spec.fingerprint:
            done[spec.name] = result
    return done


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from runtime.cli._options import enable_cache
    from runtime.errors import Interrupted, UsageError
    from runtime.site import dask_client, load_site, run_rooms

    t0 = time.perf_counter()
    if args.workers is not None and not 1 <= args.workers <= 64:
        raise UsageError(f"--workers: expected 1 to 64 worker processes, got {args.workers}")
    if args.workers is not None and args.scheduler is not None:
        raise UsageError("--workers: not with --scheduler (the running cluster has its own workers)")
    specs = load_site(args.site)
    cache = enable_cache(args)
    out = Path(args.out)
    rooms_dir = out / "rooms"
    results = finished(rooms_dir, specs)
    todo = [s for s in specs if s.name not in results]
    workers = args.workers or max(1, min(os.cpu_count() or 1, len(todo)))
    cluster = args.scheduler or f"embedded local cluster, {workers} worker process{'es' if workers > 1 else ''}"

    with contextlib.ExitStack() as stack:
        # the cluster first: an unreachable scheduler is bad input, found before anything is written
        client = stack.enter_context(dask_client(workers, args.scheduler)) if todo else None
        rooms_dir.mkdir(parents=True, exist_ok=True)
        print(f"{len(specs)} rooms: {len(results)} done before (kept), {len(todo)} to run on {cluster}")
        bar = stack.enter_context(tqdm(total=len(todo), desc="plan", unit="room"))

        def done(spec, result) -> None:
            write_json(rooms_dir / f"{spec.name}.json", result)
            results[spec.name] = result
            bar.update(1)
            what = (f"k = {result['k']}, framing {100 * result['framing']:.1f} %, {result['objective_name']} "
                    f"{result['objective']:.4g} {result['units']}" if result["status"] == "ok"
                    else f"FAILED: {result['error']}")
            bar.write(f"{spec.name}: {what}")

        try:
            if todo:
                run_rooms(client, todo, cache, done)
        except Interrupted as exc:
            exc.during = (f"after {len(results)} of {len(specs)} rooms (their results are in {rooms_dir}: run "
                          "again to resume)")
            exc.written = True
            raise

    rooms = [results[s.name] for s in specs]
    ok = [r for r in rooms if r["status"] == "ok"]
    site = {
        "site": str(args.site),
        "rooms": rooms,
        "seconds": time.perf_counter() - t0,
        "cluster": cluster,
        "resumed": [s.name for s in specs if s not in todo],
        "failed": [r["name"] for r in rooms if r["status"] != "ok"],
        "totals": {"rooms": len(rooms), "ok": len(ok), "cameras": sum(r["k"] for r in ok),
                   "cost": sum(r["cost"] for r in ok)},
        "compile_cache": cache,
    }
    write_json(out / "site.json", site)
    print(f"{len(ok)} of {len(rooms)} rooms planned: {site['totals']['cameras']} PTZs, cost "
          f"{site['totals']['cost']:g}; {site['seconds']:.1f} s; wrote {out}/site.json")
    for name in site["failed"]:
        print(f"failed: {name}: {results[name]['error']}")
    return 1 if site["failed"] else 0
