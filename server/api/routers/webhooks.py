"""Webhooks: subscribe a URL to pendant's events, test it, read its delivery log.

Each delivery is a POST of the event document, signed with HMAC-SHA256 over the body
(``X-Pendant-Signature-256: sha256=<hex>``), retried with exponential back-off until a 2xx.
docs/events.md has the receiver's side.
"""

from __future__ import annotations

from datetime import datetime
from typing import Literal
from urllib.parse import urlsplit

from fastapi import APIRouter, Response
from pydantic import Field, field_validator
from sqlalchemy import select

from db.models import Delivery, Event, Webhook
from db.outbox import KINDS
from server.api.deps import SessionDep
from server.api.schemas import In, Out
from server.service import webhooks as subscriptions
from server.service.bounds import Text

router = APIRouter(prefix="/webhooks", tags=["Events"])

EventKind = Literal["frame-committed", "calibration-computed", "import-applied",
                    "analysis-finished"]
assert set(EventKind.__args__) == set(KINDS)  # type: ignore[attr-defined]


class WebhookIn(In):
    url: Text = Field(
        max_length=2048, description="http(s) URL that receives the POSTs")
    secret: Text | None = Field(
        None, min_length=16, max_length=128,
        description="HMAC key; a random one is made (and shown once) when absent")
    kinds: list[EventKind] | None = Field(None, description="the event kinds to send; all "
                                                            "when absent")

    @field_validator("url")
    @classmethod
    def _http_url(cls, v: str) -> str:
        parts = urlsplit(v)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError("must be an http:// or https:// URL with a host")
        return v


class WebhookOut(Out):
    id: int
    url: str
    kinds: list[str] | None
    active: bool
    created_at: datetime
    secret: str | None = Field(None, description="only in the answer that created it")


class DeliveryOut(Out):
    id: int
    event_id: int
    kind: str
    state: Literal["pending", "sending", "delivered", "failed"]
    attempts: int
    next_attempt_at: datetime
    delivered_at: datetime | None
    last_status: int | None
    last_error: str | None


class TestOut(Out):
    event_id: int
    delivery_id: int


def _out(h: Webhook, secret: str | None = None) -> WebhookOut:
    return WebhookOut(id=h.id, url=h.url, kinds=None if h.kinds is None else h.kinds["kinds"],
                      active=h.active, created_at=h.created_at, secret=secret)


@router.post("", status_code=201)
def create_webhook(body: WebhookIn, db: SessionDep) -> WebhookOut:
    """Subscribe ``url``; the answer carries the signing secret (keep it: it is not shown again)."""
    hook, secret = subscriptions.create_webhook(db, body.url, body.secret, body.kinds)
    return _out(hook, secret)


@router.get("")
def list_webhooks(db: SessionDep) -> list[WebhookOut]:
    return [_out(h) for h in db.scalars(select(Webhook).order_by(Webhook.id))]


@router.delete("/{webhook_id}", status_code=204)
def delete_webhook(webhook_id: int, db: SessionDep) -> Response:
    """Unsubscribe; pending deliveries to it are dropped with it."""
    subscriptions.delete_webhook(db, webhook_id)
    return Response(status_code=204)


@router.post("/{webhook_id}/test", status_code=202)
def test_webhook(webhook_id: int, db: SessionDep) -> TestOut:
    """Queue a ``ping`` event to this webhook alone, through the normal signed delivery."""
    d = subscriptions.ping_webhook(db, webhook_id)
    return TestOut(event_id=d.event_id, delivery_id=d.id)


@router.get("/{webhook_id}/deliveries")
def list_deliveries(webhook_id: int, db: SessionDep) -> list[DeliveryOut]:
    """The delivery log, newest first: state, attempts, last HTTP status and error."""
    subscriptions.get_webhook(db, webhook_id)
    rows = db.execute(select(Delivery, Event.kind).join(Event, Event.id == Delivery.event_id)
                      .where(Delivery.webhook_id == webhook_id).order_by(Delivery.id.desc())
                      .limit(500)).all()
    return [DeliveryOut(id=d.id, event_id=d.event_id, kind=kind, state=d.state,  # type: ignore[arg-type]
                        attempts=d.attempts, next_attempt_at=d.next_attempt_at,
                        delivered_at=d.delivered_at, last_status=d.last_status,
                        last_error=d.last_error) for d, kind in rows]
