"""The paper's reference results (Tables 9 and 10), as data: the tables and the charts read them from here."""

from __future__ import annotations

#: Table 9 of the paper, for side-by-side display (values as printed there).
PAPER_TABLE9: dict[str, dict[str, str]] = {
    "no_variation": {"simplistic": "≈100 %", "rigorous": "≈100 %", "collision": "≈100 %"},
    "obstacles": {"simplistic": "…", "rigorous": "…", "collision": "η{20,10,0} ≈ 100 %"},
    "light_intensity": {"simplistic": "[-0.4, +0.1] cd", "rigorous": "[-0.2, +0.9] cd", "collision": "[-0.6, +1.0] cd"},
    "light_direction": {"simplistic": "[-14°, +1°]", "rigorous": "[-2°, +4°]", "collision": "[-18°, +28°]"},
    "position": {"simplistic": "≈100 %", "rigorous": "≈100 %", "collision": "≈100 %"},
    "orientation": {"simplistic": "[-35°, +15°]", "rigorous": "[-25°, +25°]", "collision": "[-55°, +40°]"},
    "heading_inversion": {"simplistic": "≈96.91 %", "rigorous": "≈72.89 %", "collision": "≈91.09 %"},
    "speed_limit": {"simplistic": "40 km/h", "rigorous": "35 km/h", "collision": "50 km/h"},
    "unseen_worlds": {"simplistic": "–", "rigorous": "–", "collision": "–"},  # beyond the paper
}

#: The paper's Table 10 ranges (offsets from the default), as numbers: the table and the chart use them.
PAPER_TABLE10_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "NVIDIA's approach (paper)": {"light_intensity": (-0.2, 0.3), "light_direction": (-3.0, 7.0),
                                  "orientation": (-20.0, 10.0)},
    "Our approach (paper)": {"light_intensity": (-0.6, 1.2), "light_direction": (-30.0, 30.0),
                             "orientation": (-45.0, 10.0)},
}
PAPER_TABLE10 = {
    "NVIDIA's approach (paper)": {
        "training_time": "~1.8 hr", "latency": "4-7 ms (mode 4.99 ms)", "no_variation": "≈100 %",
        "position": "≈100 %", "heading_inversion": "≈100 %", "speed_limit": "50 km/h"},
    "Our approach (paper)": {
        "training_time": "~1.4 hr", "latency": "2-6 ms (mode 3.99 ms)", "no_variation": "≈100 %",
        "position": "≈100 %", "heading_inversion": "≈100 %", "speed_limit": "100 km/h"},
}
