"""The printed report of a cross-validation: the per-track summary and one row per recording, as Markdown
(the picture is :mod:`tools.realdata.crossval_plot`)."""

from __future__ import annotations

from collections.abc import Sequence

from tools.realdata.crossval import RecordingScore, summarise


def _cell(value: float | None, spec: str) -> str:
    return "–" if value is None else format(value, spec)


def format_tables(scores: Sequence[RecordingScore], peer: Sequence[RecordingScore] = ()) -> str:
    """Markdown: the per-track summary, then one row per recording (bold MSE: beats always-0).

    The words of the glossary: "r to intent" is r against the recorded steering's 9-frame average (the
    driver's intent); "r9" is that average's own r with the recorded steering, about the most any model's r
    reaches there; "autonomy %" is the degree of autonomy. A recording without a take-over has no rate.
    """
    lines = ["| track | recordings | r9 | mean r | r to intent | beats always-0 | mean autonomy % | s per take-over |"
             + (" peer: mean r | r to intent | beats always-0 | mean autonomy % | s per take-over |" if peer else ""),
             "|---|---|---|---|---|---|---|---|" + ("---|---|---|---|---|" if peer else "")]
    peer_by_track = {t.track: t for t in summarise(peer)}
    for t in summarise(scores):
        row = (f"| {t.track} | {t.recordings} | {_cell(t.mean_intent_r, '.2f')} | {t.mean_r:.2f} | "
               f"{_cell(t.mean_r_to_intent, '.2f')} | {t.beats_zero} of {t.recordings} | "
               f"{_cell(t.mean_eta, '.1f')} | {_cell(t.seconds_per_takeover, '.1f')} |")
        if peer:
            p = peer_by_track.get(t.track)
            row += (f" {p.mean_r:.2f} | {_cell(p.mean_r_to_intent, '.2f')} | {p.beats_zero} of {p.recordings} | "
                    f"{_cell(p.mean_eta, '.1f')} | {_cell(p.seconds_per_takeover, '.1f')} |"
                    if p else " – | – | – | – | – |")
        lines.append(row)
    lines += ["", "| recording | track | fold | frames | always-0 MSE | MSE | r | r9 | r to intent | "
              "autonomy % (take-overs; s per take-over) |" + (" peer MSE | peer r | peer autonomy % |" if peer else ""),
              "|---|---|---|---|---|---|---|---|---|---|" + ("---|---|---|" if peer else "")]
    peer_by_name = {p.name: p for p in peer}

    def mse(s: RecordingScore) -> str:
        return f"**{s.mse:.4f}**" if s.beats_zero else f"{s.mse:.4f}"

    def loop(s: RecordingScore) -> str:
        if s.eta is None:
            return "–"
        if not s.interventions or s.seconds_per_takeover is None:
            return f"{s.eta:.1f} ({s.interventions or 0})"
        return f"{s.eta:.1f} ({s.interventions}; {s.seconds_per_takeover:.1f} s)"

    for s in sorted(scores, key=lambda s: (s.track, s.name.lower())):
        row = (f"| {s.name} | {s.track} | {s.fold} | {s.frames} | {s.zero_mse:.4f} | {mse(s)} | {s.pearson_r:.2f} | "
               f"{_cell(s.intent_r, '.2f')} | {_cell(s.r_to_intent, '.2f')} | {loop(s)} |")
        if peer:
            theirs = peer_by_name.get(s.name)
            row += f" {mse(theirs)} | {theirs.pearson_r:.2f} | {loop(theirs)} |" if theirs else " – | – | – |"
        lines.append(row)
    return "\n".join(lines)
