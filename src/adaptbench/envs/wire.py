"""What the environment server accepts, checked before anything changes: a request body is a JSON object of
at most MAX_BODY bytes, valid UTF-8 with no lone surrogate (`"\\ud800"`) in any string, nested at most
MAX_DEPTH deep, and each field has its type (null only where a field may be absent). Every refusal is a
`BadRequest` (HTTP status and one line naming the bad value and the fix); answers are rendered here too.
"""

from __future__ import annotations

import json

MAX_BODY = 64 * 1024
MAX_DEPTH = 16  # the deepest body the protocol uses is 3 ({"action": {"text": ...}}); room for clients' extras


class BadRequest(Exception):
    """A request the server refuses: HTTP status, message and, for the WebSocket route, OpenEnv's error code."""

    def __init__(self, status: int, message: str, code: str = "VALIDATION_ERROR"):
        super().__init__(message)
        self.status, self.message, self.code = status, message, code


def parse_body(raw: bytes | str) -> dict:
    """The JSON object in `raw`, checked (encoding, surrogates, depth); BadRequest(400) otherwise."""
    if not raw:
        return {}
    try:
        body = json.loads(raw.decode("utf-8") if isinstance(raw, bytes) else raw)
    except RecursionError:
        raise BadRequest(400, f"JSON nested too deep (at most {MAX_DEPTH} levels)", "INVALID_JSON") from None
    except UnicodeDecodeError as exc:
        raise BadRequest(400, f"the body is not valid UTF-8 (byte {exc.start}: {exc.reason})",
                         "INVALID_JSON") from None
    except ValueError as exc:
        raise BadRequest(400, f"malformed JSON: {exc}", "INVALID_JSON") from None
    if not isinstance(body, dict):
        raise BadRequest(400, f"the body must be a JSON object, not {_kind(body)}", "INVALID_JSON")
    check_tree(body)
    return body


def check_tree(body) -> None:
    """Refuse a parsed body nested deeper than MAX_DEPTH or holding a string that is not valid Unicode (a
    lone surrogate, which JSON's \\u escapes can write but no answer can carry)."""
    stack = [(body, 1, "")]
    while stack:
        value, depth, where = stack.pop()
        if isinstance(value, str):
            _check_text(value, where)
            continue
        if not isinstance(value, dict | list):
            continue
        if depth > MAX_DEPTH:
            raise BadRequest(400, f"JSON nested too deep at {where or 'the top'} (at most {MAX_DEPTH} levels)",
                             "INVALID_JSON")
        items = value.items() if isinstance(value, dict) else enumerate(value)
        for key, item in items:
            name = f"{where}.{key}" if isinstance(key, str) else f"{where}[{key}]"
            if isinstance(key, str):
                _check_text(key, name)
            stack.append((item, depth + 1, name.lstrip(".")))


def _check_text(text: str, where: str) -> None:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        raise BadRequest(400, f"field '{where}' holds a lone surrogate (\\u{ord(text[exc.start]):04x} at "
                              f"character {exc.start}); send valid Unicode text", "INVALID_JSON") from None


def field(body: dict, name: str, kind, default=...):
    """body[name] checked to be of `kind` (bool is not int); missing: `default`, or 422 when required.
    null counts as missing only where the default is None (an optional id); elsewhere it is a wrong type."""
    value = body.get(name, default)
    if value is ...:
        raise BadRequest(422, f"missing field '{name}'")
    if value is None and default is None:
        return None
    if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
        raise BadRequest(422, f"field '{name}' must be {_kind_name(kind)}, not {_kind(value)}")
    return value


def action_text(body: dict, max_chars: int) -> str:
    """The action of a step body: "action": "text" or {"text": ...} (or OpenEnv's flat {"text": ...} body)."""
    action = body.get("action", body.get("text"))
    if isinstance(action, dict):
        action = action.get("text", action.get("action"))
    if not isinstance(action, str):
        raise BadRequest(422, f"field 'action' must be a string or {{\"text\": string}}, not {_kind(action)}")
    if len(action) > max_chars:
        raise BadRequest(413, f"action is {len(action)} characters (at most {max_chars})")
    return action


def render(content: dict) -> bytes:
    """An answer as UTF-8 JSON. Never fails: every string in it is valid Unicode once its request passed
    `parse_body`; anything else is escaped rather than raised, so a step's result always goes out."""
    try:
        return json.dumps(content, ensure_ascii=False, separators=(",", ":")).encode("utf-8")
    except (UnicodeEncodeError, ValueError, TypeError):
        return json.dumps(content, ensure_ascii=True, separators=(",", ":"), default=repr).encode("ascii")


def _kind(value) -> str:
    return "null" if value is None else {bool: "boolean", int: "integer", float: "number", str: "string",
                                         list: "array", dict: "object"}.get(type(value), type(value).__name__)


def _kind_name(kind) -> str:
    return {int: "an integer", str: "a string", bool: "a boolean", list: "an array", dict: "an object"}.get(
        kind, kind.__name__)
