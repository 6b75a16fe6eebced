"""omnijax's rooms with I/O: the command line, the real-time loop, PTZ output, validation, calibration.

Importing it quiets OpenCV and its FFmpeg back end, unless the environment already says
otherwise: both print their own warnings on stderr when a file or camera cannot be opened
(``[ WARN:0@0.2] global cap_v4l.cpp ... can't open camera by index``), before omnijax's one
line saying what was wrong. Set ``OPENCV_LOG_LEVEL=INFO`` and ``OPENCV_FFMPEG_LOGLEVEL=32``
to see them again. (Read when OpenCV is first imported: omnijax imports it after this.)
"""

import os as _os

_os.environ.setdefault("OPENCV_LOG_LEVEL", "SILENT")
_os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
