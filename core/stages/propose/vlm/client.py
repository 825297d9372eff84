"""A minimal OpenAI-compatible chat client for the vision-language model (standard library only).

Protocol: ``POST {endpoint}/chat/completions`` with ``{"model", "messages", "temperature": 0,
"max_tokens"}``; images travel inline as ``data:image/png;base64,...`` URLs in ``image_url``
content parts. Served this way by vLLM, LMDeploy (InternVL), SGLang, Ollama, llama.cpp and hosted
APIs. Nothing here touches the network unless an endpoint is configured: :func:`vlm_config`
refuses to build a configuration without one. Inside Blender the add-on must also check
``bpy.app.online_access`` before starting a worker that uses the VLM.

Retries: connection errors, HTTP 5xx and 429 are retried ``retries`` times with exponential
backoff; other 4xx answers fail at once. ``timeout`` is a deadline for the whole request,
retries included: a watchdog shuts the connection down when it passes, so neither a silent nor
a trickling server holds the stage longer.
"""

from __future__ import annotations

import base64
import http.client
import json
import os
import socket
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from typing import Any

from ....model.errors import ArtgsError, InputError

ENV_ENDPOINT = "ARTGS_VLM_ENDPOINT"
ENV_MODEL = "ARTGS_VLM_MODEL"
ENV_API_KEY = "ARTGS_VLM_API_KEY"
ENV_COORDS = "ARTGS_VLM_COORDS"
COORDS = ("auto", "grid1000", "pixels", "unit")


@dataclass(frozen=True)
class VlmConfig:
    """Where and how to ask the VLM.

    ``coords`` says how bare coordinate lists in answers are read (see ``vlm.parse``):
    ``auto`` (default), ``grid1000`` (InternVL), ``pixels`` (Qwen2.5-VL) or ``unit`` (0..1).
    ``width`` x ``height`` is the rendered view sent with each question (multiples of 28 suit
    InternVL's 448 px tiles and Qwen's 28 px patches).
    """

    endpoint: str
    model: str
    api_key: str | None = None
    timeout: float = 60.0
    retries: int = 2
    backoff: float = 1.0
    max_tokens: int = 1024
    width: int = 448
    height: int = 336
    coords: str = "auto"

    def __repr__(self) -> str:  # never print the key
        return (f"VlmConfig(endpoint={self.endpoint!r}, model={self.model!r}, "
                f"api_key={'set' if self.api_key else None}, timeout={self.timeout})")


def vlm_config(args_endpoint: str | None = None, args_model: str | None = None,
               timeout: float = 60.0, **options: Any) -> VlmConfig:
    """The VLM configuration from command-line values, else the environment.

    The API key is read only from ``$ARTGS_VLM_API_KEY`` (the add-on sets it from its preferences),
    never from a command-line argument. Raises :class:`InputError` when no endpoint or model is
    configured, before any work starts.
    """
    endpoint = (args_endpoint or os.environ.get(ENV_ENDPOINT, "")).strip()
    model = (args_model or os.environ.get(ENV_MODEL, "")).strip()
    if not endpoint:
        raise InputError("--vlm-endpoint", f"no VLM endpoint configured: set ${ENV_ENDPOINT} (or "
                         "the add-on preference 'VLM endpoint', or --vlm-endpoint) to an "
                         "OpenAI-compatible base URL such as http://127.0.0.1:23333/v1")
    if not endpoint.startswith(("http://", "https://")):
        raise InputError("--vlm-endpoint", f"{endpoint!r} is not an http:// or https:// URL")
    if not model:
        raise InputError("--vlm-model", f"no VLM model name configured: set ${ENV_MODEL} (or the "
                         "add-on preference 'VLM model', or --vlm-model), e.g. the name the server "
                         f"lists at {endpoint}/models")
    if not timeout or timeout <= 0:
        raise InputError("--vlm-timeout", f"must be a positive number of seconds, not {timeout}")
    coords = options.pop("coords", None) or os.environ.get(ENV_COORDS, "auto")
    if coords not in COORDS:
        raise InputError(f"${ENV_COORDS}", f"must be one of {COORDS}, not {coords!r}")
    return VlmConfig(endpoint=endpoint.rstrip("/"), model=model,
                     api_key=os.environ.get(ENV_API_KEY) or None, timeout=float(timeout),
                     coords=coords, **options)


def user_message(text: str, png: bytes | None = None) -> dict[str, Any]:
    """A user chat message: the text, and the PNG image as a base64 data URL when given."""
    if png is None:
        return {"role": "user", "content": text}
    url = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
    return {"role": "user", "content": [{"type": "text", "text": text},
                                        {"type": "image_url", "image_url": {"url": url}}]}


def assistant_message(text: str) -> dict[str, Any]:
    """A previous answer, to continue a conversation."""
    return {"role": "assistant", "content": text}


def chat(config: VlmConfig, messages: list[dict[str, Any]]) -> str:
    """Send ``messages`` and return the answer text; :class:`ArtgsError` names the endpoint.

    ``config.timeout`` is a deadline for the whole request, retries and back-off included: a
    server that trickles its answer byte by byte is cut off when it passes.
    """
    url = f"{config.endpoint}/chat/completions"
    body = json.dumps({"model": config.model, "messages": messages, "temperature": 0,
                       "max_tokens": config.max_tokens}).encode("utf-8")
    headers = {"Content-Type": "application/json", "Accept": "application/json"}
    if config.api_key:
        headers["Authorization"] = f"Bearer {config.api_key}"
    deadline = time.monotonic() + config.timeout
    late = ArtgsError(f"VLM endpoint {url} gave no complete answer within {config.timeout:g} s "
                      "(the whole request, retries included; raise --vlm-timeout for slow models)")
    watchdog = _Watchdog(deadline)
    try:
        return _post(urllib.request.Request(url, data=body, headers=headers, method="POST"),
                     config, watchdog, late)
    finally:
        watchdog.disarm()


