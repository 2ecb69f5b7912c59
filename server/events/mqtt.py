"""Events on MQTT, on topics shaped like a unified namespace (ISA-95 levels).

Topic: ``<site>/<area>/<cell>/pendant/<event>`` with ``cell`` the controller's name, e.g.
``plant1/body-shop/cell-1/pendant/frame-committed``. The message is the event document
(JSON, the same as a webhook's body), published with QoS 1. paho-mqtt talks to the broker.
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field
from urllib.parse import urlsplit

import paho.mqtt.client as mqtt

from db.models import Delivery, Event, Webhook
from db.outbox import event_document
from server.events.dispatcher import DeliveryFailed


def topic(site: str, area: str, cell: str | None, kind: str) -> str:
    """The event's topic; MQTT's separators and wildcards in a name become ``_``.

    >>> topic("plant1", "body-shop", "cell-1", "frame-committed")
    'plant1/body-shop/cell-1/pendant/frame-committed'
    """
    clean = [p.replace("/", "_").replace("+", "_").replace("#", "_")
             for p in (site, area, cell or "_service")]
    return "/".join(clean + ["pendant", kind])


@dataclass
class MqttSink:
    """Publishes each event to the broker at ``url`` (``mqtt://host:port``)."""

    url: str
    site: str = "site"
    area: str = "area"
    timeout_s: float = 5.0
    _client: mqtt.Client | None = field(default=None, init=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, init=False)

    def _connected(self) -> mqtt.Client:
        with self._lock:
            if self._client is None or not self._client.is_connected():
                parts = urlsplit(self.url)
                if parts.scheme != "mqtt" or not parts.hostname:
                    raise DeliveryFailed(f"MQTT URL {self.url!r} is not mqtt://host[:port]")
                client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="",
                                     protocol=mqtt.MQTTv311)
                if parts.username:
                    client.username_pw_set(parts.username, parts.password)
                try:
                    client.connect(parts.hostname, parts.port or 1883, keepalive=30)
                except OSError as err:
                    raise DeliveryFailed(f"MQTT broker {parts.hostname}:{parts.port or 1883}: "
                                         f"{err}") from None
                client.loop_start()
                self._client = client
            return self._client

    def send(self, delivery: Delivery, event: Event, hook: Webhook | None) -> int | None:
        client = self._connected()
        body = json.dumps(event_document(event), separators=(",", ":"))
        info = client.publish(topic(self.site, self.area, event.controller_name, event.kind),
                              body, qos=1)
        try:
            info.wait_for_publish(timeout=self.timeout_s)
        except (RuntimeError, ValueError) as err:
            raise DeliveryFailed(f"MQTT publish: {err}") from None
        if not info.is_published():
            raise DeliveryFailed("MQTT publish not acknowledged in time")
        return None

    def close(self) -> None:
        if self._client is not None:
            self._client.loop_stop()
            self._client.disconnect()
