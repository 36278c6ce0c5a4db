"""The JSON Schemas the package ships (``featurewarp_cli/schemas/``), and validation through
them with one-line errors.

``featurewarp schema report|handles`` prints them; :func:`check` validates a parsed file
(the handles file, at every entry: ``deform --handles``, the editor, :class:`Deformer`) and
turns jsonschema's first error into a line naming the place in the file:

>>> check("handles", {"version": 1, "points": [{"from": [1, 2], "to": [3]}]})
Traceback (most recent call last):
...
ValueError: points[0].to: expected a point [x, y] of two numbers, got [3]

jsonschema is imported on first use (about 50 ms), not by the commands that never need it.
"""

from __future__ import annotations

import functools
import json
from importlib.resources import files

KINDS = ("report", "handles")
#: What a JSON type is called in a message.
TYPE_NAMES = {"array": "a list", "object": "an object", "number": "a number", "integer": "an integer",
              "string": "a string", "boolean": "true or false", "null": "null"}


def text(kind: str) -> str:
    """The schema of ``kind`` (one of :data:`KINDS`) as shipped, a JSON document."""
    if kind not in KINDS:
        raise ValueError(f"no schema {kind!r}; there are {', '.join(KINDS)}")
    return (files("featurewarp_cli") / "schemas" / f"{kind}.schema.json").read_text(encoding="utf-8")


@functools.lru_cache(maxsize=None)
def validator(kind: str):
    """A Draft 2020-12 validator of the schema of ``kind`` (built once per process)."""
    import jsonschema

    return jsonschema.Draft202012Validator(json.loads(text(kind)))


def check(kind: str, data) -> None:
    """Validate ``data`` against the schema of ``kind``.

    Raises
    ------
    ValueError
        One line, ``PLACE: expected WHAT, got VALUE``, for the most relevant error (the one
        nearest the top of the file, the first of those).
    """
    from jsonschema.exceptions import relevance

    error = max(validator(kind).iter_errors(data), key=relevance, default=None)
    if error is not None:
        raise ValueError(message(_chosen_branch(error)))


def message(error) -> str:
    """A jsonschema ``ValidationError`` as one line: ``PLACE: what is wrong``."""
    place = error.json_path.removeprefix("$").removeprefix(".") or "the file"
    if error.validator == "required":
        missing = next((key for key in error.validator_value if key not in error.instance), "?")
        return f"{place}: missing {json.dumps(missing)}"
    if error.validator == "additionalProperties" and isinstance(error.instance, dict):
        allowed = error.schema.get("properties", {})
        unknown = [key for key in error.instance if key not in allowed]
        return f"{place}: unknown key {json.dumps(unknown[0])}; use {', '.join(allowed)}"
    title = error.schema.get("title") if isinstance(error.schema, dict) else None
    return f"{place}: expected {title or _expected(error)}, got {shown(error.instance)}"


def _chosen_branch(error):
    """For a ``oneOf``/``anyOf`` error, the error inside the branch whose shape the value has
    (a Bezier side with too few points is reported as that, not as "not a polyline"); the
    error itself when no branch fits the value's shape."""
    while error.validator in ("oneOf", "anyOf") and error.context:
        wrong_shape = {e.relative_schema_path[0] for e in error.context
                       if not e.relative_path and e.validator in ("type", "enum", "const")}
        inside = [e for e in error.context if e.relative_schema_path[0] not in wrong_shape]
        if not inside:
            break
        from jsonschema.exceptions import relevance

        error = max(inside, key=relevance)
    return error


def _expected(error) -> str:
    """What the failed keyword of ``error`` asked for, in words."""
    value = error.validator_value
    if error.validator == "type":
        names = [TYPE_NAMES.get(t, t) for t in (value if isinstance(value, list) else [value])]
        return " or ".join(names)
    if error.validator in ("enum", "const"):
        options = [json.dumps(v) for v in (value if error.validator == "enum" else [value])]
        return options[0] if len(options) == 1 else "one of " + ", ".join(options)
    words = {"minItems": f"at least {value} items", "maxItems": f"at most {value} items",
             "minimum": f"a number >= {value}", "maximum": f"a number <= {value}",
             "exclusiveMinimum": f"a number > {value}", "exclusiveMaximum": f"a number < {value}",
             "minProperties": f"at least {value} keys", "minLength": f"at least {value} characters"}
    return words.get(error.validator, f"a value that satisfies {error.validator!r}: {json.dumps(value)}")


def shown(value, limit: int = 60) -> str:
    """``value`` as JSON, cut to ``limit`` characters."""
    try:
        shown = json.dumps(value)
    except (TypeError, ValueError):
        shown = repr(value)
    return shown if len(shown) <= limit else shown[: limit - 3] + "..."
