"""Blender glue: preferences, properties, building and reading Blender objects, the worker client."""


def register() -> None:
    """Register preferences, properties, operators and panels."""


def unregister() -> None:
    """Unregister everything ``register`` added, in reverse order."""
