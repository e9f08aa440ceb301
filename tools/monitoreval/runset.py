"""The benchmark's runs, as data: held-out nominal driving, the paper's robustness axes at graded intensities,
unseen worlds, and degraded models. Nothing here is a calibration run: the monitor's thresholds come from
``rbc monitor fit --calibration`` (other world seeds), and a test checks the two never share a world.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

#: World seeds of the held-out nominal runs (training range, apart from the monitor's training 0-29 and
#: calibration 200-229 worlds in the bundled model's recipe).
NOMINAL_WORLDS = range(300, 400)
#: Built-in tracks driven as nominal runs besides the worlds (several spawn seeds each).
NOMINAL_TRACKS = ("lake", "mountain")
#: World seeds of the failure predictor's own runs (rbc monitor failures): the steering model's training range,
#: apart from the monitor's calibration 200-229 and the benchmark's 300-399 worlds.
FAILURE_WORLDS = range(30, 200)
#: Axes the failure predictor never learns from, so the benchmark shows it on a kind of failure it never saw.
HELD_OUT_AXES = ("sun", "unseen_world")
#: World seeds of the evaluation range (never trained or calibrated on): the unseen-world runs.
UNSEEN_WORLDS_FIRST = 1_000_000


@dataclass(frozen=True)
class RunSpec:
    """One run of the benchmark."""

    name: str
    group: str  # "nominal", "perturbed" or "degraded"
    axis: str  # what is changed: "none", "light", "sun", "yaw", "cones", "unseen_world", "weight_noise", "undertrained"
    intensity: float  # the axis's value (light factor, degrees, cones, noise sigma, a checkpoint's epochs); 0 for none
    track: str
    seed: int = 0
    light_intensity: float = 1.0
    light_direction_deg: float = 0.0
    yaw_offset_deg: float = 0.0
    cones: int = 0
    weight_noise: float = 0.0  # sigma of the steering weights' noise, relative to each tensor's std
    # an under-trained checkpoint driven instead of the served model, with the served model's monitor: the content
    # digest of its file (runner.file_digest); "" for the served model
    checkpoint: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if not d["checkpoint"]:  # a run of the served model is keyed as it was before checkpoints existed
            del d["checkpoint"]
        return d


def nominal_runs(count: int) -> list[RunSpec]:
    """``count`` held-out nominal runs: one lap each, generated worlds and built-in tracks in turn."""
    out = []
    for i in range(count):
        if i % 5 == 4:
            track = NOMINAL_TRACKS[(i // 5) % len(NOMINAL_TRACKS)]
            out.append(RunSpec(f"nominal-{track}-{i}", "nominal", "none", 0.0, track, seed=i))
        else:
            seed = NOMINAL_WORLDS[i % len(NOMINAL_WORLDS)]
            out.append(RunSpec(f"nominal-world{seed}-{i}", "nominal", "none", 0.0, f"world:{seed}", seed=i))
    return out


#: The perturbed axes and their graded intensities (the paper's robustness axes, Tables 9-10, pushed further).
PERTURBATIONS: dict[str, tuple[float, ...]] = {
    "light": (0.12, 0.18, 0.25, 4.0, 6.0, 8.0, 10.0, 12.0),  # scene light intensity (1: nominal)
    "sun": (120.0, 180.0),  # sun direction offset, degrees
    "yaw": (25.0, 40.0, -25.0, -40.0),  # spawn heading offset, degrees
    "cones": (10.0, 20.0),  # traffic cones on the road (this model was never taught to avoid them)
    "unseen_world": (0.0,),  # a world of the evaluation seeds
}
#: Degraded steering models: Gaussian noise on every weight tensor, sigma relative to the tensor's std.
WEIGHT_NOISE = (0.15, 0.3, 0.5, 0.7)


def failing_runs(per_setting: int) -> list[RunSpec]:
    """``per_setting`` runs of each perturbation and each degraded model, on worlds and tracks in turn."""
    out = []
    for axis, values in PERTURBATIONS.items():
        for value in values:
            for k in range(per_setting):
                world = f"world:{NOMINAL_WORLDS[(k * 7) % len(NOMINAL_WORLDS)]}" if k % 2 else "lake"
                if axis == "cones":
                    world = "lake"
                elif axis == "unseen_world":
                    world = f"world:{UNSEEN_WORLDS_FIRST + k}"
                out.append(RunSpec(f"{axis}{value:g}-{k}", "perturbed", axis, value, world, seed=100 + k,
                                   light_intensity=value if axis == "light" else 1.0,
                                   light_direction_deg=value if axis == "sun" else 0.0,
                                   yaw_offset_deg=value if axis == "yaw" else 0.0,
                                   cones=int(value) if axis == "cones" else 0))
    for sigma in WEIGHT_NOISE:
        for k in range(per_setting):
            out.append(RunSpec(f"noise{sigma:g}-{k}", "degraded", "weight_noise", sigma, _degraded_track(k),
                               seed=200 + k, weight_noise=sigma))
    return out


def _degraded_track(k: int) -> str:
    """The ``k``-th run of a degraded model: lake and worlds in turn."""
    return "lake" if k % 2 == 0 else f"world:{NOMINAL_WORLDS[(k * 11) % len(NOMINAL_WORLDS)]}"


def undertrained_runs(checkpoints: Sequence[tuple[str, str, float]], per_setting: int) -> list[RunSpec]:
    """``per_setting`` runs of each under-trained checkpoint, given as (name, content digest, epochs trained), on
    the weight-noise runs' tracks and spawn seeds (lake and worlds in turn)."""
    return [RunSpec(f"undertrained-{name}-{k}", "degraded", "undertrained", epochs, _degraded_track(k), seed=200 + k,
                    checkpoint=digest)
            for name, digest, epochs in checkpoints for k in range(per_setting)]


#: The failure predictor's settings: harsher than the benchmark's, so the steering model, which drives its own
#: training worlds well, fails often enough to learn from (axis -> intensities); the held-out axes are not here.
FAILURE_SETTINGS: dict[str, tuple[float, ...]] = {
    "weight_noise": (0.3, 0.5, 0.7),
    "yaw": (40.0, -40.0),
    "cones": (15.0, 20.0),  # more do not fit on the shorter worlds (25 m apart)
    "light": (0.08, 6.0),
}


def failure_training_runs(per_setting: int, nominal: int) -> list[RunSpec]:
    """The failure predictor's runs: ``per_setting`` runs of each of :data:`FAILURE_SETTINGS` and ``nominal``
    nominal runs, all on worlds of :data:`FAILURE_WORLDS` (no built-in track, no benchmark or calibration world,
    no evaluation world)."""
    out, k = [], 0
    worlds = list(FAILURE_WORLDS)

    def world() -> str:
        nonlocal k
        k += 1
        return f"world:{worlds[(k * 37) % len(worlds)]}"

    for axis, values in FAILURE_SETTINGS.items():
        for value in values:
            for i in range(per_setting):
                name = f"train-{'noise' if axis == 'weight_noise' else axis}{value:g}-{i}"
                out.append(RunSpec(name, "degraded" if axis == "weight_noise" else "perturbed", axis, value, world(),
                                   seed=500 + i, light_intensity=value if axis == "light" else 1.0,
                                   yaw_offset_deg=value if axis == "yaw" else 0.0,
                                   cones=int(value) if axis == "cones" else 0,
                                   weight_noise=value if axis == "weight_noise" else 0.0))
    for i in range(nominal):
        out.append(RunSpec(f"train-nominal-{i}", "nominal", "none", 0.0, world(), seed=700 + i))
    return out
