"""A local stand-in for the Hugging Face Hub's dataset endpoints, serving one directory as a repo.

Enough of the API for ``huggingface_hub.snapshot_download`` (``HF_ENDPOINT=http://127.0.0.1:PORT``):
the revision info, the recursive file tree, and each file (HEAD and GET) with the commit and ETag
headers it checks. Binds 127.0.0.1 on a free port; stops when the ``with`` block ends.
"""

from __future__ import annotations

import hashlib
import http.server
import json
import threading
from pathlib import Path
from urllib.parse import unquote, urlparse

COMMIT = "0123456789abcdef0123456789abcdef01234567"


class FakeHub:
    """Serve ``root`` as the dataset repo ``repo_id``. ``requests`` lists the paths asked for."""

    def __init__(self, root: Path, repo_id: str) -> None:
        self.root, self.repo_id = Path(root), repo_id
        self.requests: list[str] = []
        hub = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def log_message(self, *args) -> None:
                pass

            def do_GET(self) -> None:
                hub._answer(self, head=False)

            def do_HEAD(self) -> None:
                hub._answer(self, head=True)

        self._server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self._server.server_address[1]}"

    def _files(self) -> list[Path]:
        return sorted(p for p in self.root.rglob("*") if p.is_file())

    def _answer(self, h: http.server.BaseHTTPRequestHandler, head: bool) -> None:
        path = unquote(urlparse(h.path).path)
        self.requests.append(path)
        resolve = f"/datasets/{self.repo_id}/resolve/"
        if path.startswith(resolve):
            file = self.root / path[len(resolve):].split("/", 1)[1]
            if not file.is_file():
                return h.send_error(404)
            data = file.read_bytes()
            h.send_response(200)
            h.send_header("Content-Length", str(len(data)))
            h.send_header("X-Repo-Commit", COMMIT)
            h.send_header("ETag", f'"{hashlib.sha1(data).hexdigest()}"')
            h.end_headers()
            if not head:
                h.wfile.write(data)
            return
        if path.startswith(f"/api/datasets/{self.repo_id}/revision/"):
            body = {"id": self.repo_id, "sha": COMMIT,
                    "siblings": [{"rfilename": str(p.relative_to(self.root))} for p in self._files()]}
        elif path.startswith(f"/api/datasets/{self.repo_id}/tree/"):
            body = [{"type": "file", "path": str(p.relative_to(self.root)), "size": p.stat().st_size,
                     "oid": hashlib.sha1(p.read_bytes()).hexdigest()} for p in self._files()]
        else:
            return h.send_error(404)
        data = json.dumps(body).encode()
        h.send_response(200)
        h.send_header("Content-Type", "application/json")
        h.send_header("Content-Length", str(len(data)))
        h.end_headers()
        h.wfile.write(data)

    def __enter__(self) -> FakeHub:
        threading.Thread(target=self._server.serve_forever, daemon=True).start()
        return self

    def __exit__(self, *exc) -> None:
        self._server.shutdown()
        self._server.server_close()
