"""Errors a user can act on: one line, naming the file and the field."""

from pathlib import Path

#: How a warning line starts (``rtreflect: warning: FILE: reason``, on stderr; `--strict` counts them): the render
#: succeeded, or a CAD face was read short of the reader's promise.
WARNING = "rtreflect: warning: "
#: Longest quoted value (a token, a name) shown in a message: enough to recognise it, short enough to read.
QUOTE_LIMIT = 60


def one_line(text: str) -> str:
    """``text`` with line breaks and other control characters escaped, so a message stays one line.

    Paths, names and parser or OS messages can carry newlines; a CI log or a script
    reading the first line of stderr would then see half a message.
    """
    return "".join(ch if ch.isprintable() or ch == " " else ascii(ch)[1:-1] for ch in str(text))


def quote(value: object) -> str:
    """A value for a message: repr, shortened to `QUOTE_LIMIT` characters."""
    text = repr(value)
    return text if len(text) <= QUOTE_LIMIT else text[:QUOTE_LIMIT - 5] + "…" + text[-4:]


class RtreflectError(Exception):
    """Bad input or an environment problem the user can fix; the command line exits 2."""


class SceneError(RtreflectError):
    """A scene or geometry file that cannot be used, with where and why."""

    def __init__(self, file: object, field: str, message: str):
        self.file = str(file)
        self.field = field
        self.reason = message
        where = f"{self.file}: {field}" if field else self.file
        super().__init__(one_line(f"{where}: {message}"))


class SceneErrors(SceneError):
    """Several independent problems of one scene, each a `SceneError`; the first stands for all of them.

    ``str()`` is the first error's line (so one-line reporters such as a batch summary keep
    working); `error_lines` gives every line, which the command line prints one per line.
    """

    def __init__(self, errors: list[SceneError]):
        # Flatten nested collections (a table's unknown keys inside a scene's errors).
        self.errors = [leaf for error in errors for leaf in getattr(error, "errors", [error])]
        first = self.errors[0]
        super().__init__(first.file, first.field, first.reason)


def error_lines(exc: BaseException) -> list[str]:
    """The one-line message of each problem ``exc`` stands for (several for a `SceneErrors`)."""
    return [str(error) for error in getattr(exc, "errors", [exc])]


#: Largest scene or geometry text read: about two million control points of .bpt text, whose parse
#: already takes a gigabyte. The cap also stops /dev/zero or an endless pipe from filling memory.
MAX_TEXT_BYTES = 64 << 20


def read_text(path: Path, what: str) -> str:
    """A UTF-8 text file's contents; a missing, unreadable, binary or huge file is a `SceneError` naming it.

    Pipes work (a scene from a script through ``<(...)``): the file is read, not measured first.
    """
    try:
        with open(path, "rb") as stream:
            data = stream.read(MAX_TEXT_BYTES + 1)
        if len(data) > MAX_TEXT_BYTES:
            raise SceneError(path, "", f"{what} is larger than {MAX_TEXT_BYTES >> 20} MB; no scene or geometry file is")
        return data.decode("utf-8-sig")  # a byte-order mark (Windows editors) is not content
    except FileNotFoundError:
        raise SceneError(path, "", f"{what} not found") from None
    except OSError as exc:
        raise SceneError(path, "", f"cannot read {what} ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise SceneError(path, "", f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except ValueError as exc:  # e.g. a NUL character in the path, which no file system accepts
        raise SceneError(path, "", f"cannot read {what} ({exc})") from None
