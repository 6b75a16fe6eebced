"""What happened, for people and home automation: person appeared, left, face captured (a JSON-lines log,
:class:`EventLog`), and the same events on an MQTT broker (:class:`MqttPublisher`)."""

from runtime.events.log import EVENTS as EVENTS, EventLog as EventLog
from runtime.events.mqtt import MqttPublisher as MqttPublisher, parse_mqtt_url as parse_mqtt_url
