"""Reading files from disk (rigs, scenarios, PTZ profiles, observations): the one place they are read and parsed;
and the one place a rig file is written back (its ``[[zones]]``, :func:`write_zones`).

Every such file is a regular file of at most :data:`MAX_FILE_BYTES`, in UTF-8; anything else
(a directory, a device, UTF-16, random bytes) is one line naming the file and what was
expected, raised as the caller's error type (exit code 2 from the command line).
"""

from __future__ import annotations

import codecs
import json
import os
import stat
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING

from omnijax.config import ConfigError

if TYPE_CHECKING:
    from omnijax.config import Rig, Zone
    from omnijax.world import Scenario


#: Where the shipped scenarios live (``configs/scenarios`` of the checkout).
SCENARIOS_DIR = Path(__file__).resolve().parents[1] / "configs" / "scenarios"


def scenario_path(spec: str | Path) -> Path:
    """A scenario file: a path as given, or the bare name of a shipped scenario (``three_people``)."""
    path = Path(spec)
    if path.is_file():
        return path
    named = SCENARIOS_DIR / f"{spec}.toml"
    if path.suffix != ".toml" and path.parent == Path(".") and named.is_file():
        return named
    names = ", ".join(sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml")))
    raise ConfigError(f"{spec}: no such scenario file, nor a scenario name ({names})")


#: Largest file read as a rig, scenario, profile, observations or calibration file (bytes).
MAX_FILE_BYTES = 16 * 2**20


def read_bytes(path: str | Path, kind: str = "config file", error: type[Exception] = ConfigError) -> bytes:
    """The bytes of a regular file; a missing, unreadable or oversized file, a directory or a device is
    one line (``error``) naming the file as a ``kind``."""
    path = Path(path)
    try:
        st = path.stat()
        if stat.S_ISDIR(st.st_mode):
            raise error(f"{path}: is a directory, expected a {kind}")
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{path}: not a regular file, expected a {kind}")
        if st.st_size > MAX_FILE_BYTES:
            raise error(f"{path}: {st.st_size} bytes, expected a {kind} of at most {MAX_FILE_BYTES // 2**20} MB")
        return path.read_bytes()
    except FileNotFoundError:
        raise error(f"{path}: no such {kind}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read the {kind}: {exc.strerror or exc}") from None


def read_text(path: str | Path, kind: str = "config file", error: type[Exception] = ConfigError) -> str:
    """A text file in UTF-8 (a UTF-8 byte-order mark is skipped); UTF-16 or other bytes are one line
    (``error``) saying where the first byte that is not UTF-8 is."""
    data = read_bytes(path, kind, error)
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        raise error(f"{path}: UTF-16 text, expected a {kind} in UTF-8 (save it as UTF-8)")
    try:
        return data.removeprefix(codecs.BOM_UTF8).decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise error(f"{path}: not UTF-8 text (byte 0x{data[exc.start]:02x} on line {line}), "
                    f"expected a {kind} in UTF-8") from None


def read_toml(path: str | Path, kind: str = "config file", error: type[Exception] = ConfigError) -> dict:
    """Parse a TOML file (see :func:`read_text`); a malformed file is one line (``error``) naming it."""
    text = read_text(path, kind, error)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}") from None


def read_json(path: str | Path, kind: str, error: type[Exception] = ConfigError):
    """Parse a JSON file (see :func:`read_text`); a malformed file is one line (``error``) naming it."""
    text = read_text(path, kind, error)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{path}: not valid JSON: {exc}") from None


def read_rig_toml(path: str | Path, _within: tuple[Path, ...] = ()) -> dict:
    """A rig file's tables, with those of the rig file it ``extends`` (a path relative to it) taken key
    by key where it gives none: ``extends = "paper.toml"`` and one ``[detection]`` key make a site that
    differs from the paper's rig by that key. Arrays of tables (``[[zones]]``) replace the base's whole."""
    path = Path(path)
    data = read_toml(path)
    base_name = data.pop("extends", None)
    if base_name is None:
        return data
    if not isinstance(base_name, str):
        raise ConfigError(f"{path}: extends: expected the name of a rig file (a string), got {base_name!r}")
    base_path = path.parent / base_name
    if not base_path.is_file():
        raise ConfigError(f"{path}: extends: no such rig file {str(base_path)!r}")
    if base_path.resolve() in _within + (path.resolve(),):
        raise ConfigError(f"{path}: extends: {str(base_path)!r} extends this file again (a loop)")
    return over_tables(read_rig_toml(base_path, _within + (path.resolve(),)), data)


