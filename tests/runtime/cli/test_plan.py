"""`omnijax plan` (docs/site.md): a small site on an embedded cluster of one worker, a failed room among
finished ones, resuming, the choice of k, bad input; against a separately started `dask scheduler` and
`dask worker` on 127.0.0.1 (slow)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from types import SimpleNamespace

import pytest

from runtime.cli import main
from runtime.site import choose, load_site
from tests.paths import CONFIGS

PAPER = CONFIGS / "paper.toml"


def _site(folder: Path, rooms: str, head: str = "") -> Path:
    """A site file of tiny rooms (1 m floor grid, 3 candidates per variable, one start, 100 trials)."""
    path = folder / "site.toml"
    path.write_text(f'rig = "{PAPER}"\ncameras = [1]\ncandidates = 3\ntrials = 100\n{head}\n'
                    '[layout]\ngrid_step = 1.0\nstarts = 1\n' + rooms)
    return path


ROOMS = """
[[rooms]]
name = "office"
outline = [[-2.0, -2.0], [3.0, -2.0], [3.0, 2.0], [-2.0, 2.0]]

[[rooms]]
name = "broken"
rig = "broken.toml"

[[rooms]]
name = "ell"
outline = [[-2.0, -2.0], [4.0, -2.0], [4.0, 1.0], [1.0, 1.0], [1.0, 3.0], [-2.0, 3.0]]
"""


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """The tiny site planned once on an embedded cluster of one worker: its folder, site.json and exit code.
    The room "broken" has a PTZ above the omni camera."""
    folder = tmp_path_factory.mktemp("site")
    (folder / "broken.toml").write_text(PAPER.read_text().replace("H_f = 2.00 ", "H_f = 3.50 "))
    site = _site(folder, ROOMS)
    t0 = time.perf_counter()
    code = main(["plan", str(site), "--out", str(folder / "out"), "--workers", "1"])
    return SimpleNamespace(folder=folder, site=site, out=folder / "out", code=code,
                           report=json.loads((folder / "out" / "site.json").read_text()),
                           seconds=time.perf_counter() - t0)


@pytest.mark.slow
def test_plan_writes_the_contract(planned):
    rep = planned.report
    assert [r["name"] for r in rep["rooms"]] == ["office", "broken", "ell"]  # the site file's order
    assert rep["seconds"] > 0 and "embedded local cluster, 1 worker process" in rep["cluster"]
    for room in (rep["rooms"][0], rep["rooms"][2]):
        assert room["status"] == "ok" and room["k"] == 1 and len(room["cameras"]) == 1
        assert set(room["cameras"][0]) == {"D_c_m", "H_f_m", "theta_c_deg"}
        assert room["objective"] > 0 and 0 <= room["framing"] <= 1 and room["cost"] == 1.0
        check = room["validation"]
        assert check["containment"]["trials"] > 0 and 0 <= check["containment"]["rate"] <= 1
        assert check["floor"]["points"] > 0
        assert (planned.out / "rooms" / f"{room['name']}.json").is_file()
    assert rep["totals"] == {"rooms": 3, "ok": 2, "cameras": 2, "cost": 2.0}


@pytest.mark.slow
def test_a_failed_room_is_reported_and_the_others_finish(planned):
    broken = planned.report["rooms"][1]
    assert planned.code == 1 and planned.report["failed"] == ["broken"]
    assert broken["status"] == "failed" and "foveal.H_f = 3.5 m is above the omni camera" in broken["error"]
    assert "\n" not in broken["error"]


@pytest.mark.slow
def test_plan_resumes_without_rerunning_finished_rooms(planned, capsys):
    files = {n: (planned.out / "rooms" / f"{n}.json").stat().st_mtime_ns for n in ("office", "ell")}
    (planned.folder / "broken.toml").write_text(PAPER.read_text().replace("H_f = 2.00 ", "H_f = 3.60 "))
    code = main(["plan", str(planned.site), "--out", str(planned.out), "--workers", "1"])
    out = capsys.readouterr().out
    rep = json.loads((planned.out / "site.json").read_text())
    assert code == 1 and "3 rooms: 2 done before (kept), 1 to run" in out
    assert rep["resumed"] == ["office", "ell"] and "H_f = 3.6 m" in rep["rooms"][1]["error"]
    assert {n: (planned.out / "rooms" / f"{n}.json").stat().st_mtime_ns for n in files} == files
    spec = {s.name: s for s in load_site(planned.site)}  # a changed room (its fingerprint) is run again
    assert spec["office"].fingerprint == json.loads((planned.out / "rooms" / "office.json").read_text())["fingerprint"]


def test_choose_the_fewest_cameras_that_reach_the_target():
    res = {k: SimpleNamespace(summary={"framing": f}) for k, f in ((1, 0.80), (2, 0.96), (3, 0.99))}
    assert choose(res, 0.95) == (2, True)
    assert choose(res, 0.999) == (3, False)
    flat = {k: SimpleNamespace(summary={"framing": 0.9}) for k in (1, 2)}
    assert choose(flat, 0.95) == (1, False)  # no gain: the fewest


BAD_SITES = [
    ("", "site.toml: rooms: missing key"),
    ('[[rooms]]\nname = "a"\n', "expected either rig (a rig file) or outline"),
    ('[[rooms]]\nname = "a b"\noutline = [[0, 0], [1, 0], [0, 1]]\n', "name 'a b': expected letters"),
    ('[[rooms]]\nname = "a"\noutline = [[0, 0], [1, 0], [0, 1]]\n[[rooms]]\nname = "a"\noutline = [[0, 0], [1, 0], '
     '[0, 1]]\n', "room names must differ (twice: a)"),
    ('cameras = [9]\n[[rooms]]\nname = "a"\noutline = [[0, 0], [1, 0], [0, 1]]\n', "cameras.0: expected PTZ cameras"),
    ('colour = 1\n[[rooms]]\nname = "a"\noutline = [[0, 0], [1, 0], [0, 1]]\n', "colour: unknown key"),
]


@pytest.mark.parametrize("text,expect", BAD_SITES, ids=[b[1][:30] for b in BAD_SITES])
def test_bad_site_file_exits_2_with_one_line(tmp_path, capsys, text, expect):
    site = tmp_path / "site.toml"
    site.write_text(text)
    code = main(["plan", str(site), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and expect in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args,expect", [
    (["--workers", "0"], "--workers: expected 1 to 64"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:9"], "--workers: not with --scheduler"),
])
def test_bad_flags_exit_2_with_one_line(tmp_path, capsys, args, expect):
    site = _site(tmp_path, ROOMS)
    code = main(["plan", str(site), "--out", str(tmp_path / "out"), *args])
    err = capsys.readouterr().err
    assert code == 2 and expect in err and err.count("\n") == 1


def test_the_shipped_building_has_twelve_rooms():
    specs = load_site(CONFIGS / "sites" / "building.toml")
    assert len(specs) == 12 and all(s.error is None for s in specs)
    assert tomllib.loads((CONFIGS / "sites" / "building.toml").read_text())["cameras"] == [1, 2, 3]


# ---------------------------------------------------------------------------------------------
# A cluster started by hand, as a user would


def _dask(*args, log: Path) -> subprocess.Popen:
    return subprocess.Popen([str(Path(sys.executable).parent / "dask"), *args], stdout=log.open("w"),
                            stderr=subprocess.STDOUT, start_new_session=True)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@pytest.mark.slow
def test_plan_on_a_separately_started_scheduler_and_worker(tmp_path, capsys):
    """`dask scheduler` and `dask worker` on 127.0.0.1 (ports the OS picks), `omnijax plan --scheduler`:
    the same results as on the embedded cluster; an unreachable scheduler is one line, exit 2."""
    info = tmp_path / "scheduler.json"
    scheduler = _dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file",
                      str(info), log=tmp_path / "scheduler.log")
    worker = None
    try:
        deadline = time.monotonic() + 60
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(info.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        worker = _dask("worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--no-dashboard",
                       log=tmp_path / "worker.log")
        site = _site(tmp_path, ROOMS.split("[[rooms]]\nname = \"broken\"")[0])
        code = main(["plan", str(site), "--out", str(tmp_path / "out"), "--scheduler", address])
        rep = json.loads((tmp_path / "out" / "site.json").read_text())
        assert code == 0 and rep["cluster"] == address and [r["status"] for r in rep["rooms"]] == ["ok"]
    finally:
        for proc in (worker, scheduler):
            if proc is not None:
                _stop(proc)
    capsys.readouterr()
    code = main(["plan", str(site), "--out", str(tmp_path / "out2"), "--scheduler", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err
    assert code == 2 and "--scheduler: cannot connect to tcp://127.0.0.1:9" in err and err.count("\n") == 1
    assert not (tmp_path / "out2").exists()
