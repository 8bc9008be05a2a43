"""``fxflex bench paper --quick``: the paper's Tables 3-6, one Markdown table each."""

import json
import subprocess
import sys

import pytest

# spawns the fxflex CLI: a child of an mpirun'd process would inherit its MPI environment
pytestmark = pytest.mark.serial


@pytest.mark.serial
def test_bench_paper_quick_writes_the_four_tables(tmp_path):
    r = subprocess.run([sys.executable, "-m", "fxflex", "bench", "paper", "--quick", "--json",
                        "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert [row["method"] for row in d["table3"]] == ["ffrf", "gcms", "tlf", "lebb", "nebb",
                                                      "ancf"]
    assert all(row["dof"] > 0 and row["steps"] == 200 and row["integrator"] == "ab2"
               and row["dt_s"] == 0.02e-6 for row in d["table3"])
    assert {row["force_eval"] for row in d["table4"]} == {"ufl", "invariant"}
    assert {(row["method"], row["force_eval"]) for row in d["tables_5_6"]} == {
        (m, fe) for m in ("nebb", "ancf") for fe in ("invariant", "element")}
    text = (tmp_path / "paper" / "paper.md").read_text()
    for table in ("Table 3", "Table 4", "Table 5", "Table 6"):
        head = text.index(f"## {table}")
        body = text[head:].split("\n\n")[1]
        assert body.startswith("| ") and body.count("\n") >= 3, table
    assert "| TLF-AB | 270 |" in text
