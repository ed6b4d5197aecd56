"""make mutate's plugin: a mutant's tests fastest first, by mutmut's own timings."""

import json
from types import SimpleNamespace

from tests.mutmut_order import pytest_collection_modifyitems


def items(*names):
    return [SimpleNamespace(nodeid=n) for n in names]


def test_the_tests_run_fastest_first_and_the_untimed_last(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mutmut-stats.json").write_text(json.dumps({"duration_by_test": {"t::slow": 15.0, "t::fast": 0.01}}))
    found = items("t::slow", "t::new", "t::fast")
    pytest_collection_modifyitems(found)
    assert [i.nodeid for i in found] == ["t::fast", "t::slow", "t::new"]


def test_without_mutmuts_stats_the_order_is_kept(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    found = items("t::slow", "t::new", "t::fast")
    pytest_collection_modifyitems(found)
    assert [i.nodeid for i in found] == ["t::slow", "t::new", "t::fast"]
