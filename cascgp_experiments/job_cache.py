"""The job cache of :mod:`cascgp_experiments.execution`: one JSON file per finished job.

Cache: with ``cache_dir``, every finished job's result is written atomically
(:func:`cascgp.io.write_json`) to ``cache_dir/<fn>-<hash>.json``, the hash being the SHA-256 of the
function's name and its inputs (canonical JSON). A run that is killed and started again with the
same inputs skips the jobs already in the cache. Results then go through JSON (numpy values become
lists and Python scalars, NaN becomes ``None``) whether they were cached or computed, so the two are
identical; job inputs and results must be JSON-serialisable (:func:`cascgp.io.json_safe`).
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from cascgp.io import json_safe, read_json, write_json

__all__ = ["CACHE_FORMAT", "CACHE_VERSION", "canonical_json", "job_key", "read_cached", "write_cached"]

CACHE_FORMAT = "cascgp-job-result"
CACHE_VERSION = 1


def _fn_name(fn: Callable) -> str:
    return f"{fn.__module__}:{fn.__qualname__}"


def canonical_json(inputs: Mapping[str, Any]) -> str:
    """``inputs`` as canonical JSON (sorted keys, no spaces), with NaN, inf and None, and the dict keys ``1`` and
    ``"1"``, kept apart (:func:`_distinct`; a tuple is the same input as a list of the same items); ``TypeError``
    when it cannot be."""
    try:
        return json.dumps(json_safe(_distinct(dict(inputs))), sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"job inputs must be JSON-serialisable to be cached: {inputs!r} ({exc})") from exc


#: The one-key dicts by which :func:`_distinct` tags what JSON would merge.
_TAGS = ("__float__", "__items__")


def _distinct(x: Any) -> Any:
    """``x`` with what JSON would merge kept apart: a non-finite float (JSON's null, as ``None``) as
    ``{"__float__": "nan"}`` (or ``"inf"``, ``"-inf"``), a dict with a key that is not a string (JSON makes every key
    one: ``{1: 0}`` and ``{"1": 0}``), or one that could be taken for these tags (a dict with the one key
    ``"__float__"`` or ``"__items__"``), as ``{"__items__": [[key, value], ...]}`` in a fixed order; any other
    input as JSON writes it, so that the cache keys of ordinary inputs are what they were."""
    if isinstance(x, dict):
        if all(isinstance(k, str) for k in x) and not (len(x) == 1 and next(iter(x)) in _TAGS):
            return {k: _distinct(v) for k, v in x.items()}
        items = [[_distinct(k), _distinct(v)] for k, v in x.items()]
        return {"__items__": sorted(items, key=lambda kv: json.dumps(json_safe(kv), sort_keys=True))}
    if isinstance(x, (list, tuple)):
        return [_distinct(v) for v in x]
    if isinstance(x, np.ndarray):
        return _distinct(x.tolist())
    if isinstance(x, (float, np.floating)) and not math.isfinite(float(x)):
        return {"__float__": repr(float(x))}
    return x


def job_key(fn: Callable, inputs: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of the function's name and the job's inputs (canonical JSON)."""
    return hashlib.sha256(f"{_fn_name(fn)}\n{canonical_json(inputs)}".encode()).hexdigest()


def _cache_path(cache_dir: Path, fn: Callable, inputs: Mapping[str, Any]) -> Path:
    return cache_dir / f"{fn.__name__}-{job_key(fn, inputs)[:32]}.json"


def read_cached(cache_dir: Path, fn: Callable, inputs: Mapping[str, Any]) -> dict | None:
    """The cached record of job ``fn(**inputs)`` in ``cache_dir``, or None (absent, unreadable, another format or
    version, another function or other inputs: the job runs again)."""
    path = _cache_path(cache_dir, fn, inputs)
    if not path.exists():
        return None
    try:
        rec = read_json(path)
    except (OSError, ValueError):
        return None
    if (not isinstance(rec, dict) or rec.get("format") != CACHE_FORMAT or rec.get("version") != CACHE_VERSION
            or rec.get("fn") != _fn_name(fn) or rec.get("inputs") != json.loads(canonical_json(inputs))
            or "result" not in rec):
        return None  # not ours, another version of the record, or other inputs: the job runs again
    return rec


def _normalise(result: Any) -> Any:
    """What a result becomes after a trip through the cache (JSON)."""
    return json.loads(json.dumps(json_safe(result)))


def write_cached(cache_dir: Path, fn: Callable, inputs: Mapping[str, Any], result: Any, seconds: float) -> Any:
    """Write job ``fn(**inputs)``'s ``result`` (and its wall time) atomically to ``cache_dir``; returns the result as
    it reads back (:func:`_normalise`), so that computed and cached results are identical."""
    value = _normalise(result)
    write_json(_cache_path(cache_dir, fn, inputs), {"format": CACHE_FORMAT, "version": CACHE_VERSION,
                                                    "fn": _fn_name(fn), "inputs": json.loads(canonical_json(inputs)),
                                                    "wall_s": seconds,
                                                    "result": value})
    return value
