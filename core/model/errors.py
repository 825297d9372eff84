"""User-facing errors: a message that names what is wrong and where."""

from __future__ import annotations

from pathlib import Path


class ArtgsError(Exception):
    """An error the user can act on; the CLI prints its message without a traceback."""


class InputError(ArtgsError):
    """Bad input, refused before any work starts.

    The message names the file and, where there is one, the frame and the field.
    """

    def __init__(self, file: str | Path, message: str, *, frame: str | int | None = None,
                 field: str | None = None) -> None:
        self.file = str(file)
        self.frame = frame
        self.field = field
        where = self.file
        if frame is not None:
            where += f", frame {frame}"
        if field is not None:
            where += f", field '{field}'"
        super().__init__(f"{where}: {message}")


class Cancelled(ArtgsError):
    """The user cancelled a long stage."""


class NothingFound(ArtgsError):
    """A stage ran but found nothing to write; earlier outputs are left as they were.
    ``reason``: what the stage measured that explains it (for a stand-in to repeat)."""

    def __init__(self, message: str, *, reason: str = "") -> None:
        self.reason = reason
        super().__init__(message)
