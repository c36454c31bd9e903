"""Log format of ``zonecast serve``: stdlib :mod:`logging`, one line per record.

Two formats (``zonecast serve --log-format text|json``):

- ``text`` (default): ``2026-11-23T07:30:14.123Z WARNING zonecast.service.ingest readings
  rejected (off_grid, 1) on zonecast/office6/telemetry: ... building=office6 reason=off_grid``
  -- time (UTC), level, logger, message, then the record's structured fields as key=value;
- ``json``: one JSON object per line with ``time``, ``level``, ``logger``, ``message``, the
  structured fields (``building``, ``reason``, ``transport``, ``topic``, ``count``, ...)
  and ``exception`` (the traceback) when there is one.

Structured fields are the ``extra={...}`` of a logging call: the service passes
``building`` on start-up, resume, broker connection and every reject, and ``reason`` on
every reject (``zonecast.service.ingest.log_rejections``).
"""

from __future__ import annotations

import json
import logging
import sys
from datetime import UTC, datetime
from typing import Any, Literal, TextIO

__all__ = ["FORMATS", "JsonFormatter", "TextFormatter", "configure_logging", "record_fields"]

FORMATS = ("text", "json")

#: attributes every LogRecord has; anything else on a record came from ``extra``
_STANDARD = frozenset(vars(logging.LogRecord("", 0, "", 0, "", (), None))) | {
    "message", "asctime", "taskName"}


def record_fields(record: logging.LogRecord) -> dict[str, Any]:
    """The structured fields of a record (what the logging call passed as ``extra``)."""
    return {k: v for k, v in vars(record).items() if k not in _STANDARD and not k.startswith("_")}


def _time(record: logging.LogRecord) -> str:
    return datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds") \
        .replace("+00:00", "Z")


class JsonFormatter(logging.Formatter):
    """One JSON object per record: ``time`` (UTC ISO-8601), ``level``, ``logger``,
    ``message``, the record's structured fields, ``exception`` if any."""

    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {"time": _time(record), "level": record.levelname,
                               "logger": record.name, "message": record.getMessage()}
        for key, value in record_fields(record).items():
            out.setdefault(key, value)
        if record.exc_info:
            out["exception"] = self.formatException(record.exc_info)
        elif record.exc_text:
            out["exception"] = record.exc_text
        if record.stack_info:
            out["stack"] = self.formatStack(record.stack_info)
        return json.dumps(out, default=str, ensure_ascii=False)


class TextFormatter(logging.Formatter):
    """``<time UTC> <LEVEL> <logger> <message> key=value ...`` and the traceback, if any."""

    def format(self, record: logging.LogRecord) -> str:
        line = f"{_time(record)} {record.levelname} {record.name} {record.getMessage()}"
        fields = record_fields(record)
        if fields:
            line += " " + " ".join(f"{k}={_text(v)}" for k, v in fields.items())
        if record.exc_info:
            line += "\n" + self.formatException(record.exc_info)
        elif record.exc_text:
            line += "\n" + record.exc_text
        return line


def _text(value: Any) -> str:
    text = value if isinstance(value, str) else json.dumps(value, default=str)
    return json.dumps(text) if not text or any(c in text for c in ' "=\n') else text


def configure_logging(fmt: Literal["text", "json"] = "text", level: str | int = "INFO",
                      stream: TextIO | None = None) -> logging.Handler:
    """Send every log record (the service's and uvicorn's) to ``stream`` (default stderr)
    in format ``fmt``, replacing the root logger's handlers; returns the handler.

    Raises
    ------
    ValueError
        ``fmt`` is not ``text`` or ``json``, or ``level`` is not a logging level name.
    """
    if fmt not in FORMATS:
        raise ValueError(f"log format {fmt!r}: use one of {', '.join(FORMATS)}")
    if isinstance(level, str):
        number = logging.getLevelNamesMapping().get(level.upper())
        if number is None:
            raise ValueError(f"log level {level!r}: use debug, info, warning, error or critical")
        level = number
    handler = logging.StreamHandler(sys.stderr if stream is None else stream)
    handler.setFormatter(JsonFormatter() if fmt == "json" else TextFormatter())
    root = logging.getLogger()
    for old in list(root.handlers):
        root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(level)
    # uvicorn's own loggers: no handlers of their own, through the root's
    for name in ("uvicorn", "uvicorn.error", "uvicorn.access"):
        lg = logging.getLogger(name)
        lg.handlers.clear()
        lg.propagate = True
    return handler
