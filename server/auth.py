"""Bearer tokens from the configuration, with roles: `viewer` reads; `operator` also acts.

No or unknown token: 401 (with WWW-Authenticate); a known token without the role: 403. Browsers'
EventSource and <img> cannot send headers, so GET requests may carry the token as `?access_token=`
instead (it then shows in access logs: keep the service on the lab network).
"""
from __future__ import annotations

import hashlib

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from .settings import Settings, token_refusal, token_role


def require_role(role: str):
    """A dependency (async: it runs on the event loop, no thread hop) that returns who calls ("operator
    3fa0c2d1": role and a token fingerprint) or raises; the tokens are those of the app serving the request
    (request.app.state.services.settings), so module-level routers (server/routers/) can use it."""
    bearer = HTTPBearer(auto_error=False, description=f"a token with the {role} role (or above)")

    async def check(request: Request, creds: HTTPAuthorizationCredentials | None = Depends(bearer)) -> str:
        settings: Settings = request.app.state.services.settings
        token = creds.credentials if creds else ""
        if not token and request.method == "GET":
            token = request.query_params.get("access_token", "")
        found = token_role(settings.tokens, token)
        refused = token_refusal(found, role)
        if refused:
            status, detail = refused
            raise HTTPException(status, detail, headers={"WWW-Authenticate": "Bearer"} if status == 401 else None)
        return f"{found} {hashlib.sha256(token.encode()).hexdigest()[:8]}"  # who, without the secret

    return check
