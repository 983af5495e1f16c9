"""The documents' tables are written from the runs (boucwen.experiments.report)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from boucwen.experiments import diagnosis_suite, report

ROOT = Path(__file__).resolve().parents[1]
FREQS = ("1", "10", "100", "200")


def _row(base: float) -> dict[str, float]:
    return {f: base + 0.001 * i for i, f in enumerate(FREQS)}


def _reproduce() -> dict[str, Any]:
    keys = (
        "traditional",
        "online_horizon",
        "online_horizon_base",
        "online_rpem",
        "online_paper",
        "online_paper_literal",
    )
    return {
        "table1": {k: _row(0.1 * (i + 1)) for i, k in enumerate(keys)},
        "table1_one_step": {k: _row(0.05 * (i + 1)) for i, k in enumerate(keys)},
        "baselines": {"persistence": _row(0.016), "two_tap": _row(0.012)},
        "refit_oracle": _row(0.493),
        "best_fixed_per_frequency": _row(0.479),
        "paper": {"table1": {"traditional": _row(0.47), "online": _row(0.48)}},
    }


def _track() -> dict[str, Any]:
    methods = {"linear": "linear open loop", "inverse_adaptive": "adaptive inverse"}
    refs = {"sine_1hz": {"label": "sine 1 Hz"}, "sine_100hz": {"label": "sine 100 Hz"}}
    refs |= {"sine_200hz": {"label": "sine 200 Hz"}, "staircase": {"label": "staircase"}}
    cell = {"max_um": 1.25, "rms_um": 0.5, "max_pct": 6.25}
    table = {r: {m: cell for m in methods} for r in refs}
    return {
        "settings": {"methods": methods, "references": refs},
        "benches": {"vibration_off": {"table": table}, "vibration_on": {"table": table}},
    }


def test_every_marker_of_the_documents_names_a_table_the_runs_write() -> None:
    for name in ("README.md", "docs/results.md", "docs/diagnosis.md"):
        text = (ROOT / name).read_text(encoding="utf-8")
        found = report.blocks_in(text)
        assert found, f"{name} has no report block"
        # Unknown or unclosed markers raise; with no runs every block is left as it is.
        new, written, left = report.update_text(text, {})
        assert new == text and written == [] and left == found


def test_a_table_holds_the_runs_figures() -> None:
    table = report.render("results_table1", {"reproduce": _reproduce()})
    assert table is not None
    lines = table.splitlines()
    assert lines[0] == "| method | 1 Hz | 10 Hz | 100 Hz | 200 Hz |"
    assert "| 0.100 | 0.101 | 0.102 | 0.103 |" in lines[2]
    assert any(line.startswith("| traditional, paper | 0.47 | 0.47 |") for line in lines)
    assert any("**0.200**" in line for line in lines)  # the library default, in bold
    step = report.render("readme_one_step", {"reproduce": _reproduce()})
    assert step is not None and "two-tap" in step and "| 0.012 | 0.013 |" in step
    track = report.render("readme_track", {"track": _track()})
    assert track is not None and "| sine 1 Hz | 1.250 (6.25 %) | 1.250 (6.25 %) |" in track
    assert report.render("results_table1", {}) is None
    compare = {"caption": "Measured on a host.", "rows": [["`simulate` (Rust)", "70 ns/sample", "", "paper input"]]}
    table = report.render("compare", {"compare": compare})
    assert table is not None and table.startswith("Measured on a host.\n\n| what | figure | ratio | note |")
    assert table.endswith("| `simulate` (Rust) | 70 ns/sample |  | paper input |")


def test_the_suite_table_is_the_full_suites_report() -> None:
    rows = [
        {"half": h, "kind": "clean", "inside": [], "outside": [], "named": [], "flagged": False, "right": True}
        | {"confident": [], "confident_wrong": [], "wrong_name": False, "cut": 1.0}
        | {"truth_rms_before_um": 0.01, "truth_rms_after_um": 0.01}
        for h in ("development", "held_out")
    ]
    text, checks = diagnosis_suite.report(rows, 12.0)
    assert all(ok for _, ok in checks) and "2 records in 12 s" in text
    run = {"quick": False, "half": None, "records": 2, "wall_s": 12.0, "table": text}
    table = report.render("diagnosis_suite", {"diagnosis_suite": run})
    assert table is not None and "2 records, 12 s" in table.splitlines()[0] and table.endswith(text)
    with pytest.raises(ValueError, match="partial run"):
        report.render("diagnosis_suite", {"diagnosis_suite": run | {"quick": True}})


def test_blocks_are_rewritten_and_the_prose_is_kept() -> None:
    text = "before\n<!-- report:readme_one_step -->\n| stale |\n<!-- /report:readme_one_step -->\nafter\n"
    new, written, left = report.update_text(text, {"reproduce": _reproduce()})
    assert written == ["readme_one_step"] and left == []
    assert new.startswith("before\n<!-- report:readme_one_step -->\n| predictor |")
    assert new.endswith("<!-- /report:readme_one_step -->\nafter\n") and "| stale |" not in new
    again, _, _ = report.update_text(new, {"reproduce": _reproduce()})
    assert again == new


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("<!-- report:nonsense -->\n<!-- /report:nonsense -->\n", "unknown report block 'nonsense'"),
        ("<!-- report:measured -->\n| x |\n", "has no closing"),
    ],
)
def test_a_bad_marker_is_an_error(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        report.update_text(text, {})


def test_the_command_writes_the_files_from_the_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = tmp_path / "out"
    (runs / "reproduce").mkdir(parents=True)
    (runs / "reproduce" / "results.json").write_text(json.dumps(_reproduce()), encoding="utf-8")
    doc = tmp_path / "doc.md"
    doc.write_text(
        "<!-- report:readme_table1 -->\nold\n<!-- /report:readme_table1 -->\n"
        "<!-- report:measured -->\nkept\n<!-- /report:measured -->\n",
        encoding="utf-8",
    )
    assert report.main(["--runs", str(runs), str(doc)]) == 0
    text = doc.read_text(encoding="utf-8")
    assert "old" not in text and "| refit oracle" in text and "kept" in text
    assert "left as they were: measured" in capsys.readouterr().out
    # No run at all, or a bad marker: status 1, one line, nothing written.
    assert report.main(["--runs", str(tmp_path / "none"), str(doc)]) == 1
    assert capsys.readouterr().err.count("\n") == 1
    bad = tmp_path / "bad.md"
    bad.write_text("<!-- report:nonsense -->\n<!-- /report:nonsense -->\n", encoding="utf-8")
    assert report.main(["--runs", str(runs), str(doc), str(bad)]) == 1
    assert doc.read_text(encoding="utf-8") == text
    assert capsys.readouterr().err.count("\n") == 1


def test_the_plant_family_table_counts_the_plants_beside_the_traditional_fit() -> None:
    cell = {"ratio_oracle": {"median": 0.9, "worst": 1.5}, "below_traditional": 3, "within_1_05_traditional": 4}
    cell |= {"traditional_ratio_oracle_median": 1.2}
    summary = {m: {f: cell for f in ("1", "10", "100", "200")} for m in ("horizon", "rpem")}
    run = {"summary": summary, "count": 5, "seed": 1, "wall_s": 9.0}
    table = report.render("plant_family", {"plant_family": run})
    assert table is not None and table.startswith("5 plants (generator seed 1), 9 s.")
    rows = {line.split(" | ")[0]: line for line in table.splitlines() if line.startswith("| ")}
    # At 1 Hz the count is of plants within 1.05× of the traditional fit, else below it.
    assert rows["| online `horizon` (library default)"].endswith(
        "| 0.90 (1.50); 4/5 | 0.90 (1.50); 3/5 | 0.90 (1.50); 3/5 | 0.90 (1.50); 3/5 |"
    )
    assert "| online `rpem`" in rows and not any("paper" in k for k in rows)
    assert rows["| traditional (offline fit at 1 Hz, then fixed), median"].endswith("| 1.20 | 1.20 | 1.20 | 1.20 |")
