"""Everything that stands in for the outside world or measures the server: the Unity-wire client,
the headless simulator, the data collector, the robustness experiments and the benchmarks."""
