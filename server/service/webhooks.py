"""Webhooks: subscribe a URL to pendant's events, unsubscribe it, ping it.

A subscription is a ``Webhook`` row with its signing secret; ``server.events`` delivers the
outbox's events to it. Creating and deleting one are audited (``webhook.create``,
``webhook.delete``; never the secret); a ping is an event of its own, queued to this webhook
alone through the normal signed delivery.
"""

from __future__ import annotations

import secrets

from sqlalchemy.orm import Session

from db import crud
from db.models import Delivery, Event, Webhook
from server.auth import audit


def get_webhook(db: Session, webhook_id: int) -> Webhook:
    """The webhook ``webhook_id``; NotFound naming it if there is none."""
    hook = crud._get(db, Webhook, webhook_id)  # an id beyond the backend's range: not found
    if hook is None:
        raise crud.NotFound(("webhook_id",), f"no webhook {webhook_id}")
    return hook


def create_webhook(db: Session, url: str, secret: str | None,
                   kinds: list[str] | None) -> tuple[Webhook, str]:
    """Subscribe ``url`` to ``kinds`` (None: every kind), signed with ``secret`` (a random one
    when None); the webhook and its secret (shown to the caller once)."""
    secret = secret or secrets.token_urlsafe(32)
    hook = Webhook(url=url, secret=secret, kinds=None if kinds is None else {"kinds": list(kinds)})
    db.add(hook)
    db.flush()
    audit.record(db, "webhook.create", after={"webhook_id": hook.id, "url": hook.url,
                                              "kinds": kinds})  # never the secret
    return hook, secret


def delete_webhook(db: Session, webhook_id: int) -> None:
    """Unsubscribe; pending deliveries to it are dropped with it."""
    hook = get_webhook(db, webhook_id)
    audit.record(db, "webhook.delete", before={"webhook_id": hook.id, "url": hook.url})
    db.delete(hook)


def ping_webhook(db: Session, webhook_id: int) -> Delivery:
    """Queue a ``ping`` event to this webhook alone; its delivery (``event_id``, ``id``)."""
    hook = get_webhook(db, webhook_id)
    ev = Event(kind="ping", payload={"webhook_id": hook.id, "url": hook.url})
    db.add(ev)
    db.flush()
    d = Delivery(event_id=ev.id, sink="webhook", webhook_id=hook.id)
    db.add(d)
    db.flush()
    return d
