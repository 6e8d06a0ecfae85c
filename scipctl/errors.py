"""Exceptions that the CLI maps to exit codes (kept import-light: the CLI loads this at start-up)."""

from typing import Optional


class CommandFailed(Exception):
    """The command ran, and the answer is "no" (exit code 1): no reliable match, a rule broken, ..."""

    def __init__(self, message: str, payload: Optional[dict] = None):
        super().__init__(message)
        self.payload = payload
