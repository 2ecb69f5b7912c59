"""Log in and out, who am I, the audit trail, users and their tokens (REST faces of the store)."""

from __future__ import annotations

import csv
import io
import json
from datetime import datetime, timezone
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Request, Response
from pydantic import BaseModel, ConfigDict, Field

from db.auth_models import AuditRecord
from db.crud import MAX_ID
from server.auth import audit, tokens
from server.auth.guard import CSRF_COOKIE, SESSION_COOKIE, _refuse
from server.api.deps import SessionDep
from server.service.bounds import Text

router = APIRouter(tags=["Auth"])
NOT_FOUND = {404: {"description": "No such user"}}


class In(BaseModel):
    model_config = ConfigDict(extra="forbid")


class LoginIn(In):
    token: str = Field(min_length=1, max_length=200, description="an API token (pdt_...)")


class MeOut(BaseModel):
    user: str | None
    role: str | None
    permissions: list[str]
    source: str
    idle: bool


class UserIn(In):
    name: Text = Field(min_length=1, max_length=64)
    role: Text = Field(min_length=1, max_length=32)


class UserOut(BaseModel):
    id: int
    name: str
    role: str
    created_at: datetime
    revoked_at: datetime | None


class TokenIn(In):
    days: float | None = Field(90.0, gt=0, le=3650, description="lifetime; null = no expiry")
    label: Text = Field("", max_length=64)


class TokenOut(BaseModel):
    user: str
    token: str = Field(description="shown once; only its SHA-256 is stored")
    expires_days: float | None


class RoleOut(BaseModel):
    name: str
    permissions: list[str]
    description: str


class AuditOut(BaseModel):
    id: int
    at: datetime
    user: str | None
    role: str | None
    source: str
    request_id: str | None
    client: str | None
    action: str
    controller_id: int | None
    table: str | None
    number: int | None
    session_id: int | None
    before: dict[str, Any] | None
    after: dict[str, Any] | None
    quality: dict[str, Any] | None


def audit_out(r: AuditRecord) -> AuditOut:
    return AuditOut(id=r.id, at=r.at, user=r.user_name, role=r.role, source=r.source,
                    request_id=r.request_id, client=r.client, action=r.action,
                    controller_id=r.controller_id, table=r.entry_table, number=r.number,
                    session_id=r.session_id, before=r.before, after=r.after, quality=r.quality)


def user_out(u: Any) -> UserOut:
    return UserOut(id=u.id, name=u.name, role=u.role, created_at=u.created_at,
                   revoked_at=u.revoked_at)


# ---------------------------------------------------------------------------------- login

@router.post("/auth/login")
def login(body: LoginIn, request: Request, response: Response, db: SessionDep) -> MeOut:
    """Trade an API token for a browser login: an HttpOnly, SameSite=Strict session cookie and
    a CSRF token (also in the readable ``pendant_csrf`` cookie) the page sends with commands."""
    found = tokens.actor_of_token(db, body.token.strip())
    if found is None:
        raise _refuse(401, ("body", "token"), "unknown, expired or revoked token",
                      "unauthorized")
    user, role = found
    settings = request.app.state.settings
    cookie, csrf = tokens.start_web_session(db, user, settings.session_lifetime_s)
    secure = request.url.scheme == "https"
    response.set_cookie(SESSION_COOKIE, cookie, httponly=True, samesite="strict", secure=secure,
                        path="/", max_age=int(settings.session_lifetime_s))
    response.set_cookie(CSRF_COOKIE, csrf, httponly=False, samesite="strict", secure=secure,
                        path="/", max_age=int(settings.session_lifetime_s))
    return MeOut(user=user.name, role=role.name, permissions=sorted(role.permissions),
                 source="pendant", idle=False)


@router.post("/auth/logout", status_code=204)
def logout(request: Request, db: SessionDep) -> Response:
    """End the browser login (its cookie stops working) and clear the cookies."""
    cookie = request.cookies.get(SESSION_COOKIE)
    found = tokens.web_session(db, cookie) if cookie else None
    if found is not None:
        found[0].ended_at = datetime.now(timezone.utc)
    r = Response(status_code=204)
    r.delete_cookie(SESSION_COOKIE, path="/")
    r.delete_cookie(CSRF_COOKIE, path="/")
    return r


