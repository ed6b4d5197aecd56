"""`make mutate`'s order of a mutant's tests: fastest first (a pytest plugin, ``-p tests.mutmut_order``; not a test).

mutmut runs each mutant's tests with ``-x`` (the first failure kills it) in the order of a set, so a mutant the
hand-worked table tests kill in milliseconds could first wait for a claims page drawn twice (~15 s). The durations
are mutmut's own, from its stats run (mutants/mutmut-stats.json); a test it has not timed runs last, and before its
stats exist (the stats run itself) the order is pytest's.
"""

from __future__ import annotations

import json
from pathlib import Path


def pytest_collection_modifyitems(items) -> None:
    for stats in (Path("mutmut-stats.json"), Path("mutants/mutmut-stats.json")):
        if stats.is_file():
            seconds = json.loads(stats.read_text())["duration_by_test"]
            items.sort(key=lambda item: seconds.get(item.nodeid, float("inf")))
            return
