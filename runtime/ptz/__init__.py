"""PTZ output: VISCA and Pelco-D encoders and parsers, device profiles, the serial driver, and an emulator.

- :mod:`runtime.ptz.visca`, :mod:`runtime.ptz.pelco_d`: pure ``bytes`` encoders, incremental parsers.
- :mod:`runtime.ptz.profile`: device profiles (``configs/devices/*.toml``); the one place where
  omnijax pan/tilt/zoom become device units.
- :mod:`runtime.ptz.base`: :class:`~runtime.ptz.base.DriverBase`, what every driver shares (the latest
  target, connect/disconnect, queries, counters).
- :mod:`runtime.ptz.driver`: :class:`PtzDriver` over any pyserial URL (and VISCA over IP).
- :mod:`runtime.ptz.visca_ip`: VISCA over IP framing, the camera's side, the driver's UDP port.
- :mod:`runtime.ptz.transports`: which driver and transport a ``--ptz`` URL selects (the one dispatch).
- :mod:`runtime.ptz.emulator`: cameras on a pseudo-terminal or a UDP socket (``omnijax ptz-emulator``).
"""

from .driver import PtzDriver, PtzError, PtzPortError
from .emulator import Faults, PelcoDCamera, PtyEmulator, UdpEmulator, ViscaCamera
from .profile import (
    DeviceProfile,
    DeviceTarget,
    ProfileError,
    PtzPosition,
    default_profile,
    load_profile,
    parse_profile,
)
from .transports import Capabilities, make_driver

__all__ = [
    "Capabilities", "DeviceProfile", "DeviceTarget", "Faults", "PelcoDCamera", "ProfileError", "PtyEmulator",
    "PtzDriver",
    "PtzError", "PtzPortError", "PtzPosition", "UdpEmulator", "ViscaCamera", "default_profile", "load_profile",
    "make_driver", "parse_profile",
]
