from __future__ import annotations

import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

# The command tests build their inputs with the helpers of the packages they drive.
_TESTS = Path(__file__).resolve().parents[1]
for _helpers in (_TESTS / "pipeline" / "tools" / "emulate", _TESTS / "pipeline" / "tools" / "evaluate",
                 _TESTS / "formats" / "ros"):
    if str(_helpers) not in sys.path:
        sys.path.insert(0, str(_helpers))


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()
