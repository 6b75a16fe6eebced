"""The operator's console: a live web page and its JSON API (``--serve HOST:PORT`` of ``run`` and ``demo``).

- :mod:`runtime.console.server`: the aiohttp server in its own thread, the API, the token;
- :mod:`runtime.console.live`: the snapshot the drawing thread leaves for it;
- :mod:`runtime.console.calibration`: the calibration assistant;
- ``static/``: the page (HTML, JavaScript, CSS; no build step, no external files).
"""

from runtime.console.server import Console as Console, bind as bind, parse_serve as parse_serve