def _post(request: urllib.request.Request, config: VlmConfig, watchdog: _Watchdog,
          late: ArtgsError) -> str:
    """The request with retries until ``watchdog.deadline``; the answer text."""
    url, deadline = request.full_url, watchdog.deadline
    opener = _opener(url, watchdog)
    attempt = 0
    while True:
        try:
            with opener.open(request, timeout=max(deadline - time.monotonic(), 1e-3)) as response:
                raw = response.read()
            if time.monotonic() >= deadline:   # the watchdog cut the answer short
                raise late
            return _answer_text(raw, url)
        except urllib.error.HTTPError as exc:
            detail = _excerpt(exc.read() if exc.fp is not None else b"")
            problem = f"VLM endpoint {url} answered HTTP {exc.code} {exc.reason}: {detail}"
            if exc.code < 500 and exc.code != 429:
                raise ArtgsError(problem) from None
        except (TimeoutError, socket.timeout):
            raise late from None
        except urllib.error.URLError as exc:
            if isinstance(exc.reason, (TimeoutError, socket.timeout)) \
                    or time.monotonic() >= deadline:
                raise late from None
            problem = f"VLM endpoint {url} is unreachable: {exc.reason}"
        except (OSError, http.client.HTTPException) as exc:
            if time.monotonic() >= deadline:
                raise late from None
            problem = f"VLM endpoint {url} connection failed: {exc}"
        if attempt >= config.retries:
            raise ArtgsError(f"{problem} (after {attempt + 1} attempts)")
        pause = config.backoff * 2 ** attempt
        if time.monotonic() + pause >= deadline:
            raise ArtgsError(f"{problem} (no time left within --vlm-timeout "
                             f"{config.timeout:g} s to retry)")
        time.sleep(pause)
        attempt += 1


class _Watchdog:
    """Shuts connections' sockets down at the deadline, so a blocked read ends then."""

    def __init__(self, deadline: float) -> None:
        self.deadline = deadline
        self.timers: list[threading.Timer] = []

    def arm(self, sock: socket.socket) -> None:
        timer = threading.Timer(max(self.deadline - time.monotonic(), 0.0), _shutdown, (sock,))
        timer.daemon = True
        timer.start()
        self.timers.append(timer)

    def disarm(self) -> None:
        for timer in self.timers:
            timer.cancel()


def _shutdown(sock: socket.socket) -> None:
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass   # already closed


def _deadline_connection(base: type) -> type:
    """``base`` (HTTP(S)Connection) whose socket is shut down at the watchdog's deadline."""
    class Connection(base):
        def __init__(self, *args, watchdog: _Watchdog, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            self._watchdog = watchdog

        def connect(self) -> None:
            super().connect()
            self._watchdog.arm(self.sock)
    return Connection


_HTTPConnection = _deadline_connection(http.client.HTTPConnection)
_HTTPSConnection = _deadline_connection(http.client.HTTPSConnection)


class _HTTPHandler(urllib.request.HTTPHandler):
    def __init__(self, watchdog: _Watchdog) -> None:
        super().__init__()
        self.watchdog = watchdog

    def http_open(self, req):
        return self.do_open(_HTTPConnection, req, watchdog=self.watchdog)


class _HTTPSHandler(urllib.request.HTTPSHandler):
    def __init__(self, watchdog: _Watchdog) -> None:
        super().__init__()
        self.watchdog = watchdog

    def https_open(self, req):
        return self.do_open(_HTTPSConnection, req, context=self._context,
                            watchdog=self.watchdog)


def _opener(url: str, watchdog: _Watchdog) -> urllib.request.OpenerDirector:
    """A URL opener whose connections end at the watchdog's deadline; a server on this machine
    is reached directly, never through a proxy from ``$http_proxy``/``$https_proxy`` (others
    follow the environment like any urllib client)."""
    handlers: list[Any] = [_HTTPHandler(watchdog), _HTTPSHandler(watchdog)]
    host = (urllib.parse.urlsplit(url).hostname or "").lower()
    if host in ("localhost", "::1") or host.startswith("127."):
        handlers.append(urllib.request.ProxyHandler({}))
    return urllib.request.build_opener(*handlers)


def _answer_text(raw: bytes, url: str) -> str:
    """The first choice's text from a chat-completions response body."""
    try:
        data = json.loads(raw.decode("utf-8"))
        content = data["choices"][0]["message"]["content"]
    except (UnicodeDecodeError, json.JSONDecodeError, KeyError, IndexError, TypeError) as exc:
        raise ArtgsError(f"VLM endpoint {url} sent an answer that is not a chat completion "
                         f"({type(exc).__name__}): {_excerpt(raw)}") from None
    if isinstance(content, list):  # content parts
        content = "".join(p.get("text", "") for p in content if isinstance(p, dict))
    if not isinstance(content, str):
        raise ArtgsError(f"VLM endpoint {url} sent no text content: {_excerpt(raw)}")
    return content


def _excerpt(raw: bytes, limit: int = 300) -> str:
    text = raw.decode("utf-8", errors="replace").strip().replace("\n", " ")
    return (text[:limit] + "...") if len(text) > limit else (text or "(empty body)")
