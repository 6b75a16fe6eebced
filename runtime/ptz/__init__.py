"""PTZ output: VISCA and Pelco-D encoders and parsers, device profiles, the serial driver, and an emulator.

- :mod:`runtime.ptz.visca`, :mod:`runtime.ptz.pelco_d`: pure ``bytes`` encoders, incremental parsers.
- :mod:`runtime.ptz.profile`: device profiles (``configs/devices/*.toml``); the one place where
  omnijax pan/tilt/zoom become device units.
- :mod:`runtime.ptz.driver`: :class:`PtzDriver` over any pyserial URL.
- :mod:`runtime.ptz.emulator`: cameras on a pseudo-terminal (``omnijax ptz-emulator``).
"""

from .driver import PtzDriver, PtzError, PtzPortError
from .emulator import Faults, PelcoDCamera, PtyEmulator, ViscaCamera
from .profile import (
    DeviceProfile,
    DeviceTarget,
    ProfileError,
    PtzPosition,
    default_profile,
    load_profile,
    parse_profile,
)

__all__ = [
    "DeviceProfile", "DeviceTarget", "Faults", "PelcoDCamera", "ProfileError", "PtyEmulator", "PtzDriver",
    "PtzError", "PtzPortError", "PtzPosition", "ViscaCamera", "default_profile", "load_profile", "parse_profile",
]
