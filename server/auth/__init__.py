"""Who may change a frame: users and roles, API tokens and browser logins, the audit trail.

- ``permissions``: the permissions, the default roles, and ONE table route -> permission;
- ``tokens``: users, roles, tokens and browser sessions in the DB (secrets stored hashed);
- ``guard``: the app-level dependency that authenticates, checks the table and CSRF;
- ``audit``: the append-only audit records, written by a ``before_flush`` hook;
- ``web``: Host allow-list, CORS and the security headers of pages (ASGI middleware);
- ``routes``: ``/auth/login``, ``/auth/logout``, ``/auth/me``, ``/audit``, ``/users``.
"""
