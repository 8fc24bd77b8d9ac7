"""A minimal HTTP client for the annotation API (stdlib only), recording every body it received."""

from __future__ import annotations

import http.client
import json
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit


@dataclass
class Response:
    status: int
    headers: dict[str, str]
    body: bytes

    def json(self) -> Any:
        return json.loads(self.body)


@dataclass
class Client:
    url: str
    token: str | None = None
    cookie: str | None = None  # send the token as the login cookie instead of a Bearer header
    seen: list[tuple[str, Response]] = field(default_factory=list)

    def request(
        self, method: str, path: str, body: bytes | None = None, headers: dict[str, str] | None = None
    ) -> Response:
        parts = urlsplit(self.url)
        conn = http.client.HTTPConnection(parts.hostname or "127.0.0.1", parts.port, timeout=30)
        h = dict(headers or {})
        if self.cookie is not None:
            h["Cookie"] = f"pilworld_judge={self.cookie}"
        elif self.token is not None:
            h["Authorization"] = f"Bearer {self.token}"
        try:
            conn.request(method, path, body=body, headers=h)
            r = conn.getresponse()
            resp = Response(r.status, {k.lower(): v for k, v in r.getheaders()}, r.read())
        finally:
            conn.close()
        self.seen.append((path, resp))
        return resp

    def get(self, path: str, headers: dict[str, str] | None = None) -> Response:
        return self.request("GET", path, headers=headers)

    def put_json(self, path: str, value: Any) -> Response:
        return self.request("PUT", path, json.dumps(value).encode(), {"Content-Type": "application/json"})

    def queue(self) -> list[str]:
        return [i["id"] for i in self.get("/api/queue").json()["items"]]

    def label(self, item: str, success: bool, frame: int | None = None, category: str | None = None) -> Response:
        body = {"success": success, "first_hallucination_frame": frame, "category": category}
        return self.put_json(f"/api/items/{item}/label", body)
