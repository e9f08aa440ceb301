"""Ray, imported only when a command is asked for ``--backend ray`` (it is an optional extra)."""

from __future__ import annotations

from types import ModuleType

from tools.errors import CommandError

#: Where the runs of ``rbc eval`` and the worlds of ``rbc collect --worlds`` go: this machine, or Ray tasks.
BACKENDS = ("local", "ray")
INSTALL_HINT = 'install the cluster extra: pip install "robust-behavioral-cloning[cluster]"'


def import_ray() -> ModuleType:
    """The ``ray`` module, or a one-line error saying how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise CommandError("--backend ray needs Ray, which is not installed", INSTALL_HINT) from exc
    return ray


def init_ray(ray: ModuleType, workers: int, address: str | None) -> bool:
    """Join the cluster at ``address``, or start a private local instance with ``workers`` CPUs.

    Returns whether this process started Ray (and so shuts it down); an initialised Ray is reused.
    """
    if ray.is_initialized():
        return False
    if address:
        ray.init(address=address)
    else:
        ray.init(num_cpus=max(1, workers), include_dashboard=False, _node_ip_address="127.0.0.1")
    return True
