"""User-facing errors: one line naming what is wrong and what is allowed."""

__all__ = ["FxflexError", "SceneError"]


class FxflexError(Exception):
    """An error caused by the user's input; the CLI prints its message as one line and exits 2."""


class SceneError(FxflexError):
    """Invalid scene key or value. The message names the dotted key and the allowed values."""

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(f"{key}: {message}")
