"""A local OpenAI-compatible server on 127.0.0.1 (the only stand-in the tests use: no VLM
runs here): ``Server(handler)``, where ``handler(request_handler)`` writes the answer, and
``answer(text)`` for a handler that answers ``text`` as the assistant's message."""

from __future__ import annotations

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer


class Server:
    """A local OpenAI-compatible server; ``handler(request_handler)`` writes the answer."""

    def __init__(self, handler) -> None:
        self.requests: list[float] = []
        self.closed: list[float] = []
        server = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                self.rfile.read(int(self.headers["Content-Length"]))
                server.requests.append(time.monotonic())
                try:
                    handler(self)
                except OSError:
                    pass
                server.closed.append(time.monotonic())

            def log_message(self, *args) -> None:
                pass

        self.http = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.http.daemon_threads = True
        self.http.block_on_close = False
        threading.Thread(target=self.http.serve_forever, args=(0.05,), daemon=True).start()

    @property
    def endpoint(self) -> str:
        return f"http://127.0.0.1:{self.http.server_address[1]}/v1"

    def close(self) -> None:
        self.http.shutdown()
        self.http.server_close()


def answer(text: str):
    """A handler answering ``text`` as the assistant's message."""
    def handler(h: BaseHTTPRequestHandler) -> None:
        body = json.dumps({"choices": [{"message": {"role": "assistant", "content": text}}]})
        h.send_response(200)
        h.send_header("Content-Type", "application/json")
        h.send_header("Content-Length", str(len(body)))
        h.end_headers()
        h.wfile.write(body.encode())
    return handler
