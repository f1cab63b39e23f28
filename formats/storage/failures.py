"""What went wrong at a URL, in a few words, and whether trying again may help.

fsspec's filesystems raise each library's own exceptions (botocore, aiohttp, gcsfs), so
the failure is read from the exception's class, its HTTP status and its errno, never by
importing those libraries. Messages never carry the exception's URLs unredacted.
"""

from __future__ import annotations

import errno

from formats.storage.urls import redact_text

__all__ = ["describe", "is_not_found", "is_transient"]

_STATUS_WORDS = {
    400: "bad request (HTTP 400)", 401: "not authorised (HTTP 401): check the credentials",
    403: "access denied (HTTP 403): check the credentials and the bucket's permissions",
    404: "not found (HTTP 404)", 416: "range not satisfiable (HTTP 416)",
}


def _status(err: BaseException) -> int | None:
    for attr in ("status", "status_code", "code"):
        v = getattr(err, attr, None)
        if isinstance(v, int) and 100 <= v <= 599:
            return v
    response = getattr(err, "response", None)  # botocore ClientError
    if isinstance(response, dict):
        v = response.get("ResponseMetadata", {}).get("HTTPStatusCode")
        if isinstance(v, int):
            return v
    return None


def _names(err: BaseException) -> str:
    return " ".join(c.__name__ for c in type(err).__mro__)


def _inner(err: BaseException) -> BaseException:
    """The failure under fsspec's wrapping: its HTTP filesystem raises every failure to
    reach a URL (403, a timeout, a refused connection) as FileNotFoundError from it."""
    cause = err.__cause__
    if isinstance(err, FileNotFoundError) and cause is not None:
        return _inner(cause)
    return err


def is_not_found(err: BaseException) -> bool:
    """Whether the object is missing (HTTP 404), not its bucket or the way to it."""
    return describe(err) == _STATUS_WORDS[404]


def describe(err: BaseException) -> str:
    """One phrase for an exception raised while reading or writing a URL."""
    err = _inner(err)
    text = " ".join(redact_text(str(err)).split())
    names = _names(err)
    status = _status(err)
    if "bucket does not exist" in text.lower() or "NoSuchBucket" in text:
        return "the bucket does not exist"
    if isinstance(err, FileNotFoundError) or status == 404:
        return _STATUS_WORDS[404]
    if isinstance(err, PermissionError) or status in (401, 403):
        return _STATUS_WORDS[status if status in (401, 403) else 403]
    if status is not None:
        return _STATUS_WORDS.get(status, f"HTTP {status}" + (f" ({text})" if text else ""))
    if "Timeout" in names or isinstance(err, TimeoutError):
        return "timed out"
    if isinstance(err, ConnectionRefusedError) or getattr(err, "errno", None) == errno.ECONNREFUSED:
        return "connection refused"
    if "Connect" in names or "connect" in text.lower():
        return "cannot connect (connection refused or host unreachable)"
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def is_transient(err: BaseException) -> bool:
    """Whether the failure may pass: a timeout, a lost or refused connection, HTTP 5xx or
    429 (too many requests). Not found, access denied and bad requests are final."""
    err = _inner(err)
    if isinstance(err, FileNotFoundError | PermissionError | IsADirectoryError):
        return False
    status = _status(err)
    if status is not None:
        return status >= 500 or status == 429
    names = _names(err)
    return (isinstance(err, TimeoutError | ConnectionError) or "Timeout" in names
            or "Connect" in names or "ServerDisconnected" in names
            or "ClientPayloadError" in names)
