"""A local OpenAI-compatible server on 127.0.0.1 (the only stand-in the tests use: no VLM
runs here). ``Server(handler)``, where ``handler(request_handler, body)`` writes the answer;
``answer(text)`` answers ``text`` as the assistant's message and ``reply(fn)`` answers what
``fn(body) -> (status, body_text, delay_seconds)`` says. Every request is recorded."""

from __future__ import annotations

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Callable, NamedTuple

Handler = Callable[[BaseHTTPRequestHandler, Any], None]


class Request(NamedTuple):
    """One request the server received: path, headers, JSON body, arrival (monotonic s)."""

    path: str
    headers: dict[str, str]
    body: Any
    at: float


class Server:
    """A local OpenAI-compatible server; also a context manager that closes it."""

    def __init__(self, handler: Handler) -> None:
        self.requests: list[Request] = []
        self.closed: list[float] = []
        server = self

        class RequestHandler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                server.requests.append(Request(self.path, dict(self.headers), body,
                                               time.monotonic()))
                try:
                    handler(self, body)
                except OSError:          # the client gave up (timeout tests)
                    pass
                server.closed.append(time.monotonic())

            def log_message(self, *args) -> None:
                pass

        self.http = ThreadingHTTPServer(("127.0.0.1", 0), RequestHandler)
        self.http.daemon_threads = True
        self.http.block_on_close = False   # do not wait for a deliberately slow answer
        threading.Thread(target=self.http.serve_forever, args=(0.05,), daemon=True).start()

    @property
    def endpoint(self) -> str:
        return f"http://127.0.0.1:{self.http.server_address[1]}/v1"

    def close(self) -> None:
        self.http.shutdown()
        self.http.server_close()

    def __enter__(self) -> "Server":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def completion(text: str) -> str:
    """An OpenAI chat-completion body whose assistant message is ``text``."""
    return json.dumps({"id": "x", "object": "chat.completion",
                       "choices": [{"index": 0, "message": {"role": "assistant", "content": text},
                                    "finish_reason": "stop"}]})


def reply(fn: Callable[[Any], tuple[int, str, float]]) -> Handler:
    """A handler answering ``fn(body) -> (status, body_text, delay_seconds)``."""
    def handler(h: BaseHTTPRequestHandler, body: Any) -> None:
        status, text, delay = fn(body)
        time.sleep(delay)
        data = text.encode()
        h.send_response(status)
        h.send_header("Content-Type", "application/json")
        h.send_header("Content-Length", str(len(data)))
        h.end_headers()
        h.wfile.write(data)
    return handler


def answer(text: str) -> Handler:
    """A handler answering ``text`` as the assistant's message."""
    return reply(lambda body: (200, completion(text), 0.0))