def over_tables(base: dict, over: dict) -> dict:
    """``base`` with ``over``'s keys laid over it table by table: a table's keys replace the base table's
    one by one, anything else (a value, an array of tables) replaces it whole. Neither is changed."""
    merged = dict(base)
    for key, value in over.items():
        both = isinstance(value, dict) and isinstance(merged.get(key), dict)
        merged[key] = {**merged[key], **value} if both else value
    return merged


def load_rig(path: str | Path, overrides: dict[str, dict] | None = None,
             flags: dict[str, str] | None = None) -> Rig:
    """Load and validate a rig file; files it names are read relative to it (:func:`read_rig_toml`: a
    rig file may extend another).

    ``overrides`` ({section: {key: value}}, e.g. from command-line flags) replace
    the file's keys before validation, so they are checked like the file's own
    and a bad one is named by its dotted key ("... (with command-line overrides)"), and by its
    flag where ``flags`` ({"section.key": "--flag"}) names the flag that set it.
    """
    path = Path(path)
    base = path.parent

    def calib_text(name: str) -> str:
        return read_text(base / name, "calibration file")

    data = read_rig_toml(path)
    source = str(path)
    given = {section: keys for section, keys in (overrides or {}).items() if keys}
    if given:
        data = over_tables(data, given)
        source = f"{path} (with command-line overrides)"
    try:
        return build_rig(data, source, calib_text)
    except ConfigError as exc:
        msg = str(exc)
        for key, flag in (flags or {}).items():
            section, name = key.split(".", 1)
            given = (overrides or {}).get(section, {}).get(name) is not None
            if given and (key in msg or f"{section}: {name} " in msg):
                raise ConfigError(f"{flag}: {msg}") from None
        raise


def build_rig(data: dict, source: str, read_text=None) -> Rig:
    """:func:`omnijax.parse_rig` of a parsed rig file, and refused (one line naming ``source``) if its omni
    camera cannot see its own room: every rig a command uses passes here, before any work."""
    from omnijax.config import parse_rig  # here, not at the top: reading a PTZ profile needs no JAX
    from omnijax.detection import polar_range

    rig = parse_rig(data, source=source, read_text=read_text)
    try:
        polar_range(rig)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    return rig


def scenario_rig_path(path: str | Path) -> Path:
    """The rig file a scenario file names (relative to it)."""
    from omnijax.world import read_scenario_header

    path = Path(path)
    return path.parent / read_scenario_header(read_toml(path, "scenario file"), source=str(path)).rig


def load_scenario(path: str | Path, rig_overrides: dict[str, dict] | None = None) -> tuple[Rig, Scenario]:
    """Load and validate a scenario file and the rig file it names (relative to the scenario).

    ``rig_overrides`` replace keys of the rig file as in :func:`load_rig`.
    """
    from omnijax.world import parse_scenario, read_scenario_header

    path = Path(path)
    data = read_toml(path, "scenario file")
    header = read_scenario_header(data, source=str(path))
    rig_path = path.parent / header.rig
    if not rig_path.is_file():
        raise ConfigError(f"{path}: rig: no such rig file {str(rig_path)!r}")
    rig = load_rig(rig_path, rig_overrides)
    return rig, parse_scenario(data, rig, source=str(path))


def write_zones(path: str | Path, zones: tuple[Zone, ...]) -> None:
    """Replace the ``[[zones]]`` of the rig file ``path`` with ``zones``, keeping everything else as it was
    (comments too: tomlkit). Atomic: the new text goes to a temporary file beside it, is loaded as a rig
    (a file that would not load is never written), then renamed over it."""
    import tomlkit

    path = Path(path)
    doc = tomlkit.parse(read_text(path))
    if "zones" in doc:
        del doc["zones"]
    if zones:
        tables = tomlkit.aot()
        for z in zones:
            t = tomlkit.table()
            t["kind"] = z.kind
            points = tomlkit.array()
            points.extend([[round(x, 1), round(y, 1)] for x, y in z.points])
            t["points"] = points
            if z.name is not None:
                t["name"] = z.name
            tables.append(t)
        doc["zones"] = tables
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(tomlkit.dumps(doc))
        load_rig(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
