"""The events on an MQTT broker (``--mqtt URL``), through paho-mqtt (the Eclipse client home-automation
set-ups use; docs/console.md says why).

``mqtt://[USER:PASSWORD@]HOST[:PORT][/PREFIX]`` (``mqtts://`` for TLS, port 8883 by default; PREFIX
``omnijax`` by default). Each event is published as JSON to ``PREFIX/events/<event>`` (QoS 1), and
``PREFIX/status`` holds ``online`` while the command runs (retained; ``offline`` when it ends or, as the
broker's last will, when the connection is lost). The client runs its own network thread and
reconnects by itself; publishing never waits, so neither the drawing thread nor the loop is held up
by a slow or absent broker (messages wait in the client's queue meanwhile, at most
:data:`MAX_QUEUED`). Events published while the client is (re)connecting may reach the broker out
of order (the client resends its queue on connecting while new events go straight out): order
by an event's ``frame`` or ``time``, which only grow.

A broker that does not answer at the start, or goes away later, is one warning line per outage
(``MQTT broker ... unreachable`` / ``lost``, with the reason) and one when it is back (``connected again
after N s``); the command runs on meanwhile, its events still in ``events.jsonl``, and the client
retries every 1 to :data:`RETRY_MAX_S` s. ``summary()`` counts the outages.
"""

from __future__ import annotations

import json
import logging
import os
import re
import threading
import time
import urllib.parse
from dataclasses import dataclass

import paho.mqtt.client as mqtt

#: Messages kept while the broker is away (the oldest new ones are dropped beyond).
MAX_QUEUED = 1000
#: Longest wait between two attempts to reach the broker (s); the first retry comes after 1 s.
RETRY_MAX_S = 10

log = logging.getLogger("omnijax.events")
_PREFIX = re.compile(r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$")


@dataclass(frozen=True)
class MqttUrl:
    host: str
    port: int
    prefix: str
    tls: bool
    user: str | None = None
    password: str | None = None

    def shown(self) -> str:
        """The URL without its password (for messages)."""
        auth = f"{self.user}@" if self.user else ""
        return f"{'mqtts' if self.tls else 'mqtt'}://{auth}{self.host}:{self.port}/{self.prefix}"


def parse_mqtt_url(url: str) -> MqttUrl:
    """``--mqtt``'s URL; a ``ValueError`` saying what was expected otherwise."""
    expected = "expected mqtt://[USER:PASSWORD@]HOST[:PORT][/PREFIX] (or mqtts://)"
    u = urllib.parse.urlsplit(url)
    if u.scheme not in ("mqtt", "mqtts") or not u.hostname:
        raise ValueError(f"{expected}, got {url!r}")
    try:
        port = u.port or (8883 if u.scheme == "mqtts" else 1883)
    except ValueError:
        raise ValueError(f"{expected}: the port must be 1-65535") from None
    prefix = u.path.strip("/") or "omnijax"
    if not _PREFIX.match(prefix) or u.query or "#" in url:
        raise ValueError(f"{expected}: PREFIX is topic levels of letters, digits, _ and - (no wildcards), "
                         f"got {u.path!r}")
    return MqttUrl(host=u.hostname, port=port, prefix=prefix, tls=u.scheme == "mqtts",
                   user=urllib.parse.unquote(u.username) if u.username else None,
                   password=urllib.parse.unquote(u.password) if u.password else None)


class MqttPublisher:
    """Publishes events to the broker of ``url`` (see the module docstring); call it with an event."""

    def __init__(self, url: str):
        self.url = parse_mqtt_url(url)
        self.published = 0
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"omnijax-{os.getpid()}")
        self.client.max_queued_messages_set(MAX_QUEUED)
        if self.url.user:
            self.client.username_pw_set(self.url.user, self.url.password)
        if self.url.tls:
            self.client.tls_set()
        self.status_topic = f"{self.url.prefix}/status"
        self.client.will_set(self.status_topic, "offline", qos=1, retain=True)
        self.client.reconnect_delay_set(1, RETRY_MAX_S)
        self.client.on_connect = self._on_connect
        self.client.on_connect_fail = self._on_connect_fail
        self.client.on_disconnect = self._on_disconnect
        self.outages = 0
        self._lock = threading.Lock()
        self._down_since: float | None = None  # in an outage since (monotonic s)
        self._closing = False

    def _down(self, what: str, why: str) -> None:
        """The broker cannot be reached: a warning at the first failure of an outage, then quiet."""
        with self._lock:  # the warning is said before the outage is counted: a reader of outages sees both
            if self._down_since is not None or self._closing:
                return
            self._down_since = time.monotonic()
            log.warning("MQTT broker %s %s (%s); retrying every 1-%d s, the events are still written to "
                        "events.jsonl", self.url.shown(), what, why, RETRY_MAX_S)
            self.outages += 1

    def _on_connect(self, client, _userdata, _flags, reason_code, _properties) -> None:
        if reason_code.is_failure:
            self._down("refused the connection", str(reason_code))
            return
        client.publish(self.status_topic, "online", qos=1, retain=True)
        with self._lock:
            since, self._down_since = self._down_since, None
        if since is not None:
            log.warning("MQTT broker %s connected again after %.1f s", self.url.shown(), time.monotonic() - since)

    def _on_connect_fail(self, _client, _userdata) -> None:
        self._down("unreachable", "no connection")

    def _on_disconnect(self, _client, _userdata, _flags, reason_code, _properties) -> None:
        if not self._closing:
            self._down("lost", str(reason_code))

    @property
    def connected(self) -> bool:
        return self.client.is_connected()

    def start(self) -> MqttPublisher:
        """Connect in the background (reconnecting as needed); returns at once."""
        self.client.connect_async(self.url.host, self.url.port, keepalive=30)
        self.client.loop_start()
        return self

    def __call__(self, event: dict) -> None:
        self.client.publish(f"{self.url.prefix}/events/{event['event']}", json.dumps(event), qos=1)
        self.published += 1

    def close(self, timeout: float = 2.0) -> None:
        """Say ``offline``, let the queued messages out (at most ``timeout`` s), disconnect."""
        self._closing = True  # the disconnect that follows is ours: no warning
        if self.connected:
            self.client.publish(self.status_topic, "offline", qos=1, retain=True).wait_for_publish(timeout)
        self.client.disconnect()
        self.client.loop_stop()

    def summary(self) -> dict:
        return {"broker": self.url.shown(), "published": self.published, "connected": self.connected,
                "outages": self.outages}
