"""Warp's logging helpers: a replaceable logger and the level that gates it.

Messages go through the active logger: any object with ``debug(message)``,
``info(message)``, ``warning(message, category=None, stacklevel=1)`` and
``error(message)`` (the ``Logger`` protocol). The default one writes debug and
info lines to stdout, warnings through ``warnings.warn`` and errors to stderr.
``kdsl.config.log_level`` (``LOG_DEBUG`` .. ``LOG_ERROR``) says which are emitted.
"""

from __future__ import annotations

import sys
import warnings
from typing import Any, Protocol, runtime_checkable

from kdsl import config
from kdsl.errors import KdslError

LOG_DEBUG = 10
LOG_INFO = 20
LOG_WARNING = 30
LOG_ERROR = 40


@runtime_checkable
class Logger(Protocol):
    """What ``set_logger`` accepts: four methods, one per level."""

    def debug(self, message: str) -> None: ...

    def info(self, message: str) -> None: ...

    def warning(self, message: str, category: Any = None, stacklevel: int = 1) -> None: ...

    def error(self, message: str) -> None: ...


class LoggerBasic:
    """The default logger: stdout for debug/info, ``warnings.warn``, stderr for errors."""

    def debug(self, message: str) -> None:
        sys.stdout.write(message + "\n")

    def info(self, message: str) -> None:
        sys.stdout.write(message + "\n")

    def warning(self, message: str, category: Any = None, stacklevel: int = 1) -> None:
        warnings.warn(message, category, stacklevel=stacklevel + 1)

    def error(self, message: str) -> None:
        sys.stderr.write("kdsl error: " + message + "\n")


_active: Any = LoggerBasic()


def _validate(logger: Any) -> None:
    if not isinstance(logger, Logger) or not all(
        callable(getattr(logger, m, None)) for m in ("debug", "info", "warning", "error")
    ):
        raise KdslError(
            "a logger needs callable debug(message), info(message), warning(message, "
            f"category, stacklevel) and error(message) methods; got {type(logger).__name__}"
        )


def set_logger(logger: Any) -> None:
    """Make ``logger`` the active logger (None restores the default one)."""
    global _active
    if logger is None:
        _active = LoggerBasic()
        return
    _validate(logger)
    _active = logger


def get_logger() -> Any:
    """The active logger."""
    return _active


def log_debug(message: str) -> None:
    """Emit ``message`` at debug level (when ``config.log_level <= LOG_DEBUG``)."""
    if config.log_level <= LOG_DEBUG:
        _active.debug(message)


def log_info(message: str) -> None:
    """Emit ``message`` at info level (when ``config.log_level <= LOG_INFO``)."""
    if config.log_level <= LOG_INFO:
        _active.info(message)


def log_warning(message: str, category: Any = None, stacklevel: int = 1) -> None:
    """Emit a warning (when ``config.log_level <= LOG_WARNING``)."""
    if config.log_level <= LOG_WARNING:
        _active.warning(message, category=category, stacklevel=stacklevel + 2)


def log_error(message: str) -> None:
    """Emit an error message (always)."""
    _active.error(message)


class ScopedLogger:
    """``with ScopedLogger(my_logger):`` routes messages to ``my_logger`` for a block."""

    def __init__(self, logger: Any) -> None:
        if logger is not None:
            _validate(logger)
        self.logger = logger

    def __enter__(self) -> ScopedLogger:
        self.saved = _active
        set_logger(self.logger)
        return self

    def __exit__(self, *exc_info: object) -> None:
        global _active
        _active = self.saved


class ScopedLogLevel:
    """``with ScopedLogLevel(LOG_WARNING):`` sets ``config.log_level`` for a block."""

    def __init__(self, log_level: int) -> None:
        if not isinstance(log_level, int) or isinstance(log_level, bool):
            raise KdslError(f"ScopedLogLevel takes an int level (LOG_DEBUG..), not {log_level!r}")
        self.log_level = log_level

    def __enter__(self) -> ScopedLogLevel:
        self.saved = config.log_level
        config.log_level = self.log_level
        return self

    def __exit__(self, *exc_info: object) -> None:
        config.log_level = self.saved
