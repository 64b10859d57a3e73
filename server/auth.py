"""Bearer tokens from the configuration, with roles: `viewer` reads; `operator` also acts.

No or unknown token: 401 (with WWW-Authenticate); a known token without the role: 403. Browsers'
EventSource and <img> cannot send headers, so GET requests may carry the token as `?access_token=`
instead (it then shows in access logs: keep the service on the lab network).
"""
from __future__ import annotations

import hashlib
import hmac

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from .settings import ROLES, Settings


def require_role(role: str):
    """A dependency (async: it runs on the event loop, no thread hop) that returns who calls ("operator
    3fa0c2d1": role and a token fingerprint) or raises; the tokens are those of the app serving the request
    (request.app.state.services.settings), so module-level routers (server/routers/) can use it."""
    rank = ROLES.index(role)
    bearer = HTTPBearer(auto_error=False, description=f"a token with the {role} role (or above)")

    async def check(request: Request, creds: HTTPAuthorizationCredentials | None = Depends(bearer)) -> str:
        settings: Settings = request.app.state.services.settings
        token = creds.credentials if creds else ""
        if not token and request.method == "GET":
            token = request.query_params.get("access_token", "")
        found = next((r for t, r in settings.tokens.items() if hmac.compare_digest(t.encode(), token.encode())), None)
        if found is None:
            raise HTTPException(401, "a valid bearer token is needed (Authorization: Bearer <token>)",
                                headers={"WWW-Authenticate": "Bearer"})
        if ROLES.index(found) < rank:
            raise HTTPException(403, f"this needs the {role} role; the token is {found}")
        return f"{found} {hashlib.sha256(token.encode()).hexdigest()[:8]}"  # who, without the secret

    return check
