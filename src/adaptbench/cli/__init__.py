"""The `adapt` command: one module per command group (`author`, `episode`, `grammar`, `runs`, `model`),
shared argument types in `argtypes`, and one error handler in `main`."""

from .main import build_parser, main, report_spec_error

__all__ = ["build_parser", "main", "report_spec_error"]
