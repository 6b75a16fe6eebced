"""A real MQTT broker for the tests: amqtt (pure Python, from PyPI) on 127.0.0.1, in a thread of its own,
and a paho-mqtt subscriber collecting what arrives."""

from __future__ import annotations

import asyncio
import json
import socket
import threading
import time

import paho.mqtt.client as mqtt


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Broker:
    """``with Broker() as b:`` an amqtt broker at ``b.url`` (``mqtt://127.0.0.1:PORT``; ``port``: that port, else a
    free one) until the block ends."""

    def __init__(self, port: int | None = None):
        self.port = port or free_port()
        self.url = f"mqtt://127.0.0.1:{self.port}"
        self._ready, self._stop = threading.Event(), None
        self._thread = threading.Thread(target=self._run, name="amqtt-broker", daemon=True)
        self.error: BaseException | None = None

    def _run(self) -> None:
        from amqtt.broker import Broker as AmqttBroker

        async def main():
            broker = AmqttBroker({"listeners": {"default": {"type": "tcp", "bind": f"127.0.0.1:{self.port}"}},
                                  "plugins": {"amqtt.plugins.authentication.AnonymousAuthPlugin":
                                              {"allow_anonymous": True}}})
            self._stop = asyncio.Event()
            await broker.start()
            self._ready.set()
            await self._stop.wait()
            await broker.shutdown()

        self._loop = asyncio.new_event_loop()
        try:
            self._loop.run_until_complete(main())
        except BaseException as exc:  # reported by __enter__
            self.error = exc
            self._ready.set()

    def __enter__(self) -> Broker:
        self._thread.start()
        if not self._ready.wait(20) or self.error is not None:
            raise RuntimeError(f"the test broker did not start: {self.error!r}")
        return self

    def __exit__(self, *exc) -> None:
        self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10)


class Subscriber:
    """A paho-mqtt client subscribed to ``topic`` on ``port``; ``messages`` are (topic, JSON payload)."""

    def __init__(self, port: int, topic: str):
        self.messages: list[tuple[str, object]] = []
        self._subscribed = threading.Event()
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"test-sub-{port}")
        self.client.on_connect = lambda c, *_: c.subscribe(topic, qos=1)
        self.client.on_subscribe = lambda *_: self._subscribed.set()
        self.client.on_message = lambda _c, _u, m: self.messages.append((m.topic, _json(m.payload)))
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()
        if not self._subscribed.wait(10):
            raise RuntimeError("the test subscriber could not subscribe")

    def wait_for(self, predicate, timeout: float = 10.0) -> list:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            got = [m for m in list(self.messages) if predicate(m)]
            if got:
                return got
            time.sleep(0.05)
        return []

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def _json(payload: bytes):
    try:
        return json.loads(payload)
    except ValueError:
        return payload.decode(errors="replace")
