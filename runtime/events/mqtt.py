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
"""

from __future__ import annotations

import json
import os
import re
import urllib.parse
from dataclasses import dataclass

import paho.mqtt.client as mqtt

#: Messages kept while the broker is away (the oldest new ones are dropped beyond).
MAX_QUEUED = 1000
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
        self.client.on_connect = self._on_connect

    def _on_connect(self, client, _userdata, _flags, reason_code, _properties) -> None:
        if not reason_code.is_failure:
            client.publish(self.status_topic, "online", qos=1, retain=True)

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
        if self.connected:
            self.client.publish(self.status_topic, "offline", qos=1, retain=True).wait_for_publish(timeout)
        self.client.disconnect()
        self.client.loop_stop()

    def summary(self) -> dict:
        return {"broker": self.url.shown(), "published": self.published, "connected": self.connected}
