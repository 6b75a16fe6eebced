"""Omnidirectional camera models behind one interface: image radius r <-> ray angle phi (eq 1-2)."""

from ._camera import (
    PROFILES as PROFILES,
    Equidistant as Equidistant,
    Equisolid as Equisolid,
    OCamCalib as OCamCalib,
    OCamCalibFile as OCamCalibFile,
    OmniCamera as OmniCamera,
    Paraboloid as Paraboloid,
    RadialProfile as RadialProfile,
    parse_ocamcalib as parse_ocamcalib,
)
