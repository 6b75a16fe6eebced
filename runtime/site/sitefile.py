"""Site files (``omnijax plan SITE.toml``): the rooms of a building, each a rig file or an outline, the
candidate numbers of PTZs, and how a room's number is chosen. Parsed once, here, into one
:class:`RoomSpec` per room: plain data (the room's rig as a parsed TOML mapping, with the files it
names read already), so that a task can run on any worker of a cluster, sharing no file system.
"""

from __future__ import annotations

import copy
import hashlib
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

from annotated_types import Len
from pydantic import Field, model_validator

from omnijax.config import MAX_PTZS, ConfigError, Coordinate, Section, validate, within
from runtime.files import read_rig_toml, read_text, read_toml

#: What a room's name may hold: it names the room's result file.
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
#: Most rooms one site file may list.
MAX_ROOMS = 1000

Point = Annotated[list[Coordinate], Len(2, 2)]
Polygon = Annotated[list[Point], Len(3)]
CameraCount = Annotated[int, within(1, MAX_PTZS, "PTZ cameras", why="the most a rig may have")]


class SiteRoomSection(Section):
    name: str = Field(description="the room's name (letters, digits, _ . -): names its result")
    rig: str | None = Field(None, description="the room's rig file, relative to the site file")
    outline: Polygon | None = Field(None, description="or the room's floor outline (m), the site's rig around it")
    exclude: list[Polygon] = Field(default_factory=list, description="with outline: excluded zones (m)")
    cameras: Annotated[list[CameraCount], Len(1, MAX_PTZS)] | None = Field(
        None, description="candidate numbers of PTZs for this room (default: the site's)")

    @model_validator(mode="after")
    def _one_source(self):
        if not NAME.match(self.name):
            raise ValueError(f"name {self.name!r}: expected letters, digits, '_', '.' or '-' (at most 64, "
                             "starting with a letter or digit): it names the room's result file")
        if (self.rig is None) == (self.outline is None):
            raise ValueError(f"room {self.name!r}: expected either rig (a rig file) or outline (with the site's "
                             "rig), not both or neither")
        if self.exclude and self.outline is None:
            raise ValueError(f"room {self.name!r}: exclude goes with outline (a rig file has its own room.exclude)")
        return self


class SiteFile(Section):
    rig: str | None = Field(None, description="rig file the rooms given by outline start from")
    cameras: Annotated[list[CameraCount], Len(1, MAX_PTZS)] = Field(
        default_factory=lambda: [1, 2, 3], description="candidate numbers of PTZs per room")
    framing_target: Annotated[float, Field(gt=0, le=1)] = Field(
        0.95, description="choose the fewest PTZs whose framing reaches this share of the floor")
    ptz_price: Annotated[float, Field(ge=0, le=1e9)] = Field(1.0, description="cost of one PTZ (any currency)")
    candidates: Annotated[int, within(3, 27, "candidate values per variable", why="their cube is searched")] = Field(
        7, description="candidate values per search variable of each room's grid check")
    trials: Annotated[int, within(100, 1_000_000, "Monte Carlo trials")] = Field(
        2000, description="Monte Carlo trials of each room's pointing-containment check")
    layout: dict[str, Any] = Field(default_factory=dict, description="[layout] keys set in every room's rig")
    rooms: Annotated[list[SiteRoomSection], Len(1, MAX_ROOMS)]

    @model_validator(mode="after")
    def _rooms(self):
        names = [r.name for r in self.rooms]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"room names must differ (twice: {', '.join(twice)})")
        if self.rig is None and any(r.outline is not None for r in self.rooms):
            raise ValueError("rig is required when a room is given by its outline (the rig it starts from)")
        return self


@dataclass(frozen=True)
class RoomSpec:
    """One room's task: its rig as a parsed TOML mapping (site's [layout] keys applied), the text of the
    files the rig names (by name), the candidate numbers of PTZs, and the site's settings."""

    name: str
    source: str
    rig: dict
    files: dict[str, str]
    cameras: tuple[int, ...]
    framing_target: float
    ptz_price: float
    candidates: int
    trials: int
    error: str | None = None
    fingerprint: str = field(default="")


def _fingerprint(spec: RoomSpec) -> str:
    """A hash of everything the room's result depends on: a result is reused only for the same task."""
    payload = json.dumps([spec.rig, spec.files, spec.cameras, spec.framing_target, spec.ptz_price,
                          spec.candidates, spec.trials], sort_keys=True, default=str)
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


def _rig_data(path: Path) -> tuple[dict, dict[str, str]]:
    """A rig file's mapping (with the file it extends) and the text of the calibration file it names
    (relative to it)."""
    data = read_rig_toml(path)
    files = {}
    calib = data.get("omni", {}).get("calib_file") if isinstance(data.get("omni"), dict) else None
    if isinstance(calib, str):
        files[calib] = read_text(path.parent / calib, "calibration file")
    return data, files


def load_site(path: str | Path) -> list[RoomSpec]:
    """The rooms of a site file. A bad site file is a :class:`ConfigError` (one line); a room whose rig
    file cannot be read becomes a spec with its ``error`` (reported as a failed room, the others go on)."""
    path = Path(path)
    site = validate(SiteFile, read_toml(path, "site file"), str(path))
    base = None
    if site.rig is not None:
        base = _rig_data(path.parent / site.rig)
    specs = []
    for room in site.rooms:
        error = None
        try:
            if room.rig is not None:
                rig_path = path.parent / room.rig
                data, files = _rig_data(rig_path)
                source = str(rig_path)
            else:
                data, files = copy.deepcopy(base[0]), dict(base[1])
                data["room"] = {"outline": room.outline, "exclude": room.exclude}
                # the PTZ's configured place: under the omni camera (in any room); the search moves it
                tables = data["foveal"] if isinstance(data.get("foveal"), list) else [data.get("foveal")]
                for table in tables:
                    if isinstance(table, dict):
                        table.update({"D_c": 0.0, "theta_c_deg": 0.0})
                source = f"{path} (room {room.name}: {site.rig} with its outline)"
        except ConfigError as exc:
            data, files, source, error = {}, {}, str(path), str(exc)
        if site.layout:
            data["layout"] = {**data.get("layout", {}), **site.layout}
            source += " with the site's [layout]" if room.rig is not None else ""
        spec = RoomSpec(name=room.name, source=source, rig=data, files=files,
                        cameras=tuple(sorted(set(room.cameras or site.cameras))), framing_target=site.framing_target,
                        ptz_price=site.ptz_price, candidates=site.candidates, trials=site.trials, error=error)
        specs.append(RoomSpec(**{**spec.__dict__, "fingerprint": _fingerprint(spec)}))
    return specs
