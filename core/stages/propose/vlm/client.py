"""A minimal OpenAI-compatible chat client for the vision-language model (standard library only).

Protocol: ``POST {endpoint}/chat/completions`` with ``{"model", "messages", "temperature": 0,
"max_tokens"}``; images travel inline as ``data:image/png;base64,...`` URLs in ``image_url``
content parts. Served this way by vLLM, LMDeploy (InternVL), SGLang, Ollama, llama.cpp and hosted
APIs. Nothing here touches the network unless an endpoint is configured: :func:`vlm_config`
refuses to build a configuration without one. Inside Blender the add-on must also check
``bpy.app.online_access`` before starting a worker that uses the VLM.

Retries: connection errors, HTTP 5xx and 429 are retried ``retries`` times with exponential
backoff; other 4xx answers fail at once; a request that gets no answer within ``timeout`` fails
without retry (the server may still be busy with it).
"""

from __future__ import annotations

import base64
import http.client
import json
import os
import socket
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

    ``coords`` says how bare coordinate lists in answers are read (see ``core.vlm_parse``):
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
    """Send ``messages`` and return the answer text; :class:`ArtgsError` names the endpoint."""
    url = f"{config.endpoint}/chat/completions"
    body = json.dumps({"model": config.model, "messages": messages, "temperature": 0,
                       "max_tokens": config.max_tokens}).encode("utf-8")
    headers = {"Content-Type": "application/json", "Accept": "application/json"}
    if config.api_key:
        headers["Authorization"] = f"Bearer {config.api_key}"
    opener = _opener(url)
    attempt = 0
    while True:
        request = urllib.request.Request(url, data=body, headers=headers, method="POST")
        try:
            with opener.open(request, timeout=config.timeout) as response:
                raw = response.read()
            return _answer_text(raw, url)
        except urllib.error.HTTPError as exc:
            detail = _excerpt(exc.read() if exc.fp is not None else b"")
            problem = f"VLM endpoint {url} answered HTTP {exc.code} {exc.reason}: {detail}"
            if exc.code < 500 and exc.code != 429:
                raise ArtgsError(problem) from None
        except (TimeoutError, socket.timeout) as exc:
            raise ArtgsError(f"VLM endpoint {url} gave no answer within {config.timeout:g} s "
                             f"(raise --vlm-timeout for slow models)") from exc
        except urllib.error.URLError as exc:
            if isinstance(exc.reason, (TimeoutError, socket.timeout)):
                raise ArtgsError(f"VLM endpoint {url}: connection timed out after "
                                 f"{config.timeout:g} s") from exc
            problem = f"VLM endpoint {url} is unreachable: {exc.reason}"
        except (OSError, http.client.HTTPException) as exc:
            problem = f"VLM endpoint {url} connection failed: {exc}"
        if attempt >= config.retries:
            raise ArtgsError(f"{problem} (after {attempt + 1} attempts)")
        time.sleep(config.backoff * 2 ** attempt)
        attempt += 1


def _opener(url: str) -> urllib.request.OpenerDirector:
    """A URL opener; a server on this machine is reached directly, never through a proxy from
    ``$http_proxy``/``$https_proxy`` (others follow the environment like any urllib client)."""
    host = (urllib.parse.urlsplit(url).hostname or "").lower()
    if host in ("localhost", "::1") or host.startswith("127."):
        return urllib.request.build_opener(urllib.request.ProxyHandler({}))
    return urllib.request.build_opener()


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
