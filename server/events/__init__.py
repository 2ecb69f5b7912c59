"""Events for MES: the dispatcher that delivers the outbox (``db.outbox``) to webhooks
(``signing``: HMAC-SHA256) and an MQTT broker (``mqtt``: unified-namespace topics).
"""
