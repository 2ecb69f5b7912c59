"""The operations every face offers, one function each, one transaction each.

A REST route, the CLI, the OPC UA face and the controllers' own interfaces (RWS, KVP) call
these; none of them changes the rows itself. An operation takes the caller's session (its
transaction, run the same way whichever face: :mod:`server.service.transaction`, a writer's
session with the controller locked, committed with the operation's audit record; REST's
``server.api.deps`` uses its pieces, the other faces ``with transaction.writing(...)``),
checks the caller's preconditions (``if_match``: :mod:`server.service.preconditions`, with the
face's ``present`` for what a refusal shows), changes the rows through the models (so the
audit hook, ``server.auth.audit``, records what changed, in the same transaction) and returns
the changed rows for the face to present.

``sessions`` (a menu run), ``robot`` (the arm: its state, the motions, the active frames),
``slots`` (hand edits and restores), ``controllers``, ``controller_files`` (import and
export), ``export``, ``backup`` (and a JSON restore's job), ``recordings`` (and their analysis
jobs), ``webhooks``, ``jobs`` (cancel), ``external`` (external kinematics), ``bounds`` (the
ranges of every quantity), ``transaction`` (how a write runs). Nothing here imports a face
(``server.api.schemas``' input models aside).
"""
