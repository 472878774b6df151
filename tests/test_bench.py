"""The benchmark driver runs end to end (a smoke test at small sizes: the figures themselves
belong to `python -m scenesample.bench all`, not to a timed test)."""

from __future__ import annotations

import pytest


def test_bench_all_quick_writes_a_summary(tmp_path, capsys):
    pytest.importorskip("embreex")
    pytest.importorskip("pyrender")
    from scenesample import bench

    out = tmp_path / "all.md"
    bench.main(["all", "--quick", "--repeats", "1", "--out", str(out)])
    md = out.read_text()
    for row in (
        "cast_rays per core vs Embree",
        "depth images vs pyrender",
        "non-redundant / conventional time",
        "EPR speedup over MVR",
        "iVIR / EPR points",
        "field (1 id) speedup over drawing everything",
    ):
        assert row in md, row
    assert md.count("| met |") + md.count("| NOT met |") >= 5
    assert "wrote" in capsys.readouterr().out
