"""The picture of a soak: the server's RSS and open fds, and the round trip p50/p99, over time."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from protocol.runrecords import atomic_path

if TYPE_CHECKING:
    from tools.bench.soak import SoakResult


def plot_soak(result: SoakResult, path: Path) -> Path | None:
    """Three stacked panels over minutes of the run; None when matplotlib (extra ``plots``) is missing."""
    try:
        import matplotlib
    except ImportError:
        return None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    samples = result["samples"]
    t = [s["t_s"] / 60 for s in samples]
    fig, axes = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True)
    rss = axes[0]
    rss.plot(t, [s["rss_mib"] for s in samples], color="tab:blue")
    rss.set_ylabel("server RSS (MiB)")
    if (rss_start := result.get("rss_mib_start")) is not None:
        rss.axhline(rss_start + 20, color="tab:red", ls=":", lw=1, label="start + 20 MiB")
        rss.legend(loc="lower right", fontsize=8)
    axes[1].plot(t, [s["fds"] for s in samples], color="tab:green")
    axes[1].set_ylabel("open fds")
    if result.get("fds_start") is not None:
        axes[1].axhline(result["fds_start"], color="grey", ls=":", lw=1, label="before the clients")
    if result.get("fds_end") is not None and t:
        axes[1].plot([t[-1]], [result["fds_end"]], "o", color="tab:green", label="after the clients left")
        axes[1].legend(loc="center left", fontsize=8)
    lat = axes[2]
    lat.plot(t, [s["p50_ms"] for s in samples], label="p50 (10 s)", color="tab:purple", lw=0.8, alpha=0.6)
    lat.plot(t, [s["p99_ms"] for s in samples], label="p99 (10 s)", color="tab:orange", lw=0.8, alpha=0.5)
    minutes = result.get("minutes") or []
    if minutes:
        mt = [m["t_s"] / 60 for m in minutes]
        lat.step(mt, [m["p99_ms"] for m in minutes], where="pre", color="tab:red", lw=1.6,
                 label=f"p99 per {result['edge_window_s']:g} s")
    lat.set_ylabel("round trip (ms)")
    lat.set_xlabel("minutes")
    lat.set_ylim(bottom=0)
    lat.legend(loc="upper right", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    rates = result.get("rates_hz", [])
    fig.suptitle(f"rbc soak, {result['duration_s'] / 60:g} min: {result['clients']} simulators at "
                 f"{rates[0]:g}-{rates[-1]:g} Hz, a reconnect loop, an idle socket, malformed frames, live view, "
                 f"recording\n{result['telemetries']:,} telemetries: {result['unanswered']} unanswered, "
                 f"{result['double_answered']} answered twice; RSS {result['rss_mib_start']} -> "
                 f"{result['rss_mib_end']} MiB after the first minute; fds {result['fds_start']} -> "
                 f"{result['fds_end']} once the clients left", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path