@router.get("/auth/me")
def me(request: Request) -> MeOut:
    """Who the request's credential is, the role in effect (Operator once a login is idle)."""
    a: tokens.Actor = request.state.actor
    return MeOut(user=a.name, role=a.role, permissions=sorted(a.permissions), source=a.source,
                 idle=a.idle)


# ---------------------------------------------------------------------------------- audit

CSV_COLUMNS = list(AuditOut.model_fields)


@router.get("/audit", response_model=None,
            responses={200: {"content": {"application/json": {}, "text/csv": {}}}})
def get_audit(db: SessionDep,
              controller_id: Annotated[int | None, Query(ge=1, le=MAX_ID)] = None,
              table: Literal["tool", "base", "extkin"] | None = None,
              number: Annotated[int | None, Query(ge=1, le=32)] = None,
              user: Annotated[Text | None, Query(max_length=64)] = None,
              since: datetime | None = None,
              until: datetime | None = None,
              format: Literal["json", "csv"] = "json",
              limit: Annotated[int, Query(ge=1, le=100000)] = 1000
              ) -> list[AuditOut] | Response:
    """The audit trail, oldest first: filter by controller, slot (``table`` + ``number``;
    ``extkin`` for an external kinematic), user and time (ISO 8601, UTC if no zone);
    ``format=csv`` for a spreadsheet."""
    def utc(t: datetime | None) -> datetime | None:
        return t if t is None or t.tzinfo else t.replace(tzinfo=timezone.utc)

    rows = [audit_out(r) for r in audit.query(db, controller_id, table, number, user, utc(since),
                                              utc(until), limit)]
    if format == "json":
        return rows
    out = io.StringIO()
    w = csv.DictWriter(out, CSV_COLUMNS)
    w.writeheader()
    for r in rows:
        d = r.model_dump(mode="json")
        w.writerow({k: json.dumps(v) if isinstance(v, dict) else v for k, v in d.items()})
    return Response(out.getvalue(), media_type="text/csv",
                    headers={"Content-Disposition": 'attachment; filename="audit.csv"'})


# ---------------------------------------------------------------------------------- users

@router.get("/users")
def list_users(db: SessionDep) -> list[UserOut]:
    return [user_out(u) for u in tokens.list_users(db)]


@router.post("/users", status_code=201, responses={409: {"description": "The name is taken"}})
def add_user(body: UserIn, db: SessionDep) -> UserOut:
    """A new user with a role (Operator, Programmer, Expert, Administrator or a site role)."""
    from solvers.errors import CalibrationError

    try:
        return user_out(tokens.add_user(db, body.name, body.role))
    except ValueError as err:
        field, _, reason = str(err).partition(": ")
        raise CalibrationError((field,), reason) from None


@router.delete("/users/{user_name}", status_code=204,
               responses={**NOT_FOUND, 409: {"description": "The last user administrator"}})
def revoke_user(user_name: str, db: SessionDep) -> Response:
    """Revoke the user, their tokens and browser logins (their audit records stay); never the
    last active user who may administer users (409)."""
    tokens.revoke_user(db, user_name)
    return Response(status_code=204)


@router.post("/users/{user_name}/tokens", status_code=201,
             responses={**NOT_FOUND, 409: {"description": "The user is revoked"}})
def create_token(user_name: str, body: TokenIn, db: SessionDep) -> TokenOut:
    """A new API token for the user: shown once in this answer."""
    secret = tokens.create_token(db, tokens.get_user(db, user_name), body.days, body.label)
    return TokenOut(user=user_name, token=secret, expires_days=body.days)


@router.get("/roles")
def list_roles(db: SessionDep) -> list[RoleOut]:
    return [RoleOut(name=r.name, permissions=list(r.permissions), description=r.description)
            for r in tokens.list_roles(db)]
