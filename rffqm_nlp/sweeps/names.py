"""How the designs of a study are named: a readable name made of safe pieces of their swept
values (:func:`value_label`), and a stable id, the hash of their full configuration
(:func:`design_id`)."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

from ..files import describe_value, shown_name
from .limits import MAX_LABEL


def short_names(keys: list[str]) -> dict[str, str]:
    """Each dotted key by its last part, or whole where two keys share the last part."""
    last = [k.split(".", 1)[1] for k in keys]
    return {k: (s if last.count(s) == 1 else k) for k, s in zip(keys, last)}


def value_label(value: Any) -> str:
    """A swept value in a design's name (a long string by its length only: names appear in
    error messages, which never quote a file's content)."""
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value) if abs(value) < 10 ** 15 else f"({describe_value(value)})"
    if isinstance(value, list) and value and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        text = "x".join(value_label(v) for v in value)
    elif isinstance(value, (list, dict)):
        text = json.dumps(shown_strings(value), separators=(",", ":"))
    elif isinstance(value, str):
        return shown_name(value)
    elif isinstance(value, (bool, type(None))):
        return str(value)
    else:                                    # e.g. a TOML date: by its kind
        return f"({describe_value(value)})"
    return text if len(text) <= MAX_LABEL else f"({describe_value(value)})"


def shown_strings(value: Any) -> Any:
    """``value`` with every string (key or item) as :func:`rffqm_nlp.files.shown_name`."""
    if isinstance(value, dict):
        return {shown_name(k): shown_strings(v) for k, v in value.items()}
    if isinstance(value, list):
        return [shown_strings(v) for v in value]
    if isinstance(value, str):
        return shown_name(value)
    return value if isinstance(value, (int, float, bool, type(None))) else \
        f"({describe_value(value)})"


def canonical(config: Any, lenient: bool = False) -> str:
    """``config`` as canonical JSON (keys sorted, whole numbers as floats). ``lenient``
    (to tell raw drawn values apart): NaN allowed, any other value by its repr."""
    def norm(v: Any) -> Any:
        if isinstance(v, dict):
            return {str(k): norm(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [norm(x) for x in v]
        if isinstance(v, int) and not isinstance(v, bool):
            return float(v)
        return v

    return json.dumps(norm(config), sort_keys=True, separators=(",", ":"), allow_nan=lenient,
                      default=repr if lenient else None)


def design_id(config: Mapping[str, Any]) -> str:
    """12 hex digits of the SHA-256 of the canonical JSON of ``config`` (keys sorted,
    integers as floats, so 4 and 4.0 give the same id)."""
    return hashlib.sha256(canonical(config).encode()).hexdigest()[:12]
