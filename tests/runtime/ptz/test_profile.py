"""Device profiles: the shipped files, the one place where angles become device units, clamping, bad files."""

from __future__ import annotations

import copy
import math

import pytest
from hypothesis import given, strategies as st

from runtime.ptz import ProfileError, default_profile, load_profile, parse_profile
from runtime.ptz.profile import DEVICES_DIR
from tests.runtime.ptz.helpers import profile_mapping


@pytest.mark.parametrize("protocol", ["visca", "pelco-d"])
def test_shipped_profiles_load(protocol):
    assert default_profile(protocol).protocol == protocol


@pytest.mark.parametrize("path", sorted(DEVICES_DIR.glob("*.toml")), ids=lambda p: p.name)
def test_every_profile_in_configs_devices_is_valid(path):
    assert load_profile(path).name


@pytest.mark.parametrize("protocol", ["visca", "pelco-d"])
@given(pan=st.floats(-math.pi, math.pi), tilt=st.floats(-0.5, 0.5), zoom=st.floats(1.0, 18.0))
def test_to_device_and_back_within_one_unit(protocol, pan, tilt, zoom):
    p = default_profile(protocol)
    t = p.to_device(pan, tilt, zoom)
    back = p.from_device(t.pan, t.tilt, t.zoom)
    if "pan" not in t.clamped:
        d = (back.pan - pan + math.pi) % (2 * math.pi) - math.pi
        assert abs(math.degrees(d)) <= 0.5 / p.pan.units_per_deg + 1e-9
    if "tilt" not in t.clamped:
        assert abs(math.degrees(back.tilt - tilt)) <= 0.5 / p.tilt.units_per_deg + 1e-9
    if "zoom" not in t.clamped:
        z = p.zoom
        slope = max((b - a) / (y - x) for a, b, x, y in zip(z.magnification, z.magnification[1:], z.position,
                                                          z.position[1:]))
        assert abs(back.zoom - zoom) <= 0.5 * slope + 1e-9


def test_clamping_is_reported_per_axis():
    p = default_profile("visca")
    t = p.to_device(math.radians(175), math.radians(-45), 30.0)
    assert set(t.clamped) == {"pan", "tilt", "zoom"}
    assert (t.pan, t.tilt, t.zoom) == (p.limits_units("pan")[1], p.limits_units("tilt")[0], p.zoom.position[-1])
    assert p.to_device(0.1, 0.1, 2.0).clamped == ()
    with pytest.raises(ValueError, match="finite"):
        p.to_device(float("nan"), 0.0, 1.0)


def test_a_clamped_position_is_at_its_limit():
    """Where a device stops when sent beyond its range is at a limit (within a unit); inside it is not."""
    p = default_profile("visca")
    t = p.to_device(math.radians(175), math.radians(-45), 2.0)
    assert p.at_limit("tilt", t.tilt) == p.tilt.limits_deg[0] and p.at_limit("pan", t.pan) == p.pan.limits_deg[1]
    assert p.at_limit("tilt", t.tilt + 2) is None and p.at_limit("tilt", 0) is None
    turning = copy.deepcopy(profile_mapping("visca"))
    turning["pan"]["limits_deg"] = [-180.0, 180.0]
    q = parse_profile(turning)
    assert q.pan_continuous and q.at_limit("pan", q.limits_units("pan")[1]) is None


def test_mounting_maps_geometry_to_device_angles():
    m = profile_mapping("visca")
    m["mounting"] = {"pan_zero_deg": 90.0, "pan_direction": -1, "tilt_zero_deg": 5.0, "tilt_direction": -1}
    p = parse_profile(m)
    t = p.to_device(math.radians(30), math.radians(-20), 1.0)
    assert t.pan == round(60 * 14.4) and t.tilt == round(25 * 14.4)
    # 350 deg device pan is the same direction as -10 deg, which the camera can reach
    t = p.to_device(math.radians(-100), 0.0, 1.0)
    assert t.pan == round(-170 * 14.4) and "pan" not in t.clamped
    assert math.degrees(p.from_device(t.pan, t.tilt, t.zoom).pan) == pytest.approx(-100, abs=0.05)


def test_pelco_pan_turns_fully_and_tilt_is_down_positive():
    p = default_profile("pelco-d")
    assert p.pan_continuous
    t = p.to_device(math.pi - 0.001, math.radians(-30), 1.0)
    assert t.clamped == () and t.tilt == 3000
    assert p.units_apart("pan", 17999, -17999) == 2


def _bad(mutate) -> dict:
    m = copy.deepcopy(profile_mapping("visca"))
    mutate(m)
    return m


@pytest.mark.parametrize("mutate,expect", [
    (lambda m: m.update(colour="red"), "colour: unknown key"),
    (lambda m: m["pan"].update(limits_deg=[170.0, -170.0]), "pan: expected [low, high]"),
    (lambda m: m["pan"].update(units_per_deg="14.4"), "pan.units_per_deg"),
    (lambda m: m["pan"].pop("units_per_deg"), "pan.units_per_deg: missing key"),
    (lambda m: m["tilt"].update(speed=30), "tilt: speed 30 is above max_speed 23"),
    (lambda m: m["zoom"].update(position=[0, 100, 50] + m["zoom"]["position"][3:]), "position must increase"),
    (lambda m: m["zoom"].update(magnification=[1.0, 2.0]), "magnification has 2 rows"),
    (lambda m: m.update(address=9), "VISCA cameras are 1-7"),
    (lambda m: m.update(protocol="rs485"), "protocol"),
    (lambda m: m["mounting"].update(pan_direction=2), "mounting.pan_direction"),
    (lambda m: m["link"].update(reconnect_backoff_s=[3.0, 1.0]), "reconnect_backoff_s"),
    (lambda m: m["pan"].update(limits_deg=[-200.0, 200.0]), "at most 360"),
    (lambda m: m["pan"].update(limits_deg=[-3000.0, 3000.0]), "pan.limits_deg.0: expected degrees in [-360, 360]"),
    (lambda m: m["tilt"].update(max_speed_deg_s=float("inf")), "tilt.max_speed_deg_s: Input should be a finite"),
    (lambda m: m["mounting"].update(pan_zero_deg=1e300), "mounting.pan_zero_deg: expected degrees"),
])
def test_bad_profiles_are_one_line_errors(mutate, expect):
    with pytest.raises(ProfileError) as exc:
        parse_profile(_bad(mutate), source="bad.toml")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("bad.toml: ") and expect in msg


def test_pelco_units_are_fixed_by_the_protocol():
    m = profile_mapping("pelco-d")
    m["pan"]["units_per_deg"] = 10.0
    with pytest.raises(ProfileError, match="hundredths of a degree"):
        parse_profile(m)


def test_profile_files_that_cannot_be_read(tmp_path):
    with pytest.raises(ProfileError, match="no such device profile"):
        load_profile(tmp_path / "missing.toml")
    with pytest.raises(ProfileError, match="is a directory"):
        load_profile(tmp_path)
    bad = tmp_path / "bad.toml"
    bad.write_text("protocol = visca\n")
    with pytest.raises(ProfileError, match="not valid TOML"):
        load_profile(bad)
    assert load_profile("sony_evi_d70").protocol == "visca"
