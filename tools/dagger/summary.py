"""A DAgger run's summary: ``summary.json`` (a row of figures per round) and ``rounds.md`` (their table).

Written by :mod:`tools.dagger.loop` after every round, read by :mod:`tools.dagger.report`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from protocol.runrecords import code_version, write_json, write_text
from tools.dagger.config import PERTURBATIONS, DaggerConfig
from tools.dagger.records import RoundRecord

SUMMARY_JSON = "summary.json"
SUMMARY_MD = "rounds.md"


def round_row(record: RoundRecord) -> dict[str, object]:
    """One line of the summary: the figures a curve or a table needs (``NAME_eta`` and ``NAME_takeovers`` per
    track: the keys depend on the run)."""
    ev = record["eval"]
    row: dict[str, object] = {"round": record["round"], "mode": record["mode"], "beta": record["beta"],
           "expert_frames": record["expert_frames"], "learner_steps": record["collection"]["learner_steps"],
           "collection_takeovers": record["collection"]["takeovers"]}
    if "worlds" in ev:
        w = ev["worlds"]
        row |= {"worlds_mean": w["mean"], "worlds_worst": w["worst"]["eta"], "worlds_at_target": w["at_target"],
                "worlds_n": w["n"], "worlds_takeovers": w["takeovers"]}
    for name, t in ev["tracks"].items():
        row[f"{name}_eta"] = t["eta"]
        row[f"{name}_takeovers"] = t["takeovers"]
    row |= {"all_mean": ev["all"]["mean"], "all_worst": ev["all"]["worst"], "all_takeovers": ev["all"]["takeovers"]}
    for key, found in (ev.get("perturbations") or {}).items():
        row[key] = found["text"]
    return row


def write_summary(out: Path, config: DaggerConfig, records: Sequence[RoundRecord]) -> None:
    """``summary.json`` (every round's row, the config, the code version) and ``rounds.md`` (the table)."""
    rows = [round_row(r) for r in records]
    write_json(out / SUMMARY_JSON, {"mode": config.mode, "config": config.to_dict(), "seed": config.seed,
                                    "code_version": code_version(), "rounds": rows})
    write_text(out / SUMMARY_MD, rounds_table(rows))


def rounds_table(rows: Sequence[Mapping[str, object]]) -> str:
    """A Markdown table of the rounds: expert frames, beta, the worlds' mean and worst eta, the tracks."""
    if not rows:
        return ""
    tracks = [k[:-4] for k in rows[0] if k.endswith("_eta")]
    head = ["round", "mode", "beta", "expert frames", "worlds mean η", "worst world η", "worlds ≥ 95 %",
            "take-overs (worlds)"] + [f"{t} η" for t in tracks]
    perturbations = [k for k in PERTURBATIONS if k in rows[0]]
    head += [p.replace("_", " ") for p in perturbations]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        cells = [str(row["round"]), str(row["mode"]), f"{row['beta']:.3g}", f"{row['expert_frames']:,}"]
        if "worlds_mean" in row:
            cells += [f"{row['worlds_mean']:.1f} %", f"{row['worlds_worst']:.1f} %",
                      f"{row['worlds_at_target']}/{row['worlds_n']}", str(row["worlds_takeovers"])]
        else:
            cells += ["–"] * 4
        cells += [f"{row[f'{t}_eta']:.1f} % ({row[f'{t}_takeovers']})" for t in tracks]
        cells += [str(row.get(p, "–")) for p in perturbations]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
