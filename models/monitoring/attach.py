"""A steering model's file with a monitor in it: the same steering graph, plus the monitor's spec, thresholds
and graph in the metadata (:mod:`drive_server.serving.monitor`), written atomically and checked by loading it the way
drive_server does."""

from __future__ import annotations

from pathlib import Path

from drive_server.serving.model import SteeringModel
from drive_server.serving.monitor import MONITOR_GRAPH_KEY, MONITOR_KEY, MonitorSpec, encode_graph
from protocol.runrecords import atomic_path


def attach_monitor(src: Path, dst: Path, spec: MonitorSpec, graph: bytes) -> None:
    """Write ``dst``: ``src`` with the monitor; an existing monitor of ``src`` is replaced."""
    import onnx

    proto = onnx.load(str(src))
    kept = [(p.key, p.value) for p in proto.metadata_props if p.key not in (MONITOR_KEY, MONITOR_GRAPH_KEY)]
    del proto.metadata_props[:]
    for key, value in [*kept, (MONITOR_KEY, spec.to_json()), (MONITOR_GRAPH_KEY, encode_graph(graph))]:
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    with atomic_path(Path(dst)) as tmp:
        onnx.save(proto, str(tmp))
        found = SteeringModel(tmp).monitor()  # read back as drive_server reads it
        if found is None or found[0] != spec:
            raise RuntimeError(f"{dst}: the monitor did not read back as written")
