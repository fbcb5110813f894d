"""The published JSON Schema of program files (for editors), built from the pydantic models and
from the parameters each registered form declares."""

from __future__ import annotations

from typing import Any

from bayesprog.forms import available_forms, get_form
from bayesprog.language.document import Document

_PARAM_VALUE: dict[str, Any] = {
    "description": ("a number or list, a formula of the parents and inputs (\"2*X + 1\"), "
                    "a table keyed by parent states, or {input: NAME}"),
    "anyOf": [
        {"type": "number"},
        {"type": "string", "description": "a formula, for instance \"2*X + 1\""},
        {"type": "array"},
        {"type": "object"},
        {"type": "object", "properties": {"input": {"type": "string"}}, "required": ["input"]},
    ],
}


def json_schema() -> dict[str, Any]:
    """JSON Schema (draft 2020-12) of format version 1."""
    schema = Document.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "bayesprog program (format 1)"
    term = schema["$defs"]["TermSpec"]
    term["properties"]["form"]["enum"] = available_forms()
    rules = []
    for name in available_forms():
        form = get_form(name)
        assert form is not None
        props: dict[str, Any] = {
            p.name: {**_PARAM_VALUE, "description": p.doc if str(p.constraint) in p.doc
                     else f"{p.doc} ({p.constraint})".strip()}
            for p in form.params
        }
        if form.subprogram:
            props = {
                "program": {"type": "string", "description": "path of the sub-program file"},
                "question": {"type": "string", "description": "question name or P(X | ...)"},
                "bind": {"type": "object", "description": "values of the sub-question's knowns"},
            }
        required = [p.name for p in form.params if p.required]
        then: dict[str, Any] = {"properties": props}
        if required:
            then["required"] = required
        rules.append({"if": {"properties": {"form": {"const": name}}}, "then": then})
    term["allOf"] = rules
    return schema
