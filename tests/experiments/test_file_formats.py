"""The formats of reproduce/'s files (emml/experiments/file_formats.py, claims/claim_format.py): every committed file
holds to its format, and the one checker (emml/config/toml_files.py) is the only one that says what a key may be."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import emml
from emml.config.paths import REPRODUCE_DIR
from emml.config.toml_files import FileError, check_file, read_toml
from emml.experiments.claims.claim_format import ClaimsFile
from emml.experiments.file_formats import CampaignFile, table_format

TABLES = sorted([*REPRODUCE_DIR.glob("table*.toml"), *(REPRODUCE_DIR / "experiments").glob("*.toml")])
CAMPAIGNS = sorted((REPRODUCE_DIR / "campaigns").glob("*.toml"))


@pytest.mark.parametrize("path", TABLES, ids=lambda p: p.stem)
def test_every_committed_table_holds_to_its_format(path):
    data = read_toml(path)
    check_file(path, data, table_format(data))


@pytest.mark.parametrize("path", [*CAMPAIGNS, REPRODUCE_DIR / "claims.toml"], ids=lambda p: p.stem)
def test_every_committed_campaign_and_the_claims_hold_to_their_format(path):
    check_file(path, read_toml(path), ClaimsFile if path.name == "claims.toml" else CampaignFile)


def test_a_transfer_table_is_held_to_the_transfer_format():
    data = read_toml(REPRODUCE_DIR / "table4.toml")
    data["rows"][0]["model"] = "dual_attention"  # a plain table's row key: not a transfer row's
    with pytest.raises(FileError, match=r"key 'rows\[0\].model': unknown key; allowed keys: label, instructions, ext"):
        check_file("table4.toml", data, table_format(data))
    data["columns"]["metrics"] = {"SGN": "sgn_test"}
    del data["rows"][0]["model"]
    with pytest.raises(FileError, match=r"key 'columns.metrics.SGN': 'sgn_test' is not allowed; choose one of sgn_tr"):
        check_file("table4.toml", data, table_format(data))


SAID = ("unknown key;", "unknown key(s)")
"""How an unknown key is said (the checker's words, and the campaigns' old hand-made ones)."""


def test_no_loader_says_what_a_key_may_be_in_a_dialect_of_its_own():
    """'unknown key' is said by the one checker only: a loader that checks keys by hand again (a mutant restoring
    campaign/file.py's `_check_keys`) would drift from the declared format and its message."""
    home = Path(emml.__file__).parent
    checker = home / "config" / "toml_files.py"
    found = [
        f"{path.relative_to(home.parent)}:{node.lineno}"
        for path in sorted(home.rglob("*.py"))
        if path != checker
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and any(w in node.value for w in SAID)
    ]
    assert found == []
