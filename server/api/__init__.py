"""The REST face: the FastAPI app, its routers (one per menu), the request path
(``deps``: one transaction per request), errors, schemas and HTTP preconditions."""
