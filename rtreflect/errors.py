"""Errors a user can act on: one line, naming the file and the field."""


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
