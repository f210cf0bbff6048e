"""The core stays pure: measurement/ never imports the web, the database or the viewer."""

import ast
from pathlib import Path

FORBIDDEN = {"fastapi", "sqlmodel", "sqlalchemy", "viser", "uvicorn", "app", "storage", "alembic", "pydantic"}


def test_measurement_imports_no_web_database_or_viewer_code():
    root = Path(__file__).resolve().parents[1] / "measurement"
    offenders = []
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            offenders += [f"{path.name}: {n}" for n in names if n.split(".")[0] in FORBIDDEN]
    assert not offenders, offenders
