"""The PTZ errors every driver and transport raises (one line each)."""


class PtzError(RuntimeError):
    """The PTZ cannot be reached or did not answer (one line)."""


class PtzPortError(PtzError):
    """The port itself is wrong: a malformed URL, or a device path that does not exist (bad input)."""
