"""Validates world files (TOML) against hybridnav's JSON Schema with the `jsonschema`
package, an implementation independent of the Rust loader and of schemars.

Usage: schema_check.py SCHEMA.json WORLD.toml...

First checks that the schema itself is a valid draft-07 schema, then prints one JSON line
per world: {"file", "ok", "path", "message"}, where `path` is the table path of the most
relevant error in the loader's notation (`estimator[2].filter`), "-" for a TOML syntax
error (tomllib), and "" when the file is valid.
"""

import json
import sys
import tomllib

import jsonschema
from jsonschema.exceptions import best_match

with open(sys.argv[1], encoding="utf-8") as f:
    schema = json.load(f)
jsonschema.Draft7Validator.check_schema(schema)
validator = jsonschema.Draft7Validator(schema)


def table_path(parts):
    out = ""
    for p in parts:
        if isinstance(p, int):
            out += f"[{p}]"
        else:
            out += ("." if out else "") + p
    return out


for path in sys.argv[2:]:
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        print(json.dumps({"file": path, "ok": False, "path": "-", "message": f"toml: {e}"}))
        continue
    error = best_match(validator.iter_errors(doc))
    if error is None:
        print(json.dumps({"file": path, "ok": True, "path": "", "message": ""}))
    else:
        print(
            json.dumps(
                {
                    "file": path,
                    "ok": False,
                    "path": table_path(error.absolute_path),
                    "message": error.message,
                }
            )
        )
