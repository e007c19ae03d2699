"""The digest of a result record: what its run computed, so that a record edited afterwards is told apart.

A record's ``digest`` is the SHA-256 of the canonical JSON (keys sorted, no spaces, ASCII) of every key of the
record but the digest itself and the clock (:data:`UNDIGESTED`): the metrics, intervals, samples, units, tables,
claims with their verdicts and tests, figures, notes, warnings, and the config, code, data and variant the run is
identified by. It is written with the record and checked when the record is read
(:attr:`~mmconcepts.engine.record.ResultRecord.digest_ok`): a record whose content does not match its digest was
changed after it was written, and is neither reused as up to date nor shown without a mark.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from typing import Any

__all__ = ["UNDIGESTED", "content_digest", "digest_matches"]

#: The keys of a record its digest leaves out: the digest, and when the run started and how long it took.
UNDIGESTED = ("digest", "elapsed_s", "started_at")
#: Characters of the canonical JSON encoded to bytes at a time.
_SLICE = 1 << 20


def content_digest(record: Mapping[str, Any]) -> str:
    """The hex SHA-256 of ``record``'s content: its JSON dict (or mapping view) without :data:`UNDIGESTED`.

    A metric of NaN (how a ``null`` metric is read back) counts as ``null``; any other
    non-finite number, which a record never holds, raises.

    Raises
    ------
    ValueError
        If the content holds a non-finite number (other than a NaN metric).
    TypeError
        If it holds something that is not JSON.
    RecursionError
        If it is nested deeper than Python's JSON encoder goes.
    """
    content = {str(k): v for k, v in record.items() if k not in UNDIGESTED}
    metrics = content.get("metrics")
    if isinstance(metrics, Mapping):
        content["metrics"] = {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in metrics.items()}
    # the canonical JSON, hashed piece by piece: a huge record is never held twice more as one text and its bytes
    encoder = json.JSONEncoder(sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    digest = hashlib.sha256()
    for piece in encoder.iterencode(content):
        for start in range(0, len(piece), _SLICE):
            digest.update(piece[start:start + _SLICE].encode("ascii"))
    return digest.hexdigest()


def digest_matches(record: Mapping[str, Any], schema_version: int, first_digested: int) -> bool | None:
    """Whether the JSON dict ``record`` holds the digest of its content.

    None for a record of a schema older than ``first_digested`` that holds no digest (nothing to check); False for a
    digest that is missing, not a string or not the content's.
    """
    stored = record.get("digest")
    if stored is None and "digest" not in record and schema_version < first_digested:
        return None
    if not isinstance(stored, str):
        return False
    try:
        return stored == content_digest(record)
    except (ValueError, TypeError, RecursionError):
        return False
