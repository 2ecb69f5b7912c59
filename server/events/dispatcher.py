"""Delivering the outbox: claim a due delivery, send it, record the outcome, back off on failure.

Every API worker may run a dispatcher: a delivery is claimed by a compare-and-set
(``UPDATE … SET state='sending' WHERE id=? AND state='pending'``), so exactly one dispatcher
sends it on any backend and any number of hosts. A dispatcher that dies while sending leaves
the row 'sending'; after ``reclaim_s`` another takes it again (at-least-once delivery:
receivers de-duplicate by the event id).

Retries back off exponentially: attempt k waits ``backoff_s · 2^(k-1)`` (at most
``max_backoff_s``); after ``max_attempts`` the delivery is 'failed'. Every attempt's status
and error stay in the delivery log (``GET /webhooks/{id}/deliveries``).
"""

from __future__ import annotations

import json
import logging
import threading
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from typing import Protocol

import httpx
from sqlalchemy import or_, select, update
from sqlalchemy.orm import Session, sessionmaker

from db.models import Delivery, Event, Webhook
from db.outbox import event_document
from server.events.signing import HEADER, sign

log = logging.getLogger("pendant.events")


def _now() -> datetime:
    return datetime.now(timezone.utc)


class Sink(Protocol):
    def send(self, delivery: Delivery, event: Event, hook: Webhook | None) -> int | None:
        """Deliver; return the HTTP status (None where there is none); raise on failure."""


class DeliveryFailed(Exception):
    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status


@dataclass
class WebhookSink:
    """POST the event document, signed, to the webhook's URL; any 2xx is delivered."""

    timeout_s: float = 5.0
    client: httpx.Client = field(default_factory=lambda: httpx.Client(timeout=5.0))

    def send(self, delivery: Delivery, event: Event, hook: Webhook | None) -> int | None:
        assert hook is not None
        body = json.dumps(event_document(event), separators=(",", ":")).encode()
        headers = {"Content-Type": "application/json", "User-Agent": "pendant-webhooks/1",
                   "X-Pendant-Event": event.kind, "X-Pendant-Delivery": str(delivery.id),
                   HEADER: sign(hook.secret.encode(), body)}
        try:
            r = self.client.post(hook.url, content=body, headers=headers)
        except httpx.HTTPError as err:
            raise DeliveryFailed(f"{type(err).__name__}: {err}") from None
        if not 200 <= r.status_code < 300:
            raise DeliveryFailed(f"HTTP {r.status_code}", r.status_code)
        return r.status_code


@dataclass
class Dispatcher:
    """Sends due deliveries until stopped (a daemon thread per API process)."""

    make_session: sessionmaker[Session]
    sinks: dict[str, Sink]
    poll_s: float = 0.2
    backoff_s: float = 2.0
    max_backoff_s: float = 300.0
    max_attempts: int = 8
    reclaim_s: float = 60.0
    batch: int = 20
    _stop: threading.Event = field(default_factory=threading.Event, init=False)
    _thread: threading.Thread | None = field(default=None, init=False)

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="pendant-events", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                sent = self.run_once()
            except Exception:  # the database may be briefly away; say so and go on
                log.exception("event dispatch failed")
                sent = 0
            if not sent:
                self._stop.wait(self.poll_s)

    def run_once(self) -> int:
        """Claim and send what is due now; returns how many were attempted."""
        now = _now()
        with self.make_session() as db:
            due = db.scalars(select(Delivery.id).where(or_(
                (Delivery.state == "pending") & (Delivery.next_attempt_at <= now),
                (Delivery.state == "sending")
                & (Delivery.claimed_at < now - timedelta(seconds=self.reclaim_s)),
            ), Delivery.sink.in_(tuple(self.sinks))).order_by(Delivery.id).limit(self.batch)).all()
        attempted = 0
        for delivery_id in due:
            if self._claim(delivery_id, now):
                attempted += 1
                self._send(delivery_id)
        return attempted

    def _claim(self, delivery_id: int, now: datetime) -> bool:
        with self.make_session() as db:
            stale = now - timedelta(seconds=self.reclaim_s)
            n = db.execute(update(Delivery).where(
                Delivery.id == delivery_id,
                or_(Delivery.state == "pending",
                    (Delivery.state == "sending") & (Delivery.claimed_at < stale)),
            ).values(state="sending", claimed_at=now)).rowcount
            db.commit()
            return n == 1

    def _send(self, delivery_id: int) -> None:
        with self.make_session() as db:
            d = db.get(Delivery, delivery_id)
            if d is None:
                return
            event = db.get(Event, d.event_id)
            hook = db.get(Webhook, d.webhook_id) if d.webhook_id is not None else None
            d.attempts += 1
            try:
                if event is None or (d.sink == "webhook" and (hook is None or not hook.active)):
                    raise DeliveryFailed("the event or its webhook is gone")
                d.last_status = self.sinks[d.sink].send(d, event, hook)
                d.state, d.delivered_at, d.last_error = "delivered", _now(), None
            except Exception as err:  # noqa: BLE001 - every failure is recorded and retried
                d.last_status = getattr(err, "status", None)
                d.last_error = str(err)[:500]
                if d.attempts >= self.max_attempts:
                    d.state = "failed"
                else:
                    wait = min(self.backoff_s * 2 ** (d.attempts - 1), self.max_backoff_s)
                    d.state, d.next_attempt_at = "pending", _now() + timedelta(seconds=wait)
            db.commit()
