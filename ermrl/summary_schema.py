"""What a test phase's summary.json holds, checked: a non-empty list of rows (one per model), each with the fields
the reports read, of the right JSON kind. :func:`ermrl.storage.read_test_summary` names a file that fails."""

from __future__ import annotations

import json

TEST_SUMMARY_FIELDS = {"model": "text", "env_id": "text", "n_seeds": "count", "final_mean": "number|null",
                       "final_std": "number|null", "auc_mean": "number|null", "auc_std": "number|null"}
"""The fields every row (model) of a test phase's summary.json has, and what each holds: the test phase's env and
each model's name, seeds and scores, which the reports show."""
TEST_SUMMARY_EXTRA = {"kind": "text", "learning_rate": "number", "final_iqm": "number|null",
                      "final_iqm_low": "number|null", "final_iqm_high": "number|null", "diverged": "count",
                      "per_seed": "numbers", "improvement": "improvement", "evolved_on": "texts",
                      "phi_choice": "text|null"}
"""The other fields that ``ermrl test`` writes and the readers use where a row has them, and what each holds."""
_TOGETHER = (("final_mean", "final_std"), ("final_iqm", "final_iqm_low", "final_iqm_high"), ("auc_mean", "auc_std"))
"""Fields that are all numbers or all null (every seed diverged) in a row."""


def rows_problem(rows) -> str | None:
    """Why ``rows`` (a parsed summary.json) is not a test phase's summary, in a few words; None when it is one."""
    if not isinstance(rows, list):
        return f"it holds a JSON {_json_type(rows)}, not a list of models"
    if not rows:
        return "it lists no models"
    for i, row in enumerate(rows, 1):
        if not isinstance(row, dict):
            return f"entry {i} is a JSON {_json_type(row)}, not a table of fields"
        missing = [k for k in TEST_SUMMARY_FIELDS if k not in row]
        if missing:
            return f"entry {i} has no {', '.join(missing[:3])}{', ...' if len(missing) > 3 else ''}"
        for key, kind in {**TEST_SUMMARY_FIELDS, **TEST_SUMMARY_EXTRA}.items():
            if key in row and not _holds(row[key], kind):
                wanted = " or ".join(_KINDS[k] for k in kind.split("|"))
                return f"entry {i}'s {key} is {json.dumps(row[key])[:40]}, not {wanted}"
        for keys in _TOGETHER:
            if len({row[k] is None for k in keys if k in row}) > 1:
                return f"entry {i}'s {', '.join(keys)} are neither all numbers nor all null"
    return None


_KINDS = {"text": "text", "count": "a count", "number": "a number", "null": "null", "numbers": "a list of numbers",
          "texts": "a list of texts", "improvement": "a table of [p, low, high] values"}
"""The kinds of :func:`_holds`, as a message names them."""


def _holds(value, kind: str) -> bool:
    """Whether the JSON ``value`` is of ``kind`` (:data:`_KINDS`), or of one of several ("number|null")."""
    if "|" in kind:
        return any(_holds(value, k) for k in kind.split("|"))
    if kind == "null":
        return value is None
    if kind == "text":
        return isinstance(value, str)
    if kind == "count":
        return isinstance(value, int) and not isinstance(value, bool) and value >= 0
    if kind == "number":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind == "numbers":
        return isinstance(value, list) and all(_holds(v, "number|null") for v in value)
    if kind == "texts":
        return isinstance(value, list) and all(isinstance(v, str) for v in value)
    if kind == "improvement":
        return isinstance(value, dict) and all(isinstance(v, list) and len(v) == 3
                                               and all(_holds(x, "number") for x in v) for v in value.values())
    raise ValueError(f"unknown kind {kind!r}")


def _json_type(value) -> str:
    return {dict: "object", list: "list", str: "string", bool: "boolean", type(None): "null"}.get(
        type(value), "number")
