"""The per-lap table of a simulated run, as ``rbc sim`` and ``rbc demo`` print it."""

from __future__ import annotations


def print_summary(result, speed_limit_note: str) -> None:
    """The per-lap table and the run's totals."""
    cfg = result.config
    print(f"track {cfg.track} ({result.track_length_m:.0f} m), driver {result.driver}, {speed_limit_note}")
    head = (f"{'lap':>3}  {'eta %':>6}  {'int':>3}  {'causes':<26} {'time s':>7}  {'km/h':>5}  "
            f"{'cte rms':>7}  {'cte max':>7}  {'coll':>4}  {'lane':>4}")
    print(head)
    print("-" * len(head))
    for lap in result.laps:
        causes = ", ".join(f"{k} {v}" for k, v in sorted(lap.causes().items())) or "-"
        eta = f"{lap.eta:6.1f}" + ("*" if lap.eta_clamped else " ")
        flag = "" if lap.completed else "  (not finished)"
        print(f"{lap.lap:>3}  {eta:>7} {lap.n_interventions:>3}  {causes:<26} {lap.lap_time_s:>7.1f}  "
              f"{lap.mean_speed_kmh:>5.1f}  {lap.cte_rms_m:>7.2f}  {lap.cte_max_m:>7.2f}  {lap.collisions:>4}  "
              f"{lap.lane_departures:>4}{flag}")
    if any(lap.eta_clamped for lap in result.laps):
        print("* more intervention time than lap time: the degree of autonomy (Eq. 1) would be negative; shown as 0")
    for lap in result.laps:
        for i in lap.interventions:
            print(f"    lap {lap.lap}: {i.cause:<9} at s={i.s:7.1f} m  (x={i.x:7.1f}, y={i.y:7.1f})  t={i.t:7.1f} s")
    mode = "real time" if cfg.realtime else f"lock-step {cfg.control_hz:g} Hz"
    print(f"wall {result.wall_time_s:.2f} s for {result.sim_time_s:.1f} s simulated ({mode}), "
          f"{result.frames} frames ({result.frames / max(result.wall_time_s, 1e-9):.0f}/s)"
          + ("  [interrupted]" if result.interrupted else ""))
    print(f"latency p50 {result.latency_ms_p50:.2f} ms p99 {result.latency_ms_p99:.2f} ms (round trip)")
