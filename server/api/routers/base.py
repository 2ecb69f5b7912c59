"""Base menu: the 32 base slots (bases and fixed tools)."""

from server.api.routers.tables import table_router

router = table_router("base", "bases", "Base")
