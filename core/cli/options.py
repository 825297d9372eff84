"""Command-line flags derived from options dataclasses (the registry's and the tools').

A field becomes ``--field-name`` (or a positional argument with ``metadata["positional"]``), typed
from its annotation: ``bool`` is a switch (``--x/--no-x``), ``list[T]`` takes one or more values
(repeatable), ``T | None`` defaults to None. ``help`` and ``choices`` come from the metadata.
"""

from __future__ import annotations

import argparse
import types
import typing
from dataclasses import MISSING, fields
from typing import Any


def _base_type(annotation: Any) -> tuple[Any, bool]:
    """(element type, is_list) of a field annotation, with ``None`` dropped from unions."""
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        return _base_type(args[0])
    if origin in (list, tuple):
        return typing.get_args(annotation)[0], True
    return annotation, False


def add_field(parser: argparse.ArgumentParser | argparse._ArgumentGroup, cls: type, name: str,
              flags: list[str] | None = None, dest: str | None = None) -> None:
    """Add the argument of field ``name`` of ``cls`` (flags default to ``--name``)."""
    f = next(f for f in fields(cls) if f.name == name)
    typ, is_list = _base_type(typing.get_type_hints(cls)[name])
    meta = f.metadata
    default = f.default if f.default is not MISSING else (
        f.default_factory() if f.default_factory is not MISSING else None)  # type: ignore[misc]
    kw: dict[str, Any] = {"help": meta.get("help")}
    if meta.get("choices"):
        kw["choices"] = meta["choices"]
    if meta.get("positional"):
        parser.add_argument(dest or name, type=typ, **kw)
        return
    kw.update(dest=dest or name, default=default)
    flags = flags or [f"--{name.replace('_', '-')}"]
    if typ is bool:
        parser.add_argument(*flags, action=argparse.BooleanOptionalAction, **kw)
    elif is_list:
        parser.add_argument(*flags, type=typ, nargs="+", action="extend", **kw)
    else:
        parser.add_argument(*flags, type=typ, metavar=name.upper() if "choices" not in kw
                            else None, **kw)


def add_options(parser: argparse.ArgumentParser | argparse._ArgumentGroup, cls: type) -> None:
    """Add one argument per field of the options dataclass ``cls``."""
    for f in fields(cls):
        add_field(parser, cls, f.name)


def build(cls: type, ns: argparse.Namespace, dest_of: typing.Callable[[str], str] = str) -> Any:
    """An instance of ``cls`` from the parsed arguments (``dest_of`` maps a field to its dest)."""
    values = {f.name: getattr(ns, dest_of(f.name)) for f in fields(cls)
              if hasattr(ns, dest_of(f.name))}
    return cls(**values)
