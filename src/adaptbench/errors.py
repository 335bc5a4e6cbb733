"""The one error base of adaptbench. Every error the package raises on purpose is an `AdaptError`; each
subclass also inherits the built-in type it behaves as (`SpecError(AdaptError, ValueError)`, as lark's
`ConfigurationError(LarkError, ValueError)`), so `except ValueError` keeps working, and carries the exit
code the `adapt` command gives it (1: a failure, 2: a usage error). The command's one handler catches
`AdaptError` and prints its message as one line.

    try:
        domain = adaptbench.load_domain("myspec")
    except adaptbench.AdaptError as exc:
        print(exc, exc.exit_code)
"""

from __future__ import annotations


class AdaptError(Exception):
    """Base of every error adaptbench raises on purpose; `exit_code` is what `adapt` exits with."""

    exit_code: int = 1

    def __init__(self, *args, code: int | None = None):
        super().__init__(*args)
        if code is not None:
            self.exit_code = code

    @property
    def code(self) -> int:
        """The exit code (the older name)."""
        return self.exit_code
