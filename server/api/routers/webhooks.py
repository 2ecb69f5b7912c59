"""Webhooks: subscribe a URL to pendant's events, test it, read its delivery log.

Each delivery is a POST of the event document, signed with HMAC-SHA256 over the body
(``X-Pendant-Signature-256: sha256=<hex>``), retried with exponential back-off until a 2xx.
docs/events.md has the receiver's side.
"""

from __future__ import annotations

import secrets
from datetime import datetime
from typing import Literal
from urllib.parse import urlsplit

from fastapi import APIRouter, Response
from pydantic import Field, field_validator
from sqlalchemy import select

from db import crud
from db.models import Delivery, Event, Webhook
from db.outbox import KINDS
from server.auth import audit
from server.api.deps import SessionDep
from server.api.schemas import In, Out

router = APIRouter(prefix="/webhooks", tags=["Events"])

EventKind = Literal["frame-committed", "calibration-computed", "import-applied",
                    "analysis-finished"]
assert set(EventKind.__args__) == set(KINDS)  # type: ignore[attr-defined]


class WebhookIn(In):
    url: str = Field(max_length=2048, description="http(s) URL that receives the POSTs")
    secret: str | None = Field(None, min_length=16, max_length=128,
                               description="HMAC key; a random one is made (and shown once) "
                                           "when absent")
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


def _get(db: SessionDep, webhook_id: int) -> Webhook:
    hook = crud._get(db, Webhook, webhook_id)  # an id beyond the backend's range: not found
    if hook is None:
        raise crud.NotFound(("path", "webhook_id"), f"no webhook {webhook_id}")
    return hook


@router.post("", status_code=201)
def create_webhook(body: WebhookIn, db: SessionDep) -> WebhookOut:
    """Subscribe ``url``; the answer carries the signing secret (keep it: it is not shown again)."""
    secret = body.secret or secrets.token_urlsafe(32)
    hook = Webhook(url=body.url, secret=secret,
                   kinds=None if body.kinds is None else {"kinds": list(body.kinds)})
    db.add(hook)
    db.flush()
    audit.record(db, "webhook.create", after={"webhook_id": hook.id, "url": hook.url,
                                              "kinds": body.kinds})  # never the secret
    return _out(hook, secret)


@router.get("")
def list_webhooks(db: SessionDep) -> list[WebhookOut]:
    return [_out(h) for h in db.scalars(select(Webhook).order_by(Webhook.id))]


@router.delete("/{webhook_id}", status_code=204)
def delete_webhook(webhook_id: int, db: SessionDep) -> Response:
    """Unsubscribe; pending deliveries to it are dropped with it."""
    hook = _get(db, webhook_id)
    audit.record(db, "webhook.delete", before={"webhook_id": hook.id, "url": hook.url})
    db.delete(hook)
    return Response(status_code=204)


@router.post("/{webhook_id}/test", status_code=202)
def test_webhook(webhook_id: int, db: SessionDep) -> TestOut:
    """Queue a ``ping`` event to this webhook alone, through the normal signed delivery."""
    hook = _get(db, webhook_id)
    ev = Event(kind="ping", payload={"webhook_id": hook.id, "url": hook.url})
    db.add(ev)
    db.flush()
    d = Delivery(event_id=ev.id, sink="webhook", webhook_id=hook.id)
    db.add(d)
    db.flush()
    return TestOut(event_id=ev.id, delivery_id=d.id)


@router.get("/{webhook_id}/deliveries")
def list_deliveries(webhook_id: int, db: SessionDep) -> list[DeliveryOut]:
    """The delivery log, newest first: state, attempts, last HTTP status and error."""
    _get(db, webhook_id)
    rows = db.execute(select(Delivery, Event.kind).join(Event, Event.id == Delivery.event_id)
                      .where(Delivery.webhook_id == webhook_id).order_by(Delivery.id.desc())
                      .limit(500)).all()
    return [DeliveryOut(id=d.id, event_id=d.event_id, kind=kind, state=d.state,  # type: ignore[arg-type]
                        attempts=d.attempts, next_attempt_at=d.next_attempt_at,
                        delivered_at=d.delivered_at, last_status=d.last_status,
                        last_error=d.last_error) for d, kind in rows]
