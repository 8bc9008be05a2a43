"""User-facing errors: one line naming what is wrong and what is allowed.

Each carries the exit status the command line ends with: 2 for bad input (refused before
anything is written), 1 for an output that failed while the command ran.
"""

__all__ = ["FxflexError", "SceneError", "OutputError"]


class FxflexError(Exception):
    """An error caused by the user's input; the CLI prints its message as one line and exits 2."""

    status = 2


class SceneError(FxflexError):
    """Invalid scene key or value. The message names the dotted key and the allowed values."""

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(f"{key}: {message}")


class OutputError(FxflexError):
    """An output file that could not be written while the command ran (disk full, the folder
    made read-only after the start); the CLI prints the message as one line and exits 1.

    ``collective`` is true when every rank raises it together (the failure was broadcast), so
    that the ranks may still meet in collective clean-up."""

    status = 1

    def __init__(self, message: str, *, collective: bool = False):
        self.collective = collective
        super().__init__(message)
