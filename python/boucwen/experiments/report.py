"""The tables of ``README.md``, ``docs/results.md`` and ``docs/diagnosis.md``, written
from the runs.

Every table those documents show of the main job's runs sits between two markers::

    <!-- report:NAME -->
    | … the table … |
    <!-- /report:NAME -->

and is written by this module from the JSON the runs leave in ``out/`` (``bash
scripts/main.sh``): ``out/reproduce/results.json`` (Tables 1 and 1b), ``out/measured/
results.json`` (the measured records), ``out/track/results.json`` (closed-loop
tracking), ``out/compare/results.json`` (``python benches/compare.py --out
out/compare``: the speed of the core beside NumPy/SciPy) and
``out/diagnosis_suite/results.json`` (``python -m boucwen.experiments.diagnosis_suite
--out out/diagnosis_suite``: the diagnosis's evaluation suite) and
``out/plant_family/results.json`` (``python -m boucwen.experiments.plant_family --out
out/plant_family``: the online methods on a family of generated benches). Nothing
between the markers is written by hand; the prose around them is.

Run as ``python -m boucwen.experiments.report [--runs out] [FILE ...]`` (default files:
``README.md``, ``docs/results.md`` and ``docs/diagnosis.md``): each block whose run is present is rewritten;
a block whose run is missing is left as it is and named; a marker with an
unknown name is an error (exit status 1, nothing written).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .measured import markdown_table

__all__ = ["BLOCKS", "Block", "blocks_in", "main", "render", "update_text"]

#: Frequencies of the paper's tables [Hz], as keys of ``results.json``.
FREQUENCIES = ("1", "10", "100", "200")

#: A run's JSON, by the run's folder name under ``--runs``.
Runs = Mapping[str, Mapping[str, Any]]

_MARKER = re.compile(r"<!-- report:([a-z0-9_]+) -->\n(.*?)<!-- /report:\1 -->", re.DOTALL)
_OPEN = re.compile(r"<!-- report:([a-z0-9_]+) -->")


@dataclass(frozen=True)
class Block:
    """A table: the run it is written from (folder under ``--runs``) and how."""

    run: str
    write: Callable[[Mapping[str, Any]], str]


def _freq_row(label: str, values: Mapping[str, float], *, bold: bool = False, fmt: str = "{:.3f}") -> str:
    cells = [_num(values[f], fmt) for f in FREQUENCIES]
    if bold:
        label, cells = f"**{label}**", [f"**{c}**" for c in cells]
    return f"| {label} | " + " | ".join(cells) + " |"


def _num(v: float, fmt: str) -> str:
    """``fmt`` for errors below 100 µm, one decimal above (a failed model's hundreds of µm)."""
    return f"{v:.1f}" if abs(v) >= 100 else fmt.format(v)


_HEAD = "| {} | 1 Hz | 10 Hz | 100 Hz | 200 Hz |\n|---|---|---|---|---|"


def _table1(r: Mapping[str, Any], rows: Sequence[tuple[str, str, bool]]) -> str:
    """Period-ahead rows ``(key, label, bold)``; keys of ``table1``, or ``paper`` and
    ``paper_online`` (the paper's own rows), ``oracle``, ``best_fixed``."""
    t1 = r["table1"]
    sources = {
        "paper": {k: float(v) for k, v in r["paper"]["table1"]["traditional"].items()},
        "paper_online": {k: float(v) for k, v in r["paper"]["table1"]["online"].items()},
        "oracle": r["refit_oracle"],
        "best_fixed": r["best_fixed_per_frequency"],
    }
    # The paper method's row at the window its sweep chose (the run's window without a sweep).
    chosen = r.get("paper_window", {}).get("chosen", r.get("window", {}).get("samples"))
    sweep = r.get("window_sweep") or {}
    if str(chosen) in sweep:
        sources["paper_chosen"] = sweep[str(chosen)]["period_ahead"]
    elif "online_paper" in t1:
        sources["paper_chosen"] = t1["online_paper"]
    lines = [_HEAD.format("method")]
    for key, label, bold in rows:
        values = sources.get(key) or t1[key]
        label = label.replace("{paper_window}", str(chosen))
        fmt = "{:.2f}" if key in ("paper", "paper_online") else "{:.3f}"
        lines.append(_freq_row(label, values, bold=bold, fmt=fmt))
    return "\n".join(lines)


def _one_step(r: Mapping[str, Any], methods: Sequence[tuple[str, str]]) -> str:
    lines = [_HEAD.format("predictor")]
    lines += [_freq_row(label, r["table1_one_step"][key]) for key, label in methods]
    lines.append(_freq_row("persistence x̂ₖ = xₖ₋₁ (no model)", r["baselines"]["persistence"]))
    lines.append(_freq_row("two-tap x̂ₖ = 2xₖ₋₁ − xₖ₋₂ (no model)", r["baselines"]["two_tap"]))
    return "\n".join(lines)


_README_TABLE1 = (
    ("traditional", "traditional (offline fit at 1 Hz, then fixed)", False),
    ("paper", "traditional, paper", False),
    ("online_horizon", "online `horizon` (library default, input lag identified)", True),
    ("online_rpem", "online `rpem`", False),
    ("paper_chosen", "online `paper` (the paper's method, N = {paper_window} chosen by its sweep)", False),
    ("oracle", "refit oracle (offline fit on the 2 periods before)", False),
)
_RESULTS_TABLE1 = (
    ("traditional", "traditional (offline fit at 1 Hz, then fixed), this bench", False),
    ("paper", "traditional, paper", False),
    (
        "online_horizon",
        "online `horizon` (moving-horizon output error, input lag identified; library default)",
        True,
    ),
    ("online_horizon_base", "online `horizon`, seven parameters only (`Identifier.horizon`)", False),
    ("online_rpem", "online `rpem` (recursive prediction error)", False),
    ("online_paper", "online `paper` (the paper's method, default repair, N = 50)", False),
    ("paper_chosen", "online `paper`, N = {paper_window} (chosen by its window sweep)", False),
    ("online_paper_literal", "online `paper`, literal line decomposition", False),
    ("paper_online", "online, paper", False),
    ("oracle", "refit oracle: offline fit on the 2 periods before the scored one", False),
    ("best_fixed", "best fixed parameters per frequency (in-sample, no fair target)", False),
)


def _track(r: Mapping[str, Any], bench: str, refs: Sequence[str] | None, *, rms: bool) -> str:
    """Max (and RMS) tracking error [µm] with the max in % of range, per reference and
    method, on ``bench`` (``vibration_off`` / ``vibration_on``)."""
    methods: Mapping[str, str] = r["settings"]["methods"]
    references: Mapping[str, Mapping[str, Any]] = r["settings"]["references"]
    table = r["benches"][bench]["table"]
    lines = ["| reference | " + " | ".join(methods.values()) + " |", "|---|" + "---|" * len(methods)]
    for ref in refs if refs is not None else list(references):
        cells = []
        for m in methods:
            v = table[ref][m]
            pair = f"{v['max_um']:.3f} / {v['rms_um']:.3f}" if rms else f"{v['max_um']:.3f}"
            cells.append(f"{pair} ({v['max_pct']:.2f} %)")
        lines.append(f"| {references[ref]['label']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


_STEPS = (
    ("line_fit", "1, kv and x0"),
    ("rate_fit", "2, A and δ"),
    ("shape_fit", "3, n and β + γ"),
    ("return_fit", "4, γ − β"),
    ("split_fit", "5, β and γ"),
    ("window_fit", "window fit, 1–4 on the window's output (last run)"),
)
_NAMES = ("kv", "x0", "A", "beta", "gamma", "n", "delta")


def _steps(shares: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> str:
    """Share of pushes on which each step ran (in full + reduced), per frequency, with the
    median points and scatter of those pushes and the main reasons it held."""
    head = "| step | 1 Hz | 10 Hz | 100 Hz | 200 Hz | held or reduced because (mean share) |"
    lines = [head, "|---|---|---|---|---|---|"]
    for key, label in _STEPS:
        rows = shares[key]
        cells = []
        for f in FREQUENCIES:
            r = rows[f]
            share = r["ran"] + r["reduced"]
            extra = f" ({r['points']:.0f} pts, {r['noise']:.2g})" if share > 0 and key != "split_fit" else ""
            cells.append(f"{share:.3f}{extra}")
        reasons: dict[str, float] = {}
        for f in FREQUENCIES:
            for why, v in rows[f]["reasons"].items():
                reasons[why] = reasons.get(why, 0.0) + v / len(FREQUENCIES)
        why = ", ".join(f"{k} {v:.2f}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1])[:3])
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {why} |")
    return "\n".join(lines)


def _exact_table1(r: Mapping[str, Any]) -> str:
    best = r["sweep"][str(r["chosen_window"])]
    n = r["chosen_window"]
    lines = [_HEAD.format("predictor")]
    lines.append(_freq_row(f"online `paper`, N = {n}, period-ahead", best["period_ahead"]))
    lines.append(_freq_row(f"online `paper`, N = {n}, one step (the paper's metric)", best["one_step"]))
    paper = {k: float(v) for k, v in r["paper"]["table1"]["online"].items()}
    lines.append(_freq_row("online, paper (Table 1)", paper, fmt="{:.2f}"))
    lines.append(_freq_row("persistence x̂ₖ = xₖ₋₁ (no model)", r["baselines"]["persistence"]))
    lines.append(_freq_row("two-tap x̂ₖ = 2xₖ₋₁ − xₖ₋₂ (no model)", r["baselines"]["two_tap"]))
    return "\n".join(lines)


def _exact_sweep(r: Mapping[str, Any]) -> str:
    lines = [
        "| N | period-ahead 1 / 10 / 100 / 200 Hz | one step 1 / 10 / 100 / 200 Hz | meets the paper's figures at |",
        "|---|---|---|---|",
    ]
    for w, row in r["sweep"].items():
        pa = " / ".join(f"{row['period_ahead'][f]:.3f}" for f in FREQUENCIES)
        os_ = " / ".join(f"{row['one_step'][f]:.3f}" for f in FREQUENCIES)
        mark = " (chosen)" if int(w) == r["chosen_window"] else ""
        met = [f"{f} Hz" for f in FREQUENCIES if row.get("meets", {}).get(f, {}).get("both")]
        lines.append(f"| {w}{mark} | {pa} | {os_} | {', '.join(met) or 'none'} |")
    return "\n".join(lines)


def _exact_needs(r: Mapping[str, Any]) -> str:
    """What one window N needs on the paper's record (``paper_exact.needs``)."""
    nd = r["needs"]
    slow, fast = f"{nd['slow_hz']:g} Hz", f"{nd['fast_hz']:g} Hz"
    lines = [f"| N | bound on A at {slow}, best-placed window | resolves A to 10 % (≤ {nd['resolve_A']:.1e}) |"]
    lines.append("|---|---|---|")
    for w, b in nd["bound_A_slow"].items():
        lines.append(f"| {w} | {b:.1e} | {'yes' if b <= nd['resolve_A'] else 'no'} |")
    lines += [
        "",
        f"- {slow}: the window fit resolves A from N = {nd['n_min']}.",
        f"- {fast}: its part holds {nd['fast_part_samples']} samples; a run of the window fit falls on a window "
        f"wholly inside it for sure up to N = {nd['n_max']}.",
        f"- One N for both would need a {fast} part of {nd['fast_part_needed']} samples, or a sensor noise of at "
        f"most {nd['noise_needed_um'] * 1e3:.2f} nm (the bound on A at N = {nd['n_max']} and {slow} is "
        f"{nd['bound_A_slow_at_n_max']:.1e} at the record's noise).",
    ]
    return "\n".join(lines)


def _exact_table2(r: Mapping[str, Any]) -> str:
    est = r["sweep"][str(r["chosen_window"])]["table2"]
    truth = r["paper"]["table2"]
    lines = ["| f | " + " | ".join(_NAMES) + " |", "|---|" + "---|" * len(_NAMES)]
    for f in FREQUENCIES:
        cells = [f"{est[f][n]:.4g} ({truth[f][n]:.3g})" for n in _NAMES]
        lines.append(f"| {f} Hz | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _exact_budget(r: Mapping[str, Any]) -> str:
    lines = [
        "| step | f | points | median \\|A − r\\| (signal) | rms noise of r | rms bias of r | half-width m |",
        "|---|---|---|---|---|---|---|",
    ]
    for step, label in (("shape_fit", "3"), ("return_fit", "4")):
        for f in FREQUENCIES:
            b = r["step_budget"][step][f]
            lines.append(
                f"| {label} | {f} Hz | {b['points']} | {b['signal']:.2e} | {b['noise']:.2e} | {b['bias']:.2e} | "
                f"{b['half_width']} |"
            )
    return "\n".join(lines)


def _exact_bound(r: Mapping[str, Any]) -> str:
    """The Cramér–Rao bound of one window beside the error reached (``paper_exact``)."""
    quantities = (("A", "A"), ("delta", "δ"), ("n", "n"), ("beta+gamma", "β + γ"), ("A+kv", "A + kv"))
    lines = [
        "| N | f | " + " | ".join(label for _, label in quantities) + " |",
        "|---|---|" + "---|" * len(quantities),
    ]
    for w, rows in r["bound"]["windows"].items():
        for f in FREQUENCIES:
            cells = []
            for q, _ in quantities:
                e = rows[f][q]
                # An infinite bound is written to JSON as null.
                bound = "∞" if e["bound"] is None or e["bound"] == float("inf") else f"{e['bound']:.1e}"
                cells.append(bound + (f" / {e['reached']:.1e}" if "reached" in e else ""))
            lines.append(f"| {w} | {f} Hz | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _bench_sweep(r: Mapping[str, Any]) -> str:
    """The paper method's window sweep on the bench: period-ahead error per frequency and
    its worst ratio to the traditional fit (``reproduce``)."""
    trad = r["table1"]["traditional"]
    chosen = r.get("paper_window", {}).get("chosen")
    lines = ["| N | period-ahead 1 / 10 / 100 / 200 Hz | worst ratio to the traditional fit |", "|---|---|---|"]
    for w, row in (r.get("window_sweep") or {}).items():
        pa = " / ".join(_num(row["period_ahead"][f], "{:.3f}") for f in FREQUENCIES)
        ratio = max(row["period_ahead"][f] / trad[f] for f in FREQUENCIES)
        mark = " (chosen)" if chosen is not None and int(w) == chosen else ""
        lines.append(f"| {w}{mark} | {pa} | {ratio:.2f} |")
    return "\n".join(lines)


def _second(r: Mapping[str, Any]) -> dict[str, Any]:
    """The second paper-exact plant's results with the paper's tables beside them."""
    return {**r["second"], "paper": r["paper"]}


#: Every table the documents may hold, by marker name.
BLOCKS: dict[str, Block] = {
    "readme_table1": Block("reproduce", lambda r: _table1(r, _README_TABLE1)),
    "results_table1": Block("reproduce", lambda r: _table1(r, _RESULTS_TABLE1)),
    "readme_one_step": Block("reproduce", lambda r: _one_step(r, (("online_horizon", "online `horizon`, one step"),))),
    "results_one_step": Block(
        "reproduce",
        lambda r: _one_step(
            r,
            (
                ("online_horizon", "online `horizon`, one step"),
                ("online_horizon_base", "online `horizon`, seven parameters, one step"),
                ("online_rpem", "online `rpem`, one step"),
            ),
        ),
    ),
    "measured": Block("measured", lambda r: markdown_table(r["cases"])),
    "readme_track": Block(
        "track",
        lambda r: _track(r, "vibration_off", ("sine_1hz", "sine_100hz", "sine_200hz", "staircase"), rms=False),
    ),
    "track_off": Block("track", lambda r: _track(r, "vibration_off", None, rms=True)),
    "track_on": Block("track", lambda r: _track(r, "vibration_on", None, rms=True)),
    "compare": Block("compare", lambda r: _compare(r)),
    "diagnosis_suite": Block("diagnosis_suite", lambda r: _suite(r)),
    "diagnosis_speed": Block("diagnosis_speed", lambda r: _speed(r)),
    "plant_family": Block("plant_family", lambda r: _family(r)),
    "bench_window_sweep": Block("reproduce", _bench_sweep),
    "bench_paper_steps": Block("reproduce", lambda r: _steps(r["paper_steps"]["online_paper"])),
    "exact_table1": Block("paper_exact", _exact_table1),
    "exact_sweep": Block("paper_exact", _exact_sweep),
    "exact_table2": Block("paper_exact", _exact_table2),
    "exact_steps": Block("paper_exact", lambda r: _steps(r["sweep"][str(r["chosen_window"])]["steps"])),
    "exact_budget": Block("paper_exact", _exact_budget),
    "exact_bound": Block("paper_exact", _exact_bound),
    "exact_needs": Block("paper_exact", _exact_needs),
    "exact_second_sweep": Block("paper_exact", lambda r: _exact_sweep(_second(r))),
    "exact_second_table1": Block("paper_exact", lambda r: _exact_table1(_second(r))),
    "exact_second_table2": Block("paper_exact", lambda r: _exact_table2(_second(r))),
}

#: The online methods of the plant family's table, in its order, with their labels.
_FAMILY_METHODS = (
    ("horizon", "online `horizon` (library default)"),
    ("horizon_base", "online `horizon`, seven parameters only"),
    ("rpem", "online `rpem`"),
    ("paper", "online `paper` (N = 50)"),
)


def _family(r: Mapping[str, Any]) -> str:
    """The table of ``python -m boucwen.experiments.plant_family --out
    out/plant_family``: per method and frequency, the period-ahead error's ratio to the
    refit oracle, median (worst) over the plants, and on how many plants the method is
    below the traditional fit (within 1.05× of it at 1 Hz); the traditional fit's own
    median ratio last."""
    summary = r["summary"]
    freqs = list(next(iter(summary.values())))
    count = int(r["count"])
    lines = [
        f"{count} plants (generator seed {r['seed']}), {r['wall_s']:.0f} s. Each cell: ratio to the refit "
        "oracle, median (worst); plants where the method is below the traditional fit (at 1 Hz, the fit's own "
        "frequency: within 1.05× of it).",
        "",
        "| method | " + " | ".join(f"{f} Hz" for f in freqs) + " |",
        "|---|" + "---|" * len(freqs),
    ]
    for key, label in _FAMILY_METHODS:
        if key not in summary:
            continue
        cells = []
        for f in freqs:
            row = summary[key][f]
            median, worst = (_num(row["ratio_oracle"][k], "{:.2f}") for k in ("median", "worst"))
            # At 1 Hz, the traditional fit's own record, the target is to be within 1.05× of it.
            beside = row["within_1_05_traditional"] if f == "1" else row["below_traditional"]
            cells.append(f"{median} ({worst}); {beside}/{count}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    first = next(iter(summary.values()))
    trad = " | ".join(_num(first[f]["traditional_ratio_oracle_median"], "{:.2f}") for f in freqs)
    lines.append(f"| traditional (offline fit at 1 Hz, then fixed), median | {trad} |")
    return "\n".join(lines)


def _speed(r: Mapping[str, Any]) -> str:
    """The table of ``python benches/diagnosis_speed.py --out out/diagnosis_speed
    [--baseline FILE]``, with its caption."""
    return (
        "`python benches/diagnosis_speed.py --baseline BEFORE.json --out out/diagnosis_speed` "
        f"(package {r['version']}; baseline: the same script run on the code before the change, the ratio "
        f"baseline / this run; wall and CPU seconds):\n\n{r['table']}"
    )


def _suite(r: Mapping[str, Any]) -> str:
    """The report of ``python -m boucwen.experiments.diagnosis_suite --out
    out/diagnosis_suite`` (the full suite, both halves), with its caption."""
    if r["quick"] or r["half"] is not None:
        raise ValueError(
            "out/diagnosis_suite holds a partial run (--quick or --half); the document shows the full suite"
        )
    caption = (
        "`python -m boucwen.experiments.diagnosis_suite --out out/diagnosis_suite`: "
        f"{r['records']} records, {r['wall_s']:.0f} s. Each cell: records, the effect sets named "
        "(count), how many were flagged as unexplained."
    )
    return f"{caption}\n\n{r['table']}"


def _compare(r: Mapping[str, Any]) -> str:
    """The table of ``python benches/compare.py --out out/compare``, with its caption."""
    head = "| what | figure | ratio | note |\n|---|---:|---:|---|"
    rows = "\n".join("| " + " | ".join(str(c) for c in row) + " |" for row in r["rows"])
    return f"{r['caption']}\n\n{head}\n{rows}"


def load_runs(runs_dir: str | Path) -> dict[str, dict[str, Any]]:
    """The ``results.json`` of every run folder under ``runs_dir`` that has one."""
    found: dict[str, dict[str, Any]] = {}
    for name in sorted({b.run for b in BLOCKS.values()}):
        path = Path(runs_dir) / name / "results.json"
        if path.is_file():
            with open(path, encoding="utf-8") as fh:
                found[name] = json.load(fh)
    return found


def blocks_in(text: str) -> list[str]:
    """The marker names in ``text``, in order."""
    return _OPEN.findall(text)


def render(name: str, runs: Runs) -> str | None:
    """The table of block ``name`` from ``runs``; None when its run is missing.

    Raises:
        ValueError: ``name`` is not a block of :data:`BLOCKS`.
    """
    if name not in BLOCKS:
        raise ValueError(f"unknown report block {name!r} (known: {', '.join(sorted(BLOCKS))})")
    block = BLOCKS[name]
    return None if block.run not in runs else block.write(runs[block.run])


def update_text(text: str, runs: Runs) -> tuple[str, list[str], list[str]]:
    """``text`` with every block rewritten from ``runs``; also the names written and
    those left as they were (their run missing).

    Raises:
        ValueError: a marker names an unknown block, or a block is not closed.
    """
    for name in blocks_in(text):
        if name not in BLOCKS:
            raise ValueError(f"unknown report block {name!r} (known: {', '.join(sorted(BLOCKS))})")
    closed = [m.group(1) for m in _MARKER.finditer(text)]
    unclosed = [n for n in blocks_in(text) if n not in closed]
    if unclosed:
        raise ValueError(f"report block {unclosed[0]!r} has no closing <!-- /report:{unclosed[0]} -->")
    written: list[str] = []
    left: list[str] = []

    def replace(m: re.Match[str]) -> str:
        name = m.group(1)
        table = render(name, runs)
        if table is None:
            left.append(name)
            return m.group(0)
        written.append(name)
        return f"<!-- report:{name} -->\n{table}\n<!-- /report:{name} -->"

    return _MARKER.sub(replace, text), written, left


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m boucwen.experiments.report", description=__doc__.split("\n")[0])
    ap.add_argument("--runs", default="out", help="folder holding the runs' results (default: out)")
    ap.add_argument(
        "files", nargs="*", default=["README.md", "docs/results.md", "docs/diagnosis.md"], help="documents to update"
    )
    args = ap.parse_args(argv)
    runs = load_runs(args.runs)
    if not runs:
        print(f"report: no run found under {args.runs}/ (run bash scripts/main.sh first)", file=sys.stderr)
        return 1
    updated: dict[Path, str] = {}
    for name in args.files:
        path = Path(name)
        try:
            text = path.read_text(encoding="utf-8")
            new, written, left = update_text(text, runs)
        except (OSError, ValueError) as exc:
            print(f"report: {path}: {exc}", file=sys.stderr)
            return 1
        updated[path] = new
        print(f"{path}: {len(written)} table(s) written" + (f"; left as they were: {', '.join(left)}" if left else ""))
    for path, text in updated.items():
        path.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
