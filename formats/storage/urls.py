"""URLs as sonarmap tells them apart from local paths, and as it writes them down.

A log or an output may be named by a URL, ``scheme://...``, read and written through
fsspec. :func:`redact_url` is the one rule for every URL sonarmap prints or stores
(messages, ``metrics.json``, reports, ``map.mcap``): the userinfo (``user:secret@``) and
the whole query string (signed URLs carry their credentials there: ``X-Amz-Signature``,
Azure SAS ``sig``, ...) and fragment are dropped, so no credential can be written down.
"""

from __future__ import annotations

import re
from urllib.parse import urlsplit, urlunsplit

__all__ = ["EXTRAS", "URL_SCHEMES", "is_url", "redact_text", "redact_url", "scheme_of"]

#: The pip extra that installs each scheme's filesystem (``pip install 'sonarmap[s3]'``).
EXTRAS: dict[str, str] = {
    "s3": "s3", "s3a": "s3",
    "gs": "gcs", "gcs": "gcs",
    "az": "azure", "abfs": "azure", "abfss": "azure",
    "http": "http", "https": "http",
}
#: Schemes sonarmap reads and writes through fsspec (``file://`` is read as a local path).
URL_SCHEMES = frozenset(EXTRAS) | {"file"}

_SCHEME = re.compile(r"^(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*)://")
# A URL inside free text (an exception's message): up to the next blank or quote.
_IN_TEXT = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*://[^\s'\"<>]+")


def scheme_of(text: str) -> str | None:
    """The lower-case scheme of ``scheme://...`` text, or None for anything else."""
    m = _SCHEME.match(text)
    return m["scheme"].lower() if m else None


def is_url(text: str) -> bool:
    """Whether ``text`` names a location by URL (a known scheme followed by ``://``)."""
    return scheme_of(text) in URL_SCHEMES


def redact_url(url: str) -> str:
    """``url`` without userinfo, query string or fragment (the form sonarmap writes down)."""
    try:
        parts = urlsplit(url)
        host = parts.hostname or ""
        port = parts.port
    except ValueError:  # an unparsable port or bracket: keep only scheme and path
        m = _SCHEME.match(url)
        rest = url[m.end():] if m else url
        path = rest.split("?", 1)[0].split("#", 1)[0]
        path = path.rsplit("@", 1)[-1]
        return f"{m['scheme']}://{path}" if m else path
    if ":" in host:  # IPv6 literal
        host = f"[{host}]"
    netloc = host if port is None else f"{host}:{port}"
    return urlunsplit((parts.scheme, netloc, parts.path, "", ""))


def redact_text(text: str) -> str:
    """``text`` with every URL in it redacted (:func:`redact_url`)."""
    return _IN_TEXT.sub(lambda m: redact_url(m.group(0)), text)
