"""A model hub on 127.0.0.1 in the Hugging Face layout, for the download tests (HF_ENDPOINT).

It answers what ``huggingface_hub.snapshot_download`` asks, with real files from local folders:
``GET /api/models/<repo>/revision/<rev>`` (the repo's commit and file list),
``GET /api/models/<repo>/tree/<commit>`` (the files with sizes and ids), and
``HEAD`` / ``GET /<repo>/resolve/<commit>/<file>`` (the bytes, with the commit, ETag and size
headers the client reads). Nothing of the client library is mocked.
"""

from __future__ import annotations

import hashlib
import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urlparse


class LocalHub:
    """``with LocalHub({"org/name": folder, ...}) as hub:`` serves every file of each folder as
    that repo at ``hub.url``; ``hub.requests`` lists (method, path) of every request."""

    def __init__(self, repos: dict[str, Path]) -> None:
        self.repos = {rid: Path(folder) for rid, folder in repos.items()}
        self.requests: list[tuple[str, str]] = []
        self.commits = {rid: hashlib.sha1(rid.encode() + b"".join(sorted(f.name.encode() for f in folder.iterdir()))).hexdigest() for rid, folder in self.repos.items()}
        self._server: ThreadingHTTPServer | None = None

    def _files(self, repo_id: str) -> dict[str, Path]:
        folder = self.repos[repo_id]
        return {f.relative_to(folder).as_posix(): f for f in sorted(folder.rglob("*")) if f.is_file()}

    def _handler(self):
        hub = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args) -> None:  # keep test output quiet
                pass

            def _send(self, code: int, body: bytes = b"", headers: dict | None = None, head: bool = False) -> None:
                self.send_response(code)
                for k, v in (headers or {}).items():
                    self.send_header(k, v)
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                if not head:
                    self.wfile.write(body)

            def _json(self, data) -> None:
                self._send(200, json.dumps(data).encode(), {"Content-Type": "application/json"})

            def _route(self, head: bool) -> None:
                path = unquote(urlparse(self.path).path)
                hub.requests.append((self.command, path))
                parts = path.strip("/").split("/")
                if parts[:2] == ["api", "models"] and len(parts) >= 6:
                    repo_id, kind = "/".join(parts[2:4]), parts[4]
                    if repo_id not in hub.repos:
                        return self._send(404, b'{"error": "Repository not found"}', {"X-Error-Code": "RepoNotFound"}, head)
                    files = hub._files(repo_id)
                    if kind == "revision":
                        return self._json({"id": repo_id, "modelId": repo_id, "sha": hub.commits[repo_id], "private": False,
                                           "siblings": [{"rfilename": name} for name in files]})
                    if kind == "tree":
                        return self._json([
                            {"type": "file", "path": name, "size": f.stat().st_size,
                             "oid": hashlib.sha1(b"blob %d\0" % f.stat().st_size + f.read_bytes()).hexdigest()}
                            for name, f in files.items()
                        ])
                if len(parts) >= 5 and parts[2] == "resolve":
                    repo_id, name = "/".join(parts[:2]), "/".join(parts[4:])
                    f = hub._files(repo_id).get(name) if repo_id in hub.repos else None
                    if f is None:
                        return self._send(404, b"Entry not found", {"X-Error-Code": "EntryNotFound"}, head)
                    data = f.read_bytes()
                    return self._send(200, data, {"X-Repo-Commit": hub.commits[repo_id], "ETag": f'"{hashlib.sha256(data).hexdigest()}"',
                                                  "Content-Type": "application/octet-stream"}, head)
                return self._send(404, b"not found", {}, head)

            def do_GET(self) -> None:
                self._route(head=False)

            def do_HEAD(self) -> None:
                self._route(head=True)

        return Handler

    def __enter__(self) -> "LocalHub":
        self._server = ThreadingHTTPServer(("127.0.0.1", 0), self._handler())
        threading.Thread(target=self._server.serve_forever, daemon=True).start()
        return self

    @property
    def url(self) -> str:
        assert self._server is not None
        return f"http://127.0.0.1:{self._server.server_address[1]}"

    def __exit__(self, *exc) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
