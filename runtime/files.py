"""Reading TOML files from disk (rigs, scenarios, PTZ profiles): the one place they are read and parsed."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import TYPE_CHECKING

from omnijax.config import ConfigError, Rig, parse_rig

if TYPE_CHECKING:
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


def read_toml(path: str | Path, kind: str = "config file", error: type[Exception] = ConfigError) -> dict:
    """Parse a TOML file; a missing or malformed file is one line (``error``) naming the file as a ``kind``."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise error(f"{path}: no such {kind}") from None
    except IsADirectoryError:
        raise error(f"{path}: is a directory, expected a {kind} (TOML)") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}") from None


def load_rig(path: str | Path, overrides: dict[str, dict] | None = None) -> Rig:
    """Load and validate a rig file; files it names are read relative to it.

    ``overrides`` ({section: {key: value}}, e.g. from command-line flags) replace
    the file's keys before validation, so they are checked like the file's own
    and a bad one is named by its dotted key ("... (with command-line overrides)").
    """
    path = Path(path)
    base = path.parent

    def read_text(name: str) -> str:
        return (base / name).read_text()

    data = read_toml(path)
    source = str(path)
    if overrides:
        for section, keys in overrides.items():
            if keys:
                data[section] = {**data.get(section, {}), **keys}
                source = f"{path} (with command-line overrides)"
    return parse_rig(data, source=source, read_text=read_text)


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
