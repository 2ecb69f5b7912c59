"""The operations every face offers, one function each, one transaction each.

A REST route, the CLI, the OPC UA face and the controllers' own interfaces call these; none of
them writes the database itself. An operation takes the request's session (its transaction:
``server.api.deps`` begins it with the write lock and commits it), checks the caller's
preconditions (``If-Match``), changes the rows through the models (so the audit hook,
``server.auth.audit``, records what changed, in the same transaction) and returns the changed
rows for the face to present.
"""
