"""Exceptions that the CLI maps to exit codes (kept import-light: the CLI loads this at start-up).

The base layer: every module may import these (``scipctl.model`` re-exports :class:`InputError`).
"""

from typing import Optional


def one_line(text) -> str:
    """``str(text)`` with line breaks and other unprintable characters escaped as in ``repr`` (``\\n``, ``\\x00``)."""
    s = str(text)
    return s if s.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in s)


class InputError(Exception):
    """Bad input: one line naming the product (or file) and the field. CLI exit code 2.

    The attributes keep the text as given; ``str()`` escapes line breaks and other control characters
    (a product id, path or value read from the input may contain them), so it is always one line.
    """

    def __init__(self, product: str, field: str, message: str):
        self.product = product
        self.field = field
        self.message = message
        super().__init__(f"{one_line(product)}: {one_line(field)}: {one_line(message)}")


class CommandFailed(Exception):
    """The command ran, and the answer is "no" (exit code 1): no reliable match, a rule broken, ..."""

    def __init__(self, message: str, payload: Optional[dict] = None):
        super().__init__(message)
        self.payload = payload
