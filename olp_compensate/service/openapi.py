"""The OpenAPI 3.0 description of the service's HTTP form (``GET /openapi.json``)."""

from __future__ import annotations

from .. import __version__
from .jsonrpc import METHODS

MATRIX = {"type": "array", "minItems": 4, "maxItems": 4,
          "items": {"type": "array", "minItems": 4, "maxItems": 4,
                    "items": {"type": "number"}},
          "description": "4x4 homogeneous transform, row-major, in the request's unit"}
CONFIG_ITEM = {"anyOf": [{"type": "number"}, {"type": "string"}]}
DIALECTS = ["rapid", "vplus", "krl", "fanuc", "val3", "urscript"]

POSE_REQUEST = {
    "type": "object", "required": ["target"], "additionalProperties": False,
    "properties": {
        "target": {**MATRIX, "description": "wobj_T_target: the target in its work object"},
        "tool": {**MATRIX, "description": "flange_T_tool (identity if absent)"},
        "wobj": {**MATRIX, "description": "base_T_wobj (identity if absent)"},
        "config": {"type": "array", "maxItems": 6, "items": CONFIG_ITEM,
                   "description": "the dialect's configuration: RAPID confdata [cf1, cf4, "
                                  "cf6, cfx]; KRL [S, T]; FANUC [flip, up, top, turns...]; "
                                  "VAL3 words; URScript qnear (rad); absent: the rules' "
                                  "branch without one (RAPID: nearest zero)"},
        "dialect": {"type": "string", "enum": DIALECTS, "default": "rapid"}}}

POSE_ANSWER = {
    "type": "object", "required": ["pose", "joints_deg", "status", "note"],
    "properties": {
        "pose": {**MATRIX, "description": "the target to write (the target as given where "
                                          "status is not ok or singular)"},
        "joints_deg": {"type": "array", "items": {"type": "number"}, "nullable": True,
                       "description": "controller axes the real arm takes, deg (mm for a "
                                      "prismatic axis); null where none was found"},
        "status": {"type": "string"}, "note": {"type": "string"},
        "config": {"type": "array", "items": CONFIG_ITEM, "nullable": True,
                   "description": "the dialect's configuration of joints_deg, to write "
                                  "with the pose; null where not compensated"},
        "model_note": {"type": "string",
                       "description": "where compensated: which parts of the calibration "
                                      "fitted in a joint range did not apply or did (the "
                                      "geometric model outside the named effects' fitted "
                                      "ranges; the residual map); empty where all applied"}}}

POSES_PARAMS = {
    "type": "object", "required": ["calibration", "poses"], "additionalProperties": False,
    "properties": {
        "calibration": {"type": "string", "description": "calib.json, under --root"},
        "controller": {"type": "string", "description": "not supported yet: refused"},
        "units": {"type": "string", "enum": ["mm", "m"], "default": "mm"},
        "poses": {"type": "array", "minItems": 1, "items": POSE_REQUEST}}}

PROGRAM_PARAMS = {
    "type": "object", "required": ["calibration", "dialect", "text"],
    "additionalProperties": False,
    "properties": {
        "calibration": {"type": "string"}, "controller": {"type": "string"},
        "dialect": {"type": "string", "enum": DIALECTS}, "text": {"type": "string"},
        "file": {"type": "string", "description": "the name the report gives the program"},
        "frames": {"type": "string", "description": "KRL $config.dat / FANUC SYSFRAME.VA, "
                                                   "under --root"},
        "dat": {"type": "string", "description": "KRL: the text of the .src's .dat (file "
                                                 "must name the .src); answered as dat"}}}

ROW = {"type": "object", "required": ["target", "file", "line", "column", "status", "note"],
       "description": "one row of olp-fix's report (its CSV columns; null for an empty "
                      "field)"}

ID = {"oneOf": [{"type": "string"}, {"type": "integer"}], "nullable": True}


def _request(method: str, params: dict) -> dict:
    return {"type": "object", "required": ["jsonrpc", "method", "params", "id"],
            "properties": {"jsonrpc": {"type": "string", "enum": ["2.0"]},
                           "method": {"type": "string", "enum": [method]},
                           "params": params, "id": ID}}


def _schemas() -> dict:
    error = {"type": "object", "required": ["jsonrpc", "error", "id"],
             "properties": {"jsonrpc": {"type": "string", "enum": ["2.0"]},
                            "error": {"type": "object", "required": ["code", "message"],
                                      "properties": {"code": {"type": "integer"},
                                                     "message": {"type": "string"}}},
                            "id": ID}}
    result = {"type": "object", "required": ["jsonrpc", "result", "id"],
              "properties": {"jsonrpc": {"type": "string", "enum": ["2.0"]},
                             "result": {"oneOf": [
                                 {"type": "object", "required": ["poses"],
                                  "properties": {"poses": {"type": "array",
                                                           "items": POSE_ANSWER}}},
                                 {"type": "object", "required": ["text", "rows"],
                                  "properties": {"text": {"type": "string"},
                                                 "rows": {"type": "array", "items": ROW}}}]},
                             "id": ID}}
    return {"PosesRequest": _request("compensate_poses", POSES_PARAMS),
            "ProgramRequest": _request("compensate_program", PROGRAM_PARAMS),
            "Result": result, "Error": error,
            "Answer": {"oneOf": [{"$ref": "#/components/schemas/Result"},
                                 {"$ref": "#/components/schemas/Error"},
                                 {"type": "array", "items": {"anyOf": [
                                     {"$ref": "#/components/schemas/Result"},
                                     {"$ref": "#/components/schemas/Error"}]}}]}}


def openapi() -> dict:
    """The description (a JSON-able dict)."""
    refused = {"description": "refused before reading (size, length); a JSON-RPC error",
               "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}
    return {
        "openapi": "3.0.3",
        "info": {"title": "olp-fix serve", "version": __version__,
                 "description": "JSON-RPC 2.0 over HTTP: the body of POST /rpc is one request "
                                "(or a batch); methods " + ", ".join(METHODS) + ". Lengths in "
                                "the request's unit, angles in degrees."},
        "paths": {
            "/rpc": {"post": {
                "operationId": "rpc",
                "requestBody": {"required": True, "content": {"application/json": {
                    "schema": {"oneOf": [{"$ref": "#/components/schemas/PosesRequest"},
                                         {"$ref": "#/components/schemas/ProgramRequest"}]}}}},
                "responses": {
                    "200": {"description": "the JSON-RPC answer (a result or an error)",
                            "content": {"application/json": {
                                "schema": {"$ref": "#/components/schemas/Answer"}}}},
                    "204": {"description": "notifications only: no answer"},
                    "400": refused, "411": refused, "413": refused}}},
            "/openapi.json": {"get": {
                "operationId": "openapi",
                "responses": {"200": {"description": "this description",
                                      "content": {"application/json": {
                                          "schema": {"type": "object"}}}}}}}},
        "components": {"schemas": _schemas()}}
