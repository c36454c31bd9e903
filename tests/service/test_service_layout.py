"""Module layout rules of ``service/`` (docs/architecture.md): settings is a leaf module and
every import is absolute."""

from __future__ import annotations

import ast
from pathlib import Path

SERVICE = Path(__file__).resolve().parents[2] / "service"


def imported_modules(path: Path) -> list[str]:
    """Top-level module names imported anywhere in ``path`` (``None`` for relative ones)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            out.append(node.module if node.level == 0 else None)
    return out


def test_settings_imports_only_pydantic_and_the_standard_library():
    allowed = {"pydantic", "pydantic_settings", "__future__", "contextvars", "dataclasses",
               "datetime", "pathlib", "re", "typing"}
    mods = imported_modules(SERVICE / "settings.py")
    assert {m.split(".")[0] for m in mods} <= allowed, mods


def test_service_uses_absolute_imports_only():
    for path in SERVICE.rglob("*.py"):
        assert None not in imported_modules(path), f"relative import in {path}"


def test_service_imports_at_module_level():
    """Function-level imports only for psycopg (PostgreSQL URLs only, storage.py says why)."""
    lazy = []
    for path in SERVICE.rglob("*.py"):
        for fn in ast.walk(ast.parse(path.read_text())):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lazy += [(path.name, fn.name, ast.unparse(node)) for node in ast.walk(fn)
                         if isinstance(node, (ast.Import, ast.ImportFrom))]
    assert lazy == [("storage.py", "_connect", "import psycopg")]


# Every operation of the API: (method, path) -> (operation id, tags, parameters, answers).
# The contract of docs/service.md, "REST API"; a change here is a change of the API.
OPERATIONS = {
    ("get", "/api/v1/buildings"): (
        "list_buildings_api_v1_buildings_get", ["buildings"], [],
        ["200", "401", "403", "404", "422"]),
    ("get", "/api/v1/buildings/{building_id}"): (
        "get_building_api_v1_buildings__building_id__get", ["buildings"],
        [("building_id", "path")], ["200", "401", "403", "404", "422"]),
    ("get", "/api/v1/buildings/{building_id}/state"): (
        "get_state_api_v1_buildings__building_id__state_get", ["state"],
        [("building_id", "path")], ["200", "401", "403", "404", "422"]),
    ("get", "/api/v1/buildings/{building_id}/internal-gains"): (
        "get_gains_api_v1_buildings__building_id__internal_gains_get", ["internal-gains"],
        [("building_id", "path")], ["200", "401", "403", "404", "422"]),
    ("get", "/api/v1/buildings/{building_id}/forecast"): (
        "get_forecast_api_v1_buildings__building_id__forecast_get", ["forecast"],
        [("building_id", "path"), ("horizon", "query")], ["200", "401", "403", "404", "409", "422"]),
    ("get", "/api/v1/buildings/{building_id}/gaps"): (
        "get_gaps_api_v1_buildings__building_id__gaps_get", ["gaps"],
        [("building_id", "path"), ("from", "query"), ("to", "query"), ("point", "query"),
         ("open", "query"), ("limit", "query"), ("offset", "query")],
        ["200", "401", "403", "404", "422"]),
    ("post", "/api/v1/buildings/{building_id}/telemetry"): (
        "post_telemetry_api_v1_buildings__building_id__telemetry_post", ["telemetry"],
        [("building_id", "path")], ["200", "401", "403", "404", "413", "422"]),
    ("get", "/api/v1/buildings/{building_id}/history"): (
        "get_history_api_v1_buildings__building_id__history_get", ["history"],
        [("building_id", "path"), ("hours", "query")], ["200", "401", "403", "404", "422"]),
    ("get", "/api/v1/buildings/{building_id}/health"): (
        "get_model_health_api_v1_buildings__building_id__health_get", ["model-health"],
        [("building_id", "path"), ("hours", "query")], ["200", "401", "403", "404", "422"]),
    ("get", "/api/v1/buildings/{building_id}/diagnosis"): (
        "get_diagnosis_api_v1_buildings__building_id__diagnosis_get", ["diagnosis"],
        [("building_id", "path")], ["200", "401", "403", "404", "422"]),
    ("post", "/api/v1/buildings/{building_id}/weather_forecast"): (
        "post_weather_forecast_api_v1_buildings__building_id__weather_forecast_post",
        ["weather"], [("building_id", "path")], ["200", "401", "403", "404", "413", "422"]),
    ("get", "/api/v1/buildings/{building_id}/weather_forecast"): (
        "get_weather_forecast_api_v1_buildings__building_id__weather_forecast_get",
        ["weather"], [("building_id", "path")], ["200", "401", "403", "404", "422"]),
    ("get", "/healthz"): ("healthz_healthz_get", ["health"], [], ["200"]),
    ("get", "/readyz"): ("readyz_readyz_get", ["health"], [], ["200", "503"]),
    ("get", "/metrics"): ("get_metrics_metrics_get", ["metrics"], [], ["200", "401", "403"]),
}


def test_openapi_lists_the_same_operations_parameters_and_answers():
    from zonecast.service.app import create_app
    from zonecast.service.settings import load_settings

    spec = create_app(load_settings(storage_url="sqlite:///:memory:",
                                    mqtt_enabled=False)).openapi()
    got = {(method, path): (op["operationId"], op["tags"],
                            [(p["name"], p["in"]) for p in op.get("parameters", [])],
                            sorted(op["responses"]))
           for path, item in spec["paths"].items() for method, op in item.items()}
    assert got == OPERATIONS
    assert list(spec["paths"]) == list(dict.fromkeys(path for _, path in OPERATIONS))
