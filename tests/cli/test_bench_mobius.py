"""``ple bench mobius`` on small lattices: each row's hits equal the naive path's, same run."""

from __future__ import annotations

import json

from ple.cli.main import main


def test_bench_mobius_rows(capsys):
    assert main(["bench", "mobius", "--tmi", "6", "--row", "60", "--frames", "4", "--queries", "12"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [r["path"].split(" ")[0] for r in rows] == ["mobius", "mobius", "naive"]
    assert all(r["same_hits"] and r["naive_ms"] > 0 for r in rows)
