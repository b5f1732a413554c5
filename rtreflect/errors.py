"""Errors a user can act on: one line, naming the file and the field."""

from pathlib import Path


class RtreflectError(Exception):
    """Bad input or an environment problem the user can fix; the command line exits 2."""


class SceneError(RtreflectError):
    """A scene or geometry file that cannot be used, with where and why."""

    def __init__(self, file: object, field: str, message: str):
        self.file = str(file)
        self.field = field
        self.reason = message
        where = f"{self.file}: {field}" if field else self.file
        super().__init__(f"{where}: {message}")


def read_text(path: Path, what: str) -> str:
    """A UTF-8 text file's contents; a missing, unreadable or binary file is a `SceneError` naming it."""
    try:
        return Path(path).read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise SceneError(path, "", f"{what} not found") from None
    except OSError as exc:
        raise SceneError(path, "", f"cannot read {what} ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise SceneError(path, "", f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
