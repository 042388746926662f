"""Security headers of the admin page and the worker portal (/admin/, /market/), and
``X-Content-Type-Options: nosniff`` on every answer.

The two pages hold a signed-in admin's or worker's session: no other site may frame them
(``frame-ancestors 'none'``, against clickjacking), and they run only the app's own scripts
and styles. The annotation page (/annotate/) is framed by the marketplace as an MTurk
ExternalQuestion, so it gets no ``frame-ancestors``.
"""

from __future__ import annotations

from urllib.parse import urlsplit

from fastapi import FastAPI
from starlette.datastructures import MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.config import Settings, get_settings

# The pages whose answers carry the policy (their folders, and the bare names that redirect).
POLICY_PAGES = ("/admin", "/market")
# Where S3 storage without its own endpoint hands out presigned frame links.
AWS_S3_ORIGIN = "https://*.amazonaws.com"


def storage_origin(settings: Settings) -> str | None:
    """The origin of presigned storage links (frames, overlays) the pages load, if any."""
    if not settings.storage_url.startswith("s3://"):
        return None
    if not settings.s3_endpoint_url:
        return AWS_S3_ORIGIN
    parts = urlsplit(settings.s3_endpoint_url)
    return f"{parts.scheme}://{parts.netloc}"


def content_security_policy(settings: Settings) -> str:
    """The pages' policy: own scripts and styles only (an element's ``style`` is set through
    the CSSOM, which the policy does not restrict), images and fetches from the app and its
    storage, and no framing by anyone. The portal frames HITs' ExternalQuestion pages, which
    may live on any requester's site, so frames may come from any http(s) address."""
    storage = storage_origin(settings)
    extra = f" {storage}" if storage else ""
    return "; ".join((
        "default-src 'self'", "script-src 'self'", "style-src 'self'",
        f"img-src 'self' data: blob:{extra}", f"connect-src 'self' blob:{extra}",
        f"media-src 'self' blob:{extra}", "frame-src 'self' https: http:",
        "object-src 'none'", "base-uri 'none'", "form-action 'self'",
        "frame-ancestors 'none'"))


def _is_policy_page(path: str) -> bool:
    return any(path == page or path.startswith(page + "/") for page in POLICY_PAGES)


class PageHeadersMiddleware:
    """Adds nosniff to every answer, and the pages' policy to the answers of /admin/ and
    /market/ (anything but the two pages keeps the headers it had)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app
        self.policy = content_security_policy(get_settings())

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        page = _is_policy_page(scope.get("path", ""))

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                headers["X-Content-Type-Options"] = "nosniff"
                if page:
                    headers["Content-Security-Policy"] = self.policy
                    headers["X-Frame-Options"] = "DENY"  # for browsers without CSP level 2
            await send(message)

        await self.app(scope, receive, send_with_headers)


def install_page_headers(app: FastAPI) -> None:
    app.add_middleware(PageHeadersMiddleware)
