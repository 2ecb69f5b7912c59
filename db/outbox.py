"""Events for MES: what changed, written to an outbox in the same transaction as the change.

Four kinds: ``frame-committed`` (a tool or base slot changed: calibration saved, edit,
restore, import), ``calibration-computed``, ``import-applied`` and ``analysis-finished``.
:func:`emit` adds the event row and one delivery row per subscribed sink (each active webhook
whose kinds include it; the MQTT broker when one is configured). The dispatcher
(:mod:`server.events.dispatcher`) delivers them with retries; the OPC UA face raises them as
OPC UA events. A change that rolls back takes its events with it.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.models import Controller, Delivery, Event, Webhook

KINDS = ("frame-committed", "calibration-computed", "import-applied", "analysis-finished")

def emit(db: Session, kind: str, controller: Controller | None, payload: dict[str, Any]) -> Event:
    """Record ``kind`` with ``payload`` and queue its deliveries (nothing is sent here)."""
    if kind not in KINDS:
        raise ValueError(f"unknown event kind {kind!r}")
    ev = Event(kind=kind, controller_id=controller.id if controller else None,
               controller_name=controller.name if controller else None, payload=payload)
    db.add(ev)
    db.flush()
    for hook in db.scalars(select(Webhook).where(Webhook.active.is_(True))):
        if hook.kinds is None or kind in hook.kinds.get("kinds", []):
            db.add(Delivery(event_id=ev.id, sink="webhook", webhook_id=hook.id))
    if db.info.get("mqtt_sink"):  # the app's sessionmaker says a broker is configured
        db.add(Delivery(event_id=ev.id, sink="mqtt"))
    return ev


def event_document(ev: Event) -> dict[str, Any]:
    """The JSON every sink carries: id (for de-duplication), kind, controller, time, payload."""
    return {"id": ev.id, "kind": ev.kind, "controller": ev.controller_name,
            "controller_id": ev.controller_id, "created_at": ev.created_at.isoformat(),
            "payload": ev.payload}
