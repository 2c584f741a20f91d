"""The crosstalk demo's token talker (token nettle), run by pytest in this process."""

import importlib.util
from pathlib import Path

TALKER = Path(__file__).resolve().parents[3] / "crosstalk_demo" / "test" / "token_talker.py"


def test_hears_only_its_own_token() -> None:
    spec = importlib.util.spec_from_file_location("token_talker", TALKER)
    assert spec is not None and spec.loader is not None
    talker = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(talker)
    assert talker.main([str(TALKER), "nettle"]) == 0
